//! The sensors' noise variance for a slow q winding's free-rotor fit, one fit solve a tick. The
//! variance read at zero voltage (`sensor_noise`) is known to a tenth or so (16 ms of
//! readings), and the fit's resistance, which shows at the low frequencies the differences
//! weigh least, moves by the winding's own over a tenth of it (its inductance by a few tenths
//! of a percent): the variance within [`NOISE_SEARCH`] of the one read that gives the holds'
//! resistance is taken, where there is one, else the one read. More noise taken out reads
//! less resistance, down to none (no winding at all): the holds' lies between the search's
//! ends when it lies anywhere. Each evaluation is a fit's solve (an elimination and two
//! logarithms, a thousand-odd instructions on the Cortex-M4F): one a tick, the search's
//! nineteen spread over as many ticks.

use super::winding_fit::Winding;

/// The range around the variance read (its shares) and the bisections within it.
const NOISE_SEARCH: [f32; 2] = [0.6, 1.5];
const NOISE_BISECTIONS: u32 = 16;

#[derive(Clone, Copy, Debug, Default)]
pub struct NoiseMatching {
    /// The variance read at zero voltage (A²), and the bracket searched.
    read: f32,
    low: f32,
    high: f32,
    /// Evaluations made.
    step: u32,
    /// The bracket's ends do not straddle the holds' resistance (or nothing was read): the
    /// variance read is taken.
    fallback: bool,
    /// The fit found, once the search has ended.
    result: Option<Option<Winding>>,
}

impl NoiseMatching {
    /// A search around the variance `read` (A², on the fitted axis).
    pub fn new(read: f32) -> Self {
        Self {
            read,
            low: NOISE_SEARCH[0] * read,
            high: NOISE_SEARCH[1] * read,
            fallback: !(read > 0.0),
            ..Self::default()
        }
    }

    /// The fit found (`None` within: no winding), once the search has ended.
    pub fn result(&self) -> Option<Option<Winding>> {
        self.result
    }

    /// One evaluation of `winding_at` (the fit with a variance taken out), against the holds'
    /// `resistance`; the fit found once the search ends.
    pub fn advance(&mut self, winding_at: impl Fn(f32) -> Option<Winding>, resistance: f32) -> Option<Option<Winding>> {
        if self.result.is_some() {
            return self.result;
        }
        let above = |w: Option<Winding>| w.is_some_and(|w| w.resistance >= resistance);
        let step = self.step;
        self.step += 1;
        if self.fallback {
            self.result = Some(winding_at(self.read));
        } else if step == 0 {
            self.fallback = !above(winding_at(self.low));
        } else if step == 1 {
            self.fallback = above(winding_at(self.high));
        } else if step < 2 + NOISE_BISECTIONS {
            let middle = 0.5 * (self.low + self.high);
            if above(winding_at(middle)) {
                self.low = middle;
            } else {
                self.high = middle;
            }
        } else {
            self.result = Some(winding_at(self.low));
        }
        self.result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit whose resistance falls linearly with the variance taken out (1 Ω at none, 0 at
    /// 2·10⁻⁶ A², no winding beyond): the search ends on the variance that gives the holds'
    /// resistance, one evaluation a tick, in 19 ticks; where the bracket holds no such
    /// variance, or nothing was read, on the variance read.
    #[test]
    fn the_variance_giving_the_holds_resistance_is_found_one_solve_a_tick() {
        let fit = |v: f32| (v < 2e-6).then(|| Winding { inductance: 1e-3 + v, resistance: 1.0 - v / 2e-6 });
        let run = |read: f32, resistance: f32| {
            let mut m = NoiseMatching::new(read);
            let calls = core::cell::Cell::new(0);
            let counted = |v: f32| {
                calls.set(calls.get() + 1);
                fit(v)
            };
            let mut ticks = 0;
            let found = loop {
                ticks += 1;
                let before = calls.get();
                let r = m.advance(counted, resistance);
                assert_eq!(calls.get(), before + 1, "one solve a tick");
                if let Some(r) = r {
                    break r;
                }
            };
            assert_eq!(m.advance(|_| panic!("solved again"), resistance), Some(found));
            (found, ticks)
        };
        // Read 1·10⁻⁶: the holds' 0.55 Ω lies at 0.9·10⁻⁶, within [0.6, 1.5]·read.
        let (found, ticks) = run(1e-6, 0.55);
        assert_eq!(ticks, 19);
        let w = found.unwrap();
        assert!((w.resistance - 0.55).abs() < 1e-4 && w.resistance >= 0.55, "{w:?}");
        // The holds' 0.9 Ω lies at 0.2·10⁻⁶, below the bracket, and their 0.1 Ω at 1.8·10⁻⁶,
        // above it: the variance read.
        assert_eq!(run(1e-6, 0.9), (fit(1e-6), 2));
        assert_eq!(run(1e-6, 0.1), (fit(1e-6), 3));
        // Nothing read: that fit, at once.
        let (found, ticks) = run(0.0, 0.55);
        assert_eq!((found, ticks), (fit(0.0), 1));
    }
}
