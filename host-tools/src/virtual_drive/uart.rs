//! The serial line between the host and the virtual drive: bytes move at the configured baud
//! rate (10 bit times a byte: start, 8 data, stop), in both directions at once, and may be
//! corrupted on the way at a given rate (one bit flipped, as a noisy line does).
//!
//! The drive's side keeps the G474 firmware's transmit buffer (1 024 bytes, `BufferedUart`):
//! while it is full, the link task waits in `write_all` and serves nothing else.

use std::collections::VecDeque;

use crate::random::XorShift64Star;

/// The firmware's USART2 transmit buffer.
pub const TRANSMIT_BUFFER: usize = 1024;
/// Bit times per byte on the line (8N1).
pub const BITS_PER_BYTE: f64 = 10.0;

/// The two byte queues at the ends of the line: what the host wrote and the drive has not
/// received yet, and what the drive sent and the host has not read yet.
#[derive(Default)]
pub struct Wire {
    pub to_drive: VecDeque<u8>,
    pub from_drive: VecDeque<u8>,
}

/// Line settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineSettings {
    pub baud: u32,
    /// Probability that a byte is corrupted (one bit flipped), each direction.
    pub corrupt_rate: f64,
    pub seed: u64,
}

impl Default for LineSettings {
    fn default() -> Self {
        Self { baud: 921_600, corrupt_rate: 0.0, seed: 1 }
    }
}

/// What crossed the line.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LineCounters {
    pub bytes_to_drive: u64,
    pub bytes_from_drive: u64,
    pub corrupted: u64,
}

pub struct Uart {
    bytes_per_second: f64,
    receive_credit: f64,
    transmit_credit: f64,
    /// The transmit buffer: bytes the drive wrote, not yet on the line (at most
    /// [`TRANSMIT_BUFFER`]).
    transmit: VecDeque<u8>,
    /// The rest of the frame the link task is writing (`write_all` waits for room in the
    /// buffer byte by byte; meanwhile the task serves nothing else).
    writing: VecDeque<u8>,
    corrupt_rate: f64,
    random: XorShift64Star,
    pub counters: LineCounters,
}

impl Uart {
    pub fn new(line: LineSettings) -> Self {
        Self {
            bytes_per_second: line.baud as f64 / BITS_PER_BYTE,
            receive_credit: 0.0,
            transmit_credit: 0.0,
            transmit: VecDeque::new(),
            writing: VecDeque::new(),
            corrupt_rate: line.corrupt_rate,
            random: XorShift64Star(line.seed.max(1)),
            counters: LineCounters::default(),
        }
    }

    /// From now on each byte, each way, is corrupted with probability `rate` (the same random
    /// sequence carries on).
    pub fn set_corrupt_rate(&mut self, rate: f64) {
        self.corrupt_rate = rate;
    }

    /// Bytes a second the line carries each way.
    pub fn capacity(&self) -> f64 {
        self.bytes_per_second
    }

    /// The bytes that arrive at the drive during `dt` seconds (at most what the line carries;
    /// an idle line keeps no credit).
    pub fn receive(&mut self, wire: &mut Wire, dt: f64, mut deliver: impl FnMut(u8)) {
        self.receive_credit += self.bytes_per_second * dt;
        while self.receive_credit >= 1.0 {
            let Some(b) = wire.to_drive.pop_front() else {
                break;
            };
            self.receive_credit -= 1.0;
            self.counters.bytes_to_drive += 1;
            let b = self.maybe_corrupt(b);
            deliver(b);
        }
        self.receive_credit = self.receive_credit.min(1.0);
    }

    /// The link task is free: the frame it wrote last is all in the transmit buffer.
    pub fn may_write(&self) -> bool {
        self.writing.is_empty()
    }

    /// A frame from the drive: into the transmit buffer as far as it has room, the rest as
    /// room frees up.
    pub fn write(&mut self, bytes: &[u8]) {
        self.writing.extend(bytes);
        self.fill();
    }

    fn fill(&mut self) {
        while self.transmit.len() < TRANSMIT_BUFFER {
            let Some(b) = self.writing.pop_front() else { break };
            self.transmit.push_back(b);
        }
    }

    /// The bytes that leave the drive during `dt` seconds.
    pub fn send(&mut self, wire: &mut Wire, dt: f64) {
        self.transmit_credit += self.bytes_per_second * dt;
        while self.transmit_credit >= 1.0 {
            let Some(b) = self.transmit.pop_front() else {
                break;
            };
            self.transmit_credit -= 1.0;
            self.counters.bytes_from_drive += 1;
            let b = self.maybe_corrupt(b);
            wire.from_drive.push_back(b);
        }
        self.transmit_credit = self.transmit_credit.min(1.0);
        self.fill();
    }

    fn maybe_corrupt(&mut self, b: u8) -> u8 {
        if self.corrupt_rate > 0.0 && self.random.uniform() < self.corrupt_rate {
            self.counters.corrupted += 1;
            b ^ 1 << self.random.below(8)
        } else {
            b
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_move_at_the_baud_rate_and_corruption_at_its_rate() {
        let mut uart = Uart::new(LineSettings { baud: 921_600, corrupt_rate: 0.0, seed: 1 });
        let mut wire = Wire::default();
        wire.to_drive.extend(std::iter::repeat_n(7u8, 100_000));
        let mut got = 0usize;
        // One second in 16 kHz ticks.
        for _ in 0..16_000 {
            uart.receive(&mut wire, 1.0 / 16_000.0, |_| got += 1);
        }
        assert!((got as f64 - 92_160.0).abs() <= 1.0, "{got} bytes in one second at 921 600 Bd");
        // Send: the same rate out; a frame larger than the transmit buffer keeps the link task
        // waiting until the buffer has taken all of it.
        uart.write(&[1; 2000]);
        assert!(!uart.may_write());
        assert_eq!(uart.transmit.len(), TRANSMIT_BUFFER);
        for _ in 0..160 {
            uart.send(&mut wire, 1.0 / 16_000.0);
        }
        assert_eq!(wire.from_drive.len(), 921, "10 ms of line");
        assert!(!uart.may_write(), "1 079 bytes sent or in the buffer, 921 still to write");
        for _ in 0..160 {
            uart.send(&mut wire, 1.0 / 16_000.0);
        }
        assert!(uart.may_write(), "the whole frame is in the buffer after 20 ms");
        // Corruption at 1 %: about 1 % of bytes differ, by one bit each.
        let mut noisy = Uart::new(LineSettings { baud: 921_600, corrupt_rate: 0.01, seed: 3 });
        let mut wire = Wire::default();
        wire.to_drive.extend(std::iter::repeat_n(0u8, 200_000));
        let mut changed = 0;
        while !wire.to_drive.is_empty() {
            noisy.receive(&mut wire, 1e-3, |b| {
                if b != 0 {
                    assert_eq!(b.count_ones(), 1);
                    changed += 1;
                }
            });
        }
        assert!((1_700..2_300).contains(&changed), "{changed} of 200 000 at 1 %");
        assert_eq!(noisy.counters.corrupted, changed);
    }
}
