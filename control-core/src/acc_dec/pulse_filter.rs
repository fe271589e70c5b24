//! The designed Butterworth running on pulses per position tick, with whole-pulse output that
//! keeps the commanded position within a count of the designed filter.
//!
//! **Whole pulses.** Each tick the filter's *lag* — the pulses taken in and not yet given out
//! by the ideal filter, what it would still emit if the input stopped now — is rounded, and the
//! output is what makes the integer stock of pulses inside equal to it. The sum of the output
//! equals the sum of the input exactly once the filter has settled, and the commanded position
//! (the running sum of the output) differs from the designed filter's by the rounding (half a
//! count) plus the error of the computed lag.
//!
//! **Why not f32 sections.** The lag of a direct-form section is `(s1 + s2)/(1 + a1 + a2)`:
//! with poles near `z = 1` the denominator is `(ωc·T)²` (1.5·10⁻⁷ at 0.5 Hz and 0.125 ms), so
//! state rounding is amplified ~10⁷ times, and f32 cannot even represent that denominator from
//! `a1 ≈ −2`, `a2 ≈ 1`. For a move of 10⁹ counts the lag is ~10⁹ and must be right to better than
//! half a count: more than 31 bits, beyond f32 states whatever the form. The Cortex-M4F has no
//! f64 unit (software f64 would cost thousands of instructions per tick), but it multiplies
//! 32 × 32 → 64 bits in one instruction.
//!
//! **The form.** Integer states (i64, 2⁻²⁸ count resolution, [`super::fixed_point`]) in a delta
//! form whose states are the lag itself and the output velocity:
//! - the zeros first, on the integer input, exactly: the one-tick delay and `(1 + z⁻¹)^{N−1}`
//!   (seed) or `z⁻ᴺ` (all delays) as a cascade of `N` integer stages; their lag is kept
//!   exactly as an integer;
//! - then one section per pole pair, `c0 / (1 + a1·z⁻¹ + a2·z⁻²)` with `c0 = 1 + a1 + a2`, as
//!   `m = e + x`, `y ← y + c0·m − (1 − a2)·y`, `e ← m − y` (`e` the section's lag, `y` its output),
//!   which is the same difference equation rewritten with `δ = z − 1`: both coefficients are the
//!   design's well-conditioned values (`c0 ≈ (ωc·T)²`, `1 − a2 ≈ 2ζ·ωc·T`), none is near 1;
//! - and the real pole `(1 − p)/(1 − p·z⁻¹)` of an odd order as `m = e + x`, `e ← m − (1 − p)·m`.
//!
//! The filter's lag is the sum of the stages' lags: no division, nothing amplified by
//! `1/(ωc·T)²` except the rounding of `y` (2⁻²⁹ counts a product: at most `2⁻²⁹/c0 ≈ 0.01`
//! count of lag at the 0.5 Hz / 0.125 ms corner), and the coefficients carry the design's 53
//! bits. An error-feedback form would also remove the amplification but needs the rounding
//! residue of every product carried; double-f32 states cost more instructions than these
//! integer ones. `servo bench accdec` runs the grid (orders 1–6, 0.5 Hz to a quarter of the
//! sampling rate, 0.125–2 ms, moves of 1 to 10⁹ counts as one-tick steps, rectangles and
//! trapezoids of velocity) against the f64 reference ([`super::reference`]).
//!
//! **Range.** One tick takes at most ±2³¹ counts into the filter (the rest of a larger jump
//! passes straight through, still counted), and every state is kept within ±2³¹ counts: no
//! intermediate sum can overflow, and a lag beyond (a jog at hundreds of millions of counts
//! per second through a cut-off of a few hertz) saturates instead of wrapping.

use super::butterworth::{ButterworthDesign, ZeroPlacement, MAX_ORDER, MAX_PAIRS};
use super::fixed_point::{limit, Coefficient, FRACTION_BITS};

/// Most pulses one tick takes into the filter's states.
pub const MAX_FILTERED_PULSES: i64 = 1 << 31;
/// The lags are summed at 2⁻²⁷ counts so that the sum cannot overflow (the truncation, below
/// 4·2⁻²⁷ counts, is far below the states' own error).
const LAG_GUARD_BITS: u32 = 3;

/// One zero stage: `(1 + z⁻¹)` (mask −1) or `z⁻¹` (mask 0), on integers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct ZeroStage {
    previous: i64,
    mask: i64,
}

/// A pole pair's section: coefficients and state (lag and output, fixed point).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PairSection {
    dc: Coefficient,
    one_minus_a2: Coefficient,
    lag: i64,
    velocity: i64,
}

/// The real pole's section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RealSection {
    one_minus_pole: Coefficient,
    lag: i64,
}

/// The designed filter running on pulses per tick, with whole-pulse output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ButterworthPulseFilter {
    design: ButterworthDesign,
    zero_stages: [ZeroStage; MAX_ORDER as usize],
    /// Factors `(1 + z⁻¹)` among them: their output is scaled by 2^this.
    zero_bits: u32,
    /// Lag of the zero stages (exact), in 2^−zero_bits counts.
    zero_lag: i64,
    pairs: [Option<PairSection>; MAX_PAIRS],
    real: Option<RealSection>,
    /// Pulses taken in and not yet given out (exact).
    stock: i64,
}

impl ButterworthPulseFilter {
    pub fn new(design: ButterworthDesign) -> Self {
        let n = design.order as usize;
        let mut zero_stages = [ZeroStage::default(); MAX_ORDER as usize];
        // Stage 0 is the kept delay; the seed's other N − 1 are (1 + z⁻¹), python-control's
        // are delays too.
        let zero_bits = match design.zeros {
            ZeroPlacement::Seed => {
                for s in &mut zero_stages[1..n] {
                    s.mask = -1;
                }
                n as u32 - 1
            }
            ZeroPlacement::AllDelays => 0,
        };
        let mut pairs = [None; MAX_PAIRS];
        for (section, p) in pairs.iter_mut().zip(design.pole_pairs()) {
            *section = Some(PairSection {
                dc: Coefficient::new(p.dc),
                one_minus_a2: Coefficient::new(p.one_minus_a2),
                lag: 0,
                velocity: 0,
            });
        }
        let real = design.real_pole().map(|r| RealSection { one_minus_pole: Coefficient::new(r.one_minus_pole), lag: 0 });
        Self { design, zero_stages, zero_bits, zero_lag: 0, pairs, real, stock: 0 }
    }

    pub fn design(&self) -> &ButterworthDesign {
        &self.design
    }

    /// Pulses inside the filter (taken in, not yet given out).
    pub fn stock(&self) -> i64 {
        self.stock
    }

    /// The filter's lag before rounding (counts): what [`Self::stock`] is the rounding of.
    pub fn pending(&self) -> f64 {
        let lags = self.pairs.iter().flatten().map(|p| p.lag).chain(self.real.map(|r| r.lag));
        let states = lags.map(|l| l as f64).sum::<f64>() / (1u64 << FRACTION_BITS) as f64;
        states + self.zero_lag as f64 / (1u64 << self.zero_bits) as f64
    }

    /// The largest state magnitude (a section's lag or output, counts), against the limit of
    /// 2³¹ counts (for the bench's headroom figure).
    pub fn largest_state(&self) -> f64 {
        let pairs = self.pairs.iter().flatten().flat_map(|p| [p.lag, p.velocity]);
        let largest = pairs.chain(self.real.map(|r| r.lag)).map(i64::unsigned_abs).max().unwrap_or(0);
        largest as f64 / (1u64 << FRACTION_BITS) as f64
    }

    /// Empty the filter: zero state, no pulse inside.
    pub fn reset(&mut self) {
        *self = Self::new(self.design);
    }

    /// One tick: `pulses` in, whole pulses out.
    pub fn step(&mut self, pulses: i64) -> i64 {
        let n = self.design.order as usize;
        let u = pulses.clamp(-MAX_FILTERED_PULSES, MAX_FILTERED_PULSES);
        // Zeros: |w| ≤ 2^zero_bits · 2³¹, |zero_lag| ≤ N · 2^zero_bits · 2³¹.
        let mut w = u;
        for s in &mut self.zero_stages[..n] {
            let previous = core::mem::replace(&mut s.previous, w);
            w = previous + (w & s.mask);
        }
        self.zero_lag += (u << self.zero_bits) - w;
        let scale = FRACTION_BITS - self.zero_bits;
        // |x| ≤ 2⁶¹ (2³¹ counts), then a section's output (≤ 2⁶¹).
        let mut x = w << scale;
        // The lags are summed with LAG_GUARD_BITS fewer fractional bits (≤ 6·2⁵⁸ + 4·2⁵⁸).
        let mut lag = self.zero_lag << (scale - LAG_GUARD_BITS);
        for p in self.pairs.iter_mut().flatten() {
            // |m| ≤ 2⁶²; |y| ≤ 2⁶¹ + 2⁶² before its limit; |m − y| ≤ 2⁶² + 2⁶¹.
            let m = p.lag + x;
            let y = limit(p.velocity - p.one_minus_a2.times(p.velocity) + p.dc.times(m));
            p.velocity = y;
            p.lag = limit(m - y);
            lag += p.lag >> LAG_GUARD_BITS;
            x = y;
        }
        if let Some(r) = &mut self.real {
            let m = r.lag + x;
            r.lag = limit(m - r.one_minus_pole.times(m));
            lag += r.lag >> LAG_GUARD_BITS;
        }
        let unit = FRACTION_BITS - LAG_GUARD_BITS;
        let keep = (lag + (1 << (unit - 1))) >> unit;
        crate::release_whole_pulses(&mut self.stock, pulses, keep)
    }
}
