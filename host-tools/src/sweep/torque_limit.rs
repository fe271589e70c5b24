//! The torque and current limits an FMU sweep reached, from its trace. The drive itself counts
//! only the voltage circle's cut (`sweep_last_limited`): watching the torque and current
//! limits on every tick would cost the Cortex-M4 about 20 instructions each, past the tick
//! budget. The FMU's trace shows the torque command on every communication step, so on the
//! FMU the host names the results measured with the torque command at a limit as well: a
//! velocity-command amplitude of 100 rad/s on the default axis pins the torque at 2 N·m from
//! 10 Hz up and leaves the result decibels off, where the voltage flag says nothing.

use std::collections::BTreeMap;

use anyhow::{anyhow, Result};
use control_core::phase_shifted_sweep::SweepParams;
use control_core::torque_ceiling::{ExcitationEntry, TorqueCeiling};
use control_core::Params;

use crate::fmu::trace::Trace;

/// The torque command (N·m) from which a sample counts as limited: the drive's torque ceiling
/// for the sweep's injection point and dither (the stepped sine's; the PRBS mode adds none):
/// [`TorqueCeiling`], the velocity loop's clamp less the dither, which is added after it, or
/// the current limit's torque, whichever is lower (the current limit's only for a
/// torque-command injection, which the loop's clamp cannot cut and whose trace cannot tell
/// the loop's part), less a part in 10⁵ for the f32 rounding of the clamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TorqueLimits {
    pub ceiling: TorqueCeiling,
}

const ROUNDING: f64 = 1e-5;

impl TorqueLimits {
    pub fn of(params: &Params, settings: &SweepParams) -> Self {
        Self { ceiling: TorqueCeiling::of(params, ExcitationEntry::of(settings.point), settings.dither_in_use()) }
    }

    /// The torque command `torque` is at a limit.
    pub fn reached(&self, torque: f64) -> bool {
        torque.abs() >= self.lowest()
    }

    /// The torque from which a sample counts (N·m).
    pub fn lowest(&self) -> f64 {
        self.ceiling.torque as f64 * (1.0 - ROUNDING)
    }
}

/// Each frequency's share of its measured samples (one per communication step) with the torque
/// command at a limit, by frequency index (frequencies without measured samples are absent).
pub fn torque_limited_shares(t: &Trace, limits: &TorqueLimits) -> Result<BTreeMap<i64, f64>> {
    let column = |name: &str| t.column(name).ok_or_else(|| anyhow!("the FMU has no output {name}"));
    let (point, measuring, torque) = (column("acq_point")?, column("acq_measuring")?, column("torque_command_out")?);
    let mut counts: BTreeMap<i64, (usize, usize)> = BTreeMap::new();
    for i in 0..point.len() {
        if measuring[i] != 0.0 {
            let c = counts.entry(point[i] as i64).or_default();
            c.0 += 1;
            c.1 += limits.reached(torque[i]) as usize;
        }
    }
    Ok(counts.into_iter().map(|(k, (n, limited))| (k, limited as f64 / n as f64)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(rows: &[(f64, f64, f64)]) -> Trace {
        let mut t = Trace::new(["acq_point", "acq_measuring", "torque_command_out"].map(String::from).to_vec());
        for &(p, m, tq) in rows {
            t.rows.push([p, m, tq]);
        }
        t
    }

    /// On the default drive (a 2 N·m torque limit; 20 A at 0.1 N·m/A) a sample counts where
    /// the torque sits at a clamp, not below it, and only measured samples count.
    #[test]
    fn samples_at_a_clamp_count_per_frequency() {
        let params = Params::default();
        let settings = SweepParams { start_hz: 10.0, stop_hz: 20.0, points: 2, extra_hz: 0.0, ..Default::default() };
        let limits = TorqueLimits::of(&params, &settings);
        let at_loop = params.velocity.torque_limit as f64 - settings.dither as f64;
        assert!(limits.reached(at_loop) && limits.reached(-at_loop) && !limits.reached(0.99 * at_loop));
        let t = trace(&[
            (0.0, 0.0, 5.0), // not measuring: not counted
            (0.0, 1.0, at_loop),
            (0.0, 1.0, 0.1),
            (0.0, 1.0, -0.1),
            (0.0, 1.0, 0.2),
            (1.0, 1.0, 0.3),
            (1.0, 1.0, -0.3),
        ]);
        let shares = torque_limited_shares(&t, &limits).unwrap();
        assert_eq!(shares, BTreeMap::from([(0, 0.25), (1, 0.0)]));
        // A torque-command injection adds after the loop's clamp: only the current's counts.
        let point = control_core::excitation::InjectionPoint::TorqueCommand;
        let torque = TorqueLimits::of(&params, &SweepParams { point, ..settings });
        assert_eq!(torque.ceiling.clamp, control_core::torque_ceiling::TorqueClamp::CurrentLimit);
        let current = (params.motor.torque_constant() * params.current.max_current) as f64;
        assert!(torque.reached(current) && (current <= at_loop || !torque.reached(at_loop)));
    }
}
