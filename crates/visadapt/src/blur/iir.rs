//! The recursive (IIR) Gaussian used for `sigma >= IIR_MIN_SIGMA_PX`.
//!
//! # The filter
//!
//! One 1-D pass is a causal filter followed by its mirror image (anticausal), so the
//! 1-D impulse response is the autocorrelation `h ⋆ h` of the causal response
//!
//! ```text
//! h(t) = e^(-t) · (1 + C1·cos(W·t) + C2·sin(W·t)),   t ≥ 0  (t in decay times),
//! ```
//!
//! the three-pole case of Deriche's (1993) sums of damped exponentials and cosines
//! (Young & van Vliet's 1995 filter has the same kind of poles, one real and a complex
//! pair, but no zeros). The transfer function of `h ⋆ h` is `|H(iω)|²`.
//! `W`, `C1`, `C2` were fitted here (see [`W`]) to minimise the largest absolute
//! difference between `|H(iω)|² / H(0)²` and the Gaussian's `exp(-σ²ω²/2)` over all
//! `ω`, subject to `h(t) ≥ 0`. The best fit has `|(C1, C2)| < 1`, so
//! `h(t) ≥ (1 - |(C1, C2)|)·e^(-t) = 0.068·e^(-t) > 0`: the response is *strictly*
//! positive, with a 6.8 % margin under its envelope. Finite-precision rounding is far
//! below that margin, so the output of every pass, and the final image, is never
//! negative for non-negative input, whatever the dynamic range.
//!
//! The continuous model's largest gain error is 0.42 % (absolute) at any frequency.
//!
//! # Discretisation
//!
//! The discrete causal response samples `h` at the pixel centres,
//! `h[n] = h((n + 1/2)/s)` for `n ≥ 0` (the midpoint rule; sampling at `n/s` instead
//! costs up to 2 % of gain at `σ = 3`). It is a sum of geometric sequences:
//!
//! ```text
//! h[n] ∝ ρⁿ + Re(κ·wⁿ),   ρ = e^(-1/s),   w = ρ·e^(iW/s),   κ = (C1 - i·C2)·e^(iW/(2s)),
//! ```
//!
//! run as one real and one complex first-order recursion in parallel (Deriche's
//! parallel form), whose outputs are summed with the DC normalisation `K = 1/Σ h[n]`.
//! The scale `s` is solved (bisection on the closed-form moments of `h[n]`) so that the
//! variance of `h ⋆ h` is exactly `σ²`: the effective sigma is the requested one to
//! rounding, the role played in Young, van Vliet & van Ginkel (2002) by their `q(σ)`.
//!
//! # Boundaries
//!
//! Replicate ("clamp to edge"), solved exactly rather than by padding: before the first
//! sample the states are at the steady state of a constant signal `x[0]`, and the
//! anticausal states at the last sample are computed in closed form from the causal
//! states, assuming the input continues as `x[N-1]` forever — the idea of Triggs &
//! Sdika (2006), here worked out for the parallel form (derivation at
//! [`Design::backward_init`]).
//!
//! # Precision
//!
//! The recursion state is `f64`; samples are stored back as `f32` between passes. In
//! `f32` the steady state of `y = ρy + x` is off by up to about `ε/(1−ρ)` relative,
//! which times the parallel form's cancellation (about 3) broke the 1e-6 DC-gain target
//! at σ = 64 (6.6e-6 measured; it held at σ = 20). `f32` state halves the recursion's
//! instruction count (cachegrind) but the whole blur's time did not change measurably,
//! so `f64` costs nothing that matters.

/// Frequency of the damped cosine relative to its decay rate (`W = b/a`).
///
/// Fitted for this crate: `W`, [`C1`], [`C2`] minimise
/// `max_ω |(|H(iω)|/H(0))² − exp(−σ²ω²/2)|` for the causal model in the module doc,
/// subject to `h ≥ 0` (Nelder–Mead from random starts on a dense grid over
/// `ω ∈ [0, 12/σ]`, allowing the trigonometric part its own decay rate; the optimum has
/// it equal to the real pole's, and three of four starts reached it), rounded to 4
/// digits. The rounded design's
/// largest error is 0.4173 % (unrounded: 0.4168 %); `fitted_design_is_accurate`
/// re-checks it.
pub(crate) const W: f64 = 0.7872;
/// Weight of `cos(W·t)` in the causal response; see [`W`].
pub(crate) const C1: f64 = -0.8838;
/// Weight of `sin(W·t)` in the causal response; see [`W`].
pub(crate) const C2: f64 = -0.2953;

/// A complex number, only what the design needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Cx {
    pub(crate) re: f64,
    pub(crate) im: f64,
}

impl Cx {
    pub(crate) const fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    fn real(re: f64) -> Self {
        Self { re, im: 0.0 }
    }
    fn conj(self) -> Self {
        Self::new(self.re, -self.im)
    }
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    fn scale(self, k: f64) -> Self {
        Self::new(self.re * k, self.im * k)
    }
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }
    fn powi(self, n: u32) -> Self {
        (0..n).fold(Self::real(1.0), |acc, _| acc.mul(self))
    }
}

/// The poles of the discrete design for scale `s`, with `1 − ρ` and `1 − w` computed
/// without cancellation (they are tiny for large `s`).
fn poles(s: f64) -> (f64, f64, Cx, Cx) {
    let one_minus_rho = -(-1.0 / s).exp_m1();
    let rho = 1.0 - one_minus_rho;
    let phi = W / s;
    let w = Cx::new(rho * phi.cos(), rho * phi.sin());
    // 1 − ρ·cos φ = (1 − ρ) + ρ·2 sin²(φ/2)
    let half = (0.5 * phi).sin();
    let one_minus_w = Cx::new(one_minus_rho + rho * 2.0 * half * half, -w.im);
    (rho, one_minus_rho, w, one_minus_w)
}

/// The weight of the complex term for scale `s` (the midpoint shift folded in).
fn kappa(s: f64) -> Cx {
    let shift = 0.5 * W / s;
    Cx::new(C1, -C2).mul(Cx::new(shift.cos(), shift.sin()))
}

/// `Σ_{n≥0} n^k λⁿ` for `k = 0, 1, 2`, given `λ` and `1 − λ`.
fn power_sums(l: Cx, one_minus_l: Cx) -> [Cx; 3] {
    let one = Cx::real(1.0);
    let s0 = one.div(one_minus_l);
    let s1 = l.div(one_minus_l.powi(2));
    let s2 = l.mul(one.add(l)).div(one_minus_l.powi(3));
    [s0, s1, s2]
}

/// Mass and variance of the discrete causal response for scale `s`, and the variance
/// of the symmetric response `h ⋆ h` (twice the causal one).
fn moments(s: f64) -> (f64, f64) {
    let (rho, omr, w, omw) = poles(s);
    let k = kappa(s);
    let r = power_sums(Cx::real(rho), Cx::real(omr));
    let c = power_sums(w, omw);
    let m: [f64; 3] = std::array::from_fn(|i| r[i].re + k.mul(c[i]).re);
    let mean = m[1] / m[0];
    (m[0], 2.0 * (m[2] / m[0] - mean * mean))
}

/// Largest sigma the IIR is designed for; larger requests are clamped to it (see the
/// module doc of `blur`). `1 − ρ ≈ 1/(0.53 σ)` stays far above `f64` rounding.
pub(crate) const MAX_SIGMA_PX: f64 = 1.0e6;

/// Coefficients of one 1-D pass (both directions use the same ones).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Design {
    /// Real pole `ρ`.
    rho: f64,
    /// Complex pole `w`.
    w: Cx,
    /// Output weight of the real state (`K`).
    gr: f64,
    /// Output weight of the complex state (`K·κ`); the output adds `Re(gc·c)`.
    gc: Cx,
    /// `1/(1 − ρ)`, `1/(1 − w)`: steady states of the two recursions per unit input.
    sr: f64,
    sc: Cx,
    /// Backward-initialisation constants, see [`Design::backward_init`].
    a_rr: f64,
    a_rc: Cx,
    a_cr: Cx,
    a_cc1: Cx,
    a_cc2: Cx,
    /// The scale `s` (for tests).
    #[cfg_attr(not(test), allow(dead_code))]
    pub(crate) s: f64,
}

impl Design {
    /// The design whose `h ⋆ h` has variance `sigma²`. `sigma` must be finite and
    /// within `[1, MAX_SIGMA_PX]`.
    pub(crate) fn new(sigma: f64) -> Self {
        debug_assert!((1.0..=MAX_SIGMA_PX).contains(&sigma));
        let target = sigma * sigma;
        // The variance grows monotonically with s; s/σ lies within 0.46..0.54 for
        // σ ≥ 1 (checked by `scale_is_bracketed_and_monotone`).
        let (mut lo, mut hi) = (0.3 * sigma, 0.8 * sigma);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if moments(mid).1 < target {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * hi {
                break;
            }
        }
        Self::with_scale(0.5 * (lo + hi))
    }

    fn with_scale(s: f64) -> Self {
        let (rho, omr, w, omw) = poles(s);
        let k = kappa(s);
        let mass = moments(s).0;
        let gr = 1.0 / mass;
        let gc = k.scale(gr);
        let one = Cx::real(1.0);
        let r = Cx::real(rho);
        Self {
            rho,
            w,
            gr,
            gc,
            sr: 1.0 / omr,
            sc: one.div(omw),
            a_rr: rho / (1.0 - rho * rho),
            a_rc: w.div(one.sub(r.mul(w))),
            a_cr: r.div(one.sub(w.mul(r))),
            a_cc1: w.div(one.sub(w.mul(w))),
            a_cc2: w.conj().div(one.sub(w.mul(w.conj()))),
            s,
        }
    }

    /// Initialise the causal states of a lane whose first sample is `x0`: the steady
    /// state of the constant signal `x0` that replicate extension puts before it.
    #[inline]
    fn forward_init(&self, x0: f64) -> (f64, f64, f64) {
        (x0 * self.sr, x0 * self.sc.re, x0 * self.sc.im)
    }

    /// Turn the causal states after the last sample into the anticausal states "one
    /// past the end", for an input that continues as `xe` (the last sample) forever.
    ///
    /// Write `λ` for a causal pole (`ρ`, and `w` with its conjugate implied by the
    /// `Re`), `g_λ` for its output weight, `y_λ` for its state after the last sample
    /// `N−1`, and `d_λ = y_λ − xe/(1−λ)`. With the input held at `xe` the states relax
    /// as `y_λ[N−1+p] = xe/(1−λ) + d_λ·λ^p`, so the causal output is
    /// `u[N−1+p] = xe + Re Σ_λ g_λ d_λ λ^p` (unit DC gain). The anticausal state one past
    /// the end of pole `μ` is `v_μ[N] = Σ_{p≥1} μ^(p−1) u[N−1+p]`; the geometric sums give
    ///
    /// ```text
    /// v_μ[N] = xe/(1−μ) + Σ_λ ½·[ g_λ d_λ λ/(1−μλ) + conj(g_λ d_λ)·λ̄/(1−μλ̄) ],
    /// ```
    ///
    /// the parallel-form counterpart of Triggs & Sdika's (2006) matrix `M`.
    /// Checked against a long explicit padding by `boundaries_match_long_padding`.
    #[inline]
    fn backward_init(&self, xe: f64, p: f64, cr: f64, ci: f64) -> (f64, f64, f64) {
        let dr = (p - xe * self.sr) * self.gr;
        let dc = Cx::new(cr, ci).sub(self.sc.scale(xe)).mul(self.gc);
        // Real anticausal pole μ = ρ.
        let vr = xe * self.sr + dr * self.a_rr + dc.mul(self.a_rc).re;
        // Complex anticausal pole μ = w.
        let vc = self
            .sc
            .scale(xe)
            .add(self.a_cr.scale(dr))
            .add(dc.mul(self.a_cc1).add(dc.conj().mul(self.a_cc2)).scale(0.5));
        (vr, vc.re, vc.im)
    }
}

/// Per-lane recursion states of a strip of lanes.
#[derive(Debug, Default)]
pub(crate) struct Lanes {
    p: Vec<f64>,
    cr: Vec<f64>,
    ci: Vec<f64>,
    /// The last input sample of each lane, kept for the backward initialisation.
    last: Vec<f64>,
}

impl Lanes {
    fn reset(&mut self, n: usize) {
        for v in [&mut self.p, &mut self.cr, &mut self.ci, &mut self.last] {
            v.clear();
            v.resize(n, 0.0);
        }
    }
}

/// One causal step over a row of lanes: update the states with `row` and overwrite
/// `row` with the causal output. All slices have the same length.
#[inline]
fn step(d: &Design, p: &mut [f64], cr: &mut [f64], ci: &mut [f64], row: &mut [f32]) {
    let (rho, wr, wi, gr, gcr, gci) = (d.rho, d.w.re, d.w.im, d.gr, d.gc.re, d.gc.im);
    let n = row.len();
    let (p, cr, ci) = (&mut p[..n], &mut cr[..n], &mut ci[..n]);
    for (((x, p), cr), ci) in row.iter_mut().zip(p).zip(cr).zip(ci) {
        let xv = f64::from(*x);
        let np = rho * *p + xv;
        let (a, b) = (*cr, *ci);
        let ncr = wr * a - wi * b + xv;
        let nci = wr * b + wi * a;
        *p = np;
        *cr = ncr;
        *ci = nci;
        *x = (gr * np + gcr * ncr - gci * nci) as f32;
    }
}

/// Filter a strip of lanes in place along the sequence of `rows` (each row holds one
/// sample of every lane; the last row may be shorter only if all are — callers pass
/// equal-length rows). Forward, then backward, with replicate boundaries.
pub(crate) fn filter_rows<R: AsMut<[f32]>>(d: &Design, lanes: &mut Lanes, rows: &mut [R]) {
    let Some(first) = rows.first_mut() else {
        return;
    };
    let n = first.as_mut().len();
    lanes.reset(n);
    let Lanes { p, cr, ci, last } = lanes;
    for (i, &x) in first.as_mut().iter().enumerate() {
        (p[i], cr[i], ci[i]) = d.forward_init(f64::from(x));
    }
    if let Some(l) = rows.last_mut() {
        for (dst, &x) in last.iter_mut().zip(l.as_mut().iter()) {
            *dst = f64::from(x);
        }
    }
    for row in rows.iter_mut() {
        step(d, p, cr, ci, row.as_mut());
    }
    for i in 0..n {
        (p[i], cr[i], ci[i]) = d.backward_init(last[i], p[i], cr[i], ci[i]);
    }
    for row in rows.iter_mut().rev() {
        step(d, p, cr, ci, row.as_mut());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The continuous model: `max_ω |gain − Gaussian|` and the margin of `h` under its
    /// envelope, evaluated independently of the discrete code.
    #[test]
    fn fitted_design_is_accurate() {
        let kap = Cx::new(C1, -C2);
        let lam = Cx::new(1.0, -W);
        // Moments of h(t) = e^{-t}(1 + Re(κ e^{iWt})): ∫ tᵏ e^{-λt} = k!/λ^{k+1}.
        let fact = [1.0, 1.0, 2.0];
        let m: [f64; 3] = std::array::from_fn(|k| {
            fact[k] + kap.mul(Cx::real(fact[k]).div(lam.powi(k as u32 + 1))).re
        });
        let var = 2.0 * (m[2] / m[0] - (m[1] / m[0]).powi(2));
        let sigma = var.sqrt();
        let mut worst: f64 = 0.0;
        for i in 0..=24_000 {
            let om = i as f64 * 12.0 / 24_000.0 / sigma;
            let s = Cx::new(0.0, om);
            let one = Cx::real(1.0);
            let h = one.div(s.add(one)).add(
                kap.div(s.add(lam))
                    .add(kap.conj().div(s.add(lam.conj())))
                    .scale(0.5),
            );
            let gain = (h.re * h.re + h.im * h.im) / (m[0] * m[0]);
            let g = (-0.5 * (sigma * om).powi(2)).exp();
            worst = worst.max((gain - g).abs());
        }
        assert!(worst < 0.0042, "continuous model gain error {worst}");
        let margin = 1.0 - C1.hypot(C2);
        assert!(margin > 0.068, "positivity margin {margin}");
    }

    #[test]
    fn scale_is_bracketed_and_monotone() {
        let mut sigma: f64 = 1.0;
        while sigma <= MAX_SIGMA_PX {
            let lo = moments(0.3 * sigma).1;
            let hi = moments(0.8 * sigma).1;
            assert!(
                lo < sigma * sigma && hi > sigma * sigma,
                "bracket at {sigma}"
            );
            let mut prev = 0.0;
            for i in 0..=50 {
                let v = moments(sigma * (0.3 + 0.01 * f64::from(i))).1;
                assert!(v > prev, "variance not increasing at sigma {sigma}");
                prev = v;
            }
            let d = Design::new(sigma);
            let got = moments(d.s).1.sqrt();
            assert!((got / sigma - 1.0).abs() < 1e-12, "{sigma}: {got}");
            sigma *= 1.7;
        }
    }

    /// Explicit causal response, `f64`, for the references below.
    fn causal_response(d: &Design, len: usize) -> Vec<f64> {
        let k = kappa(d.s);
        (0..len)
            .map(|n| {
                let rn = d.rho.powi(n as i32);
                let wn = d.w.powi(n as u32);
                d.gr * (rn + k.mul(wn).re)
            })
            .collect()
    }

    #[test]
    fn recursion_matches_explicit_response_and_is_positive() {
        for sigma in [3.0, 7.5, 40.0] {
            let d = Design::new(sigma);
            let h = causal_response(&d, (60.0 * sigma) as usize);
            assert!(h.iter().all(|&v| v > 0.0));
            let sum: f64 = h.iter().sum();
            assert!((sum - 1.0).abs() < 1e-9, "{sigma}: mass {sum}");
            // Feed an impulse through the causal recursion alone.
            let n = h.len();
            let (mut p, mut cr, mut ci) = (vec![0.0], vec![0.0], vec![0.0]);
            for (i, &hv) in h.iter().enumerate().take(n) {
                let mut x = [if i == 0 { 1.0f32 } else { 0.0 }];
                step(&d, &mut p, &mut cr, &mut ci, &mut x);
                assert!(
                    (f64::from(x[0]) - hv).abs() <= 1e-6 * h[0].max(hv),
                    "{sigma} n={i}"
                );
            }
        }
    }

    /// Reference: symmetric response `h ⋆ h` applied to the signal extended by
    /// replication over `pad` samples each side, in `f64`.
    fn reference(d: &Design, x: &[f64]) -> Vec<f64> {
        let pad = (80.0 * d.s) as usize + 10;
        let h = causal_response(d, pad);
        let n = x.len() as isize;
        let ext = |i: isize| x[i.clamp(0, n - 1) as usize];
        // causal pass over [−pad, n+pad)
        let lo = -(pad as isize);
        let hi = n + pad as isize;
        let mut u = vec![0.0; (hi - lo) as usize];
        for i in lo..hi {
            let mut acc = 0.0;
            for (k, &hk) in h.iter().enumerate() {
                acc += hk * ext(i - k as isize);
            }
            u[(i - lo) as usize] = acc;
        }
        let uu = |i: isize| u[(i.clamp(lo, hi - 1) - lo) as usize];
        (0..n)
            .map(|i| {
                h.iter()
                    .enumerate()
                    .map(|(k, &hk)| hk * uu(i + k as isize))
                    .sum()
            })
            .collect()
    }

    #[test]
    fn boundaries_match_long_padding() {
        for sigma in [3.0, 9.0] {
            let d = Design::new(sigma);
            let x: Vec<f64> = (0..40)
                .map(|i| 1.0 + (i as f64 * 0.7).sin().abs() * 5.0 + if i == 3 { 50.0 } else { 0.0 })
                .collect();
            let want = reference(&d, &x);
            let mut rows: Vec<[f32; 1]> = x.iter().map(|&v| [v as f32]).collect();
            filter_rows(&d, &mut Lanes::default(), &mut rows);
            for (i, (r, w)) in rows.iter().zip(&want).enumerate() {
                assert!(
                    (f64::from(r[0]) - w).abs() < 2e-6 * w.abs(),
                    "sigma {sigma} i {i}: {} vs {w}",
                    r[0]
                );
            }
        }
    }
}
