//! The FMI 2.0 archive through the `fmi` crate's FMI 2.0 import: the position-step scenario
//! gives, in every output at every step, the bits of the Rust host's run of the FMI 3.0
//! archive (one binary, one model).

use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common};
use host_tools::fmu::scenario::Scenario;
use host_tools::paths::{default_fmu, workspace_root};
use servo_axis::variables::{by_name, Kind};

#[test]
fn the_fmi_crates_fmi2_import_gives_the_rust_hosts_bits() {
    let fmi2 = default_fmu().with_file_name("servo_axis_fmi2.fmu");
    assert!(fmi2.exists(), "{} is missing: run the bundle (scripts/test does)", fmi2.display());
    let scenario = Scenario::load(&workspace_root().join("scenarios/position_step.toml")).unwrap();
    let reference = cross_checks::load_fmu().run(&scenario, |_| {}).unwrap();

    let import: Fmi2Import = fmi::import::from_path(&fmi2).expect("the fmi crate imports the FMI 2.0 archive");
    let mut inst = import.instantiate_cs("axis", false, false).expect("instantiates");
    inst.setup_experiment(None, 0.0, None).unwrap();
    inst.enter_initialization_mode().unwrap();
    inst.exit_initialization_mode().unwrap();
    let columns: Vec<(u32, Kind)> = reference.columns[1..]
        .iter()
        .map(|n| {
            let d = by_name(n).unwrap_or_else(|| panic!("{n}"));
            (d.vr, d.kind)
        })
        .collect();
    let read = |inst: &mut fmi::fmi2::instance::Instance<fmi::CS>| -> Vec<f64> {
        columns
            .iter()
            .map(|&(vr, kind)| match kind {
                Kind::Float64 => {
                    let mut v = [0.0];
                    inst.get_real(&[vr], &mut v).unwrap();
                    v[0]
                }
                Kind::Int32 => {
                    let mut v = [0];
                    inst.get_integer(&[vr], &mut v).unwrap();
                    v[0] as f64
                }
                Kind::Boolean => {
                    let mut v = [0];
                    inst.get_boolean(&[vr], &mut v).unwrap();
                    v[0] as f64
                }
            })
            .collect()
    };
    let h = 0.00025;
    let command = by_name("position_command").unwrap().vr;
    let mut rows = vec![read(&mut inst)];
    for k in 0..reference.rows.len() - 1 {
        let t = k as f64 * h;
        if (t - 0.01).abs() < 0.5 * h {
            inst.set_real(&[command], &[1.0]).unwrap();
        }
        inst.do_step(t, h, true).unwrap();
        rows.push(read(&mut inst));
    }
    let mut compared = 0;
    for (k, (row, reference)) in rows.iter().zip(&reference.rows).enumerate() {
        for (c, (a, b)) in row.iter().zip(&reference[1..]).enumerate() {
            assert_eq!(
                a.to_bits(),
                b.to_bits(),
                "row {k}, {}: fmi crate FMI 2.0 {a} vs Rust host FMI 3.0 {b}",
                reference_name(c)
            );
            compared += 1;
        }
    }
    assert!(rows.last().unwrap().iter().any(|x| *x != 0.0), "the axis moved");
    println!("fmi crate FMI 2.0 import: {compared} values, bit for bit");

    fn reference_name(c: usize) -> String {
        format!("column {}", c + 1)
    }
}
