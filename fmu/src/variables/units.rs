//! Units of the variables with their SI base-unit exponents (the model description's
//! `BaseUnit`), and the type definition each unit is declared through.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    Second,
    Radian,
    RadianPerSecond,
    RadianPerSecondSquared,
    NewtonMetre,
    Ampere,
    Volt,
    Ohm,
    VoltPerAmpereSecond,
    Henry,
    Weber,
    KilogramMetreSquared,
    NewtonMetrePerRadian,
    NewtonMetreSecondPerRadian,
    Hertz,
    PerSecond,
    Decibel,
    Degree,
}

/// Exponents of kg, m, s, A and rad, and the factor to SI (`value_SI = factor · value`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseUnit {
    pub kg: i32,
    pub m: i32,
    pub s: i32,
    pub a: i32,
    pub rad: i32,
    pub factor: f64,
}

impl Unit {
    pub const ALL: [Unit; 18] = [
        Unit::Second,
        Unit::Radian,
        Unit::RadianPerSecond,
        Unit::RadianPerSecondSquared,
        Unit::NewtonMetre,
        Unit::Ampere,
        Unit::Volt,
        Unit::Ohm,
        Unit::VoltPerAmpereSecond,
        Unit::Henry,
        Unit::Weber,
        Unit::KilogramMetreSquared,
        Unit::NewtonMetrePerRadian,
        Unit::NewtonMetreSecondPerRadian,
        Unit::Hertz,
        Unit::PerSecond,
        Unit::Decibel,
        Unit::Degree,
    ];

    /// The unit's name as written in the model description (Modelica notation).
    pub fn name(self) -> &'static str {
        match self {
            Unit::Second => "s",
            Unit::Radian => "rad",
            Unit::RadianPerSecond => "rad/s",
            Unit::RadianPerSecondSquared => "rad/s2",
            Unit::NewtonMetre => "N.m",
            Unit::Ampere => "A",
            Unit::Volt => "V",
            Unit::Ohm => "Ohm",
            Unit::VoltPerAmpereSecond => "V/(A.s)",
            Unit::Henry => "H",
            Unit::Weber => "Wb",
            Unit::KilogramMetreSquared => "kg.m2",
            Unit::NewtonMetrePerRadian => "N.m/rad",
            Unit::NewtonMetreSecondPerRadian => "N.m.s/rad",
            Unit::Hertz => "Hz",
            Unit::PerSecond => "1/s",
            Unit::Decibel => "dB",
            Unit::Degree => "deg",
        }
    }

    /// The `Float64Type` (FMI 3.0) / `SimpleType` (FMI 2.0) that carries the unit.
    pub fn type_name(self) -> &'static str {
        match self {
            Unit::Second => "Time",
            Unit::Radian => "Angle",
            Unit::RadianPerSecond => "AngularVelocity",
            Unit::RadianPerSecondSquared => "AngularAcceleration",
            Unit::NewtonMetre => "Torque",
            Unit::Ampere => "Current",
            Unit::Volt => "Voltage",
            Unit::Ohm => "Resistance",
            Unit::VoltPerAmpereSecond => "CurrentIntegralGain",
            Unit::Henry => "Inductance",
            Unit::Weber => "MagneticFlux",
            Unit::KilogramMetreSquared => "Inertia",
            Unit::NewtonMetrePerRadian => "RotationalStiffness",
            Unit::NewtonMetreSecondPerRadian => "RotationalDamping",
            Unit::Hertz => "Frequency",
            Unit::PerSecond => "Rate",
            Unit::Decibel => "Gain",
            Unit::Degree => "PhaseAngle",
        }
    }

    /// The quantity (`quantity` attribute of the type).
    pub fn quantity(self) -> &'static str {
        self.type_name()
    }

    pub fn base(self) -> BaseUnit {
        let b = |kg, m, s, a, rad| BaseUnit { kg, m, s, a, rad, factor: 1.0 };
        match self {
            Unit::Second => b(0, 0, 1, 0, 0),
            Unit::Radian => b(0, 0, 0, 0, 1),
            Unit::RadianPerSecond => b(0, 0, -1, 0, 1),
            Unit::RadianPerSecondSquared => b(0, 0, -2, 0, 1),
            Unit::NewtonMetre => b(1, 2, -2, 0, 0),
            Unit::Ampere => b(0, 0, 0, 1, 0),
            Unit::Volt => b(1, 2, -3, -1, 0),
            Unit::Ohm => b(1, 2, -3, -2, 0),
            Unit::VoltPerAmpereSecond => b(1, 2, -4, -2, 0),
            Unit::Henry => b(1, 2, -2, -2, 0),
            Unit::Weber => b(1, 2, -2, -1, 0),
            Unit::KilogramMetreSquared => b(1, 2, 0, 0, 0),
            Unit::NewtonMetrePerRadian => b(1, 2, -2, 0, -1),
            Unit::NewtonMetreSecondPerRadian => b(1, 2, -1, 0, -1),
            Unit::Hertz => b(0, 0, -1, 0, 0),
            Unit::PerSecond => b(0, 0, -1, 0, 0),
            // A logarithmic ratio: dimensionless (no offset or factor expresses dB).
            Unit::Decibel => b(0, 0, 0, 0, 0),
            Unit::Degree => BaseUnit { factor: std::f64::consts::PI / 180.0, ..b(0, 0, 0, 0, 1) },
        }
    }
}
