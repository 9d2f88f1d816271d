//! The exact separable convolution used for small sigma.
//!
//! The kernel is a sampled Gaussian `k[j] ∝ exp(−j²/(2τ²))`, `|j| ≤ R`,
//! `R = max(1, ⌈4σ⌉)`, normalised to unit sum, with `τ` chosen so that the *discrete*
//! kernel's variance `Σ j² k[j]` is exactly `σ²`.
//!
//! For `σ ≥ 1` this is the ordinary sampled Gaussian: `τ` exceeds `σ` by less than
//! 0.04 % (3.6e-4 at most, just below 5 px), just compensating the variance lost by
//! truncating at `4σ`, and sampling aliases only `exp(−2π²σ²)` of the spectrum. Below about 0.5 px a Gaussian sampled at
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

/// Samples computed together by the baseline build (SSE2): eight vectors, independent
/// accumulators so that the multiply-add latency is hidden; [`NARROW`] for the rest.
pub(crate) const LANES_BASELINE: usize = 32;
/// Samples computed together by the AVX2 build: eight vectors of eight. Each tap adds
/// to every accumulator, so a block needs as many vectors as the multiply-add's latency
/// times its throughput (4 × 2 on current x86-64 cores) to keep the units busy: four
/// vectors (32 samples) ran at half the rate.
pub(crate) const LANES_AVX2: usize = 64;
/// Samples computed together by the AVX-512 build: eight vectors of sixteen.
pub(crate) const LANES_AVX512: usize = 128;
/// The narrower block for what is left after the wide ones: one AVX2 vector.
pub(super) const NARROW: usize = 8;

/// One output sample: `h[0]·x(0) + Σ_j h[j]·(x(−j) + x(j))`, the same operations in the
/// same order for rows and columns and for every block width, so that all round
/// identically.
#[inline(always)]
pub(super) fn tap_sum<const FMA: bool>(half: &[f32], x: impl Fn(isize) -> f32) -> f32 {
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
pub(super) fn tap_sum_lanes<'a, const FMA: bool, const N: usize>(
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
pub(super) fn lanes_at<const N: usize>(v: &[f32], at: usize) -> &[f32; N] {
    v[at..at + N].try_into().expect("N samples")
}

/// Compute `out[i]` for all `i` from `x(i, d)`, the input at offset `d` from output `i`,
/// in blocks of `L`, then [`NARROW`], then one (the same result for any `L`).
#[inline(always)]
fn convolve<const FMA: bool, const L: usize>(
    half: &[f32],
    out: &mut [f32],
    block: impl Fn(usize, isize) -> usize,
    src: &[f32],
) {
    let n = out.len();
    let mut i = 0;
    while i + L <= n {
        let acc = tap_sum_lanes::<FMA, L>(half, |d| lanes_at(src, block(i, d)));
        out[i..i + L].copy_from_slice(&acc);
        i += L;
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

/// One segment of rows of an [exact pass](super::exact_pass): the rows it writes and,
/// in place, the input rows beyond them that other segments overwrite, saved before the
/// pass.
pub(crate) struct Segment<'a, const P: usize> {
    /// Index of the segment's first row.
    pub(crate) start: usize,
    /// The segment's rows of every plane (the output; in place, also the input).
    pub(crate) rows: [&'a mut [f32]; P],
    /// In place: the input rows above the segment that its kernel reaches, from row
    /// `above.0`, per plane (empty otherwise).
    pub(crate) above: (usize, [Vec<f32>; P]),
    /// In place: the input rows below the segment that its kernel reaches, per plane.
    pub(crate) below: [Vec<f32>; P],
}

impl<const P: usize> Segment<'_, P> {
    /// Input row `y` of every plane, written by `fill(y, prior, rows)` into `pad_rows`
    /// (one padded row of `padded` samples per plane, the row itself from sample `left`),
    /// then its first and last samples replicated into the padding on each side. `prior`
    /// is row `y`'s content before the pass when `in_place` (from the segment's rows or
    /// the rows saved above and below it), empty slices otherwise. Returns what `fill`
    /// returned.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn fill_padded<S>(
        &self,
        y: usize,
        width: usize,
        in_place: bool,
        pad_rows: &mut [f32],
        padded: usize,
        left: usize,
        fill: &impl Fn(usize, [&[f32]; P], [&mut [f32]; P]) -> S,
    ) -> S {
        let (a, w) = (self.start, width);
        let b = a + self.rows[0].len() / w;
        let prior: [&[f32]; P] = std::array::from_fn(|p| {
            if !in_place {
                &[][..]
            } else if y < a {
                &self.above.1[p][(y - self.above.0) * w..][..w]
            } else if y >= b {
                &self.below[p][(y - b) * w..][..w]
            } else {
                &self.rows[p][(y - a) * w..][..w]
            }
        });
        let mut parts = pad_rows.chunks_exact_mut(padded);
        let rows: [&mut [f32]; P] = std::array::from_fn(|_| {
            let part = parts.next().expect("P padded rows");
            &mut part[left..left + w]
        });
        let s = fill(y, prior, rows);
        for row in pad_rows.chunks_exact_mut(padded).take(P) {
            let (first, last) = (row[left], row[left + w - 1]);
            row[..left].fill(first);
            row[left + w..].fill(last);
        }
        s
    }
}

/// Run one segment of an exact pass: every input row its outputs need (the segment's
/// rows and `r` beyond each end, the boundary replicated) is produced by
/// `fill(y, prior, rows)` into the middle of a padded row, or with `direct` read where it
/// is (no copy; `fill` is not called), and convolved along the row into a ring of
/// `2r + GROUP` rows; each group of [`GROUP`] output rows is then the
/// convolution down the ring, a [`COLUMN_BLOCK`] of columns at a time for all rows of
/// the group, written to the segment's rows and handed to `finish` row by row. `prior`
/// is row `y`'s content before the pass when `in_place`, empty slices otherwise. Returns
/// the sum (`add`) of what `fill` returned for the segment's own rows and of what
/// `finish` returned.
///
/// Each output sample goes through the same operations in the same order as in a
/// separate row pass and column pass ([`convolve`] along the row, then down the
/// column), so the result does not depend on how the rows are split into segments.
/// A plane one sample wide (or high) is not filtered along that axis (it is constant
/// along it).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn segment<const FMA: bool, const L: usize, const P: usize, S>(
    half: &[f32],
    width: usize,
    height: usize,
    in_place: bool,
    mut seg: Segment<'_, P>,
    direct: Option<&Direct<'_, P>>,
    fill: &impl Fn(usize, [&[f32]; P], [&mut [f32]; P]) -> S,
    finish: &impl Fn(usize, [&mut [f32]; P]) -> S,
    add: &impl Fn(S, S) -> S,
    mut acc: S,
) -> S {
    assert!(
        !(in_place && direct.is_some()),
        "segment: rows read in place cannot be written in place"
    );
    let r = half.len() - 1;
    let n = 2 * r + 1;
    // The ring holds the rows of a group of GROUP output rows: their `2r + GROUP` inputs.
    let m = n + GROUP - 1;
    let w = width;
    let padded = w + 2 * r;
    let a = seg.start;
    let b = a + seg.rows[0].len() / w;
    let mut scratch = Scratch::take();
    // Ring rows start on cache-line boundaries: the column pass then reads whole lines
    // (a vector load across two lines costs two).
    let stride = w.next_multiple_of(ALIGN);
    let (ring, pad) = scratch.split(P * m * stride, P * padded);
    // Where the `n` input rows of each output row of a group are in the ring.
    let mut offsets = vec![0usize; GROUP * n];
    let mut next = a.saturating_sub(r);
    for o in (a..b).step_by(GROUP) {
        let count = GROUP.min(b - o);
        while next <= (o + count - 1 + r).min(height - 1) {
            let y = next;
            next += 1;
            let slot = y % m;
            if let Some(d) = direct {
                for (p, source) in d.planes.iter().enumerate() {
                    let dst = &mut ring[(p * m + slot) * stride..][..w];
                    let row = &source[y * d.stride..][..d.stride];
                    d.convolve::<FMA, L>(half, dst, row, pad);
                }
                continue;
            }
            let s = seg.fill_padded(y, w, in_place, pad, padded, r, fill);
            if (a..b).contains(&y) {
                acc = add(acc, s);
            }
            for (p, row) in pad.chunks_exact_mut(padded).enumerate() {
                let dst = &mut ring[(p * m + slot) * stride..][..w];
                if w > 1 {
                    convolve::<FMA, L>(half, dst, |i, d| (i + r).wrapping_add_signed(d), row);
                } else {
                    dst.copy_from_slice(&row[r..r + w]);
                }
            }
        }
        for (k, offs) in offsets.chunks_exact_mut(n).take(count).enumerate() {
            for (j, off) in offs.iter_mut().enumerate() {
                *off = ((o + k + j).saturating_sub(r).min(height - 1) % m) * stride;
            }
        }
        // Down the ring a block of columns at a time for every output row of the group,
        // so that the block's ring rows are read from the L1 cache after the first: row
        // by row, each output row read all `2r + 1` ring rows (more than the L1 holds)
        // from the L2 cache.
        for (p, plane) in seg.rows.iter_mut().enumerate() {
            let base = p * m * stride;
            for c0 in (0..w).step_by(COLUMN_BLOCK) {
                let c1 = (c0 + COLUMN_BLOCK).min(w);
                // The AVX-512 build computes the block's rows in tiles that keep their
                // ring rows in registers; the rows it leaves go the common way.
                let tiled = if L == LANES_AVX512 && height > 1 {
                    let out = &mut plane[(o - a) * w..];
                    column_tiles(half, ring, base, &offsets, count, out, w, c0..c1)
                } else {
                    0
                };
                for (k, offs) in offsets.chunks_exact(n).take(count).enumerate().skip(tiled) {
                    let row = &mut plane[(o + k - a) * w..][c0..c1];
                    if height > 1 {
                        convolve::<FMA, L>(
                            half,
                            row,
                            |x, d| base + offs[(d + r as isize) as usize] + c0 + x,
                            ring,
                        );
                    } else {
                        row.copy_from_slice(&ring[base + offs[r] + c0..][..c1 - c0]);
                    }
                }
            }
        }
        for k in 0..count {
            let row = (o + k - a) * w;
            let out: [&mut [f32]; P] = seg.rows.each_mut().map(|p| &mut p[row..][..w]);
            acc = add(acc, finish(o + k, out));
        }
    }
    scratch.give_back();
    acc
}

/// The input rows of a [`segment`] read where they are: row `y` of plane `p` is
/// `planes[p][y * stride..][..stride]`, and the segment's column `i` is its column `x0 + i`
/// (the segment's width of columns from `x0`, inside the row). Along the row the blur
/// reads the row's own samples beyond the segment's columns, and replicates its first and
/// last samples past its ends, so each output is the whole row's blur.
pub(crate) struct Direct<'a, const P: usize> {
    pub(crate) planes: [&'a [f32]; P],
    pub(crate) stride: usize,
    pub(crate) x0: usize,
}

impl<const P: usize> Direct<'_, P> {
    /// `dst[i]`, the blur along `row` (one row of a plane, `stride` samples) at its column
    /// `x0 + i`: read in place where the kernel stays inside the row, from a copy with the
    /// row's end samples replicated (in `pad`, at least `dst.len() + 2r` samples) within
    /// `r` of its ends. Each sample through [`tap_sum`]'s operations, as in [`segment`]'s
    /// padded rows (the same values; a row of one sample is not filtered).
    #[inline(always)]
    fn convolve<const FMA: bool, const L: usize>(
        &self,
        half: &[f32],
        dst: &mut [f32],
        row: &[f32],
        pad: &mut [f32],
    ) {
        let (r, x0, w, n) = (half.len() - 1, self.x0, dst.len(), row.len());
        if n == 1 {
            dst.fill(row[0]);
            return;
        }
        // Outputs `lo..hi` read only samples of the row: `x0 + i − r ≥ 0` and
        // `x0 + i + r < n`.
        let lo = r.saturating_sub(x0).min(w);
        let hi = n.saturating_sub(r + x0).clamp(lo, w);
        convolve::<FMA, L>(
            half,
            &mut dst[lo..hi],
            |i, d| (x0 + lo + i).wrapping_add_signed(d),
            row,
        );
        // The outputs near an end: the samples they read, the row's ends replicated.
        let last = (n - 1) as isize;
        for (from, to) in [(0, lo), (hi, w)] {
            if from == to {
                continue;
            }
            let count = to - from + 2 * r;
            for (k, v) in pad[..count].iter_mut().enumerate() {
                let at = (x0 + from + k) as isize - r as isize;
                *v = row[at.clamp(0, last) as usize];
            }
            convolve::<FMA, L>(
                half,
                &mut dst[from..to],
                |i, d| (i + r).wrapping_add_signed(d),
                &pad[..count],
            );
        }
    }
}

/// Output rows of one tile of [`column_tiles`].
const TILE_ROWS: usize = 4;
/// Columns of one tile of [`column_tiles`]: one AVX-512 vector.
const TILE_LANES: usize = 16;
/// Largest kernel radius [`column_tiles`] handles: a tile's `TILE_ROWS + 2R` input
/// vectors and `TILE_ROWS` accumulators must fit the 32 vector registers of AVX-512
/// (28 at R = 10); wider kernels go the common way.
const TILE_MAX_RADIUS: usize = 10;
/// Input rows of a tile of the widest radius.
const TILE_INPUTS: usize = TILE_ROWS + 2 * TILE_MAX_RADIUS;

/// The pass down the ring for the columns `cols` of the first rows of a group, in tiles
/// of [`TILE_ROWS`] output rows × [`TILE_LANES`] columns of a whole [`COLUMN_BLOCK`],
/// whose `TILE_ROWS + 2R` input vectors are each loaded once and held in registers: the
/// common way loads the `2r + 1` inputs of every output vector from the L1 cache (19
/// loads at R = 9 against 5.5), and its loads, not its arithmetic, bounded it. Every
/// output goes through the operations of [`tap_sum`] in its order, so the result is the
/// same bit for bit (tested). `offsets` are those of [`segment`] (per output row of the
/// group, its `2r + 1` ring rows), `out` the group's output rows (`width` apart).
/// Returns how many of the group's `count` rows it wrote (0 for a partial block or a
/// radius above [`TILE_MAX_RADIUS`]).
///
/// Compiled for AVX-512 with fused multiply-adds, one target-feature function per
/// radius (inlined into [`segment`], the ten of them kept it from being inlined into
/// its own); only [`segment`]'s AVX-512 build calls it.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn column_tiles(
    half: &[f32],
    ring: &[f32],
    base: usize,
    offsets: &[usize],
    count: usize,
    out: &mut [f32],
    width: usize,
    cols: std::ops::Range<usize>,
) -> usize {
    if cols.len() != COLUMN_BLOCK {
        return 0;
    }
    macro_rules! radii {
        ($($r:literal)*) => {
            match half.len() - 1 {
                $($r => crate::simd::run_inlined!(Avx512Fma, {
                    tiles::<$r>(half, ring, base, offsets, count, out, width, cols.start)
                }),)*
                _ => 0,
            }
        };
    }
    const _: () = assert!(TILE_MAX_RADIUS == 10);
    radii!(1 2 3 4 5 6 7 8 9 10)
}

/// [`column_tiles`] for the radius `R` and a whole block from column `c0`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn tiles<const R: usize>(
    half: &[f32],
    ring: &[f32],
    base: usize,
    offsets: &[usize],
    count: usize,
    out: &mut [f32],
    width: usize,
    c0: usize,
) -> usize {
    let n = 2 * R + 1;
    let taps: [f32; TILE_MAX_RADIUS + 1] = std::array::from_fn(|j| half[j.min(R)]);
    let mut k0 = 0;
    while k0 + TILE_ROWS <= count {
        // Input row t of the tile (output row k0 + k reads t = k + R + d) in the block,
        // as arrays so that no load needs a bounds check; the entries past the tile's
        // last input are not read.
        let rows: [&[f32; COLUMN_BLOCK]; TILE_INPUTS] = std::array::from_fn(|t| {
            let t = t.min(TILE_ROWS + 2 * R - 1);
            let (k, j) = if t < n {
                (k0, t)
            } else {
                (k0 + t + 1 - n, n - 1)
            };
            ring[base + offsets[k * n + j] + c0..][..COLUMN_BLOCK]
                .try_into()
                .expect("a block")
        });
        for v in 0..COLUMN_BLOCK / TILE_LANES {
            let c = v * TILE_LANES;
            let x = |t: usize| -> [f32; TILE_LANES] {
                *<&[f32; TILE_LANES]>::try_from(&rows[t][c..c + TILE_LANES]).expect("a vector")
            };
            let mut acc: [[f32; TILE_LANES]; TILE_ROWS] =
                std::array::from_fn(|k| x(k + R).map(|v| taps[0] * v));
            // The taps written out (a loop over them was left rolled at R = 9 and 10,
            // its inputs then reloaded); `j ≤ R` is decided at compile time.
            macro_rules! taps {
                ($($j:literal)*) => {$(
                    if $j <= R {
                        for (k, acc) in acc.iter_mut().enumerate() {
                            let (lo, hi) = (x(k + R - $j), x(k + R + $j));
                            for l in 0..TILE_LANES {
                                acc[l] = madd::<true>(taps[$j], lo[l] + hi[l], acc[l]);
                            }
                        }
                    }
                )*};
            }
            taps!(1 2 3 4 5 6 7 8 9 10);
            for (k, acc) in acc.iter().enumerate() {
                out[(k0 + k) * width + c0 + c..][..TILE_LANES].copy_from_slice(acc);
            }
        }
        k0 += TILE_ROWS;
    }
    k0
}

/// The ring and padded rows of a segment, kept by each thread from one pass to the next
/// (fresh memory for every pass costs page faults: about 1 MiB per 1080p frame).
pub(super) struct Scratch(Vec<f32>);

/// Output rows of a segment computed together down the ring, a block of columns at a
/// time (see [`segment`]).
const GROUP: usize = 8;

/// Columns per block of the pass down the ring: a multiple of every block width of
/// [`convolve`], small enough that the `2r + GROUP` ring rows of a block (at most 24 KiB
/// at r = 20, 13 KiB at r = 9) stay in a 48 KiB L1 cache.
const COLUMN_BLOCK: usize = 128;

/// Samples per cache line (64 bytes).
const ALIGN: usize = 16;

/// Scratch larger than this (in samples, 16 MiB) is freed after its pass, not kept.
const SCRATCH_KEEP_MAX: usize = 1 << 22;

thread_local! {
    static SCRATCH: std::cell::Cell<Vec<f32>> = const { std::cell::Cell::new(Vec::new()) };
}

impl Scratch {
    pub(super) fn take() -> Self {
        Scratch(SCRATCH.with(std::cell::Cell::take))
    }

    /// Two buffers of `a` and `b` samples (their content is left from earlier use), the
    /// first starting on a multiple of [`ALIGN`] samples in memory.
    pub(super) fn split(&mut self, a: usize, b: usize) -> (&mut [f32], &mut [f32]) {
        self.0.resize(a + b + ALIGN, 0.0);
        let misalign = (self.0.as_ptr() as usize / size_of::<f32>()) % ALIGN;
        let skip = (ALIGN - misalign) % ALIGN;
        let (a_buf, b_buf) = self.0[skip..].split_at_mut(a);
        (a_buf, &mut b_buf[..b])
    }

    pub(super) fn give_back(self) {
        if self.0.len() <= SCRATCH_KEEP_MAX {
            SCRATCH.with(|s| s.set(self.0));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_variance_is_exact_and_taps_positive() {
        for sigma in [
            1e-3, 0.1, 0.25, 0.26, 0.3, 0.5, 0.7, 1.0, 1.7, 2.99, 4.38, 4.99,
        ] {
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
        // σ ≥ 1: the plain sampled Gaussian (τ within 0.04 % of σ below 5 px).
        for sigma in [1.0f64, 2.0, 2.99, 4.99] {
            let k = kernel(sigma);
            let r = k.len() / 2;
            let ratio = f64::from(k[r + 1]) / f64::from(k[r]);
            let tau = (-0.5 / ratio.ln()).sqrt();
            assert!((tau / sigma - 1.0).abs() < 4e-4, "{sigma}: τ = {tau}");
        }
        // Small σ: the plain sampled Gaussian would be 7 % narrow at 0.5 px.
        let k = kernel(0.5);
        let r = k.len() / 2;
        let tau = (-0.5 / (f64::from(k[r + 1]) / f64::from(k[r])).ln()).sqrt();
        assert!(tau > 0.52, "τ = {tau}");
    }
}
