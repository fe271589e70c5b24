//! A winding's inductance from its current's response to a broadband voltage: the current
//! of a resistance–inductance branch sampled every tick follows `i[k+1] = a·i[k] + b·v[k−1] + c`
//! (the voltage of a tick is applied over the next one; `c` takes the sensors' offsets and the
//! inverter's constant voltage error), with `a = e^{−RT/L}` and `b = (1 − a)/R`. A least-squares
//! fit of `a` and `b` over a pseudo-random voltage gives `L = −T·(1 − a)/(b·ln a)`, which holds
//! from time constants near a tick (`a` near 0) to far longer ones (`a` near 1, where it tends
//! to `T/b`). The fit regresses the current's change over the tick, `i[k+1] − i[k] = −(1 − a)·i[k]
//! + b·v[k−1] + c`: near `a = 1` that keeps `1 − a` to the sums' precision, where fitting
//! `a` itself would lose it.

use super::regression::Regression;

/// Running sums of a first-order fit, the samples taken relative to the first ones (the
/// ripple is small beside the currents' and voltages' means: f32 sums of raw values would
/// lose it).
#[derive(Clone, Copy, Debug, Default)]
pub struct WindingFit {
    origin: Option<(f32, f32)>,
    /// Regressors x = (i[k], v[k−1], the dead-time voltage per volt at the tick's start)
    /// against y = i[k+1] − i[k].
    sums: Regression<3>,
}

/// What a fit found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Winding {
    /// Inductance (H).
    pub inductance: f32,
    /// The resistance the fit implies, `(1 − a)/b` (Ω): a check on the one measured at rest.
    pub resistance: f32,
}

/// A resistance within the part's range: 1 mΩ to 100 Ω (a fit outside it is passed over for
/// the next, a measurement outside it refused).
pub fn resistance_in_range(ohms: f32) -> bool {
    ohms > 1e-3 && ohms < 100.0
}

/// An inductance within the part's range: 1 µH to 1 H.
pub fn inductance_in_range(henries: f32) -> bool {
    henries > 1e-6 && henries < 1.0
}

impl Winding {
    /// Resistance and inductance both within the part's range.
    pub fn in_range(&self) -> bool {
        resistance_in_range(self.resistance) && inductance_in_range(self.inductance)
    }
}

impl WindingFit {
    /// One tick: the current now (`previous`), the current a tick later (`next`) and the
    /// voltage applied in between (asked for a tick before `previous` was read).
    #[cfg(test)]
    pub fn add(&mut self, previous: f32, next: f32, voltage: f32) {
        let (i0, v0) = *self.origin.get_or_insert((previous, voltage));
        self.sums.add([previous - i0, voltage - v0, 0.0], next - previous);
    }

    /// [`Self::add`], with the inverter's dead-time voltage of unknown size fitted too:
    /// `shape` is its voltage along the axis over the tick per volt of dead time, for the
    /// phase currents' signs at the tick's start. Where the chips swing the phase currents
    /// through zero on a winding faster than a tick, the flips of that voltage follow the
    /// current and read as extra resistance (a decay past what any branch gives) unless they
    /// are fitted; where they take the current to about zero and the sensors' noise flips
    /// its sign there, as a pole a little too slow.
    pub fn add_with_dead_time(&mut self, previous: f32, next: f32, voltage: f32, shape: f32) {
        let (i0, v0) = *self.origin.get_or_insert((previous, voltage));
        self.sums.add([previous - i0, voltage - v0, shape], next - previous);
    }

    /// The winding at `tick` (s) from the sums; `None` when they do not determine one (too
    /// few samples, no excitation, or a response no resistance–inductance branch gives). The
    /// first-order fit alone where it gives a winding; the dead-time regressor's where it does
    /// not (a winding faster than a tick whose chips swing the phase currents through zero).
    /// Not the other way round: on a slow winding the current's sign follows the current
    /// itself, and the regressor would take the decay's share.
    pub fn winding(&self, tick: f32) -> Option<Winding> {
        self.fitted(tick, 2).or_else(|| self.fitted(tick, 3))
    }

    /// The fit with the dead-time regressor alone (`None` where it finds no winding, or where
    /// the regressor does not vary apart from the others). For a winding that settles within
    /// the tick, whose current the chips take to about zero (`Commissioning::d_winding`): the
    /// regressor then takes the flips the sensors' noise makes there, which the first-order
    /// fit reads as a pole a little too slow.
    pub fn winding_with_dead_time(&self, tick: f32) -> Option<Winding> {
        self.fitted(tick, 3)
    }

    /// The winding of the fit of the first `terms` regressors (2: the first-order fit; 3: with
    /// the dead-time regressor).
    fn fitted(&self, tick: f32, terms: usize) -> Option<Winding> {
        if self.sums.samples() < 16.0 {
            return None;
        }
        let [minus_decay, b, ..] = self.sums.coefficients(terms)?;
        let decay = -minus_decay;
        if !(decay > 0.0 && decay < 1.0 && b > 0.0) {
            return None;
        }
        let a = 1.0 - decay;
        // (1 − a)/(−ln a): 1/(1 + (1−a)/2 + (1−a)²/3 …) near a = 1, where ln a loses digits.
        let ratio = if decay < 1e-3 { 1.0 / (1.0 + decay * (0.5 + decay / 3.0)) } else { decay / -libm::logf(a) };
        Some(Winding { inductance: tick * ratio / b, resistance: decay / b })
    }

    /// Where [`Self::winding`] finds none on a winding whose current settles within the tick:
    /// the first-order fit's pole within ±[`SETTLED_POLE`] of zero, its gain `b` positive
    /// (after [`Self::winding`], only a pole at zero or just below reaches this: one just above
    /// is a winding it fits). There the chips swing the phase currents
    /// through zero at each reversal and their magnitude barely changes, so the dead-time
    /// voltage's flips follow the current's sign as closely as the current itself: the pole
    /// and the dead time cannot be told apart (beside anything the model leaves out, the pole
    /// reads below zero). The resistance is then `1/b` (the dead time, a share of the chips,
    /// reads as a little more) and the time constant is taken as a third of a tick, the
    /// fastest the sequence measures: enough to close a current loop (a slower winding than
    /// that makes the loop slower than designed, not unstable), whose stages after measure
    /// the winding with the phase currents' signs held.
    pub fn settled_within_tick(&self, tick: f32) -> Option<Winding> {
        if self.sums.samples() < 16.0 {
            return None;
        }
        let [minus_decay, b, ..] = self.sums.coefficients(2)?;
        let pole = 1.0 + minus_decay;
        if !(libm::fabsf(pole) < SETTLED_POLE && b > 0.0) {
            return None;
        }
        let resistance = 1.0 / b;
        Some(Winding { inductance: resistance * tick / 3.0, resistance })
    }
}

/// The first-order fit's largest pole magnitude read as a current that settles within the
/// tick ([`WindingFit::settled_within_tick`]): `e^{−1.6}`, a time constant of 0.6 tick.
const SETTLED_POLE: f32 = 0.2;

#[cfg(test)]
mod tests {
    use super::*;

    /// An exact discrete RL branch driven by ±1 V chips: the fit returns its L and R, from a
    /// time constant of a third of a tick to thousands of ticks, with an offset on top. (Far
    /// below a tick, 20 µH on 10 Ω say, the current settles within the tick and the samples
    /// hold no trace of the inductance.)
    #[test]
    fn a_resistance_inductance_branch_is_fitted_from_a_third_of_a_tick_to_thousands() {
        let tick = 62.5e-6f64;
        for (r, l) in [(1.0, 20e-6), (0.3, 0.5e-3), (0.05, 10e-3), (0.05, 20e-6), (10.0, 10e-3), (10.0, 0.2e-3)] {
            let a = (-r * tick / l).exp();
            let b = (1.0 - a) / r;
            let mut fit = WindingFit::default();
            let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
            let (mut i, mut v_prev, mut v) = (0.7f64, 0.0f64, 0.0f64);
            for _ in 0..4095 {
                let next = a * i + b * v_prev + 0.01 / r;
                fit.add(i as f32 + 0.02, next as f32 + 0.02, v_prev as f32);
                i = next;
                v_prev = v;
                v = 1.0 + chips.next_chip() as f64;
            }
            let w = fit.winding(tick as f32).expect("a fit");
            assert!((w.inductance as f64 / l - 1.0).abs() < 0.01, "R {r} L {l}: {w:?}");
            assert!((w.resistance as f64 / r - 1.0).abs() < 0.05, "R {r} L {l}: {w:?}");
        }
    }

    /// A branch faster than a tick whose chips swing its current through zero, with the
    /// inverter's dead-time voltage flipping with the current's sign at each tick's start (the
    /// exact discrete model): without the dead-time regressor the fit finds no branch (its
    /// flips read as a decay past 1); with it, R and L within 1 %. On a slow branch the
    /// first-order fit is kept (the sign follows the current there): its inductance within
    /// 1 % for a dead time of a hundredth of the chips (its implied resistance, a check on the
    /// holds' only, is not held there).
    #[test]
    fn a_fast_branch_with_dead_time_is_fitted_with_its_dead_time() {
        let tick = 62.5e-6f64;
        for (r, l, dead) in [(1.0, 20e-6, 0.3), (1.4, 50e-6, 0.3), (0.5, 5e-3, 0.005)] {
            let a = (-r * tick / l).exp();
            let b = (1.0 - a) / r;
            let (mut with, mut without) = (WindingFit::default(), WindingFit::default());
            let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
            let sign = |x: f64| if x >= 0.0 { 1.0 } else { -1.0 };
            let (mut i, mut v_prev, mut v) = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..4095 {
                let next = a * i + b * (v_prev - dead * sign(i));
                with.add_with_dead_time(i as f32, next as f32, v_prev as f32, sign(i) as f32);
                without.add(i as f32, next as f32, v_prev as f32);
                i = next;
                v_prev = v;
                v = 0.5 * chips.next_chip() as f64;
            }
            let w = with.winding(tick as f32).expect("a fit");
            assert!((w.inductance as f64 / l - 1.0).abs() < 0.01, "R {r} L {l}: {w:?}");
            if l / r < tick {
                assert!((w.resistance as f64 / r - 1.0).abs() < 0.01, "R {r} L {l}: {w:?}");
                assert_eq!(without.winding(tick as f32), None, "R {r} L {l}");
            }
        }
    }

    /// A branch settling within the tick (0.36 of one) under a dead-time voltage of 8 % of its
    /// chips, fitted without the dead-time regressor: the flips read as a pole below zero and
    /// no branch is found; `settled_within_tick` gives `R = 1/b` (high by the dead time's
    /// share, under a fifth) and a third of a tick. A slower branch (two ticks), whose pole is
    /// plain, is not read as settled.
    #[test]
    fn a_branch_settling_within_the_tick_is_closed_on_its_gain() {
        let tick = 62.5e-6f64;
        for (r, l, settles) in [(0.99, 22e-6, true), (1.6, 34e-6, true), (1.0, 125e-6, false)] {
            let a = (-r * tick / l).exp();
            let b = (1.0 - a) / r;
            let dead = 0.08 * 0.65;
            let mut fit = WindingFit::default();
            let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
            let sign = |x: f64| if x >= 0.0 { 1.0 } else { -1.0 };
            let (mut i, mut v_prev, mut v) = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..4095 {
                let next = a * i + b * (v_prev - dead * sign(i));
                fit.add(i as f32, next as f32, v_prev as f32);
                i = next;
                v_prev = v;
                v = 0.65 * chips.next_chip() as f64;
            }
            let settled = fit.settled_within_tick(tick as f32);
            if !settles {
                assert_eq!(settled, None, "R {r} L {l}");
                assert!(fit.winding(tick as f32).is_some(), "R {r} L {l}");
                continue;
            }
            assert_eq!(fit.winding(tick as f32), None, "R {r} L {l}");
            let w = settled.expect("settled");
            assert!(w.resistance as f64 > r && (w.resistance as f64 / r - 1.0) < 0.2, "R {r} L {l}: {w:?}");
            assert_eq!(w.inductance, w.resistance * tick as f32 / 3.0);
        }
    }

    #[test]
    fn no_excitation_fits_nothing() {
        let mut fit = WindingFit::default();
        for _ in 0..100 {
            fit.add(1.0, 1.0, 0.5);
        }
        assert_eq!(fit.winding(62.5e-6), None);
        assert_eq!(fit.settled_within_tick(62.5e-6), None);
    }
}
