//! Phase-current and bus-voltage sensing from ADC counts: offset calibration with the bridge
//! off, then scaling. The board gives the scales (shunt, amplifier gain, divider, reference);
//! this is the part that runs the same way on every board and can be tested on the host.
//!
//! The number of current channels is the board's (two shunts with the third phase computed,
//! or three shunts of which the board picks two per period). Calibration averages
//! [`CALIBRATION_SAMPLES`] conversions per current channel while no current flows. An offset further than [`OFFSET_WINDOW`] (a fraction of full scale) from
//! mid-scale means a broken amplifier, a missing power stage or a bridge that was not off:
//! sensing refuses to become ready and says which channel, so the bridge is never enabled on
//! made-up currents.

use core::fmt;

pub const CALIBRATION_SAMPLES: u32 = 1024;
/// Largest distance of a current offset from mid-scale, as a fraction of full scale.
pub const OFFSET_WINDOW: f32 = 0.1;

/// How the board's converters read the phase currents and the bus voltage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensingScales {
    /// Full-scale count (4095 for 12 bits).
    pub full_scale: u16,
    /// Phase current per count away from the offset (A/count; the sign makes positive
    /// current flow into the motor).
    pub amps_per_count: f32,
    /// Bus voltage per count (V/count).
    pub volts_per_count: f32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SensingError {
    /// A scale that is zero, negative where it must not be, or not finite.
    Scale,
    /// The offset of this phase channel (0, 1, ...) is too far from mid-scale.
    Offset { channel: usize, counts: f32 },
}

impl fmt::Display for SensingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Scale => {
                write!(f, "sensing scales must be finite and non-zero (full scale > 0, volts per count > 0)")
            }
            Self::Offset { channel, counts } => {
                write!(f, "current channel {channel}: offset {counts} counts is too far from mid-scale (amplifier, power stage, or bridge not off?)")
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum State<const N: usize> {
    Calibrating { sums: [u32; N], n: u32 },
    Ready { offsets: [f32; N] },
    Failed(SensingError),
}

/// `N` phase-current channels and the bus voltage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentSensing<const N: usize> {
    scales: SensingScales,
    state: State<N>,
}

impl<const N: usize> CurrentSensing<N> {
    pub fn new(scales: SensingScales) -> Result<Self, SensingError> {
        let ok = scales.full_scale > 0
            && scales.amps_per_count.is_finite()
            && scales.amps_per_count != 0.0
            && scales.volts_per_count.is_finite()
            && scales.volts_per_count > 0.0;
        if !ok {
            return Err(SensingError::Scale);
        }
        Ok(Self { scales, state: State::Calibrating { sums: [0; N], n: 0 } })
    }

    /// Feed one conversion while calibrating (the bridge must be off); returns whether the
    /// offsets are known now. After a failure it keeps returning the failure.
    pub fn calibrate(&mut self, currents: [u16; N]) -> Result<bool, SensingError> {
        match &mut self.state {
            State::Ready { .. } => Ok(true),
            State::Failed(e) => Err(*e),
            State::Calibrating { sums, n } => {
                for (s, &c) in sums.iter_mut().zip(currents.iter()) {
                    *s += c as u32;
                }
                *n += 1;
                if *n < CALIBRATION_SAMPLES {
                    return Ok(false);
                }
                let offsets = sums.map(|s| s as f32 / CALIBRATION_SAMPLES as f32);
                let mid = 0.5 * self.scales.full_scale as f32;
                let window = OFFSET_WINDOW * self.scales.full_scale as f32;
                if let Some(channel) = (0..N).find(|&c| (offsets[c] - mid).abs() > window) {
                    let e = SensingError::Offset { channel, counts: offsets[channel] };
                    self.state = State::Failed(e);
                    return Err(e);
                }
                self.state = State::Ready { offsets };
                Ok(true)
            }
        }
    }

    pub fn ready(&self) -> bool {
        matches!(self.state, State::Ready { .. })
    }

    /// The calibrated offsets (counts), for the log; None until calibrated.
    pub fn offsets(&self) -> Option<[f32; N]> {
        match self.state {
            State::Ready { offsets } => Some(offsets),
            _ => None,
        }
    }

    /// Start calibrating again (for instance after the power stage was switched on late).
    pub fn recalibrate(&mut self) {
        self.state = State::Calibrating { sums: [0; N], n: 0 };
    }

    /// Phase currents (A) and bus voltage (V); None until calibrated.
    pub fn convert(&self, currents: [u16; N], bus: u16) -> Option<([f32; N], f32)> {
        let State::Ready { offsets } = self.state else { return None };
        let k = self.scales.amps_per_count;
        let mut amps = [0.0; N];
        for c in 0..N {
            amps[c] = (currents[c] as f32 - offsets[c]) * k;
        }
        Some((amps, bus as f32 * self.scales.volts_per_count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCALES: SensingScales = SensingScales { full_scale: 4095, amps_per_count: -0.0155, volts_per_count: 0.0158 };

    #[test]
    fn offsets_are_averaged_then_counts_become_amps_and_volts() {
        let mut s = CurrentSensing::<2>::new(SCALES).unwrap();
        assert_eq!(s.convert([2048, 2048], 3000), None, "nothing before calibration");
        for k in 0..CALIBRATION_SAMPLES {
            // Offsets 2040 and 2060 with ±3 counts of noise that averages out.
            let n = [0i32, 3, -3][(k % 3) as usize];
            let done = s.calibrate([(2040 + n) as u16, (2060 - n) as u16]).unwrap();
            assert_eq!(done, k + 1 == CALIBRATION_SAMPLES);
        }
        assert!(s.ready());
        let o = s.offsets().unwrap();
        assert!((o[0] - 2040.0).abs() < 0.01 && (o[1] - 2060.0).abs() < 0.01, "{o:?}");
        let ([a, b], v) = s.convert([2140, 1960], 3000).unwrap();
        // 100 counts above and below the (noise-averaged) offsets; the noise left
        // 1/1024 of a count at most.
        assert!((a - 100.0 * -0.0155).abs() < 1e-3 && (b - -100.0 * -0.0155).abs() < 1e-3, "{a} {b}");
        assert!((v - 3000.0 * 0.0158).abs() < 1e-3);
    }

    #[test]
    fn an_offset_far_from_mid_scale_is_refused_and_stays_refused() {
        let mut s = CurrentSensing::<2>::new(SCALES).unwrap();
        let mut last = Ok(false);
        for _ in 0..CALIBRATION_SAMPLES {
            last = s.calibrate([2048, 100]);
        }
        assert!(matches!(last, Err(SensingError::Offset { channel: 1, .. })), "{last:?}");
        assert!(!s.ready());
        assert!(s.convert([2048, 2048], 1000).is_none());
        assert!(s.calibrate([2048, 2048]).is_err(), "a failure is not forgotten by more samples");
        s.recalibrate();
        assert_eq!(s.calibrate([2048, 2048]), Ok(false));
    }

    #[test]
    fn three_channels_each_with_its_offset_and_the_third_refused_by_its_number() {
        let mut s = CurrentSensing::<3>::new(SCALES).unwrap();
        for _ in 0..CALIBRATION_SAMPLES {
            s.calibrate([2000, 2050, 2100]).unwrap();
        }
        let ([a, b, c], _) = s.convert([2010, 2050, 2080], 0).unwrap();
        assert!((a - 10.0 * -0.0155).abs() < 1e-4 && b == 0.0 && (c - -20.0 * -0.0155).abs() < 1e-4, "{a} {b} {c}");
        let mut s = CurrentSensing::<3>::new(SCALES).unwrap();
        let mut last = Ok(false);
        for _ in 0..CALIBRATION_SAMPLES {
            last = s.calibrate([2048, 2048, 3000]);
        }
        assert!(matches!(last, Err(SensingError::Offset { channel: 2, .. })), "{last:?}");
    }

    #[test]
    fn bad_scales_are_refused() {
        for bad in [
            SensingScales { full_scale: 0, ..SCALES },
            SensingScales { amps_per_count: f32::NAN, ..SCALES },
            SensingScales { amps_per_count: 0.0, ..SCALES },
            SensingScales { volts_per_count: -1.0, ..SCALES },
        ] {
            assert_eq!(CurrentSensing::<3>::new(bad), Err(SensingError::Scale), "{bad:?}");
        }
    }
}
