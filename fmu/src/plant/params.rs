//! Plant parameters and their validation.

use std::fmt;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantParams {
    pub pole_pairs: u32,
    pub resistance: f64,
    pub ld: f64,
    pub lq: f64,
    pub flux_linkage: f64,
    pub bus_voltage: f64,
    pub motor_inertia: f64,
    pub load_inertia: f64,
    pub shaft_stiffness: f64,
    pub shaft_damping: f64,
    pub motor_coulomb: f64,
    pub motor_viscous: f64,
    pub load_coulomb: f64,
    pub load_viscous: f64,
    /// Optional second mode on the load (seed 001's anti-resonance): absorber inertia
    /// (0 = none), its spring and damping to the load.
    pub absorber_inertia: f64,
    pub absorber_stiffness: f64,
    pub absorber_damping: f64,
    /// Velocity scale of the smoothed Coulomb friction `Fc·tanh(ω/ω_s)` (rad/s).
    pub coulomb_velocity: f64,
    pub encoder_counts_per_rev: u32,
    /// What a real machine hides from its drive, which commissioning finds out: the rotor's
    /// mechanical angle from its electrical zero at power-up (rad; the encoder's counter starts
    /// at 0 there), and whether the counter counts down when the rotor turns forward.
    pub rotor_start_angle: f64,
    pub encoder_reversed: bool,
    /// The current sensors' offsets (A) and gains (1 = exact) of phases a and b.
    pub current_offset: [f64; 2],
    pub current_gain: [f64; 2],
    /// The inverter's dead-time voltage: each phase's voltage short by this against its
    /// current's sign (V; 0 = an ideal inverter).
    pub dead_time_voltage: f64,
    pub current_noise_std: f64,
    pub acceleration_noise_std: f64,
    pub noise_seed: u64,
    /// Base tick (s) and integration sub-steps per tick.
    pub tick: f64,
    pub substeps: u32,
}

impl Default for PlantParams {
    fn default() -> Self {
        Self {
            pole_pairs: 4,
            resistance: 0.3,
            ld: 0.5e-3,
            lq: 0.5e-3,
            flux_linkage: 0.1 / 6.0,
            bus_voltage: 48.0,
            motor_inertia: 5.0e-5,
            load_inertia: 1.0e-4,
            // k = J_L·(2π·150 Hz)²: anti-resonance 150 Hz, resonance 150·√3 ≈ 260 Hz;
            // c = 2·0.05·√(k·J_L): 5 % damping at the anti-resonance.
            shaft_stiffness: 88.83,
            shaft_damping: 0.009425,
            motor_coulomb: 0.01,
            motor_viscous: 1.0e-5,
            load_coulomb: 0.02,
            load_viscous: 2.0e-5,
            absorber_inertia: 0.0,
            absorber_stiffness: 0.0,
            absorber_damping: 0.0,
            coulomb_velocity: 0.05,
            encoder_counts_per_rev: 1 << 20,
            // Any angle: the drive commissions before anything moves.
            rotor_start_angle: 0.7,
            encoder_reversed: false,
            current_offset: [0.0; 2],
            current_gain: [1.0; 2],
            dead_time_voltage: 0.0,
            current_noise_std: 0.0,
            acceleration_noise_std: 0.0,
            noise_seed: 1,
            tick: 1.0 / 16_000.0,
            substeps: 1,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum PlantError {
    NotPositive {
        field: &'static str,
        value: f64,
    },
    Negative {
        field: &'static str,
        value: f64,
    },
    NotFinite {
        field: &'static str,
    },
    /// A term that the integrator does not solve exactly is too fast for the sub-step.
    TooStiff {
        mode: &'static str,
        rate: f64,
        substep: f64,
    },
}

impl fmt::Display for PlantError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotPositive { field, value } => write!(f, "plant {field} must be > 0 (got {value})"),
            Self::Negative { field, value } => write!(f, "plant {field} must be >= 0 (got {value})"),
            Self::NotFinite { field } => write!(f, "plant {field} is not a finite number"),
            Self::TooStiff { mode, rate, substep } => write!(
                f,
                "plant {mode} has a rate of {rate:.3e} 1/s: too fast for a sub-step of {substep:.3e} s \
                 (h·rate must stay below {STIFF_LIMIT}); raise plant.substeps or soften the model"
            ),
        }
    }
}

impl std::error::Error for PlantError {}

fn positive(field: &'static str, v: f64) -> Result<(), PlantError> {
    if !v.is_finite() {
        Err(PlantError::NotFinite { field })
    } else if v <= 0.0 {
        Err(PlantError::NotPositive { field, value: v })
    } else {
        Ok(())
    }
}

fn non_negative(field: &'static str, v: f64) -> Result<(), PlantError> {
    if !v.is_finite() {
        Err(PlantError::NotFinite { field })
    } else if v < 0.0 {
        Err(PlantError::Negative { field, value: v })
    } else {
        Ok(())
    }
}

/// Largest `h·rate` accepted for the explicitly integrated terms.
pub const STIFF_LIMIT: f64 = 0.5;

impl PlantParams {
    /// Integration sub-step (s).
    pub fn substep(&self) -> f64 {
        self.tick / self.substeps as f64
    }

    pub fn validate(&self) -> Result<(), PlantError> {
        positive("pole_pairs", self.pole_pairs as f64)?;
        positive("resistance", self.resistance)?;
        positive("ld", self.ld)?;
        positive("lq", self.lq)?;
        positive("flux_linkage", self.flux_linkage)?;
        positive("bus_voltage", self.bus_voltage)?;
        positive("motor_inertia", self.motor_inertia)?;
        positive("load_inertia", self.load_inertia)?;
        positive("shaft_stiffness", self.shaft_stiffness)?;
        non_negative("shaft_damping", self.shaft_damping)?;
        non_negative("motor_coulomb", self.motor_coulomb)?;
        non_negative("motor_viscous", self.motor_viscous)?;
        non_negative("load_coulomb", self.load_coulomb)?;
        non_negative("load_viscous", self.load_viscous)?;
        positive("coulomb_velocity", self.coulomb_velocity)?;
        non_negative("absorber_inertia", self.absorber_inertia)?;
        non_negative("absorber_damping", self.absorber_damping)?;
        if self.absorber_inertia > 0.0 {
            positive("absorber_stiffness", self.absorber_stiffness)?;
        } else {
            non_negative("absorber_stiffness", self.absorber_stiffness)?;
        }
        positive("encoder_counts_per_rev", self.encoder_counts_per_rev as f64)?;
        if !self.rotor_start_angle.is_finite() {
            return Err(PlantError::NotFinite { field: "rotor_start_angle" });
        }
        for (field, v) in [("current_offset_a", self.current_offset[0]), ("current_offset_b", self.current_offset[1])] {
            if !v.is_finite() {
                return Err(PlantError::NotFinite { field });
            }
        }
        for (field, v) in [("current_gain_a", self.current_gain[0]), ("current_gain_b", self.current_gain[1])] {
            positive(field, v)?;
        }
        non_negative("dead_time_voltage", self.dead_time_voltage)?;
        non_negative("current_noise_std", self.current_noise_std)?;
        non_negative("acceleration_noise_std", self.acceleration_noise_std)?;
        positive("tick", self.tick)?;
        positive("substeps", self.substeps as f64)?;

        let h = self.substep();
        let (jm, jl) = (self.motor_inertia, self.load_inertia);
        // The windings and the shaft are solved exactly; what is explicit is the friction
        // slope near zero speed, the electromechanical coupling (torque ↔ back-EMF through
        // the held speed) and the rotation of the stator voltage within a sub-step.
        let modes = [
            ("motor friction", (self.motor_coulomb / self.coulomb_velocity) / jm),
            ("load friction", (self.load_coulomb / self.coulomb_velocity) / jl),
            (
                "electromechanical coupling",
                (1.5 * (self.pole_pairs as f64 * self.flux_linkage).powi(2) / (self.lq * jm)).sqrt(),
            ),
        ];
        for (mode, rate) in modes {
            if rate * h > STIFF_LIMIT {
                return Err(PlantError::TooStiff { mode, rate, substep: h });
            }
        }
        Ok(())
    }
}
