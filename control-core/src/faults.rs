//! Latched fault flags. Any fault switches the PWM off until cleared.

/// Bit set of latched faults.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Faults(pub u32);

impl Faults {
    pub const OVERCURRENT: u32 = 1 << 0;
    pub const BUS_UNDERVOLTAGE: u32 = 1 << 1;
    pub const BUS_OVERVOLTAGE: u32 = 1 << 2;
    pub const FOLLOWING_ERROR: u32 = 1 << 3;
    pub const NOT_FINITE: u32 = 1 << 4;
    pub const ENCODER: u32 = 1 << 5;
    /// The power stage's own protection (the timer's break input) switched the bridge off.
    pub const HARDWARE_BREAK: u32 = 1 << 6;
    /// Current sensing is not calibrated or its offsets are implausible.
    pub const SENSING: u32 = 1 << 7;
    /// A set-point outside its range (`crate::ranges`) reached the loop.
    pub const COMMAND_RANGE: u32 = 1 << 8;
    /// A mode was asked of an axis whose motor is not commissioned (`Params::commissioned`).
    pub const NOT_COMMISSIONED: u32 = 1 << 9;

    pub fn any(self) -> bool {
        self.0 != 0
    }
    pub fn contains(self, bit: u32) -> bool {
        self.0 & bit != 0
    }
    pub fn latch(&mut self, bit: u32) {
        self.0 |= bit;
    }
    /// Names of the set bits, for logs and reports.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [(u32, &str); 10] = [
            (Faults::OVERCURRENT, "overcurrent"),
            (Faults::BUS_UNDERVOLTAGE, "bus undervoltage"),
            (Faults::BUS_OVERVOLTAGE, "bus overvoltage"),
            (Faults::FOLLOWING_ERROR, "following error"),
            (Faults::NOT_FINITE, "non-finite value in the loop"),
            (Faults::ENCODER, "encoder jump"),
            (Faults::HARDWARE_BREAK, "hardware break input"),
            (Faults::SENSING, "current sensing not calibrated"),
            (Faults::COMMAND_RANGE, "command out of range"),
            (Faults::NOT_COMMISSIONED, "motor not commissioned"),
        ];
        NAMES.into_iter().filter(move |(b, _)| self.0 & b != 0).map(|(_, n)| n)
    }
}

/// The set bits' names joined by ", ", or "none": for logs and error messages.
impl core::fmt::Display for Faults {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if !self.any() {
            return f.write_str("none");
        }
        for (k, name) in self.names().enumerate() {
            if k > 0 {
                f.write_str(", ")?;
            }
            f.write_str(name)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    #[test]
    fn shown_as_the_names_of_the_set_bits() {
        assert_eq!(Faults::default().to_string(), "none");
        let mut f = Faults::default();
        f.latch(Faults::HARDWARE_BREAK);
        f.latch(Faults::OVERCURRENT);
        assert_eq!(f.to_string(), "overcurrent, hardware break input");
    }
}
