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
//! The design is computed in `f64`; samples are `f32` between passes. The recursion
//! itself runs in the deviation form of [`Kernel`]: a constant input reproduces itself
//! exactly whatever the precision, where the plain parallel form in `f32` missed the
//! 1e-6 DC-gain target at σ = 64 (6.6e-6: its states are sums growing as `1/(1−ρ)`).
//! The states are `f32` up to [`F32_MAX_SIGMA_PX`] and `f64` above (an update smaller
//! than half an ulp of the state is lost, an error growing with `s`); the two agree
//! within 3e-6 relative on HDR data up to that bound (`f32_and_f64_states_agree`), and
//! `f32` runs eight lanes per AVX2 vector instead of four. States decaying towards zero
//! are flushed before they reach the slow subnormal numbers (see [`flush`]).

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
    /// The sigma designed for.
    sigma: f64,
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
        Self::with_scale(0.5 * (lo + hi), sigma)
    }

    fn with_scale(s: f64, sigma: f64) -> Self {
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
            sigma,
        }
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

/// Largest sigma run with `f32` recursion states; above it the states are `f64`.
///
/// In the deviation form of [`Kernel`] a constant signal is reproduced exactly at any
/// sigma, but an update `(1 − ρ)·d` smaller than half an ulp of the state is lost, so
/// the states can lag the exact ones by about `ε/(1 − ρ) ≈ ε·s` relative (`ε = 2⁻²⁴`,
/// `s ≈ σ/2`): 4e-6 at this bound, against the design's 0.42 % gain error.
/// `f32_and_f64_states_agree` measures the difference on HDR data up to this bound.
pub(crate) const F32_MAX_SIGMA_PX: f64 = 128.0;

/// The precision of the recursion states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Precision {
    F32,
    F64,
}

/// Arithmetic of the recursion states (`f32` or `f64`).
pub(crate) trait Real:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + PartialOrd
{
    fn from_f64(v: f64) -> Self;
    fn from_f32(v: f32) -> Self;
    fn to_f64(self) -> f64;
    fn to_f32(self) -> f32;
    /// `a·b + c`, fused when `FMA` (the instruction exists only then).
    fn madd<const FMA: bool>(a: Self, b: Self, c: Self) -> Self;
    fn abs(self) -> Self;
    fn max(self, o: Self) -> Self;
    /// A lane whose states are all smaller than this in magnitude forgets them (see
    /// [`flush`]): far enough above the subnormal numbers that a band of [`BAND`] steps
    /// cannot decay into them (the states fall by at most `ρ^BAND ≥ e^(−BAND/1.5)` ≈
    /// 2⁻³¹ per band, σ ≥ 3).
    const FORGET: Self;
    /// An imaginary state smaller than this times the real states is set to zero.
    const NEGLIGIBLE: Self;
    const ZERO: Self;
}

impl Real for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn from_f32(v: f32) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn madd<const FMA: bool>(a: Self, b: Self, c: Self) -> Self {
        crate::simd::madd::<FMA>(a, b, c)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32::abs(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    /// 2⁻⁹⁰ ≈ 8.1e-28 (`f32` subnormals are below 2⁻¹²⁶).
    const FORGET: Self = 8.077_936e-28;
    /// 2⁻⁴⁰ ≈ 9.1e-13.
    const NEGLIGIBLE: Self = 9.094_947e-13;
    const ZERO: Self = 0.0;
}

impl Real for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn from_f32(v: f32) -> Self {
        f64::from(v)
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline(always)]
    fn madd<const FMA: bool>(a: Self, b: Self, c: Self) -> Self {
        if FMA { a.mul_add(b, c) } else { a * b + c }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f64::max(self, o)
    }
    /// 2⁻⁹⁶⁰ (`f64` subnormals are below 2⁻¹⁰²²).
    const FORGET: Self = 1.026_134_200_324_594_1e-289;
    /// 2⁻⁴⁰ ≈ 9.1e-13.
    const NEGLIGIBLE: Self = 9.094_947_017_729_282e-13;
    const ZERO: Self = 0.0;
}

/// The per-sample coefficients of one direction of [`Design`] in the deviation form.
///
/// The states are normalised to the input's units, `q = (1 − ρ)·p` and
/// `c = (1 − w)·c_std` for the real state `p` and complex state `c_std` of the parallel
/// form, and updated from the deviations `d = x − q`, `e = x − c` of the new sample:
///
/// ```text
/// q ← q + (1 − ρ)·d,    c ← c + (1 − w)·e,    y = x − G·ρ·d − Re(H·w·e),
/// ```
///
/// with `G = K/(1 − ρ)` and `H = K·κ/(1 − w)` the output weights of the normalised
/// states (`G + Re H = 1`, the unit DC gain; the output uses `q_new − x = −ρ·d` and
/// `c_new − x = −w·e`). It is the same filter as the parallel form, but a constant
/// signal gives `d = e = 0`: the output equals the input exactly, in any precision, and
/// the states are not sums that grow as `1/(1 − ρ)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Kernel<T> {
    /// `1 − ρ`.
    a: T,
    /// `1 − w`, real and imaginary parts.
    br: T,
    bi: T,
    /// `Re w = 1 − Re(1 − w)`.
    wr: T,
    /// `G·ρ`.
    alpha: T,
    /// `H·w`, real and imaginary parts.
    hr: T,
    hi: T,
}

impl Design {
    /// The deviation-form coefficients of this design in precision `T`.
    pub(crate) fn kernel<T: Real>(&self) -> Kernel<T> {
        let one_minus_w = Cx::new(1.0 - self.w.re, -self.w.im);
        let g = self.gr * self.sr;
        let h = self.gc.mul(self.sc).mul(self.w);
        Kernel {
            a: T::from_f64(1.0 / self.sr),
            br: T::from_f64(one_minus_w.re),
            bi: T::from_f64(one_minus_w.im),
            wr: T::from_f64(self.w.re),
            alpha: T::from_f64(g * self.rho),
            hr: T::from_f64(h.re),
            hi: T::from_f64(h.im),
        }
    }

    /// The state precision for this design: `f32` up to [`F32_MAX_SIGMA_PX`].
    pub(crate) fn precision(&self) -> Precision {
        if self.sigma <= F32_MAX_SIGMA_PX {
            Precision::F32
        } else {
            Precision::F64
        }
    }
}

/// One causal step of `N` lanes: update the states with the samples `x` and overwrite
/// them with the output.
#[inline(always)]
fn step<T: Real, const FMA: bool, const N: usize>(
    k: &Kernel<T>,
    q: &mut [T; N],
    cr: &mut [T; N],
    ci: &mut [T; N],
    x: &mut [f32; N],
) {
    for l in 0..N {
        let xv = T::from_f32(x[l]);
        let dv = xv - q[l];
        let e = xv - cr[l];
        let c_im = ci[l];
        q[l] = T::madd::<FMA>(k.a, dv, q[l]);
        cr[l] = T::madd::<FMA>(k.bi, c_im, T::madd::<FMA>(k.br, e, cr[l]));
        ci[l] = T::madd::<FMA>(k.bi, e, k.wr * c_im);
        let y = T::madd::<FMA>(k.hi, c_im, T::madd::<FMA>(k.hr, e, k.alpha * dv));
        x[l] = (xv - y).to_f32();
    }
}

/// Per-lane states of the recursion, in the deviation form of [`Kernel`].
struct States<T> {
    q: Vec<T>,
    cr: Vec<T>,
    ci: Vec<T>,
}

/// Keep the states out of the subnormal numbers, which x86 processors compute about a
/// hundred times slower, without changing any result that matters. Run once per band.
///
/// In a constant region the imaginary state decays geometrically to zero; it is set to
/// zero once below 2⁻⁴⁰ of the real states, which moves the output by about 1e-12 of
/// them. In a black region all states decay to zero; once all are below
/// [`Real::FORGET`] the lane forgets them: its output is then exactly that of a
/// filter whose history is zero, so for non-negative input it stays non-negative (the
/// impulse response is positive), and it drops by at most about 1e-27 of the input's
/// units. Tinier data (below about 1e-16 overall) may still meet subnormal numbers
/// within a band: it is then only slower, never wrong.
#[inline(always)]
fn flush<T: Real, const N: usize>(q: &mut [T; N], cr: &mut [T; N], ci: &mut [T; N]) {
    for l in 0..N {
        let real = q[l].abs().max(cr[l].abs());
        let tiny_im = ci[l].abs() < T::NEGLIGIBLE * real;
        let forget = real.max(ci[l].abs()) < T::FORGET;
        if tiny_im || forget {
            ci[l] = T::ZERO;
        }
        if forget {
            q[l] = T::ZERO;
            cr[l] = T::ZERO;
        }
    }
}

/// Run `N` adjacent lanes, starting at lane `l0` of every row, through the rows of
/// `band` (in reverse order when `reverse`), the states held in registers meanwhile.
#[inline(always)]
fn run_lanes<T: Real, const FMA: bool, const N: usize, R: AsMut<[f32]>>(
    k: &Kernel<T>,
    states: &mut States<T>,
    band: &mut [R],
    l0: usize,
    reverse: bool,
) {
    #[inline(always)]
    fn lanes<U: Copy, const N: usize>(v: &mut [U], l0: usize) -> &mut [U; N] {
        (&mut v[l0..l0 + N])
            .try_into()
            .expect("N lanes in every row")
    }
    let mut q = *lanes::<T, N>(&mut states.q, l0);
    let mut cr = *lanes::<T, N>(&mut states.cr, l0);
    let mut ci = *lanes::<T, N>(&mut states.ci, l0);
    if reverse {
        for r in band.iter_mut().rev() {
            step::<T, FMA, N>(k, &mut q, &mut cr, &mut ci, lanes(r.as_mut(), l0));
        }
    } else {
        for r in band.iter_mut() {
            step::<T, FMA, N>(k, &mut q, &mut cr, &mut ci, lanes(r.as_mut(), l0));
        }
    }
    flush(&mut q, &mut cr, &mut ci);
    *lanes::<T, N>(&mut states.q, l0) = q;
    *lanes::<T, N>(&mut states.cr, l0) = cr;
    *lanes::<T, N>(&mut states.ci, l0) = ci;
}

/// Lanes filtered together: enough independent recursions to hide the latency of
/// each step's dependency chain (four AVX2 vectors of `f32`).
const WIDE: usize = 32;
/// The narrower block for what is left after the [`WIDE`] ones: one AVX2 vector.
const NARROW: usize = 8;
/// Rows run per block of lanes before the next block: the band's rows stay in cache
/// and their pages in the TLB while every block of lanes crosses them, and the rows
/// are still read nearly in address order.
const BAND: usize = 32;

/// Run every lane of `band` (rows of `n` lanes) through it, [`WIDE`] lanes at a time,
/// then [`NARROW`], then one.
#[inline(always)]
fn run_band<T: Real, const FMA: bool, R: AsMut<[f32]>>(
    k: &Kernel<T>,
    states: &mut States<T>,
    band: &mut [R],
    n: usize,
    reverse: bool,
) {
    let mut l0 = 0;
    while l0 + WIDE <= n {
        run_lanes::<T, FMA, WIDE, R>(k, states, band, l0, reverse);
        l0 += WIDE;
    }
    while l0 + NARROW <= n {
        run_lanes::<T, FMA, NARROW, R>(k, states, band, l0, reverse);
        l0 += NARROW;
    }
    while l0 < n {
        run_lanes::<T, FMA, 1, R>(k, states, band, l0, reverse);
        l0 += 1;
    }
}

/// Filter every lane of `rows` (each row holds one sample of every lane, all rows of
/// the same length) along the sequence of rows, forward then backward, with
/// replicate boundaries, in precision `T`.
#[inline(always)]
pub(crate) fn filter_rows<T: Real, const FMA: bool, R: AsMut<[f32]>>(d: &Design, rows: &mut [R]) {
    let k = d.kernel::<T>();
    let (Some(x0), Some(xe)) = (
        rows.first_mut().map(|r| r.as_mut().to_vec()),
        rows.last_mut().map(|r| r.as_mut().to_vec()),
    ) else {
        return;
    };
    let n = x0.len();
    // Before the first sample the input is x0 forever: the states are at x0.
    let q: Vec<T> = x0.iter().map(|&x| T::from_f32(x)).collect();
    let mut states = States {
        cr: q.clone(),
        q,
        ci: vec![T::ZERO; n],
    };
    for band in rows.chunks_mut(BAND) {
        run_band::<T, FMA, R>(&k, &mut states, band, n, false);
    }
    // The anticausal states one past the end, computed in f64 from the causal ones.
    let (omr, omw) = (1.0 / d.sr, Cx::real(1.0).div(d.sc));
    for (l, &x) in xe.iter().enumerate() {
        let p = states.q[l].to_f64() * d.sr;
        let c = Cx::new(states.cr[l].to_f64(), states.ci[l].to_f64()).mul(d.sc);
        let (vr, vcr, vci) = d.backward_init(f64::from(x), p, c.re, c.im);
        let v = Cx::new(vcr, vci).mul(omw);
        states.q[l] = T::from_f64(vr * omr);
        states.cr[l] = T::from_f64(v.re);
        states.ci[l] = T::from_f64(v.im);
    }
    for band in rows.rchunks_mut(BAND) {
        run_band::<T, FMA, R>(&k, &mut states, band, n, true);
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
            let k = d.kernel::<f64>();
            let (mut q, mut cr, mut ci) = ([0.0], [0.0], [0.0]);
            for (i, &hv) in h.iter().enumerate().take(n) {
                let mut x = [if i == 0 { 1.0f32 } else { 0.0 }];
                step::<f64, false, 1>(&k, &mut q, &mut cr, &mut ci, &mut x);
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

    /// The kernels in both precisions and on both instruction sets against the
    /// explicit `f64` convolution, over several bands and every width of lane block
    /// (lane `l` carries the signal times `1 + l`): within 2e-6 relative (`f64` states)
    /// and 1e-5 (`f32`).
    #[test]
    fn boundaries_match_long_padding() {
        const LANES: usize = WIDE + NARROW + 3;
        for sigma in [3.0, 9.0] {
            let d = Design::new(sigma);
            let x: Vec<f64> = (0..3 * BAND + 7)
                .map(|i| 1.0 + (i as f64 * 0.7).sin().abs() * 5.0 + if i == 3 { 50.0 } else { 0.0 })
                .collect();
            let want = reference(&d, &x);
            for isa in crate::simd::Isa::all_available() {
                for prec in [Precision::F32, Precision::F64] {
                    let mut rows: Vec<[f32; LANES]> = x
                        .iter()
                        .map(|&v| std::array::from_fn(|l| (v * (1.0 + l as f64)) as f32))
                        .collect();
                    let fma = isa.fma();
                    crate::simd::at_level!(
                        isa,
                        match (prec, fma) {
                            (Precision::F32, true) => filter_rows::<f32, true, _>(&d, &mut rows),
                            (Precision::F32, false) => filter_rows::<f32, false, _>(&d, &mut rows),
                            (Precision::F64, true) => filter_rows::<f64, true, _>(&d, &mut rows),
                            (Precision::F64, false) => filter_rows::<f64, false, _>(&d, &mut rows),
                        }
                    );
                    let tol = if prec == Precision::F64 { 2e-6 } else { 1e-5 };
                    for (i, (r, w)) in rows.iter().zip(&want).enumerate() {
                        for (l, &v) in r.iter().enumerate() {
                            let w = w * (1.0 + l as f64);
                            assert!(
                                (f64::from(v) - w).abs() < tol * w.abs(),
                                "{isa:?} {prec:?} sigma {sigma} i {i} lane {l}: {v} vs {w}"
                            );
                        }
                    }
                }
            }
        }
    }
}
