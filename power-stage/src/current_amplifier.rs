//! The IHM08M1's shunt amplifiers as the ADC sees them: 10 mΩ low-side shunts into amplifiers
//! of gain 5.18 biased at half the 3.3 V reference (UM1996), with the sign the board gives:
//! a phase current into the motor lowers the count. ST's motor-control SDK computes the
//! phase current as offset − ADC for this board, and Apache NuttX's IHM08M1 board support
//! gives the current-sense gain as −5.18 ("inverted current"). This model is the reference the
//! firmware's scales ([`crate::ratings::SCALES`]) are tested against.

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShuntAmplifier {
    pub shunt_ohm: f32,
    /// Output volts per shunt volt, in the phase current's sense (negative: inverting).
    pub gain: f32,
    /// Output at zero current, V.
    pub bias_volts: f32,
    /// ADC reference, V.
    pub vref: f32,
    pub full_scale: u16,
}

pub const IHM08M1: ShuntAmplifier =
    ShuntAmplifier { shunt_ohm: 0.010, gain: -5.18, bias_volts: 1.65, vref: 3.3, full_scale: 4095 };

impl ShuntAmplifier {
    /// The ADC count for a current through the shunt (A, positive in the phase current's
    /// sense: into the motor), rounded and limited to the converter's range.
    pub fn counts(&self, shunt_current: f32) -> u16 {
        let volts = self.bias_volts + self.gain * self.shunt_ohm * shunt_current;
        let c = volts / self.vref * self.full_scale as f32 + 0.5;
        if c <= 0.0 {
            0
        } else if c >= self.full_scale as f32 {
            self.full_scale
        } else {
            c as u16
        }
    }

    /// The largest current either way the converter can show from the bias (A).
    pub fn range_amps(&self) -> f32 {
        let headroom =
            if self.bias_volts < self.vref - self.bias_volts { self.bias_volts } else { self.vref - self.bias_volts };
        headroom / (self.shunt_ohm * self.gain.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn current_into_the_motor_lowers_the_count() {
        let a = IHM08M1;
        let mid = a.counts(0.0);
        assert_eq!(mid, 2048);
        // 10 A: 0.1 V on the shunt, 0.518 V at the output, 642.8 counts below the bias.
        assert!((mid - a.counts(10.0)).abs_diff(643) <= 1);
        assert!((a.counts(-10.0) - mid).abs_diff(643) <= 1);
        assert_eq!(a.counts(40.0), 0, "beyond the range: clipped");
        assert!((a.range_amps() - 31.85).abs() < 0.01);
    }
}
