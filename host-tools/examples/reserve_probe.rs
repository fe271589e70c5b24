use host_tools::autotune::axis_under_test::OnFmu;
use host_tools::autotune::bench::draw;
use host_tools::autotune::design::{design, margins_of, MarginGoal, SearchGrid};
use host_tools::autotune::drive_dynamics::DriveDynamics;
use host_tools::autotune::loop_plant;
use host_tools::autotune::measured_mechanics::measure_mechanics;
use host_tools::autotune::mechanics::Mechanics;
use host_tools::fmu::configuration::configuration;

fn main() -> anyhow::Result<()> {
    let seed: u64 = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(1);
    let n: u32 = std::env::args().nth(2).map(|s| s.parse().unwrap()).unwrap_or(200);
    let idxs: Vec<usize> = std::env::args().skip(3).map(|s| s.parse().unwrap()).collect();
    let machines = draw(n, seed);
    let fmu = host_tools::fmu::runner::Fmu::load(&host_tools::paths::default_fmu())?;
    let std = MarginGoal::named("standard").unwrap();
    for idx in idxs {
        let m = machines[idx];
        let parameters = m.parameters();
        let plant = configuration(&parameters)?.plant;
        let mut on = OnFmu(&fmu);
        let measured = measure_mechanics(&mut on, &parameters, 0.2, host_tools::sweep::bench::VELOCITY)?;
        let params = measured.params;
        let period = params.rates.velocity_period() as f64;
        let truth = Mechanics::of_plant(&plant);
        let td = DriveDynamics::on_plant(&params, &plant);
        let tp = |f: f64| loop_plant(&td, &truth, f);
        let model = |f: f64| measured.model(f);
        let mf = measured.calibration.mechanics.features_hz();
        println!("machine {idx} {m:?}");
        let tf = truth.features_hz();
        let od = design(&tp, period, &std, &SearchGrid::STANDARD, &tf);
        let or = od.and_then(|d| host_tools::autotune::refinement::refine(&tp, period, &std, &d, 4000, &tf));
        println!(
            "  oracle design on truth bw {:?} refined {:?}",
            od.map(|d| d.margins.bandwidth_hz),
            or.map(|d| (d.margins.bandwidth_hz, d.tuning))
        );
        if let Some(o) = or {
            let om = margins_of(&o.tuning, &model, period, 4000, &mf).unwrap();
            let grid = host_tools::autotune::margins::log_grid(1.0, 0.999 * 0.5 / period, 3000);
            let sens = |pl: &dyn Fn(f64) -> num_complex::Complex64, f: f64| {
                let l = o.tuning.response(f, period) * pl(f);
                (1.0 / (1.0 + l)).norm()
            };
            let (mut bt, mut bm) = ((0.0, 0.0), (0.0, 0.0));
            for &f in &grid {
                let a = sens(&tp, f);
                if a > bt.1 {
                    bt = (f, a)
                }
                let b = sens(&model, f);
                if b > bm.1 {
                    bm = (f, b)
                }
            }
            println!("  S peak truth {bt:?} model {bm:?}");
            for f in [20.0, 40.0, 48.0, 50.0, 52.0, 55.0, 60.0, 100.0, 300.0, 700.0, 1000.0, 1500.0] {
                let r = model(f) / tp(f);
                println!("   {f} Hz model/truth {:.4} dB {:.3} deg", 20.0 * r.norm().log10(), r.arg().to_degrees());
            }
            println!(
                "  oracle on model: bw {:.0} pm {:.2} gm {:.2} ms {:.3}",
                om.bandwidth_hz, om.phase_margin_deg, om.gain_margin_db, om.sensitivity_peak
            );
        }
        println!("  truth {:?}\n  model {:?}", truth, measured.calibration.mechanics);
        for (dp, dg, dm) in [(3.0, 1.0, 0.02), (0.5, 0.25, 0.01), (0.0, 0.0, 0.0)] {
            let goal = MarginGoal { phase_margin_deg: 45.0 + dp, gain_margin_db: 6.0 + dg, sensitivity_peak: 1.6 - dm };
            let d = design(&model, period, &goal, &SearchGrid::STANDARD, &mf);
            match d {
                Some(d) => {
                    let t = margins_of(&d.tuning, &tp, period, 4000, &truth.features_hz()).unwrap();
                    println!(
                        "  reserve {dp} {dg} {dm}: model bw {:.0} pm {:.2} | truth bw {:.0} pm {:.2} gm {:.2} ms {:.3} held {}",
                        d.margins.bandwidth_hz, d.margins.phase_margin_deg, t.bandwidth_hz, t.phase_margin_deg, t.gain_margin_db, t.sensitivity_peak, std.held_by(&t)
                    );
                }
                None => println!("  reserve {dp}: none"),
            }
        }
    }
    Ok(())
}
