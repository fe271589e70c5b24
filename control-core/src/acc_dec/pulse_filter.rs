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
//! **The form.** Integer states (i64, 2⁻³⁰ count resolution, [`super::fixed_point`]) in a delta
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
//! `1/(ωc·T)²` except the rounding of `y` (2⁻³⁰ counts a product: at most `2⁻³⁰/c0 ≈ 0.006`
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

/// Most pulses one tick takes into the filter's states (the i32 range).
pub const MAX_FILTERED_PULSES: i64 = i32::MAX as i64;
/// The zeros' output is scaled by 2⁵ whatever the order (their weights sum to 32).
const ZERO_BITS: u32 = 5;
/// The lags are summed at 2⁻²⁷ counts so that the sum cannot overflow (the truncation, below
/// 4·2⁻²⁷ counts, is far below the states' own error).
const LAG_GUARD_BITS: u32 = 3;

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
    /// The zeros as weights on the last N + 1 inputs (the newest first), summing to 2⁵: the
    /// kept delay and the binomial coefficients of `(1 + z⁻¹)^{N−1}` scaled by `2^{6−N}`, or
    /// one weight on the input N ticks ago.
    zero_weights: [i32; MAX_ORDER as usize + 1],
    inputs: [i32; MAX_ORDER as usize + 1],
    /// Lag of the zeros (exact), in 2⁻⁵ counts.
    zero_lag: i64,
    pairs: [PairSection; MAX_PAIRS],
    pair_count: usize,
    real: Option<RealSection>,
    /// Pulses taken in and not yet given out (exact).
    stock: i64,
}

impl ButterworthPulseFilter {
    pub fn new(design: ButterworthDesign) -> Self {
        let n = design.order as usize;
        let mut zero_weights = [0; MAX_ORDER as usize + 1];
        match design.zeros {
            ZeroPlacement::Seed => {
                // Input j ticks ago, j = 1..=N: C(N − 1, j − 1) · 2^{6−N} (sum 2⁵).
                let mut c = 1i32;
                for j in 1..=n {
                    zero_weights[j] = c << (1 + ZERO_BITS as usize - n);
                    c = c * (n - j) as i32 / j as i32;
                }
            }
            ZeroPlacement::AllDelays => zero_weights[n] = 1 << ZERO_BITS,
        }
        let unused =
            PairSection { dc: Coefficient::new(1.0), one_minus_a2: Coefficient::new(1.0), lag: 0, velocity: 0 };
        let mut pairs = [unused; MAX_PAIRS];
        for (section, p) in pairs.iter_mut().zip(design.pole_pairs()) {
            *section = PairSection {
                dc: Coefficient::new(p.dc),
                one_minus_a2: Coefficient::new(p.one_minus_a2),
                lag: 0,
                velocity: 0,
            };
        }
        let real =
            design.real_pole().map(|r| RealSection { one_minus_pole: Coefficient::new(r.one_minus_pole), lag: 0 });
        Self {
            design,
            zero_weights,
            inputs: [0; MAX_ORDER as usize + 1],
            zero_lag: 0,
            pairs,
            pair_count: design.pole_pairs().len(),
            real,
            stock: 0,
        }
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
        let lags = self.pairs[..self.pair_count].iter().map(|p| p.lag).chain(self.real.map(|r| r.lag));
        let states = lags.map(|l| l as f64).sum::<f64>() / (1u64 << FRACTION_BITS) as f64;
        states + self.zero_lag as f64 / (1u64 << ZERO_BITS) as f64
    }

    /// The largest state magnitude (a section's lag or output, counts), against the limit of
    /// 2³¹ counts (for the bench's headroom figure).
    pub fn largest_state(&self) -> f64 {
        let pairs = self.pairs[..self.pair_count].iter().flat_map(|p| [p.lag, p.velocity]);
        let largest = pairs.chain(self.real.map(|r| r.lag)).map(i64::unsigned_abs).max().unwrap_or(0);
        largest as f64 / (1u64 << FRACTION_BITS) as f64
    }

    /// Empty the filter: zero state, no pulse inside.
    pub fn reset(&mut self) {
        *self = Self::new(self.design);
    }

    /// One tick: `pulses` in, whole pulses out.
    pub fn step(&mut self, pulses: i64) -> i64 {
        let u = match i32::try_from(pulses) {
            Ok(u) => u,
            Err(_) => saturate_to_i32(pulses),
        };
        // Zeros: |w| ≤ 2⁵ · 2³¹, |zero_lag| ≤ N · 2⁵ · 2³¹.
        let i = &mut self.inputs;
        (i[6], i[5], i[4], i[3], i[2], i[1], i[0]) = (i[5], i[4], i[3], i[2], i[1], i[0], u);
        let w = self.inputs.iter().zip(&self.zero_weights).map(|(&x, &c)| x as i64 * c as i64).sum::<i64>();
        self.zero_lag += ((u as i64) << ZERO_BITS) - w;
        // |x| ≤ 2⁶¹ (2³¹ counts), then a section's output (≤ 2⁶¹).
        let mut x = w << (FRACTION_BITS - ZERO_BITS);
        // The lags are summed with LAG_GUARD_BITS fewer fractional bits (≤ 6·2⁵⁸ + 4·2⁵⁸).
        let mut lag = self.zero_lag << (FRACTION_BITS - ZERO_BITS - LAG_GUARD_BITS);
        for p in &mut self.pairs[..self.pair_count] {
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

/// The part of a larger jump the filter takes (the rest passes straight through).
#[cold]
fn saturate_to_i32(pulses: i64) -> i32 {
    pulses.clamp(-MAX_FILTERED_PULSES, MAX_FILTERED_PULSES) as i32
}
