//! Faults the virtual drive injects at a given time (`--fault KIND@SECONDS`, seconds since it
//! started), as a bench test of a board would provoke them:
//!
//! - `encoder-disconnect`: the encoder cable comes off. The G474 counts quadrature edges in
//!   TIM2; with the lines open, the bridge's switching noise makes the counter run off: the
//!   count runs off by three quarters of a revolution within a tick and then stands still.
//!   The core's plausibility check (more than half a revolution in a tick) sees the jump.
//! - `break`: the power stage's overcurrent comparator trips: TIM1's break input switches the
//!   bridge off at once (hardware) and flags it; the drive latches the fault.
//! - `undervoltage`: the bus supply sags to [`UNDERVOLTAGE_VOLTS`] and stays there.

use anyhow::{anyhow, bail, Result};

/// The bus voltage after an `undervoltage` fault: below the board's 10 V trip.
pub const UNDERVOLTAGE_VOLTS: f64 = 8.0;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardFault {
    EncoderDisconnect,
    Break,
    Undervoltage,
}

impl BoardFault {
    pub const ALL: [Self; 3] = [Self::EncoderDisconnect, Self::Break, Self::Undervoltage];

    pub fn name(self) -> &'static str {
        match self {
            Self::EncoderDisconnect => "encoder-disconnect",
            Self::Break => "break",
            Self::Undervoltage => "undervoltage",
        }
    }
}

/// A fault and when it happens (s since start).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduledFault {
    pub fault: BoardFault,
    pub at: f64,
}

impl std::str::FromStr for ScheduledFault {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Self> {
        let names = || BoardFault::ALL.map(BoardFault::name).join(", ");
        let (kind, at) =
            s.split_once('@').ok_or_else(|| anyhow!("`{s}`: a fault is KIND@SECONDS (KIND: {})", names()))?;
        let fault = BoardFault::ALL
            .into_iter()
            .find(|f| f.name() == kind.trim())
            .ok_or_else(|| anyhow!("`{kind}` is not a fault the virtual drive injects ({})", names()))?;
        let at: f64 =
            at.trim().trim_end_matches('s').parse().map_err(|_| anyhow!("`{at}` is not a time in seconds"))?;
        if !(at.is_finite() && at >= 0.0) {
            bail!("a fault's time must be a finite number of seconds ≥ 0 (got {at})");
        }
        Ok(Self { fault, at })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_with_their_time_and_bad_ones_say_why() {
        let f: ScheduledFault = "break@2.5".parse().unwrap();
        assert_eq!(f, ScheduledFault { fault: BoardFault::Break, at: 2.5 });
        let f: ScheduledFault = "encoder-disconnect@1s".parse().unwrap();
        assert_eq!(f.fault, BoardFault::EncoderDisconnect);
        for (bad, why) in
            [("break", "KIND@SECONDS"), ("fire@1", "not a fault"), ("break@x", "not a time"), ("break@-1", "≥ 0")]
        {
            let e = bad.parse::<ScheduledFault>().unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
