//! Adaptation luminances of the world and display observers.
//!
//! Ferwerda et al. 1996, Sec. 4.4: "For the world adaptation we choose half the highest
//! visible luminance. For the display observer we use half the maximum screen luminance
//! (typically 80/2 = 40 cd/m²)." The cones adapt to the photopic luminance, the rods to the
//! scotopic luminance, each computed from its own channel.
//!
//! # "Highest visible"
//!
//! A literal maximum lets one hot pixel, a specular glint or a light source a few pixels
//! wide set the adaptation of the whole scene. We define the highest visible luminance as
//! a high quantile: the smallest luminance that no more than a fraction `f` of the pixels
//! exceed, with `f` = [`DEFAULT_HOT_PIXEL_FRACTION`] = 0.1 % by default (about 2000 pixels,
//! a 45 × 45 pixel patch, of a 1920 × 1080 image). Non-finite and negative values count as
//! zero. The quantile is exact, computed in O(n) with a histogram on the f32 bit pattern
//! followed by a selection inside the one bin that holds it.

/// Default fraction of pixels allowed to be brighter than the "highest visible" luminance.
/// A project choice (see the module docs), overridable by the caller.
pub const DEFAULT_HOT_PIXEL_FRACTION: f64 = 1e-3;

/// The display maximum luminance of a typical monitor in cd/m² (paper Sec. 4.4).
pub const DEFAULT_DISPLAY_MAX_CD_M2: f64 = 80.0;

/// Half a luminance: the paper's rule for both adaptation levels (Sec. 4.4).
pub const ADAPTATION_FRACTION: f64 = 0.5;

/// The value `v` such that at most `fraction` of `values` are greater than `v` (the
/// `(1 − fraction)` quantile, taking the next sample up). Non-finite and negative samples
/// count as 0. Returns 0 for an empty slice. `fraction` is clamped to [0, 1].
pub fn highest_visible(values: &[f32], fraction: f64) -> f32 {
    highest_visible_by(values.len(), |i| values[i], fraction)
}

/// [`highest_visible`] of values produced by `value(i)` for `i` in `0..n` (so that derived
/// channels, e.g. a scotopic estimate, need no buffer of their own).
pub fn highest_visible_by(n: usize, value: impl Fn(usize) -> f32 + Sync, fraction: f64) -> f32 {
    if n == 0 {
        return 0.0;
    }
    let clean = |v: f32| if v.is_finite() && v > 0.0 { v } else { 0.0 };
    let fraction = if fraction.is_nan() { 0.0 } else { fraction.clamp(0.0, 1.0) };
    // Number of samples allowed above the answer; the answer is the sample of rank
    // `n - 1 - allowed` in ascending order.
    let allowed = ((n as f64) * fraction).floor() as usize;
    let rank = n - 1 - allowed.min(n - 1);

    // Positive finite f32 order like their bit patterns; the top 16 bits make 32768 bins
    // (sign clear), each spanning a relative width of 1/128.
    const BINS: usize = 1 << 15;
    let bin = |v: f32| (v.to_bits() >> 16) as usize;
    let histogram = |range: std::ops::Range<usize>| {
        let mut h = vec![0u32; BINS];
        for i in range {
            h[bin(clean(value(i)))] += 1;
        }
        h
    };
    let counts = chunked_histogram(n, &histogram);
    let mut seen = 0usize;
    let mut target = 0;
    for (b, &c) in counts.iter().enumerate() {
        if seen + c as usize > rank {
            target = b;
            break;
        }
        seen += c as usize;
    }
    let mut inside: Vec<f32> = (0..n)
        .map(|i| clean(value(i)))
        .filter(|&v| bin(v) == target)
        .collect();
    let k = rank - seen;
    let (_, v, _) = inside.select_nth_unstable_by(k, f32::total_cmp);
    *v
}

#[cfg(feature = "rayon")]
fn chunked_histogram(n: usize, histogram: &(dyn Fn(std::ops::Range<usize>) -> Vec<u32> + Sync)) -> Vec<u64> {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 18;
    let chunks = n.div_ceil(CHUNK);
    (0..chunks)
        .into_par_iter()
        .map(|c| histogram(c * CHUNK..((c + 1) * CHUNK).min(n)))
        .fold(
            || vec![0u64; 1 << 15],
            |mut acc, h| {
                acc.iter_mut().zip(h).for_each(|(a, b)| *a += b as u64);
                acc
            },
        )
        .reduce(
            || vec![0u64; 1 << 15],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

#[cfg(not(feature = "rayon"))]
fn chunked_histogram(n: usize, histogram: &dyn Fn(std::ops::Range<usize>) -> Vec<u32>) -> Vec<u64> {
    histogram(0..n).into_iter().map(u64::from).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_is_exact() {
        // 0..10000 shuffled deterministically: the 0.1 % quantile lets 10 samples above.
        let mut v: Vec<f32> = (0..10_000).map(|i| ((i * 7919) % 10_000) as f32).collect();
        assert_eq!(highest_visible(&v, 1e-3), 9989.0);
        assert_eq!(highest_visible(&v, 0.0), 9999.0);
        assert_eq!(highest_visible(&v, 0.5), 4999.0);
        assert_eq!(highest_visible(&v, 1.0), 0.0);
        // Values spread over 40 orders of magnitude and sharing bins still come out exact.
        v = (0..5000).map(|i| 1e-20f32 * 1.015f32.powi(i)).collect();
        let mut sorted = v.clone();
        sorted.sort_by(f32::total_cmp);
        assert_eq!(highest_visible(&v, 0.01), sorted[4950 - 1]);
    }

    #[test]
    fn hot_pixels_do_not_set_the_adaptation() {
        let mut v = vec![100.0f32; 1920 * 1080];
        for p in v.iter_mut().step_by(1001) {
            *p = 1e7; // 2072 hot pixels, just under 0.1 %
        }
        assert_eq!(highest_visible(&v, 1e-3), 100.0);
        // With no allowance the literal maximum is found.
        assert_eq!(highest_visible(&v, 0.0), 1e7);
    }

    #[test]
    fn invalid_samples_count_as_zero() {
        let v = [f32::NAN, f32::INFINITY, -5.0, 2.0, f32::NEG_INFINITY];
        assert_eq!(highest_visible(&v, 0.0), 2.0);
        assert_eq!(highest_visible(&[f32::NAN; 4], 0.0), 0.0);
        assert_eq!(highest_visible(&[], 0.0), 0.0);
    }
}
