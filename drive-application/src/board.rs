//! The board interface: what the application needs of the hardware, and nothing else.
//!
//! - [`PowerStage`], used by the control tick: the sample taken at the top of the PWM count
//!   (three shunt counts, the bus voltage count, the accelerometer's count), the encoder count, the break input, the
//!   shunt choice under the duties in force, the duties, the gate drive, the watchdog. The
//!   tick is the call of [`crate::drive::Drive::tick`] itself: the board calls it from its
//!   sampling interrupt (G474: ADC1's end of injected sequence).
//! - [`ParamFlash`], used by the link side: two flash pages for the parameter set.
//! - Serial bytes: the board's link task hands received bytes to
//!   [`crate::drive::Host::receive`] and sends the frames it returns (and those of
//!   [`crate::drive::Host::stream_frame`]); the application never waits on the port, so an
//!   async UART (Embassy), a pseudo-terminal or a test buffer all fit.

use control_core::current_sensing::SensingScales;

/// Shunt channels sampled per tick (U, V, W).
pub const CURRENT_CHANNELS: usize = 3;

/// One conversion of the sampling instant: shunt counts U, V, W, the bus voltage count and
/// the machine-end accelerometer's count (see `crate::accelerometer_input`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub shunts: [u16; CURRENT_CHANNELS],
    pub bus: u16,
    pub accelerometer: u16,
}

/// The power stage and its sensors, as the control tick uses them.
pub trait PowerStage {
    /// ADC counts to amperes and volts.
    const SCALES: SensingScales;
    /// Volts per count of the accelerometer's input (the converter's reference over its
    /// full scale).
    const ACCELEROMETER_VOLTS_PER_COUNT: f32;
    /// The PWM rate, at which the board samples and calls the tick (Hz): the only
    /// current-loop rate the drive accepts.
    const TICK_HZ: f32;
    /// This tick's sample (acknowledges the conversion).
    fn take_sample(&mut self) -> Sample;
    /// The encoder's quadrature count.
    fn encoder_count(&mut self) -> i32;
    /// The break input (the stage's own overcurrent comparator) switched the bridge off since
    /// the last call (clears the flag).
    fn break_tripped(&mut self) -> bool;
    /// The phase currents U and V (A) from the three shunt currents, believing the shunts
    /// whose low sides conducted long enough under `duties_in_force`.
    fn phase_currents(&self, shunt_amps: [f32; CURRENT_CHANNELS], duties_in_force: [f32; 3]) -> [f32; 2];
    /// Duty cycles 0..1 of the three half-bridges, in force from the next PWM period.
    fn write_duties(&mut self, duties: [f32; 3]);
    /// Gate drive on or off; off takes effect at once.
    fn set_outputs(&mut self, on: bool);
    /// One feed of the watchdog that resets the chip when the tick stops.
    fn feed_watchdog(&mut self);
}

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Offset or length not a multiple of [`ParamFlash::WRITE_BYTES`], or beyond the page.
    Alignment,
    /// The flash controller reported an error.
    Hardware,
}

/// Two pages of flash for the parameter set (page 0 and page 1). Programming writes erased
/// bytes only, in units of [`Self::WRITE_BYTES`] at offsets that are multiples of it. An erase
/// or a write may stall the processor (the G474's single flash bank): the board switches the
/// gate drive off and keeps the watchdog from firing meanwhile.
pub trait ParamFlash {
    /// Bytes of one page.
    const PAGE_BYTES: usize;
    /// Programming unit (8: the G474's double word).
    const WRITE_BYTES: usize;
    fn read(&mut self, page: usize, offset: usize, bytes: &mut [u8]) -> Result<(), FlashError>;
    /// Every byte of the page to 0xFF.
    fn erase(&mut self, page: usize) -> Result<(), FlashError>;
    fn program(&mut self, page: usize, offset: usize, bytes: &[u8]) -> Result<(), FlashError>;
}
