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
//! zero. The quantile is exact, computed in O(n). When the fraction leaves at most
//! [`TOP_K_MAX`] samples above it (the usual case: 2074 at 1080p by default), in one pass
//! that keeps only the brightest samples seen (a buffer compacted by selection whenever it
//! fills, whose threshold then rises), starting from a threshold guessed from a sample of
//! the pixels and checked (searched again from 0 when fewer samples lie above it than
//! the answer needs); otherwise with a histogram on the f32 bit pattern
//! refined by a second pass inside the one bin that holds it.

use crate::simd::Isa;

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
    highest_visible_of(values.len(), [values], fraction)[0]
}

/// [`highest_visible`] of `K` channels at once (e.g. photopic and scotopic luminance),
/// without a buffer for derived channels: `fill` hands out the values of the pixels a
/// block at a time, one plane per channel ([`Blocks`]; a closure
/// `fill(start, planes)` that writes pixels `start..start + len` of channel `k` into
/// `planes[k]` is one, and so are `K` slices).
///
/// Exact, in two histogram passes over the IEEE-754 bit pattern (which orders like the
/// value for non-negative floats): the high 16 bits find the bin holding the wanted rank,
/// the low 16 bits of the samples in that bin find the sample itself.
pub fn highest_visible_of<const K: usize>(
    n: usize,
    fill: impl Blocks<K>,
    fraction: f64,
) -> [f32; K] {
    if n == 0 {
        return [0.0; K];
    }
    let fraction = if fraction.is_nan() {
        0.0
    } else {
        fraction.clamp(0.0, 1.0)
    };
    // Number of samples allowed above the answer; the answer is the sample of rank
    // `n - 1 - allowed` in ascending order.
    let allowed = ((n as f64) * fraction).floor() as usize;
    let rank = n - 1 - allowed.min(n - 1);
    let keep = n - rank;
    if keep <= TOP_K_MAX {
        return top_k::<K>(n, &fill, keep);
    }
    by_histogram(n, &fill, rank)
}

/// The two-pass histogram quantile: the sample of `rank` (ascending) of each channel.
fn by_histogram<const K: usize>(n: usize, fill: &impl Blocks<K>, rank: usize) -> [f32; K] {
    let high = high_histograms::<K>(n, fill);
    let located: [(u32, usize); K] = std::array::from_fn(|k| locate(&high[k], rank));
    let low = low_histograms::<K>(n, fill, located.map(|l| l.0));
    std::array::from_fn(|k| {
        let (low_bits, _) = locate(&low[k], located[k].1);
        f32::from_bits((located[k].0 << 16) | low_bits)
    })
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

/// Bins of each histogram (16 bits of the float).
const BINS: usize = 1 << 16;
/// Pixels per block handed to `fill`.
pub const BLOCK: usize = 1024;
/// Pixels per parallel work item.
const CHUNK: usize = 1 << 20;

/// The bit pattern used for ordering: non-finite and non-positive samples count as 0.
/// Positive finite floats are exactly the patterns 1..=0x7f7f_ffff (negative ones have the
/// sign bit set, infinities and NaNs have an all-ones exponent), so one compare decides.
#[inline(always)]
fn order_bits(v: f32) -> u32 {
    let b = v.to_bits();
    if b.wrapping_sub(1) < 0x7f7f_ffff {
        b
    } else {
        0
    }
}

/// The largest ordering key of a plane: a maximum over lanes of 16 values at a time
/// (independent lanes, which the compiler vectorises at any width), then across them.
#[inline(always)]
fn plane_max(plane: &[f32]) -> u32 {
    const LANES: usize = 16;
    let mut lanes = [0u32; LANES];
    let mut chunks = plane.chunks_exact(LANES);
    for chunk in &mut chunks {
        for (lane, v) in lanes.iter_mut().zip(chunk) {
            *lane = (*lane).max(order_bits(*v));
        }
    }
    let tail = chunks.remainder().iter().map(|v| order_bits(*v));
    lanes.into_iter().chain(tail).max().unwrap_or(0)
}

/// The values of `K` channels of `n` pixels, handed out a block of at most [`BLOCK`]
/// pixels at a time, one plane per channel (so that each channel's loop is a plain vector
/// loop: pixels interleaved as `[[f32; K]]` cost shuffles in every loop over them).
pub trait Blocks<const K: usize>: Sync {
    /// The values of pixels `start..start + len` (`len` ≤ [`BLOCK`]) of each channel:
    /// slices of the caller's planes where the channel is stored, or written into
    /// `scratch` (its first `len` values) where it is derived.
    fn block<'s>(
        &'s self,
        start: usize,
        len: usize,
        scratch: &'s mut [[f32; BLOCK]; K],
    ) -> [&'s [f32]; K];
}

/// A closure `fill(start, planes)` writing the values of pixels `start..start + len` of
/// channel `k` into `planes[k]` (of length `len`).
impl<const K: usize, F: Fn(usize, [&mut [f32]; K]) + Sync> Blocks<K> for F {
    #[inline(always)]
    fn block<'s>(
        &'s self,
        start: usize,
        len: usize,
        scratch: &'s mut [[f32; BLOCK]; K],
    ) -> [&'s [f32]; K] {
        self(start, scratch.each_mut().map(|p| &mut p[..len]));
        scratch.each_ref().map(|p| &p[..len])
    }
}

/// Stored planes, one per channel, each at least as long as the pixel count: handed out
/// as they are, without a copy.
impl<const K: usize> Blocks<K> for [&[f32]; K] {
    #[inline(always)]
    fn block<'s>(
        &'s self,
        start: usize,
        len: usize,
        _scratch: &'s mut [[f32; BLOCK]; K],
    ) -> [&'s [f32]; K] {
        self.map(|p| &p[start..start + len])
    }
}

/// The block buffers of a [`Blocks`]: one plane of [`BLOCK`] values per channel.
struct Planes<const K: usize>([[f32; BLOCK]; K]);

impl<const K: usize> Planes<K> {
    fn new() -> Self {
        Planes([[0.0; BLOCK]; K])
    }

    /// The values of pixels `start..start + len` of each channel.
    #[inline(always)]
    fn fill<'s>(
        &'s mut self,
        fill: &'s impl Blocks<K>,
        start: usize,
        len: usize,
    ) -> [&'s [f32]; K] {
        fill.block(start, len, &mut self.0)
    }
}

/// Largest number of samples kept per channel by the one-pass quantile (3 % of a 1080p
/// frame); more, and the histogram quantile is used.
pub const TOP_K_MAX: usize = 1 << 16;

/// The brightest `keep` ordering keys of one channel seen so far (or all, if fewer are
/// positive), unordered: every key above `floor` is kept, and when the buffer holds
/// twice `keep` it is cut back to the `keep` largest and `floor` rises to the smallest
/// of them (no key at or below it can be among the `keep` largest any more).
struct Brightest {
    keep: usize,
    floor: u32,
    keys: Vec<u32>,
}

impl Brightest {
    /// Keeping the `keep` brightest keys above `floor`.
    fn new(keep: usize, floor: u32) -> Self {
        Brightest {
            keep,
            floor,
            keys: Vec::with_capacity(2 * keep.max(BLOCK)),
        }
    }

    #[inline(always)]
    fn offer(&mut self, key: u32) {
        if key > self.floor {
            self.keys.push(key);
            if self.keys.len() >= 2 * self.keep.max(BLOCK) {
                self.cut();
            }
        }
    }

    /// Keep the `keep` largest keys; raise `floor` to the smallest of them.
    fn cut(&mut self) {
        if self.keys.len() > self.keep {
            let at = self.keys.len() - self.keep;
            self.keys.select_nth_unstable(at);
            self.keys.drain(..at);
            // Keys equal to the new floor are not needed: `keep` keys ≥ it are held.
            self.floor = self.floor.max(*self.keys.iter().min().expect("keep ≥ 1"));
        }
    }

    fn merge(mut self, other: Brightest) -> Brightest {
        self.floor = self.floor.max(other.floor);
        let floor = self.floor;
        self.keys.retain(|&k| k >= floor);
        self.keys
            .extend(other.keys.into_iter().filter(|&k| k >= floor));
        self.cut();
        self
    }

    /// The `keep`-th largest sample, `None` if fewer than `keep` are above the floor
    /// the search started from.
    fn answer(self) -> Option<f32> {
        self.answer_key().map(f32::from_bits)
    }

    /// [`Brightest::answer`] as its ordering key.
    fn answer_key(mut self) -> Option<u32> {
        self.cut();
        (self.keys.len() >= self.keep).then(|| *self.keys.iter().min().expect("keep ≥ 1"))
    }
}

/// Pixels per sampled run of [`floor_guess`], and the distance between runs: the same
/// share of the pixels (1/64) as runs of 16 every 1024, but in runs of two cache lines
/// per plane that the hardware prefetcher follows. Runs of 16 took every sample from a
/// new 4 KiB page, one cache and TLB miss after another: measured (perf, 1080p
/// `stages/plan`) 14 % of `plan` for 1/64 of its pixels.
const GUESS_RUN: usize = 128;
const GUESS_STRIDE: usize = 8192;
/// [`floor_guess`] aims at this many times `keep` samples above its guess.
const GUESS_MARGIN: usize = 4;
/// Fewest sampled keys above the guess for it to be made (fewer: no guess).
const GUESS_MIN_ABOVE: usize = 32;

/// A floor below which the `keep`-th largest key of each channel very probably lies,
/// from a sample of one run of pixels in every [`GUESS_STRIDE`]: the sample's key with
/// about [`GUESS_MARGIN`]` · keep` keys of the whole image above it, scaled. Starting the
/// one-pass search from it, only the few keys above it are kept (on a frame whose
/// brightness grows down the rows almost every key raised the running floor and paid for
/// it); [`top_k`] checks that at least `keep` keys were above it and otherwise searches
/// again from 0, so the answer stays exact. 0 (no guess) when the sample is too small.
fn floor_guess<const K: usize>(n: usize, fill: &impl Blocks<K>, keep: usize) -> [u32; K] {
    // The sample's size: one run at every stride, the last one cut at the image's end.
    let runs = n.div_ceil(GUESS_STRIDE);
    let m = match runs {
        0 => 0,
        r => (r - 1) * GUESS_RUN + GUESS_RUN.min(n - (r - 1) * GUESS_STRIDE),
    };
    // The sample's j-th largest key has about j·n/m keys of the image above it.
    let above = (GUESS_MARGIN * keep).saturating_mul(m) / n.max(1);
    if above < GUESS_MIN_ABOVE || above >= m {
        return [0; K];
    }
    // The sample's key of rank `above` from the top, found as the one-pass quantile
    // finds its own: only the brightest sampled keys are kept (a buffer of a few KiB,
    // where the whole sample, 2 × 130 KiB at 1080p, was a fresh mapping per call).
    let mut top: [Brightest; K] = std::array::from_fn(|_| Brightest::new(above + 1, 0));
    let mut planes = Planes::<K>::new();
    for start in (0..n).step_by(GUESS_STRIDE) {
        let len = GUESS_RUN.min(n - start);
        let block = planes.fill(fill, start, len);
        for (top, plane) in top.iter_mut().zip(block) {
            for v in plane {
                top.offer(order_bits(*v));
            }
        }
    }
    // Fewer than `above + 1` positive keys in the sample: the key of that rank is 0.
    top.map(|t| t.answer_key().unwrap_or(0))
}

/// The one-pass quantile: the `keep`-th largest sample of each channel.
fn top_k<const K: usize>(n: usize, fill: &impl Blocks<K>, keep: usize) -> [f32; K] {
    let guess = floor_guess::<K>(n, fill, keep);
    if let Some(found) = top_k_above(n, fill, keep, guess) {
        return found;
    }
    // Fewer than `keep` keys above the guess: search again from 0.
    top_k_above(n, fill, keep, [0; K]).expect("from floor 0 every channel has an answer")
}

/// [`top_k`] from the floors `floor`, `None` if a channel had fewer than `keep` keys
/// above its floor (with floor 0 that means fewer than `keep` positive samples: the
/// answer is then 0).
fn top_k_above<const K: usize>(
    n: usize,
    fill: &impl Blocks<K>,
    keep: usize,
    floor: [u32; K],
) -> Option<[f32; K]> {
    top_k_above_on(Isa::detect(), n, fill, keep, floor)
}

/// [`top_k_above`] compiled for `isa` (the same answer on every level: comparisons only).
fn top_k_above_on<const K: usize>(
    isa: Isa,
    n: usize,
    fill: &impl Blocks<K>,
    keep: usize,
    floor: [u32; K],
) -> Option<[f32; K]> {
    let top = fold_chunks(
        n,
        || std::array::from_fn::<_, K, _>(|k| Brightest::new(keep, floor[k])),
        // One call per level, so that each is compiled inside its target-feature
        // function (the per-pixel `fill`, keys and maximum, vectorised at its width).
        |range, top| crate::simd::at_level!(isa, offer_range(range, fill, top)),
        |a, b| {
            let mut b = b.into_iter();
            a.map(|a| a.merge(b.next().expect("K channels")))
        },
    );
    let mut found = [0.0; K];
    for (k, (top, f)) in top.into_iter().zip(&mut found).enumerate() {
        match top.answer() {
            Some(v) => *f = v,
            None if floor[k] == 0 => *f = 0.0,
            None => return None,
        }
    }
    Some(found)
}

/// Offer the keys of the pixels of `range` to `top`, a block of [`BLOCK`] at a time (the
/// loop of [`for_each_block`] written out, so that all of it is compiled inside the
/// caller's target-feature function: a closure handed on is compiled outside it).
#[inline(always)]
fn offer_range<const K: usize>(
    range: std::ops::Range<usize>,
    fill: &impl Blocks<K>,
    top: &mut [Brightest; K],
) {
    let mut planes = Planes::<K>::new();
    let mut start = range.start;
    while start < range.end {
        let len = BLOCK.min(range.end - start);
        let block = planes.fill(fill, start, len);
        // A block none of whose keys of a channel is above that channel's floor adds
        // nothing to it (`offer` would keep none): one vectorised maximum skips it.
        // Most blocks of a frame are below the floor once it has risen (the bright
        // samples are a fraction of a percent, and clustered).
        for (top, plane) in top.iter_mut().zip(block) {
            if plane_max(plane) > top.floor {
                for v in plane {
                    top.offer(order_bits(*v));
                }
            }
        }
        start += len;
    }
}

/// Histograms of the high 16 bits of each channel.
fn high_histograms<const K: usize>(n: usize, fill: &impl Blocks<K>) -> Vec<Vec<u64>> {
    histograms::<K>(n, |range, h| {
        for_each_block(range, fill, |block| {
            for (h, plane) in h.iter_mut().zip(block) {
                for v in plane {
                    h[(order_bits(*v) >> 16) as usize] += 1;
                }
            }
        })
    })
}

/// Histograms of the low 16 bits of the samples whose high 16 bits equal `bins[k]`.
fn low_histograms<const K: usize>(
    n: usize,
    fill: &impl Blocks<K>,
    bins: [u32; K],
) -> Vec<Vec<u64>> {
    histograms::<K>(n, |range, h| {
        for_each_block(range, fill, |block| {
            for ((h, plane), bin) in h.iter_mut().zip(block).zip(bins) {
                for v in plane {
                    let b = order_bits(*v);
                    if b >> 16 == bin {
                        h[(b & 0xffff) as usize] += 1;
                    }
                }
            }
        })
    })
}

/// Call `f` with the values of `range`, a block of up to [`BLOCK`] pixels at a time, in
/// order, one plane per channel.
#[inline(always)]
fn for_each_block<const K: usize>(
    range: std::ops::Range<usize>,
    fill: &impl Blocks<K>,
    mut f: impl FnMut([&[f32]; K]),
) {
    let mut planes = Planes::<K>::new();
    let mut start = range.start;
    while start < range.end {
        let len = BLOCK.min(range.end - start);
        f(planes.fill(fill, start, len));
        start += len;
    }
}

/// Run `count` over chunks of `0..n` and sum the `K` histograms. Each worker counts
/// into one set of histograms for all the chunks it takes (fresh memory is expensive: a
/// 1080p frame would otherwise touch megabytes of new pages per pass).
fn histograms<const K: usize>(
    n: usize,
    count: impl Fn(std::ops::Range<usize>, &mut [Vec<u64>]) + Sync,
) -> Vec<Vec<u64>> {
    fold_chunks(
        n,
        || vec![vec![0u64; BINS]; K],
        |range, h: &mut Vec<Vec<u64>>| count(range, h),
        |mut a, b| {
            for (a, b) in a.iter_mut().zip(b) {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
            }
            a
        },
    )
}

/// Fold `count` over chunks of `0..n` into states made by `fresh` (one per worker, in
/// parallel with the `rayon` feature), then `merge` the states.
fn fold_chunks<S: Send>(
    n: usize,
    fresh: impl Fn() -> S + Sync + Send,
    count: impl Fn(std::ops::Range<usize>, &mut S) + Sync,
    merge: impl Fn(S, S) -> S + Sync + Send,
) -> S {
    let chunks = n.div_ceil(CHUNK);
    let range = |c: usize| c * CHUNK..((c + 1) * CHUNK).min(n);
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        (0..chunks)
            .into_par_iter()
            .fold(&fresh, |mut s, c| {
                count(range(c), &mut s);
                s
            })
            .reduce(&fresh, merge)
    }
    #[cfg(not(feature = "rayon"))]
    {
        let _ = merge;
        let mut s = fresh();
        for c in 0..chunks {
            count(range(c), &mut s);
        }
        s
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

    /// The one-pass quantile and the histogram quantile agree exactly, across chunk
    /// boundaries (several workers), with ties, zeros, NaNs and negative samples, and
    /// on an ascending ramp (every sample raises the running floor).
    #[test]
    fn one_pass_and_histogram_quantiles_agree() {
        let n = 2 * CHUNK + 12_345;
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let noisy: Vec<f32> = (0..n)
            .map(|_| match rnd() % 10 {
                0 => 0.0,
                1 => f32::NAN,
                2 => -3.0,
                3 => 7.25, // many ties
                _ => f32::from_bits((rnd() % 0x7f00_0000) as u32),
            })
            .collect();
        let ramp: Vec<f32> = (0..n).map(|i| i as f32 * 0.01).collect();
        let few: Vec<f32> = (0..n)
            .map(|i| if i % 50_000 == 3 { 2.0 } else { 0.0 })
            .collect();
        for v in [&noisy, &ramp, &few] {
            let fill = |start: usize, [out]: [&mut [f32]; 1]| {
                out.copy_from_slice(&v[start..start + out.len()]);
            };
            for fraction in [0.0, 1e-6, 1e-4, 1e-3, 0.01, 0.02] {
                let allowed = ((n as f64) * fraction).floor() as usize;
                let rank = n - 1 - allowed;
                let keep = n - rank;
                assert!(keep <= TOP_K_MAX);
                let one = top_k::<1>(n, &fill, keep);
                let two = by_histogram::<1>(n, &fill, rank);
                assert_eq!(one[0].to_bits(), two[0].to_bits(), "fraction {fraction}");
                assert_eq!(highest_visible(v, fraction).to_bits(), two[0].to_bits());
            }
        }
    }

    /// Skipping the blocks whose keys all lie at or below a channel's floor keeps the
    /// answer of every channel exact: two channels of different brightness (one's
    /// bright samples clustered in a patch, the other's spread one in 997), against a
    /// sort.
    #[test]
    fn skipped_blocks_keep_each_channel_exact() {
        let (w, h) = (1920usize, 1080usize);
        let n = w * h;
        let a: Vec<f32> = (0..n)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let patch = (1500..1560).contains(&x) && (700..760).contains(&y);
                if patch {
                    1e4 + (i % 13) as f32
                } else {
                    (i % 1009) as f32 * 0.01
                }
            })
            .collect();
        let b: Vec<f32> = (0..n)
            .map(|i| {
                if i % 997 == 5 {
                    3e3 + (i % 31) as f32
                } else {
                    (i % 89) as f32
                }
            })
            .collect();
        let fill = |start: usize, [oa, ob]: [&mut [f32]; 2]| {
            oa.copy_from_slice(&a[start..start + oa.len()]);
            ob.copy_from_slice(&b[start..start + ob.len()]);
        };
        for fraction in [1e-4, 1e-3, 3e-3] {
            let got = highest_visible_of::<2>(n, fill, fraction);
            let allowed = ((n as f64) * fraction).floor() as usize;
            // Every instruction set finds the same keys, from floor 0 and from a guess
            // (which may be too high: `None`, then `top_k` searches again from 0).
            let guess = floor_guess::<2>(n, &fill, allowed + 1);
            let from_guess = top_k_above_on::<2>(Isa::Baseline, n, &fill, allowed + 1, guess);
            assert!(from_guess.is_none() || from_guess == Some(got));
            for isa in Isa::all_available() {
                let on = top_k_above_on::<2>(isa, n, &fill, allowed + 1, [0; 2]);
                assert_eq!(on, Some(got), "{isa:?}, {fraction}");
                let on = top_k_above_on::<2>(isa, n, &fill, allowed + 1, guess);
                assert_eq!(on, from_guess, "{isa:?}, {fraction}, floor {guess:?}");
            }
            for (k, v) in [&a, &b].into_iter().enumerate() {
                let mut sorted = v.clone();
                sorted.sort_by(f32::total_cmp);
                assert_eq!(got[k], sorted[n - 1 - allowed], "channel {k}, {fraction}");
            }
        }
    }

    /// The floor guessed from a sample is checked: on frames whose sampled pixels are
    /// the brightest (the guess too high: a second search) or the darkest (the guess
    /// far too low), and on a frame brightening down its rows, the one-pass answer is
    /// the histogram's, exactly.
    #[test]
    fn guessed_floor_keeps_the_answer_exact() {
        let n = 2 * CHUNK + 777;
        let sampled = |i: usize| i % GUESS_STRIDE < GUESS_RUN;
        let bright_sampled: Vec<f32> = (0..n)
            .map(|i| {
                if sampled(i) {
                    5.0
                } else {
                    (i % 997) as f32 * 1e-3
                }
            })
            .collect();
        let dark_sampled: Vec<f32> = (0..n)
            .map(|i| {
                if sampled(i) {
                    0.0
                } else {
                    1.0 + (i % 991) as f32
                }
            })
            .collect();
        let brightening: Vec<f32> = (0..n).map(|i| (i / 1920) as f32 * (i % 7) as f32).collect();
        for v in [&bright_sampled, &dark_sampled, &brightening] {
            let fill = |start: usize, [out]: [&mut [f32]; 1]| {
                out.copy_from_slice(&v[start..start + out.len()]);
            };
            for fraction in [1e-4, 1e-3, 0.01] {
                let allowed = ((n as f64) * fraction).floor() as usize;
                let rank = n - 1 - allowed;
                // The brightening frame is searched from a guess (the others need not be).
                if std::ptr::eq(v, &brightening) && fraction >= 1e-3 {
                    assert_ne!(floor_guess::<1>(n, &fill, n - rank), [0]);
                }
                let one = top_k::<1>(n, &fill, n - rank);
                let two = by_histogram::<1>(n, &fill, rank);
                assert_eq!(one[0].to_bits(), two[0].to_bits(), "fraction {fraction}");
            }
        }
        let fill = |start: usize, [out]: [&mut [f32]; 1]| {
            out.copy_from_slice(&bright_sampled[start..start + out.len()]);
        };
        // Here the guess is 5.0 itself: no key above it, so the second search ran.
        let keep = n / 1000;
        assert_eq!(floor_guess::<1>(n, &fill, keep), [5.0f32.to_bits()]);
        assert_eq!(top_k_above::<1>(n, &fill, keep, [5.0f32.to_bits()]), None);
        assert_eq!(top_k::<1>(n, &fill, keep), [5.0]);
    }

    #[test]
    fn invalid_samples_count_as_zero() {
        let v = [f32::NAN, f32::INFINITY, -5.0, 2.0, f32::NEG_INFINITY];
        assert_eq!(highest_visible(&v, 0.0), 2.0);
        assert_eq!(highest_visible(&[f32::NAN; 4], 0.0), 0.0);
        assert_eq!(highest_visible(&[], 0.0), 0.0);
    }

    #[test]
    fn channels_at_once_equal_channels_alone() {
        let a: Vec<f32> = (0..3000).map(|i| ((i * 31) % 1000) as f32 * 0.37).collect();
        let b: Vec<f32> = (0..3000).map(|i| 1e-3 * ((i * 17) % 977) as f32).collect();
        let both = highest_visible_of(
            3000,
            |start, [oa, ob]: [&mut [f32]; 2]| {
                oa.copy_from_slice(&a[start..start + oa.len()]);
                ob.copy_from_slice(&b[start..start + ob.len()]);
            },
            0.01,
        );
        assert_eq!(both, [highest_visible(&a, 0.01), highest_visible(&b, 0.01)]);
    }
}
