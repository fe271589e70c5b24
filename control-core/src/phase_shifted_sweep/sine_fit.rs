//! The on-line correlator: the sums of a three-parameter sine fit of u and y at the
//! excitation's phases, the response `G = Y/U` they give and its standard errors.

/// The smallest conditioning of the phases (1: spread over the circle, 0: one phase and its
/// opposite) from which [`SineFitSums::response`] tells a response.
pub(super) const MIN_TELLING_CONDITIONING: f32 = 0.05;

/// Sums of a three-parameter sine fit (IEEE 1057 with known frequency) of u and y:
/// `x ≈ x̄ + b·cos θ + c·sin θ`, the complex amplitude `X = b − j·c`. Unlike a plain
/// correlation it leaks neither the constant speed the sweep rides on nor the image at
/// fs − f when a record is not a whole number of cycles; and it tells how well the sample
/// phases determine the sine: the determinant of the (cos, sin) covariance, 0 when all
/// samples sit at one phase and its opposite (a single record at exactly fs/2).
///
/// u and y are summed about their first samples (`u0`, `y0`): the constant speed the sweep
/// rides on would otherwise swamp the f32 sums, in particular the squares, which give the
/// residuals. The squares and the cross product of u and y, and those of their differences
/// between consecutive samples of a record, give the noise of U and Y at the excitation
/// frequency (see [`SineFitSums::response_error`]).

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SineFitSums {
    u0: f32,
    y0: f32,
    uu: f32,
    yy: f32,
    uy: f32,
    /// Number of samples.
    pub(super) n: f32,
    c: f32,
    s: f32,
    cc: f32,
    ss: f32,
    cs: f32,
    u: f32,
    uc: f32,
    us: f32,
    y: f32,
    yc: f32,
    ys: f32,
    /// Differences between consecutive samples of one record: their count, squares and
    /// cross product, and the previous sample (`None` at a record's start).
    dn: f32,
    duu: f32,
    dyy: f32,
    duy: f32,
    previous: (f32, f32),
    has_previous: bool,
    /// Σcos², Σsin², Σcos·sin of the records' first samples (which start no difference).
    first_cc: f32,
    first_ss: f32,
    first_cs: f32,
    /// Samples whose acquisition period saw the drive's output limited (see
    /// [`PhaseShiftedSweep::end_tick`](super::PhaseShiftedSweep::end_tick)).
    pub(super) limited: u32,
}

/// Standard errors of a measured response `G = Y/U`, relative to |G|: the gain's (radial) and
/// the phase's (tangential, rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResponseError {
    pub gain: f32,
    pub phase: f32,
}

impl ResponseError {
    /// The gain's standard error in dB.
    pub fn gain_db(&self) -> f32 {
        20.0 / core::f32::consts::LN_10 * self.gain
    }
}

impl SineFitSums {
    /// One sample with the sine and cosine of its phase.
    pub(super) fn add(&mut self, u: f32, y: f32, (s, c): (f32, f32)) {
        if self.n == 0.0 {
            self.u0 = u;
            self.y0 = y;
        }
        let u = u - self.u0;
        let y = y - self.y0;
        if self.has_previous {
            let (du, dy) = (u - self.previous.0, y - self.previous.1);
            self.dn += 1.0;
            self.duu += du * du;
            self.dyy += dy * dy;
            self.duy += du * dy;
        } else {
            self.first_cc += c * c;
            self.first_ss += s * s;
            self.first_cs += c * s;
        }
        self.previous = (u, y);
        self.has_previous = true;
        self.uu += u * u;
        self.yy += y * y;
        self.uy += u * y;
        self.n += 1.0;
        self.c += c;
        self.s += s;
        self.cc += c * c;
        self.ss += s * s;
        self.cs += c * s;
        self.u += u;
        self.uc += u * c;
        self.us += u * s;
        self.y += y;
        self.yc += y * c;
        self.ys += y * s;
    }

    /// The sums of the samples added since `earlier` (a copy of these sums taken before):
    /// the same fit over that stretch only (same offsets, same last sample).
    pub(super) fn since(&self, earlier: &Self) -> Self {
        Self {
            uu: self.uu - earlier.uu,
            yy: self.yy - earlier.yy,
            uy: self.uy - earlier.uy,
            n: self.n - earlier.n,
            c: self.c - earlier.c,
            s: self.s - earlier.s,
            cc: self.cc - earlier.cc,
            ss: self.ss - earlier.ss,
            cs: self.cs - earlier.cs,
            u: self.u - earlier.u,
            uc: self.uc - earlier.uc,
            us: self.us - earlier.us,
            y: self.y - earlier.y,
            yc: self.yc - earlier.yc,
            ys: self.ys - earlier.ys,
            dn: self.dn - earlier.dn,
            duu: self.duu - earlier.duu,
            dyy: self.dyy - earlier.dyy,
            duy: self.duy - earlier.duy,
            first_cc: self.first_cc - earlier.first_cc,
            first_ss: self.first_ss - earlier.first_ss,
            first_cs: self.first_cs - earlier.first_cs,
            limited: self.limited - earlier.limited,
            ..*self
        }
    }

    /// `G = Y/U` of these sums (None when the phases or U cannot tell). Phases that nearly
    /// collapse to one value and its opposite (a half block near the acquisition Nyquist
    /// frequency: conditioning below [`MIN_TELLING_CONDITIONING`]) tell nothing either: their
    /// f32 fit is rounding, not response.
    pub(super) fn response(&self) -> Option<(f32, f32)> {
        let ((u_re, u_im), (y_re, y_im), quality) = self.solve();
        let den = u_re * u_re + u_im * u_im;
        if den > 0.0 && quality >= MIN_TELLING_CONDITIONING {
            Some(((y_re * u_re + y_im * u_im) / den, (y_im * u_re - y_re * u_im) / den))
        } else {
            None
        }
    }

    /// A new record starts: its first sample has no predecessor.
    pub(super) fn break_record(&mut self) {
        self.has_previous = false;
    }

    /// The centred (cos, sin) normal equations: `n` (at least 1), `Scc'`, `Sss'`, `Scs'` and
    /// their determinant.
    fn normal_equations(&self) -> NormalEquations {
        let n = self.n.max(1.0);
        let scc = self.cc - self.c * self.c / n;
        let sss = self.ss - self.s * self.s / n;
        let scs = self.cs - self.c * self.s / n;
        NormalEquations { n, scc, sss, scs, det: scc * sss - scs * scs }
    }

    /// `(b, c)` of `x ≈ x̄ + b·cos θ + c·sin θ` from x's sums, and the centred sums
    /// `(Sxc', Sxs')` they solve.
    fn coefficients(&self, e: &NormalEquations, x: f32, xc: f32, xs: f32) -> ((f32, f32), (f32, f32)) {
        let (pc, ps) = (xc - x * self.c / e.n, xs - x * self.s / e.n);
        (((e.sss * pc - e.scs * ps) / e.det, (e.scc * ps - e.scs * pc) / e.det), (pc, ps))
    }

    /// (U, Y) complex amplitudes and the conditioning of the phases (0..1).
    pub(super) fn solve(&self) -> ((f32, f32), (f32, f32), f32) {
        let e = self.normal_equations();
        let amplitude = |x: f32, xc: f32, xs: f32| {
            let ((b, c), _) = self.coefficients(&e, x, xc, xs);
            (b, -c)
        };
        let conditioning = crate::limit(e.det / (0.25 * e.n * e.n), 0.0, 1.0);
        (amplitude(self.u, self.uc, self.us), amplitude(self.y, self.yc, self.ys), conditioning)
    }

    /// Standard errors of `G = Y/U` (gain and phase, relative), from the residuals of both
    /// fits. The noise of U and Y and their correlation (on the torque command U carries the
    /// loop's reaction to the noise of Y) enter as `δG/G = δY/Y − δU/U`. The noise at the
    /// excitation frequency, not its average over the band, decides: the residuals' variance
    /// γ₀ and lag-one covariance γ₁ (from the differences of consecutive samples) give the
    /// first-order noise spectrum `γ₀ + 2γ₁·cos(ω·Tₐ)` (`step`: ω·Tₐ, the excitation's
    /// phase step between samples). Encoder quantisation in a velocity averaged over the
    /// acquisition period has exactly this form (γ₁ = −γ₀/2: little noise at low
    /// frequencies, twice the average near the acquisition Nyquist frequency). None when the
    /// samples cannot tell (too few, phases degenerate, no response).
    pub(super) fn response_error(&self, step: f32) -> Option<ResponseError> {
        if self.n < 8.0 || self.dn < 4.0 {
            return None;
        }
        let e = self.normal_equations();
        // Phases as degenerate as `response` refuses tell no error either: a single record at
        // exactly fs/2 (2 kHz at 4 kHz) has a determinant of f32 rounding (a conditioning of up
        // to 8·10⁻⁶ over 160 samples, 5.6·10⁻⁴ over 20 000: no fixed small threshold is safe),
        // whose prediction asked, or not, for the cap's 16 half blocks in each of the three
        // records (1.1 s instead of 0.15 s) by the chance of where the frequency started. A
        // record within about 1.5 Hz of fs/2 (160 samples) now predicts no extension either;
        // such a frequency is already measured without the settling check (its half blocks
        // tell no response) and reported with its quality.
        if !(e.det >= MIN_TELLING_CONDITIONING * 0.25 * e.n * e.n) {
            return None;
        }
        let ((bu, cu), (pcu, psu)) = self.coefficients(&e, self.u, self.uc, self.us);
        let ((by, cy), (pcy, psy)) = self.coefficients(&e, self.y, self.yc, self.ys);
        let (au, ay) = (bu * bu + cu * cu, by * by + cy * cy);
        if !(au > 0.0 && ay > 0.0) {
            return None;
        }
        // Residual sums: Σr_u², Σr_y², Σr_u·r_y.
        let ruu = self.uu - self.u * self.u / e.n - (bu * pcu + cu * psu);
        let ryy = self.yy - self.y * self.y / e.n - (by * pcy + cy * psy);
        let ruy = self.uy - self.u * self.y / e.n - (by * pcu + cy * psu);
        // The fitted sine's difference between consecutive samples is the sine of
        // coefficients (b(1 − cos φ) + c·sin φ, c(1 − cos φ) − b·sin φ) at the later sample;
        // its sum of squares over the differences (the phase sums without the records' first
        // samples) comes off the differences'.
        let (sin_step, cos_step) = crate::trigonometry::sin_cos(step);
        let (pcc, pss, pcs) = (self.cc - self.first_cc, self.ss - self.first_ss, self.cs - self.first_cs);
        let rotated = |b: f32, c: f32| (b * (1.0 - cos_step) + c * sin_step, c * (1.0 - cos_step) - b * sin_step);
        let ((dbu, dcu), (dby, dcy)) = (rotated(bu, cu), rotated(by, cy));
        let quadratic = |b1: f32, c1: f32, b2: f32, c2: f32| b1 * b2 * pcc + c1 * c2 * pss + (b1 * c2 + c1 * b2) * pcs;
        let druu = self.duu - quadratic(dbu, dcu, dbu, dcu);
        let dryy = self.dyy - quadratic(dby, dcy, dby, dcy);
        let druy = self.duy - quadratic(dbu, dcu, dby, dcy);
        // Spectrum at the excitation: γ₀ + 2γ₁ cos φ with γ₁ = γ₀ − Σ(Δr)²/(2·dn).
        let dof = e.n - 3.0;
        let spectrum = |r: f32, dr: f32| {
            let g0 = r / dof;
            let g1 = g0 - dr / (2.0 * self.dn);
            g0 + 2.0 * g1 * cos_step
        };
        let (suu, syy) = (spectrum(ruu, druu).max(0.0), spectrum(ryy, dryy).max(0.0));
        let bound = crate::square_root::sqrt(suu * syy);
        let suy = crate::limit(spectrum(ruy, druy), -bound, bound);
        // (δb, δc) of any fit have the covariance σ²·[[Sss', −Scs'], [−Scs', Scc']]/det.
        let form = |(p1, q1): (f32, f32), (p2, q2): (f32, f32)| {
            (p1 * p2 * e.sss - (p1 * q2 + q1 * p2) * e.scs + q1 * q2 * e.scc) / e.det
        };
        // Re(δX/X) = (b·δb + c·δc)/|X|², Im(δX/X) = (c·δb − b·δc)/|X|².
        let variance = |wy: (f32, f32), wu: (f32, f32)| {
            (syy * form(wy, wy) + suu * form(wu, wu) - 2.0 * suy * form(wy, wu)).max(0.0)
        };
        let gain = variance((by / ay, cy / ay), (bu / au, cu / au));
        let phase = variance((cy / ay, -by / ay), (cu / au, -bu / au));
        Some(ResponseError { gain: crate::square_root::sqrt(gain), phase: crate::square_root::sqrt(phase) })
    }
}

/// See [`SineFitSums::normal_equations`].
struct NormalEquations {
    n: f32,
    scc: f32,
    sss: f32,
    scs: f32,
    det: f32,
}
