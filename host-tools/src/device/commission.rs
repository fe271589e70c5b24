//! Commissioning a drive's motor over the link: the sequence started, waited on in the drive's
//! time, its result sent back as the drive's parameters (`Params::with_commissioned`); and an
//! experiment's parameters given the commissioned set the drive holds.

use anyhow::{bail, Result};
use control_core::commissioning::{CommissioningSettings, CommissioningStatus, MeasuredMotor};
use control_core::params::CurrentLoopGains;
use control_core::protocol::{Request, Response};
use control_core::Params;

use crate::device::link::DrivePort;
use crate::device::session::DriveSession;

/// The longest a commissioning may take (s of the drive's time).
pub const COMMISSIONING_LIMIT_S: f64 = 20.0;

/// What the drive told of a finished commissioning.
#[derive(Clone, Copy, Debug)]
pub struct Commissioned {
    pub measured: MeasuredMotor,
    /// The drive's time it took (s).
    pub seconds: f64,
    /// The parameters the drive runs with from now on.
    pub params: Params,
}

impl<T: DrivePort> DriveSession<T> {
    /// The parameters in force on the drive.
    pub fn params(&mut self) -> Result<Params> {
        match self.answer(&Request::GetParams)? {
            Response::Params(p) => Ok(p),
            Response::Refused(why) => bail!("the drive refused the parameters' request: {why}"),
            Response::FrameError(e) => bail!("the drive could not read the parameters' request: {e}"),
            other => bail!("unexpected answer to the parameters' request: {other:?}"),
        }
    }

    /// Commission the drive's motor with `settings` (its encoder's counts and its tick filled
    /// in from the drive's parameters): the sequence's result becomes the drive's parameters
    /// (not saved: [`DriveSession::save_params`] does that). A failure is an error with the
    /// sequence's reason; the drive keeps the bridge off and its parameters.
    pub fn commission(&mut self, settings: &CommissioningSettings) -> Result<Commissioned> {
        let before = self.params()?;
        let mut settings = *settings;
        settings.counts_per_rev = before.encoder_counts_per_rev;
        settings.tick_period = before.rates.tick_period();
        self.tick_hz = before.rates.current_loop_hz as f64;
        self.rest_allowing_no_commissioning()?;
        // From the start request on, every error stops the sequence (best effort: the request
        // may have acted although its answer was lost).
        let started = self.order(Request::Commission(settings), "the commissioning's start").and_then(|()| {
            let start = self.telemetry()?.tick;
            let end = self.wait_until(COMMISSIONING_LIMIT_S, |t| {
                Ok(!matches!(t.commissioning, Some(CommissioningStatus::Running(_))))
            })?;
            Ok((start, end))
        });
        let (start, end) = match started {
            Ok(both) => both,
            Err(e) => {
                let _ = self.order(Request::StopCommissioning, "the commissioning's stop");
                return Err(e);
            }
        };
        let seconds = end.tick.saturating_sub(start) as f64 / self.tick_hz;
        let measured = match end.commissioning {
            Some(CommissioningStatus::Done(m)) => m,
            Some(CommissioningStatus::Failed(fault)) => {
                bail!("commissioning failed after {seconds:.2} s: {fault:?} (the bridge is off; nothing was kept)")
            }
            other => bail!("the drive reports no finished commissioning ({other:?})"),
        };
        // Each commissioning decides the back-EMF feed-forward afresh (one that turned it off
        // on this drive's encoder before, at a smaller test current say, leaves no trace).
        let fresh = Params { current: CurrentLoopGains { decoupling: true, ..before.current }, ..before };
        let params = fresh.with_commissioned(&measured);
        self.order(Request::SetParams(params), "the commissioned parameters")?;
        Ok(Commissioned { measured, seconds, params })
    }

    /// [`DriveSession::commission`] with the default settings for the drive's encoder and tick
    /// (2 A, 12 V, 3/32 of the loop rate): what the in-process virtual drive's benches
    /// do before their experiments, as a user does once on a new machine.
    pub fn commission_with_defaults(&mut self) -> Result<Commissioned> {
        let p = self.params()?;
        self.commission(&CommissioningSettings::for_params(&p))
    }

    /// `params` as the drive runs them: the motor's constants, the encoder's mounting, the
    /// current loop's gains and its back-EMF feed-forward's choice are always the drive's own
    /// commissioned set, whatever `params`
    /// says (a plan's set is its twin's plant's, and the twin of a real machine does not know
    /// how the machine's encoder sits: its mounting given to the drive could reverse the
    /// torque); the twin runs with the same motor and gains ([`crate::fmu::runner::Fmu::as_twin_of`]).
    /// A drive that has no commissioned set is an error that says what to do.
    pub fn with_drive_commissioning(&mut self, params: &Params) -> Result<Params> {
        let drive = self.params()?;
        if !drive.commissioned {
            bail!(
                "the drive's motor is not commissioned: run `servo commission --device PORT` first (it measures the \
                 motor and the encoder's mounting; --save keeps them in the drive's flash)"
            );
        }
        // The measured mounting is in the drive's encoder counts: a plan of another resolution
        // (its twin's plant's) would turn it into another angle.
        if params.encoder_counts_per_rev != drive.encoder_counts_per_rev {
            bail!(
                "the run's encoder has {} counts per revolution, the drive's {}: set plant.encoder_counts_per_rev={} \
                 for the run (the drive's commissioning measured its encoder's mounting in its own counts)",
                params.encoder_counts_per_rev,
                drive.encoder_counts_per_rev,
                drive.encoder_counts_per_rev
            );
        }
        // The gains and the feed-forward's choice are the drive's commissioning's (it turns the
        // back-EMF feed-forward off on a coarse encoder under a strong magnet).
        let current = CurrentLoopGains {
            kp: drive.current.kp,
            ki: drive.current.ki,
            decoupling: drive.current.decoupling,
            ..params.current
        };
        Ok(Params {
            motor: drive.motor,
            encoder_mounting: drive.encoder_mounting,
            commissioned: true,
            current,
            ..*params
        })
    }
}
