//! The exact separable convolution used for small sigma.
//!
//! The kernel is a sampled Gaussian `k[j] ∝ exp(−j²/(2τ²))`, `|j| ≤ R`,
//! `R = max(1, ⌈4σ⌉)`, normalised to unit sum, with `τ` chosen so that the *discrete*
//! kernel's variance `Σ j² k[j]` is exactly `σ²`.
//!
//! For `σ ≥ 1` this is the ordinary sampled Gaussian: `τ` exceeds `σ` by less than
//! 0.03 %, just compensating the variance lost by truncating at `4σ`, and sampling
//! aliases only `exp(−2π²σ²)` of the spectrum. Below about 0.5 px a Gaussian sampled at
//! `τ = σ` is a poor model of the continuous one — its variance is wrong by tens of
//! percent (all but the centre tap vanish) — so `τ` is raised until the variance, the
//! quantity the acuity model prescribes, is right. With `R = 1` (`σ ≤ 0.25`) this is the
//! unique symmetric 3-tap kernel `[a, 1 − 2a, a]` with `2a = σ²`. The taps are all
//! positive, so the output is a convex combination of input samples.

use crate::simd::madd;

/// Radius of the kernel for `sigma`: at least 4σ, at least 1.
pub(crate) fn radius(sigma: f64) -> usize {
    ((4.0 * sigma).ceil() as usize).max(1)
}

/// Variance of the normalised sampled Gaussian of width `tau` on `[−r, r]`.
fn variance(tau: f64, r: usize) -> f64 {
    let (mut m0, mut m2) = (1.0, 0.0);
    for j in 1..=r {
        let j = j as f64;
        let g = (-0.5 * j * j / (tau * tau)).exp();
        m0 += 2.0 * g;
        m2 += 2.0 * j * j * g;
    }
    m2 / m0
}

/// The normalised taps `k[0..=2R]` (centre at `R`) whose variance is `sigma²`.
/// `sigma` must be positive, finite and below `IIR_MIN_SIGMA_PX`.
pub(crate) fn kernel(sigma: f64) -> Vec<f32> {
    let r = radius(sigma);
    let target = sigma * sigma;
    let taps: Vec<f64> = if r == 1 {
        let a = 0.5 * target;
        vec![a, 1.0 - 2.0 * a, a]
    } else {
        // variance(τ) increases with τ from 0 to the flat kernel's R(R+1)/3 > 16σ²/3,
        // so the root is bracketed; σ ≥ 0.25 here, so τ ≥ 0.05 is a safe lower end.
        let (mut lo, mut hi) = (0.05, 2.0 * sigma + 1.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if variance(mid, r) < target {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * hi {
                break;
            }
        }
        let tau = 0.5 * (lo + hi);
        let g: Vec<f64> = (0..=2 * r)
            .map(|i| {
                let j = i as f64 - r as f64;
                (-0.5 * j * j / (tau * tau)).exp()
            })
            .collect();
        let sum: f64 = g.iter().sum();
        g.iter().map(|v| v / sum).collect()
    };
    taps.iter().map(|&v| v as f32).collect()
}

/// The taps from the centre outwards, `k[R..=2R]` of [`kernel`] (the kernel is
/// symmetric, so each outer tap weighs the sum of two samples).
pub(crate) fn half_kernel(sigma: f64) -> Vec<f32> {
    let k = kernel(sigma);
    k[k.len() / 2..].to_vec()
}

/// Samples computed together: four AVX2 vectors (eight SSE2 ones), independent
/// accumulators so that the multiply-add latency is hidden; [`NARROW`] for the rest.
const WIDE: usize = 32;
/// The narrower block for what is left after the [`WIDE`] ones: one AVX2 vector.
const NARROW: usize = 8;

/// One output sample: `h[0]·x(0) + Σ_j h[j]·(x(−j) + x(j))`, the same operations in the
/// same order for rows and columns and for every block width, so that all round
/// identically.
#[inline(always)]
fn tap_sum<const FMA: bool>(half: &[f32], x: impl Fn(isize) -> f32) -> f32 {
    let mut acc = half[0] * x(0);
    for (j, &h) in half.iter().enumerate().skip(1) {
        let j = j as isize;
        acc = madd::<FMA>(h, x(-j) + x(j), acc);
    }
    acc
}

/// [`tap_sum`] for `N` adjacent outputs at once; `x(d)` gives the `N` inputs at offset
/// `d` from them.
#[inline(always)]
fn tap_sum_lanes<'a, const FMA: bool, const N: usize>(
    half: &[f32],
    x: impl Fn(isize) -> &'a [f32; N],
) -> [f32; N] {
    let c = x(0);
    let mut acc: [f32; N] = std::array::from_fn(|l| half[0] * c[l]);
    for (j, &h) in half.iter().enumerate().skip(1) {
        let j = j as isize;
        let (lo, hi) = (x(-j), x(j));
        for l in 0..N {
            acc[l] = madd::<FMA>(h, lo[l] + hi[l], acc[l]);
        }
    }
    acc
}

#[inline(always)]
fn lanes_at<const N: usize>(v: &[f32], at: usize) -> &[f32; N] {
    v[at..at + N].try_into().expect("N samples")
}

/// Compute `out[i]` for all `i` from `x(i, d)`, the input at offset `d` from output `i`,
/// in blocks of [`WIDE`], then [`NARROW`], then one.
#[inline(always)]
fn convolve<const FMA: bool>(
    half: &[f32],
    out: &mut [f32],
    block: impl Fn(usize, isize) -> usize,
    src: &[f32],
) {
    let n = out.len();
    let mut i = 0;
    while i + WIDE <= n {
        let acc = tap_sum_lanes::<FMA, WIDE>(half, |d| lanes_at(src, block(i, d)));
        out[i..i + WIDE].copy_from_slice(&acc);
        i += WIDE;
    }
    while i + NARROW <= n {
        let acc = tap_sum_lanes::<FMA, NARROW>(half, |d| lanes_at(src, block(i, d)));
        out[i..i + NARROW].copy_from_slice(&acc);
        i += NARROW;
    }
    for (i, o) in out.iter_mut().enumerate().skip(i) {
        *o = tap_sum::<FMA>(half, |d| src[block(i, d)]);
    }
}

/// Convolve one row with the kernel whose centre-outwards taps are `half` (replicate
/// boundary), using `pad` as scratch.
#[inline(always)]
pub(crate) fn row<const FMA: bool>(half: &[f32], row: &mut [f32], pad: &mut Vec<f32>) {
    let r = half.len() - 1;
    let n = row.len();
    let (Some(&first), Some(&last)) = (row.first(), row.last()) else {
        return;
    };
    pad.clear();
    pad.resize(r, first);
    pad.extend_from_slice(row);
    pad.resize(n + 2 * r, last);
    convolve::<FMA>(half, row, |i, d| (i + r).wrapping_add_signed(d), pad);
}

/// Copy a strip of row segments (all of the same width) into `scratch` as
/// `segs.len() + 2r` contiguous rows, the first and last replicated `r` times.
pub(crate) fn fill_strip(segs: &[&mut [f32]], r: usize, scratch: &mut Vec<f32>) {
    scratch.clear();
    let (Some(first), Some(last)) = (segs.first(), segs.last()) else {
        return;
    };
    for _ in 0..r {
        scratch.extend_from_slice(first);
    }
    for s in segs {
        scratch.extend_from_slice(s);
    }
    for _ in 0..r {
        scratch.extend_from_slice(last);
    }
}

/// Convolve a strip of columns vertically: `scratch` is the strip as [`fill_strip`]
/// left it, the output rows are written to `segs`.
#[inline(always)]
pub(crate) fn column_strip<const FMA: bool>(
    half: &[f32],
    scratch: &[f32],
    segs: &mut [&mut [f32]],
) {
    let r = half.len() - 1;
    let Some(sw) = segs.first().map(|s| s.len()) else {
        return;
    };
    for (y, seg) in segs.iter_mut().enumerate() {
        convolve::<FMA>(
            half,
            seg,
            |x, d| (y + r).wrapping_add_signed(d) * sw + x,
            scratch,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_variance_is_exact_and_taps_positive() {
        for sigma in [1e-3, 0.1, 0.25, 0.26, 0.3, 0.5, 0.7, 1.0, 1.7, 2.99] {
            let k = kernel(sigma);
            let r = k.len() / 2;
            assert!(r as f64 >= 4.0 * sigma);
            let sum: f64 = k.iter().map(|&v| f64::from(v)).sum();
            let var: f64 = k
                .iter()
                .enumerate()
                .map(|(i, &v)| (i as f64 - r as f64).powi(2) * f64::from(v))
                .sum::<f64>()
                / sum;
            assert!((sum - 1.0).abs() < 1e-6, "{sigma}: sum {sum}");
            assert!(
                (var.sqrt() / sigma - 1.0).abs() < 1e-4,
                "{sigma}: {}",
                var.sqrt()
            );
            assert!(k.iter().all(|&v| v > 0.0));
        }
        // σ ≥ 1: the plain sampled Gaussian (τ within 0.03 % of σ).
        for sigma in [1.0f64, 2.0, 2.99] {
            let k = kernel(sigma);
            let r = k.len() / 2;
            let ratio = f64::from(k[r + 1]) / f64::from(k[r]);
            let tau = (-0.5 / ratio.ln()).sqrt();
            assert!((tau / sigma - 1.0).abs() < 3e-4, "{sigma}: τ = {tau}");
        }
        // Small σ: the plain sampled Gaussian would be 7 % narrow at 0.5 px.
        let k = kernel(0.5);
        let r = k.len() / 2;
        let tau = (-0.5 / (f64::from(k[r + 1]) / f64::from(k[r])).ln()).sqrt();
        assert!(tau > 0.52, "τ = {tau}");
    }
}
