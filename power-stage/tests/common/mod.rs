//! What the power-stage tests measure on the models: the bridge's gates over whole periods,
//! and the sensed currents through the amplifier, the ADC's sampling instants and the
//! firmware's conversion.
#![allow(dead_code)]

use control_core::current_sensing::{CurrentSensing, SensingScales, CALIBRATION_SAMPLES};
use control_core::reference_frames::{clarke, inverse_park, park, space_vector_duties, AlphaBeta, Dq};
use power_stage::adc_words::{phase_slot, sampling_window};
use power_stage::bridge::{leg_voltage, shunt_current, BridgeModel, Tick};
use power_stage::config::IHM08M1;
use power_stage::current_amplifier::IHM08M1 as AMPLIFIER;
use power_stage::gate_driver::Gates;
use power_stage::tim1_words::Tim1Words;

pub const CLOCK: u32 = IHM08M1.timer_clock_hz;

/// Per leg over the periods run: clocks with each gate on, with both on, and the longest
/// unbroken low-side and high-side pulses.
#[derive(Clone, Copy, Debug, Default)]
pub struct GateSummary {
    pub periods: u32,
    pub high_on: [u32; 3],
    pub low_on: [u32; 3],
    pub both_on: [u32; 3],
    pub longest_low_pulse: [u32; 3],
    pub longest_high_pulse: [u32; 3],
    pub triggers: u32,
}

pub fn run(model: &mut BridgeModel, ticks: u32, mut each: impl FnMut(&Tick)) {
    for _ in 0..ticks {
        let t = model.step();
        each(&t);
    }
}

/// Run `periods` whole periods (after one period to settle) and summarise the gates.
pub fn summarise(model: &mut BridgeModel, periods: u32) -> GateSummary {
    let p = model.period_ticks();
    run(model, p, |_| {});
    let mut s = GateSummary { periods, ..Default::default() };
    let mut low_run = [0u32; 3];
    let mut high_run = [0u32; 3];
    run(model, periods * p, |t| {
        s.triggers += t.trigger as u32;
        for k in 0..3 {
            let g = t.gates[k];
            s.high_on[k] += g.high as u32;
            s.low_on[k] += g.low as u32;
            s.both_on[k] += (g.high && g.low) as u32;
            low_run[k] = if g.low { low_run[k] + 1 } else { 0 };
            high_run[k] = if g.high { high_run[k] + 1 } else { 0 };
            s.longest_low_pulse[k] = s.longest_low_pulse[k].max(low_run[k]);
            s.longest_high_pulse[k] = s.longest_high_pulse[k].max(high_run[k]);
        }
    });
    s
}

/// Every gate off on every clock of `ticks`.
pub fn all_off_for(model: &mut BridgeModel, ticks: u32) -> bool {
    let mut off = true;
    run(model, ticks, |t| off &= t.gates.iter().all(|g| !g.high && !g.low));
    off
}

/// Whether each leg followed its duty with dead time: per period, the high side on for the
/// compare value's up-and-down time less one dead time, the low side for the rest less
/// another; `dead` is the gap expected at each edge (clocks).
pub fn follows_duties(s: &GateSummary, model: &BridgeModel, dead: u32) -> Result<(), String> {
    let period = model.period_ticks();
    for k in 0..3 {
        let high_ref = 2 * model.ccr[k];
        let want_high = high_ref.saturating_sub(dead) * s.periods;
        let want_low = (period - high_ref).saturating_sub(dead) * s.periods;
        let close = |a: u32, b: u32| a.abs_diff(b) <= 2 * s.periods;
        if !close(s.high_on[k], want_high) || !close(s.low_on[k], want_low) {
            return Err(format!(
                "leg {k}: high side on {} clocks, low side {} (want {want_high} and {want_low} over {} periods)",
                s.high_on[k], s.low_on[k], s.periods
            ));
        }
    }
    Ok(())
}

/// A star-connected resistive load at standstill driven by the bridge: the phase currents
/// (positive into the motor) in steady state, found by iterating on the dead-time voltages
/// (which depend on the currents' signs).
pub fn steady_currents(model: &mut BridgeModel, bus: f32, ohms: f32) -> [f32; 3] {
    let p = model.period_ticks();
    run(model, p, |_| {});
    let mut gates = Vec::with_capacity(p as usize);
    run(model, p, |t| gates.push(t.gates));
    let mut i = [0.0f32; 3];
    for _ in 0..6 {
        let mut v = [0.0f32; 3];
        for g in &gates {
            for k in 0..3 {
                v[k] += leg_voltage(g[k], i[k], bus);
            }
        }
        let v = v.map(|x| x / p as f32);
        let neutral = (v[0] + v[1] + v[2]) / 3.0;
        i = v.map(|x| (x - neutral) / ohms);
    }
    i
}

/// The counts the ADCs convert at the next trigger for these steady phase currents: each
/// shunt's current at the middle of its sampling window, through the amplifier model.
pub fn sampled_counts(model: &mut BridgeModel, currents: [f32; 3]) -> [u16; 3] {
    let p = model.period_ticks();
    let mut since: Option<u32> = None;
    let mut counts = [None; 3];
    run(model, 2 * p, |t| {
        if t.trigger && since.is_none() && counts.iter().all(|c| c.is_none()) {
            since = Some(0);
        }
        if let Some(n) = since {
            for k in 0..3 {
                let (start, end) = sampling_window(phase_slot(k).1);
                if n == (start + end) / 2 && counts[k].is_none() {
                    counts[k] = Some(AMPLIFIER.counts(shunt_current(t.gates[k], currents[k])));
                }
            }
            since = Some(n + 1);
        }
    });
    counts.map(|c| c.expect("a trigger in two periods"))
}

/// Sensing calibrated as the firmware does it: the bridge off, no current.
pub fn calibrated(scales: SensingScales) -> CurrentSensing<3> {
    let mut s = CurrentSensing::<3>::new(scales).unwrap();
    let zero = AMPLIFIER.counts(0.0);
    for _ in 0..CALIBRATION_SAMPLES {
        s.calibrate([zero; 3]).unwrap();
    }
    s
}

/// Duties of the core's modulator for a (d, q) voltage at electrical angle `theta`.
pub fn duties_for(v: Dq, theta: f32, bus: f32) -> [f32; 3] {
    let ab = inverse_park(v, libm::sinf(theta), libm::cosf(theta));
    space_vector_duties(ab, bus)
}

/// (d, q) of two phase currents at `theta`.
pub fn dq_of(ia: f32, ib: f32, theta: f32) -> Dq {
    let ab: AlphaBeta = clarke(ia, ib);
    park(ab, libm::sinf(theta), libm::cosf(theta))
}

/// A bridge on the words, gates on, with these duties.
pub fn bridge_on(words: Tim1Words, duties: [f32; 3]) -> BridgeModel {
    let mut m = BridgeModel::new(words, CLOCK);
    m.set_duties(duties);
    m.set_moe(true);
    m
}

pub fn gates_string(g: [Gates; 3]) -> String {
    g.iter().map(|g| format!("{}{}", g.high as u8, g.low as u8)).collect::<Vec<_>>().join(" ")
}
