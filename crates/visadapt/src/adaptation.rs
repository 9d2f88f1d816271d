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
//! refined by a second pass inside the one bin that holds it.

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
///
/// Exact, in two histogram passes over the IEEE-754 bit pattern (which orders like the
/// value for non-negative floats): the high 16 bits find the bin holding the wanted rank,
/// the low 16 bits of the samples in that bin find the sample itself.
pub fn highest_visible_by(n: usize, value: impl Fn(usize) -> f32 + Sync, fraction: f64) -> f32 {
    if n == 0 {
        return 0.0;
    }
    let fraction = if fraction.is_nan() { 0.0 } else { fraction.clamp(0.0, 1.0) };
    // Number of samples allowed above the answer; the answer is the sample of rank
    // `n - 1 - allowed` in ascending order.
    let allowed = ((n as f64) * fraction).floor() as usize;
    let rank = n - 1 - allowed.min(n - 1);
    let bits = |i: usize| {
        let v = value(i);
        // Non-finite and negative samples count as 0 (bit pattern 0).
        if v.is_finite() && v > 0.0 { v.to_bits() } else { 0 }
    };
    let high = histogram(n, |i| Some(bits(i) >> 16));
    let (bin, rank_in_bin) = locate(&high, rank);
    let low = histogram(n, |i| {
        let b = bits(i);
        (b >> 16 == bin).then_some(b & 0xffff)
    });
    let (low_bits, _) = locate(&low, rank_in_bin);
    f32::from_bits((bin << 16) | low_bits)
}

/// The bin holding the sample of `rank` (0-based, ascending) and its rank within the bin.
fn locate(counts: &[u64], rank: usize) -> (u32, usize) {
    let mut seen = 0usize;
    for (b, &c) in counts.iter().enumerate() {
        if seen + c as usize > rank {
            return (b as u32, rank - seen);
        }
        seen += c as usize;
    }
    unreachable!("rank {rank} beyond the {seen} samples counted")
}

/// Counts of `key(i)` over `0..n` in 65536 bins (`None` is not counted), in parallel chunks.
fn histogram(n: usize, key: impl Fn(usize) -> Option<u32> + Sync) -> Vec<u64> {
    const BINS: usize = 1 << 16;
    let count = |range: std::ops::Range<usize>| {
        let mut h = vec![0u32; BINS];
        for i in range {
            if let Some(k) = key(i) {
                h[k as usize & (BINS - 1)] += 1;
            }
        }
        h
    };
    let add = |mut acc: Vec<u64>, h: Vec<u32>| {
        acc.iter_mut().zip(h).for_each(|(a, b)| *a += u64::from(b));
        acc
    };
    // Chunks of at most 2^31 samples so the u32 counters cannot overflow.
    const CHUNK: usize = 1 << 20;
    let chunks = n.div_ceil(CHUNK);
    let range = move |c: usize| c * CHUNK..((c + 1) * CHUNK).min(n);
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        (0..chunks)
            .into_par_iter()
            .map(|c| count(range(c)))
            .fold(|| vec![0u64; BINS], add)
            .reduce(
                || vec![0u64; BINS],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                    a
                },
            )
    }
    #[cfg(not(feature = "rayon"))]
    {
        (0..chunks).map(|c| count(range(c))).fold(vec![0u64; BINS], add)
    }
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
