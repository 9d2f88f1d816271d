//! The Gaussian of middle sigmas in two half-resolution stages.
//!
//! A Gaussian of standard deviation `σ` is two Gaussians of `σ/√2` in turn. After the
//! first, the signal holds almost nothing above a quarter of the sampling rate (the first
//! stage's gain there is `exp(−π²σ²/16)`), so it is computed only at every other sample
//! (along rows, then down columns), and the second stage, which reads those samples,
//! produces every output sample from them: output `n` is `Σ_m b(n − 2m)·z(m)`, with the
//! second kernel `b` sampled at the offsets of the output's phase and normalised per
//! phase (unit gain on both). Per output sample this is the convolution with a mixed
//! kernel `Σ_m b(n − 2m)·a(2m − k)`, whose difference from the Gaussian of `σ` is, by
//! Poisson's summation formula over the spacing 2, at most `2·exp(−π²σ²/8)` of the local
//! range: 5.5e-7 at [`MULTIRATE_MIN_SIGMA_PX`], 1e-10 at 4.38 px (the acuity sigma of a
//! 4K frame at a 20° field). Both kernels are the exact module's (`fir::kernel`: positive
//! taps, discrete variance exactly `σ²/2`, truncated at `4σ/√2`), so every output is a
//! convex combination of input samples (no negative values, no ringing beside an HDR
//! edge) and the variance is `σ²` per phase within 1e-4 (tested). The first stage's taps
//! of each parity are scaled to sum to ½, so an impulse keeps its mass at an even or an
//! odd position alike (tested). The exact kernel is
//! truncated at `4σ` instead, a tail of 6e-5 of the Gaussian; the two blurs differ by at
//! most 8e-5 of the range of an image with a 1e6:1 highlight (tested within 1e-4).
//!
//! The cost: along a row, the first stage computes half the samples with a kernel of
//! `⌈4σ/√2⌉` radius, the second every sample from half as many taps; down the columns
//! the same on half as many columns. About 40 taps per pixel at σ = 4.38 px against the
//! exact kernel's 74 (37 along each axis). The second stage's even and odd outputs about
//! one half-rate sample read the same inputs: the AVX-512 build computes the two
//! together (along rows, and for an even row and the odd one after it down the ring),
//! three loads per tap for the two outputs where the two apart take four, each output
//! still through its own operations in its own order (tested bit for bit). That took
//! the three-plane 4K blur at 4.38 px from 23.0–23.5 to 20.3–20.4 ms (2 cores). The
//! AVX2 build keeps them apart: together they ran 4 % slower there, the accumulators
//! of both phases spilled from its 16 vector registers.
//!
//! It runs as the exact kernel does, as one pass over the rows with the stage before and
//! after fused in ([`super::exact_pass`]): each input row is filtered along itself at
//! half rate into a ring; every other row, the ring gives one half-resolution row into
//! a second ring; each output row is filtered down that ring and then along itself to
//! full rate. Each output sample goes through the same operations in the same order
//! whatever the split into segments or the width of the vectors, and the half-rate grid
//! sits on the image's even rows and columns, so the result does not depend on how the
//! rows are split, and a rectangle of a plane whose corner is on an even row and column
//! gives the plane's values wherever the blur's reach ([`Kernels::reach`]) stays inside
//! it.

use super::fir::{self, LANES_AVX512, NARROW, Scratch, Segment};
use crate::simd::madd;

/// The smallest sigma, in pixels, blurred in two half-resolution stages (below it, the
/// exact kernel at full rate): where the mixed kernel's worst difference from the
/// Gaussian, `2·exp(−π²σ²/8)` of the local range, is 5.5e-7, under the
/// `REGION_TOLERANCE`-scale errors the acuity stage accepts elsewhere (1e-6), and where
/// the two stages' taps (about 30 per pixel) are fewer than the exact kernel's 58.
pub const MULTIRATE_MIN_SIGMA_PX: f32 = 3.5;

/// The two stages' kernels for one sigma.
#[derive(Debug, Clone)]
pub(crate) struct Kernels {
    /// The first stage from its centre outwards, `a[0..=ra]`.
    a: Vec<f32>,
    /// The second stage at even offsets (0, ±2, ±4, …), normalised: `be[t]` weighs
    /// `z(p − t)` and `z(p + t)` for output `2p`.
    be: Vec<f32>,
    /// The second stage at odd offsets (±1, ±3, …), normalised: `bo[t]` weighs
    /// `z(p − t)` and `z(p + 1 + t)` for output `2p + 1`.
    bo: Vec<f32>,
}

impl Kernels {
    /// The kernels for `sigma` (positive, finite, below the recursive filter's range).
    pub(crate) fn new(sigma: f64) -> Self {
        let half = sigma / std::f64::consts::SQRT_2;
        // The first stage's taps of each parity scaled to sum to ½ (they do to
        // `exp(−π²σ²/4)` untruncated): each half-rate sample takes input samples of one
        // parity at its even offsets and of the other at its odd ones, so with a tail cut
        // on one parity an impulse at an even position would keep 1 − 1.5e-5 of its
        // mass at 4.38 px and one at an odd position 1 + 1.5e-5. The gain stays 1.
        let a: Vec<f64> = fir::half_kernel(half)
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let parity = |p: usize| -> f64 {
            (p..a.len())
                .step_by(2)
                .map(|j| if j == 0 { a[0] } else { 2.0 * a[j] })
                .sum()
        };
        let (sum_a_even, sum_a_odd) = (parity(0), parity(1));
        let a: Vec<f32> = a
            .iter()
            .enumerate()
            .map(|(j, v)| (0.5 * v / if j % 2 == 0 { sum_a_even } else { sum_a_odd }) as f32)
            .collect();
        let b: Vec<f64> = fir::kernel(half).iter().map(|&v| f64::from(v)).collect();
        let rb = b.len() / 2;
        let even: Vec<f64> = (0..=rb).step_by(2).map(|o| b[rb + o]).collect();
        let odd: Vec<f64> = (1..=rb).step_by(2).map(|o| b[rb + o]).collect();
        let sum_even = even[0] + 2.0 * even[1..].iter().sum::<f64>();
        let sum_odd = 2.0 * odd.iter().sum::<f64>();
        Kernels {
            a,
            be: even.iter().map(|v| (v / sum_even) as f32).collect(),
            bo: odd.iter().map(|v| (v / sum_odd) as f32).collect(),
        }
    }

    /// Radius of the first stage.
    fn ra(&self) -> usize {
        self.a.len() - 1
    }

    /// Half-rate samples each side of an output's own that the second stage reads.
    fn mz(&self) -> usize {
        (self.be.len() - 1).max(self.bo.len())
    }

    /// How far, in pixels, an output sample reaches along a row or a column (rounded up
    /// to even, so that a rectangle grown by it from even coordinates starts on even
    /// ones): `2·mz + ra + 1`.
    pub(crate) fn reach(&self) -> usize {
        (2 * self.mz() + self.ra() + 1).next_multiple_of(2)
    }

    /// Replicated samples each side of a row before it is split into even and odd
    /// samples: at least the reach, even (so the split keeps the image's parity).
    fn pad(&self) -> usize {
        (2 * self.mz() + self.ra() + 2).next_multiple_of(2)
    }
}

/// `N` outputs of a symmetric kernel about a point between two samples:
/// `t[0]·(x(0) + x(1)) + Σ t[j]·(x(−j) + x(1 + j))`.
#[inline(always)]
fn between<'a, const FMA: bool, const N: usize>(
    t: &[f32],
    x: impl Fn(isize) -> &'a [f32; N],
) -> [f32; N] {
    let (c0, c1) = (x(0), x(1));
    let mut acc: [f32; N] = std::array::from_fn(|l| t[0] * (c0[l] + c1[l]));
    for (j, &h) in t.iter().enumerate().skip(1) {
        let j = j as isize;
        let (lo, hi) = (x(-j), x(1 + j));
        for l in 0..N {
            acc[l] = madd::<FMA>(h, lo[l] + hi[l], acc[l]);
        }
    }
    acc
}

/// `out[i]` for every `i`, a kernel `t` about sample `at(i, 0)` of `src` (`centre`) or
/// between `at(i, 0)` and `at(i, 1)`, where `at(i, d)` is the index of the input at
/// offset `d` (its lanes follow it for the outputs after `i`): in blocks of `L`, then
/// [`NARROW`], then one, each output through the same operations.
#[inline(always)]
fn filter<const FMA: bool, const L: usize>(
    t: &[f32],
    centre: bool,
    out: &mut [f32],
    src: &[f32],
    at: impl Fn(usize, isize) -> usize,
) {
    macro_rules! block {
        ($n:expr, $i:expr) => {{
            let i = $i;
            if centre {
                fir::tap_sum_lanes::<FMA, { $n }>(t, |d| fir::lanes_at(src, at(i, d)))
            } else {
                between::<FMA, { $n }>(t, |d| fir::lanes_at(src, at(i, d)))
            }
        }};
    }
    let n = out.len();
    let mut i = 0;
    while i + L <= n {
        let acc = block!(L, i);
        out[i..i + L].copy_from_slice(&acc);
        i += L;
    }
    while i + NARROW <= n {
        let acc = block!(NARROW, i);
        out[i..i + NARROW].copy_from_slice(&acc);
        i += NARROW;
    }
    while i < n {
        let acc = block!(1, i);
        out[i] = acc[0];
        i += 1;
    }
}

/// The second stage's two outputs about half-rate sample `p`, from the same loads: the
/// even one, `be` centred on `x(0)` (the operations of `fir::tap_sum_lanes`), and the odd
/// one, `bo` between `x(0)` and `x(1)` (those of [`between`]), each in its own order, so
/// that both are the same bit for bit as when computed apart. The two share their lower
/// input at each tap, so a tap loads three inputs for the two outputs where the two
/// apart load four (carrying the odd output's upper input over as the even one's next,
/// two loads, measured no faster).
#[inline(always)]
fn phases<'a, const FMA: bool, const N: usize>(
    be: &[f32],
    bo: &[f32],
    x: impl Fn(isize) -> &'a [f32; N],
) -> ([f32; N], [f32; N]) {
    let (c0, c1) = (x(0), x(1));
    let mut e: [f32; N] = std::array::from_fn(|l| be[0] * c0[l]);
    let mut o: [f32; N] = std::array::from_fn(|l| bo[0] * (c0[l] + c1[l]));
    let both = be.len().min(bo.len());
    for j in 1..both {
        let (lo, hi, next) = (x(-(j as isize)), x(j as isize), x(j as isize + 1));
        for l in 0..N {
            e[l] = madd::<FMA>(be[j], lo[l] + hi[l], e[l]);
        }
        for l in 0..N {
            o[l] = madd::<FMA>(bo[j], lo[l] + next[l], o[l]);
        }
    }
    for (j, &h) in be.iter().enumerate().skip(both) {
        let j = j as isize;
        let (lo, hi) = (x(-j), x(j));
        for l in 0..N {
            e[l] = madd::<FMA>(h, lo[l] + hi[l], e[l]);
        }
    }
    for (j, &h) in bo.iter().enumerate().skip(both.max(1)) {
        let j = j as isize;
        let (lo, hi) = (x(-j), x(1 + j));
        for l in 0..N {
            o[l] = madd::<FMA>(h, lo[l] + hi[l], o[l]);
        }
    }
    (e, o)
}

/// Both phases of the second stage ([`phases`]) for `count` consecutive half-rate
/// positions, where `at(i, d)` is the index in `src` of the input at offset `d` from
/// position `i` (its lanes follow it for the positions after `i`): in blocks of `N`,
/// then [`NARROW`], then one; `put(i, even, odd)` stores a block's outputs.
#[inline(always)]
fn pairs<const FMA: bool, const N: usize>(
    k: &Kernels,
    count: usize,
    src: &[f32],
    at: impl Fn(usize, isize) -> usize,
    mut put: impl FnMut(usize, &[f32], &[f32]),
) {
    macro_rules! block {
        ($n:expr, $i:expr) => {{
            let i = $i;
            let (e, o) = phases::<FMA, { $n }>(&k.be, &k.bo, |d| fir::lanes_at(src, at(i, d)));
            put(i, &e, &o);
        }};
    }
    let mut i = 0;
    while i + N <= count {
        block!(N, i);
        i += N;
    }
    while i + NARROW <= count {
        block!(NARROW, i);
        i += NARROW;
    }
    while i < count {
        block!(1, i);
        i += 1;
    }
}

/// One output row of the second stage along a row: `out[2i]` and `out[2i + 1]` from the
/// half-rate samples `v` (sample `i` of the row at `v[i + mz]`), both phases together
/// ([`pairs`]) and stored interleaved; an odd width's last (even) output on its own.
#[inline(always)]
fn row_to_full_rate<const FMA: bool, const N: usize>(
    k: &Kernels,
    v: &[f32],
    mz: usize,
    out: &mut [f32],
) {
    let at = |i: usize, d: isize| (i + mz).wrapping_add_signed(d);
    let count = out.len() / 2;
    pairs::<FMA, N>(k, count, v, at, |i, e, o| {
        let dst = &mut out[2 * i..2 * (i + e.len())];
        for (l, (&e, &o)) in e.iter().zip(o).enumerate() {
            dst[2 * l] = e;
            dst[2 * l + 1] = o;
        }
    });
    if out.len() % 2 == 1 {
        let e = fir::tap_sum_lanes::<FMA, 1>(&k.be, |d| fir::lanes_at(v, at(count, d)));
        out[2 * count] = e[0];
    }
}

/// Output rows computed together down the half-rate ring, a block of columns at a time.
const GROUP: usize = 8;
/// Half-rate rows computed together down the input ring.
const Z_GROUP: usize = 4;
/// Columns per block of the passes down the rings: a multiple of every block width of
/// [`filter`], small enough that a block's rows (at most `2·13 + 2·4 − 1` input rows at
/// σ = 5 px, 17 KiB) stay in the L1 cache across the group.
const COLUMN_BLOCK: usize = 128;

/// `e[i] = row[2i]`, `o[i] = row[2i + 1]`.
#[inline(always)]
fn deinterleave(row: &[f32], e: &mut [f32], o: &mut [f32]) {
    const N: usize = 16;
    let n = row.len();
    let blocks = n / (2 * N);
    for ((src, e), o) in row
        .chunks_exact(2 * N)
        .zip(e.chunks_exact_mut(N))
        .zip(o.chunks_exact_mut(N))
    {
        let src: &[f32; 2 * N] = src.try_into().expect("a block");
        let (mut te, mut to) = ([0f32; N], [0f32; N]);
        for i in 0..N {
            te[i] = src[2 * i];
            to[i] = src[2 * i + 1];
        }
        e.copy_from_slice(&te);
        o.copy_from_slice(&to);
    }
    for (i, &v) in row.iter().enumerate().skip(blocks * 2 * N) {
        if i % 2 == 0 {
            e[i / 2] = v;
        } else {
            o[i / 2] = v;
        }
    }
}

/// `out[2i] = e[i]`, `out[2i + 1] = o[i]`.
#[inline(always)]
fn interleave(e: &[f32], o: &[f32], out: &mut [f32]) {
    const N: usize = 16;
    let n = out.len();
    // Whole blocks as arrays, so that the compiler interleaves them with shuffles.
    let blocks = n / (2 * N);
    for ((dst, e), o) in out
        .chunks_exact_mut(2 * N)
        .zip(e.chunks_exact(N))
        .zip(o.chunks_exact(N))
    {
        let (e, o): (&[f32; N], &[f32; N]) = (
            e.try_into().expect("a block"),
            o.try_into().expect("a block"),
        );
        let mut t = [0f32; 2 * N];
        for i in 0..N {
            t[2 * i] = e[i];
            t[2 * i + 1] = o[i];
        }
        dst.copy_from_slice(&t);
    }
    for i in blocks * 2 * N..n {
        out[i] = if i % 2 == 0 { e[i / 2] } else { o[i / 2] };
    }
}

/// Run one segment of a pass (see `fir::segment`, whose contract this keeps) with the
/// two half-rate stages of `k`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn segment<const FMA: bool, const L: usize, const P: usize, S>(
    k: &Kernels,
    width: usize,
    height: usize,
    in_place: bool,
    mut seg: Segment<'_, P>,
    fill: &impl Fn(usize, [&[f32]; P], [&mut [f32]; P]) -> S,
    finish: &impl Fn(usize, [&mut [f32]; P]) -> S,
    add: &impl Fn(S, S) -> S,
    mut acc: S,
) -> S {
    let (w, h) = (width, height);
    let (ra, mz) = (k.ra(), k.mz());
    // Half-rate samples per row: m from −mz to (w − 1)/2 + mz, stored at m + mz; the
    // passes compute them up to a whole number of vectors (`stride`), so that no row
    // ends in a scalar tail, from input padded far enough on the right.
    let wz = (w - 1) / 2 + 2 * mz + 1;
    let stride = wz.next_multiple_of(16);
    let pad = k.pad();
    let padded = w + 2 * pad + 2 * (stride - wz);
    // Even samples of a padded row, then its odd ones.
    let evens = padded.div_ceil(2);
    let ring_a = 2 * ra + 2 * Z_GROUP + 1;
    let ring_z = 2 * mz + GROUP / 2 + Z_GROUP + 2;
    let a_row = seg.start;
    let b_row = a_row + seg.rows[0].len() / w;
    let mut scratch = Scratch::take();
    let (rings, rest) = scratch.split(
        P * (ring_a + ring_z) * stride,
        P * padded + padded + GROUP * stride + w,
    );
    let (ring1, ring2) = rings.split_at_mut(P * ring_a * stride);
    let (pad_rows, rest) = rest.split_at_mut(P * padded);
    let (eo, rest) = rest.split_at_mut(padded);
    let (vrows, yrow) = rest.split_at_mut(GROUP * stride);
    let clamp = |y: isize| y.clamp(0, h as isize - 1) as usize;
    let a_slot = |p: usize, y: usize| (p * ring_a + y % ring_a) * stride;
    let zlo = (a_row / 2) as isize - mz as isize;
    let zhi = ((b_row - 1) / 2 + mz) as isize;
    let z_slot = |p: usize, m: isize| (p * ring_z + (m - zlo) as usize % ring_z) * stride;
    let (te, to) = (k.be.len() - 1, k.bo.len());
    // The last half-rate row output row `n` reads.
    let need = |n: usize| (n / 2) as isize + if n.is_multiple_of(2) { te } else { to } as isize;
    // Ring offsets of the rows each row of a group reads (see the passes down the rings).
    let mut offs = vec![0usize; (Z_GROUP * (2 * ra + 1)).max(GROUP * (2 * mz + 2))];
    let mut next_fill = clamp(2 * zlo - ra as isize);
    let mut m = zlo;
    let mut next_out = a_row;
    while next_out < b_row {
        let (n0, n1) = (next_out, (next_out + GROUP).min(b_row));
        // The half-rate rows of the group, Z_GROUP at a time.
        while m <= need(n1 - 1) {
            let m1 = (m + Z_GROUP as isize - 1).min(zhi);
            // The input rows they read, along themselves at half rate.
            let last = clamp(2 * m1 + ra as isize);
            while next_fill <= last {
                let y = next_fill;
                next_fill += 1;
                let s = seg.fill_padded(y, w, in_place, pad_rows, padded, pad, fill);
                if (a_row..b_row).contains(&y) {
                    acc = add(acc, s);
                }
                for (p, row) in pad_rows.chunks_exact_mut(padded).enumerate() {
                    let (e, o) = eo.split_at_mut(evens);
                    deinterleave(row, e, o);
                    // z(m) at m + mz: its even samples from E(m + pad/2), odd from O.
                    let c0 = pad / 2 - mz;
                    let dst = &mut ring1[a_slot(p, y)..][..stride];
                    filter::<FMA, L>(&k.a, true, dst, eo, |i, d| {
                        let base = if d % 2 == 0 { 0 } else { evens };
                        base + (i + c0).wrapping_add_signed(d.div_euclid(2))
                    });
                }
            }
            // Down the columns at half rate, a block of columns at a time for the
            // group's rows (the block's input rows stay in the L1 cache).
            // Where each of their input rows is in the ring (plane 0), centre at `ra`.
            let rows_a = 2 * ra + 1;
            for (g, mm) in (m..=m1).enumerate() {
                for (j, o) in offs[g * rows_a..][..rows_a].iter_mut().enumerate() {
                    *o = a_slot(0, clamp(2 * mm + j as isize - ra as isize));
                }
            }
            for p in 0..P {
                let base = p * ring_a * stride;
                for c0 in (0..stride).step_by(COLUMN_BLOCK) {
                    let c1 = (c0 + COLUMN_BLOCK).min(stride);
                    for (g, mm) in (m..=m1).enumerate() {
                        let dst = z_slot(p, mm) + c0;
                        let (src, dst) = (&*ring1, &mut ring2[dst..dst + c1 - c0]);
                        let o = &offs[g * rows_a..][..rows_a];
                        filter::<FMA, L>(&k.a, true, dst, src, |i, d| {
                            base + o[(d + ra as isize) as usize] + c0 + i
                        });
                    }
                }
            }
            m = m1 + 1;
        }
        // Where the half-rate rows of each output row are in the ring (plane 0), from
        // `mz` before its own.
        let rows_z = 2 * mz + 2;
        for (g, n) in (n0..n1).enumerate() {
            let first = (n / 2) as isize - mz as isize;
            for (j, o) in offs[g * rows_z..][..rows_z].iter_mut().enumerate() {
                // Rows past the segment's last half-rate row are never read.
                *o = z_slot(0, (first + j as isize).min(zhi));
            }
        }
        for (p, plane) in seg.rows.iter_mut().enumerate() {
            let base = p * ring_z * stride;
            // Down the columns to full rate, a block of columns for the group's rows.
            for c0 in (0..stride).step_by(COLUMN_BLOCK) {
                let c1 = (c0 + COLUMN_BLOCK).min(stride);
                let mut g = 0;
                while g < n1 - n0 {
                    let n = n0 + g;
                    let o = &offs[g * rows_z..][..rows_z];
                    let at = |i: usize, d: isize| base + o[(d + mz as isize) as usize] + c0 + i;
                    // An even row and the odd one after it read the same half-rate rows:
                    // the AVX-512 build computes them together.
                    if L == LANES_AVX512 && n.is_multiple_of(2) && n + 1 < n1 {
                        let (ve, vo) = vrows[g * stride..].split_at_mut(stride);
                        let (ve, vo) = (&mut ve[c0..c1], &mut vo[c0..c1]);
                        pairs::<FMA, { LANES_AVX512 / 2 }>(k, c1 - c0, ring2, at, |i, e, o| {
                            ve[i..i + e.len()].copy_from_slice(e);
                            vo[i..i + o.len()].copy_from_slice(o);
                        });
                        g += 2;
                        continue;
                    }
                    let (t, centre) = if n.is_multiple_of(2) {
                        (&k.be, true)
                    } else {
                        (&k.bo, false)
                    };
                    let v = &mut vrows[g * stride + c0..g * stride + c1];
                    filter::<FMA, L>(t, centre, v, ring2, at);
                    g += 1;
                }
            }
            // Along each row to full rate: even outputs, then odd ones, interleaved.
            for (g, n) in (n0..n1).enumerate() {
                let v = &vrows[g * stride..][..wz];
                let at = (n - a_row) * w;
                let out = &mut plane[at..at + w];
                if L == LANES_AVX512 {
                    row_to_full_rate::<FMA, { LANES_AVX512 / 2 }>(k, v, mz, out);
                } else {
                    let (ye, yo) = yrow[..w].split_at_mut(w.div_ceil(2));
                    let at = |i: usize, d: isize| (i + mz).wrapping_add_signed(d);
                    filter::<FMA, L>(&k.be, true, ye, v, at);
                    filter::<FMA, L>(&k.bo, false, yo, v, at);
                    interleave(ye, yo, out);
                }
            }
        }
        for n in n0..n1 {
            let at = (n - a_row) * w;
            let out: [&mut [f32]; P] = seg.rows.each_mut().map(|p| &mut p[at..][..w]);
            acc = add(acc, finish(n, out));
        }
        next_out = n1;
    }
    debug_assert_eq!(next_out, b_row, "every output row written");
    scratch.give_back();
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two stages along one line in `f64`, written from their definition: `z(m) =
    /// Σ_j a(j)·x(2m − j)`, `y(n) = Σ_m b_phase(n − 2m)·z(m)`, the boundary replicated.
    fn line(x: &[f64], k: &Kernels) -> Vec<f64> {
        let n = x.len() as isize;
        let at = |i: isize| x[i.clamp(0, n - 1) as usize];
        let a: Vec<f64> = k.a.iter().map(|&v| f64::from(v)).collect();
        let ra = a.len() as isize - 1;
        let z = |m: isize| -> f64 {
            (-ra..=ra)
                .map(|j| a[j.unsigned_abs()] * at(2 * m - j))
                .sum()
        };
        (0..n)
            .map(|i| {
                let p = i.div_euclid(2);
                if i % 2 == 0 {
                    let t = k.be.len() as isize - 1;
                    (-t..=t)
                        .map(|d| f64::from(k.be[d.unsigned_abs()]) * z(p + d))
                        .sum()
                } else {
                    (0..k.bo.len() as isize)
                        .map(|t| f64::from(k.bo[t as usize]) * (z(p - t) + z(p + 1 + t)))
                        .sum()
                }
            })
            .collect()
    }

    /// The whole-plane reference: [`line`] along every row, then down every column.
    fn reference(src: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f64> {
        let k = Kernels::new(sigma);
        let mut rows: Vec<f64> = Vec::with_capacity(w * h);
        for r in src.chunks_exact(w) {
            let r: Vec<f64> = r.iter().map(|&v| f64::from(v)).collect();
            rows.extend(line(&r, &k));
        }
        let mut out = vec![0.0; w * h];
        for c in 0..w {
            let col: Vec<f64> = (0..h).map(|y| rows[y * w + c]).collect();
            for (y, v) in line(&col, &k).into_iter().enumerate() {
                out[y * w + c] = v;
            }
        }
        out
    }

    /// HDR noise with a 1e6:1 block.
    fn noise(w: usize, h: usize) -> Vec<f32> {
        let mut seed = 7u32;
        (0..w * h)
            .map(|i| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let (x, y) = (i % w, i / w);
                let block = (30..41).contains(&x) && (20..27).contains(&y);
                if block {
                    1e6
                } else {
                    (seed >> 8) as f32 / (1u32 << 24) as f32
                }
            })
            .collect()
    }

    /// The pass computes the two stages as defined: against the `f64` reference, on even
    /// and odd sizes, every instruction set, split into segments or not, within `f32`
    /// rounding (4e-7 of the largest value).
    #[test]
    fn the_pass_is_the_two_stage_definition() {
        use crate::blur::Exec;
        use crate::simd::Isa;
        for (w, h) in [(2, 2), (3, 5), (97, 64), (128, 131), (200, 37)] {
            let src = noise(w, h);
            let peak = src.iter().fold(0f32, |m, &v| m.max(v));
            for sigma in [3.5f32, 4.38, 4.99] {
                let want = reference(&src, w, h, f64::from(sigma));
                for isa in Isa::all_available() {
                    for exec in [Exec::Sequential, Exec::Parallel] {
                        let mut got = src.clone();
                        crate::blur::blur_with(exec, isa, &mut got, w, h, sigma);
                        let worst = got
                            .iter()
                            .zip(&want)
                            .map(|(&a, &b)| (f64::from(a) - b).abs())
                            .fold(0f64, f64::max);
                        assert!(
                            worst <= 4e-7 * f64::from(peak),
                            "{w}×{h} σ {sigma} {isa:?} {exec:?}: {worst:e}"
                        );
                    }
                }
            }
        }
    }

    /// Both phases computed together ([`phases`], the AVX-512 build's way along rows and
    /// down the half-rate ring) are the two phases computed apart (`fir::tap_sum_lanes`
    /// and [`between`], the other builds' way) bit for bit, at every sigma of the range
    /// (kernel pairs of equal and of unequal lengths) and for both multiply-adds.
    #[test]
    fn both_phases_together_are_the_phases_apart_bit_for_bit() {
        let src = noise(64, 1);
        let mut lengths = std::collections::BTreeSet::new();
        for sigma in [3.5f64, 3.9, 4.38, 4.7, 4.99] {
            let k = Kernels::new(sigma);
            lengths.insert(k.be.len() == k.bo.len());
            let mz = k.mz() as isize;
            for p in mz as usize..src.len() - mz as usize - 8 {
                let x = |d: isize| fir::lanes_at::<8>(&src, p.wrapping_add_signed(d));
                let (e, o) = phases::<true, 8>(&k.be, &k.bo, x);
                assert_eq!(e, fir::tap_sum_lanes::<true, 8>(&k.be, x), "σ {sigma}");
                assert_eq!(o, between::<true, 8>(&k.bo, x), "σ {sigma}");
                let (e, o) = phases::<false, 8>(&k.be, &k.bo, x);
                assert_eq!(e, fir::tap_sum_lanes::<false, 8>(&k.be, x), "σ {sigma}");
                assert_eq!(o, between::<false, 8>(&k.bo, x), "σ {sigma}");
            }
            assert!(k.be.len().abs_diff(k.bo.len()) <= 1);
        }
        assert_eq!(
            lengths.len(),
            2,
            "kernel pairs of equal and of unequal length"
        );
    }

    /// An impulse keeps its mass wherever it lies: an even and an odd position each sum
    /// to 1 within `f32` rounding (the first stage's taps of each parity sum to ½, so its
    /// truncated tail does not fall on one parity: they missed by 1.5e-5 at 4.38 px).
    #[test]
    fn an_impulse_keeps_its_mass_at_either_parity() {
        let n = 160;
        for sigma in [3.5f32, 4.38, 4.99] {
            for (x, y) in [(80, 80), (81, 80), (80, 81), (81, 81)] {
                let mut v = vec![0f32; n * n];
                v[y * n + x] = 1.0;
                crate::blur::gaussian_blur(&mut v, n, n, sigma);
                let sum: f64 = v.iter().map(|&x| f64::from(x)).sum();
                assert!((sum - 1.0).abs() < 1e-6, "σ {sigma} at ({x}, {y}): {sum}");
            }
        }
    }

    /// Each phase of the second stage has unit gain: a constant plane comes out of the
    /// blur unchanged (within `f32` rounding) on the rows and columns of either parity,
    /// planes of odd and even sides. (The kernels are normalised when built; this checks
    /// the gain through the passes that use them.)
    #[test]
    fn a_constant_plane_is_unchanged_on_either_phase() {
        for sigma in [3.5f32, 4.0, 4.38, 4.99] {
            for (w, h) in [(96, 80), (97, 81)] {
                for c in [1e-3f32, 0.37, 4.1e5] {
                    let mut v = vec![c; w * h];
                    crate::blur::gaussian_blur(&mut v, w, h, sigma);
                    let worst = v
                        .iter()
                        .map(|&x| (f64::from(x) / f64::from(c) - 1.0).abs())
                        .fold(0.0, f64::max);
                    assert!(worst <= 1e-6, "σ {sigma}, {w}×{h}, c {c}: {worst:e}");
                }
            }
        }
    }

    /// The mixed kernel's variance is `σ²` (the first stage's `σ²/2` plus the second's,
    /// per phase) within 1e-4, and every tap is positive.
    #[test]
    fn the_mixed_kernels_variance_is_sigma_squared() {
        for sigma in [3.5f64, 4.0, 4.38, 4.99] {
            let k = Kernels::new(sigma);
            let var_a: f64 =
                k.a.iter()
                    .enumerate()
                    .map(|(j, &v)| {
                        if j == 0 {
                            0.0
                        } else {
                            2.0 * (j * j) as f64 * f64::from(v)
                        }
                    })
                    .sum();
            let var_even: f64 =
                k.be.iter()
                    .enumerate()
                    .map(|(t, &v)| 2.0 * ((2 * t) * (2 * t)) as f64 * f64::from(v))
                    .sum();
            let var_odd: f64 =
                k.bo.iter()
                    .enumerate()
                    .map(|(t, &v)| 2.0 * ((2 * t + 1) * (2 * t + 1)) as f64 * f64::from(v))
                    .sum();
            for var_b in [var_even, var_odd] {
                let s = (var_a + var_b).sqrt();
                assert!((s / sigma - 1.0).abs() < 1e-4, "σ {sigma}: {s}");
            }
            assert!(k.a.iter().chain(&k.be).chain(&k.bo).all(|&v| v > 0.0));
        }
    }
}
