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
    /// Bytes the drive wrote, not yet on the line.
    transmit: VecDeque<u8>,
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
            corrupt_rate: line.corrupt_rate,
            random: XorShift64Star(line.seed.max(1)),
            counters: LineCounters::default(),
        }
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

    /// The drive may start writing a frame (its transmit buffer is not full).
    pub fn may_write(&self) -> bool {
        self.transmit.len() < TRANSMIT_BUFFER
    }

    /// A frame from the drive, queued for the line.
    pub fn write(&mut self, bytes: &[u8]) {
        self.transmit.extend(bytes);
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
    }

    /// A number in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.random.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn maybe_corrupt(&mut self, b: u8) -> u8 {
        if self.corrupt_rate > 0.0 && self.uniform() < self.corrupt_rate {
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
        // Send: the same rate out; the transmit buffer says when it is full.
        uart.write(&[1; 2000]);
        assert!(!uart.may_write());
        for _ in 0..160 {
            uart.send(&mut wire, 1.0 / 16_000.0);
        }
        assert_eq!(wire.from_drive.len(), 921, "10 ms of line");
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
