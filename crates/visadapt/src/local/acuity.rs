//! Spatially varying acuity: the Eq. 7 Gaussian with a standard deviation of its own at
//! every pixel, at a cost that does not grow with sigma.
//!
//! With local adaptation each pixel has its own acuity cutoff (Fig. 7 at its local level),
//! so its own Eq. 7 Gaussian (Ferwerda et al. 1996, Sec. 4.1). A direct per-pixel
//! convolution costs the area of the kernel. Instead the image is blurred at a small stack
//! of standard deviations in geometric steps of [`SIGMA_RATIO`] (each with the library's
//! Gaussian, flat in sigma: [`crate::blur`]) spanning the sigmas present, and each pixel
//! takes the two levels around its own sigma, weighted so that the second moment of the
//! mixed kernel is exactly `σ(x)²`: `w = (σ² − σ_a²)/(σ_b² − σ_a²)`. A mixture of two
//! Gaussians is not a Gaussian; its transfer function differs from `exp(−2π²σ²f²)` by at
//! most 1.43 % of full contrast at any frequency for this ratio (worst case over `w` and
//! `f`, computed in closed form; 3.2 % for a ratio of √2), about twice the recursive blur's
//! own 0.65 % and inside the 2 % budget of the acuity stage. Each level is blurred only
//! over the parts of the image whose pixels take it (tiles of 64² pixels, with the blur's
//! reach around them, [`crate::blur::reach_px`]), so where the sigmas vary smoothly the cost
//! is about two blurs of each plane whatever the number of levels; the result is the
//! whole-plane blur of every level's (bit for bit below [`crate::blur::IIR_MIN_SIGMA_PX`],
//! within [`REGION_TOLERANCE`] above; tested). A pixel whose sigma is a level's exactly
//! gets that level's Gaussian exactly; one below [`MIN_BLUR_SIGMA_PX`] is not blurred, as in the global operator.

use super::{EMPTY_RANGE, join_ranges, range_kernel};
use crate::operator::MIN_BLUR_SIGMA_PX;
use std::sync::Mutex;

/// Ratio of successive sigmas in the stack: `2^(1/3)` (see the module docs).
pub const SIGMA_RATIO: f64 = 1.259_921_049_894_873_2;

/// The sigmas of the stack for per-pixel sigmas `sigma_px`: geometric steps from the
/// smallest sigma at or above [`MIN_BLUR_SIGMA_PX`] to the first step at or above the
/// largest. Empty when no pixel is blurred.
pub fn levels(sigma_px: &[f32]) -> Vec<f32> {
    let r = SigmaRange::of(sigma_px);
    levels_for(r.min, r.max)
}

/// The stack's levels from the smallest to the largest blurred, finite sigma (empty when
/// there is none: `min` is `+∞`).
fn levels_for(lo: f32, hi: f32) -> Vec<f32> {
    if !lo.is_finite() {
        return Vec::new();
    }
    let mut out = vec![lo];
    while *out.last().expect("non-empty") < hi {
        let next = (f64::from(*out.last().expect("non-empty")) * SIGMA_RATIO) as f32;
        out.push(next);
    }
    out
}

/// The blurred sigmas of a set of pixels: the smallest and largest finite ones at or above
/// [`MIN_BLUR_SIGMA_PX`] (`+∞` and `0` when none) and whether one is `+∞`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SigmaRange {
    min: f32,
    max: f32,
    infinite: bool,
}

impl SigmaRange {
    const EMPTY: SigmaRange = SigmaRange {
        min: f32::INFINITY,
        max: 0.0,
        infinite: false,
    };

    fn of(sigma_px: &[f32]) -> Self {
        sigma_px.iter().fold(Self::EMPTY, |r, &s| r.with(s))
    }

    #[inline(always)]
    fn with(self, s: f32) -> Self {
        let blurred = f64::from(s) >= MIN_BLUR_SIGMA_PX;
        let finite = blurred && s.is_finite();
        SigmaRange {
            min: if finite { self.min.min(s) } else { self.min },
            max: if finite { self.max.max(s) } else { self.max },
            infinite: self.infinite | (blurred & !s.is_finite()),
        }
    }

    fn join(self, o: Self) -> Self {
        SigmaRange {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
            infinite: self.infinite | o.infinite,
        }
    }

    /// The first and last level of `levels` with weight for some pixel of the range
    /// (`None`: no pixel is blurred): the last level at or below a sigma and the next one.
    fn levels(self, levels: &[f32]) -> Option<(usize, usize)> {
        let last = levels.len() - 1;
        let below = |s: f32| levels.partition_point(|&l| l <= s).saturating_sub(1);
        match (self.min.is_finite(), self.infinite) {
            (false, false) => None,
            (false, true) => Some((last, last)),
            (true, inf) => Some((
                below(self.min),
                if inf {
                    last
                } else {
                    (below(self.max) + 1).min(last)
                },
            )),
        }
    }
}

/// Side of the square tiles, pixels, by which the levels each part of the image needs are
/// found (see [`varying_gaussian_blur`]).
const TILE_PX: usize = 64;

/// The largest difference, in the planes' own units, that restricting a level's blur to
/// the parts of the image that use it makes (display-relative units in the operator:
/// 1/4000 of an 8-bit display code). Levels under [`crate::blur::IIR_MIN_SIGMA_PX`] are
/// exact (see [`crate::blur::reach_px`]).
pub const REGION_TOLERANCE: f64 = 1e-6;

/// Blur `planes` (each `width × height`, row-major) in place, pixel `i` with a Gaussian of
/// standard deviation `sigma_px[i]` pixels (see the module docs). A pixel whose sigma is
/// below [`MIN_BLUR_SIGMA_PX`], NaN or negative keeps its value.
///
/// Each level is blurred only where pixels use it: the image is cut into tiles of 64²
/// pixels, each tile needs the levels around the sigmas in it, and a level is blurred
/// over rectangles covering its tiles and the blur's reach around them
/// ([`crate::blur::reach_px`]). The levels of the full-rate exact kernel are blurred and
/// added band by band (32 rows, each level over the runs of tiles that take it), so that
/// the output stays in cache across them; the others level by level, over regions. So
/// the cost is about two blurs of each plane wherever the sigmas vary smoothly, not one
/// per level; the result is the whole-plane blur of every level's, bit for bit below
/// [`crate::blur::IIR_MIN_SIGMA_PX`] and within [`REGION_TOLERANCE`] above (tested).
///
/// # Panics
/// If a plane or `sigma_px` does not hold `width × height` values.
pub fn varying_gaussian_blur(
    planes: &mut [&mut [f32]],
    width: usize,
    height: usize,
    sigma_px: &[f32],
) {
    let Some(stack) = Stack::new(planes.iter().map(|p| p.len()), width, height, sigma_px) else {
        return;
    };
    let mut source = Vec::with_capacity(width * height);
    for p in planes.iter_mut() {
        copy_plane(p, &mut source);
        stack.blur(p, &source);
    }
}

/// [`varying_gaussian_blur`] of planes held in vectors, without copying them: each
/// plane's samples become the source the blur reads, and the blur is written into other
/// memory (one spare plane for all, the previous plane's after the first), which then
/// replaces the plane's. The same result bit for bit; the operator's form (a copy of each
/// 1080p plane cost about 1 ms).
///
/// # Panics
/// As [`varying_gaussian_blur`].
pub fn varying_gaussian_blur_vecs(
    planes: &mut [&mut Vec<f32>],
    width: usize,
    height: usize,
    sigma_px: &[f32],
) {
    let Some(stack) = Stack::new(planes.iter().map(|p| p.len()), width, height, sigma_px) else {
        return;
    };
    // Zeroed pages from the system, touched first by the blur's parallel bands (a spare
    // kept by the thread from call to call measured no faster).
    let mut spare = vec![0f32; width * height];
    for p in planes.iter_mut() {
        std::mem::swap(*p, &mut spare);
        stack.blur(p, &spare);
    }
}

/// The levels of one varying blur and the tiles that take them, shared by its planes.
struct Stack<'a> {
    width: usize,
    height: usize,
    sigma_px: &'a [f32],
    levels: Vec<f32>,
    /// How many levels (the first ones) are the exact kernel at full rate.
    exact: usize,
    tiles: Tiles,
}

impl<'a> Stack<'a> {
    /// The stack for planes of the lengths `lens`; `None` when no pixel is blurred.
    fn new(
        lens: impl Iterator<Item = usize>,
        width: usize,
        height: usize,
        sigma_px: &'a [f32],
    ) -> Option<Self> {
        let n = width * height;
        assert_eq!(sigma_px.len(), n, "one sigma per pixel");
        for len in lens {
            assert_eq!(len, n, "plane of width × height samples");
        }
        let mut tiles = Tiles::new(sigma_px, width, height);
        let levels = tiles.stack();
        if levels.is_empty() {
            return None;
        }
        // The levels of the exact kernel at full rate come first (the sigmas rise): they
        // are blurred band by band; those of the half-rate stages and of the recursive
        // filter, after them, region by region.
        let exact =
            levels.partition_point(|&s| crate::blur::uses_full_rate_kernel(s, width, height));
        Some(Stack {
            width,
            height,
            sigma_px,
            levels,
            exact,
            tiles,
        })
    }

    /// The blur of `source` written to `out` (every sample).
    fn blur(&self, out: &mut [f32], source: &[f32]) {
        let (w, h, sig) = (self.width, self.height, self.sigma_px);
        let (levels, exact, tiles) = (&self.levels[..], self.exact, &self.tiles);
        let range = banded_levels(out, source, w, sig, levels, exact, tiles);
        if exact < levels.len() {
            region_levels(out, source, w, h, sig, levels, exact, tiles, range);
        }
    }
}

/// `plane` copied into `source` (which it replaces), in parallel.
fn copy_plane(plane: &[f32], source: &mut Vec<f32>) {
    source.clear();
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        source.par_extend(plane.par_iter().copied());
    }
    #[cfg(not(feature = "rayon"))]
    source.extend_from_slice(plane);
}

/// Rows per band of [`banded_levels`]: half a tile, so that a band's output, sigmas and
/// blurred rows (3 × 240 KiB at 1920 columns) stay in a core's 1 MiB L2 cache while its
/// levels are added, at the cost of the kernel's `2r` rows around each band blurred
/// again (1.2× the rows at r = 3, the most common radius of the benchmark's frame).
const BAND_ROWS: usize = TILE_PX / 2;

/// The levels of the exact kernel at full rate (`levels[..exact]`, each under
/// [`crate::blur::MULTIRATE_MIN_SIGMA_PX`]), blurred from `source` and added into `plane`,
/// whose pixels not blurred take their values from `source` and the others start at 0
/// (every sample is written): in parallel over
/// bands of [`BAND_ROWS`] rows, each blurring and adding its levels in their order, every
/// level only over the band's rows and the runs of adjacent tiles that take it (reading
/// the kernel's radius of columns and rows around them in `source`, where they are:
/// nothing is copied, and no column outside a run is blurred). Each blurred sample is
/// the whole-plane blur's bit for bit ([`crate::blur::exact_rows`]) and each pixel takes
/// its levels in the same order, so the result is that of blurring each level over
/// regions, one level after the other; but the band's rows of `plane` and `sigma_px`
/// are read and written while they are in cache, not once per level. Returns the range
/// of `source`: largest minus smallest value, `+∞` when one is not finite (for the
/// reach of the levels over regions, [`region_levels`]), measured band by band as the
/// bands' rows are read.
fn banded_levels(
    plane: &mut [f32],
    source: &[f32],
    width: usize,
    sigma_px: &[f32],
    levels: &[f32],
    exact: usize,
    tiles: &Tiles,
) -> f64 {
    let min_sigma = min_blur_sigma_f32();
    let height = plane.len() / width;
    // Each level's kernel once, not once per band and run.
    let kernels: Vec<Vec<f32>> = levels[..exact]
        .iter()
        .map(|&s| crate::blur::exact_half_kernel(s, width, height).expect("an exact level"))
        .collect();
    let band = |buf: &mut Vec<f32>, (b, out): (usize, &mut [f32])| {
        let y0 = b * BAND_ROWS;
        let rows = out.len() / width;
        let sig = &sigma_px[y0 * width..][..out.len()];
        let src = &source[y0 * width..][..out.len()];
        // The unblurred part: pixels not blurred take the source's values, the others
        // start at 0.
        let range = widest!(unblurred(out, src, sig, min_sigma));
        let ty = y0 / TILE_PX;
        let Some((first, last)) = tiles.band_levels(ty) else {
            return range;
        };
        let end = (last + 1).min(exact);
        for (j, half) in kernels.iter().enumerate().take(end).skip(first) {
            for [x0, x1] in tiles.runs(ty, j, 0) {
                let cw = x1 - x0;
                // Every sample is written by the blur: the buffer only grows, it is not
                // cleared for each run.
                if buf.len() < cw * rows {
                    buf.resize(cw * rows, 0.0);
                }
                let buf = &mut buf[..cw * rows];
                crate::blur::exact_rows(half, source, width, height, y0, x0..x1, buf);
                for (k, blurred) in buf.chunks_exact(cw).enumerate() {
                    let at = k * width;
                    accumulate(
                        &mut out[at + x0..at + x1],
                        blurred,
                        levels,
                        j,
                        &sig[at + x0..at + x1],
                    );
                }
            }
        }
        range
    };
    #[cfg(feature = "rayon")]
    let (lo, hi, finite) = {
        use rayon::prelude::*;
        plane
            .par_chunks_mut(BAND_ROWS * width)
            .enumerate()
            .map_init(Vec::new, band)
            .reduce(|| EMPTY_RANGE, join_ranges)
    };
    #[cfg(not(feature = "rayon"))]
    let (lo, hi, finite) = {
        let mut buf = Vec::new();
        plane
            .chunks_mut(BAND_ROWS * width)
            .enumerate()
            .map(|b| band(&mut buf, b))
            .fold(EMPTY_RANGE, join_ranges)
    };
    span(lo, hi, finite)
}

/// The levels `levels[from..]` (of the half-rate stages and the recursive filter),
/// blurred from `source` and added into `plane` after the levels below them: one level
/// after the other, each blurred over the regions that take it ([`Tiles::regions`]) with
/// the reach of [`REGION_TOLERANCE`] relative to `range` (that of `source`, from
/// [`banded_levels`]), in parallel.
///
/// A region of a finite kernel (half rate, below [`crate::blur::IIR_MIN_SIGMA_PX`]) is
/// one [`crate::blur::exact_pass`]: its rows are read from `source` as the pass needs
/// them and each blurred row is added into `plane` as soon as it is written, while it is
/// in cache (no copy of the region, no second pass over it). A region of the recursive
/// filter is copied, blurred whole, then added row by row. The same sums either way.
#[allow(clippy::too_many_arguments)]
fn region_levels(
    plane: &mut [f32],
    source: &[f32],
    width: usize,
    height: usize,
    sigma_px: &[f32],
    levels: &[f32],
    from: usize,
    tiles: &Tiles,
    range: f64,
) {
    // Each row behind a lock: the regions of one level cover disjoint pieces, so they
    // are blurred and added in parallel, each row taking one level's sums in turn and
    // the levels in their order (the same result as one region after the other).
    let rows: Vec<Mutex<&mut [f32]>> = plane.chunks_mut(width).map(Mutex::new).collect();
    // Row `y` of a region's blur (`blurred`, the crop's columns) added into the plane
    // wherever a piece of the region crosses it.
    let add_row = |region: &Region, j: usize, y: usize, blurred: &[f32]| {
        let x0 = region.crop[0];
        let mut out = rows[y].lock().unwrap_or_else(|e| e.into_inner());
        for &[px0, px1, py0, py1] in &region.pieces {
            if (py0..py1).contains(&y) {
                let sig = &sigma_px[y * width + px0..y * width + px1];
                accumulate(
                    &mut out[px0..px1],
                    &blurred[px0 - x0..px1 - x0],
                    levels,
                    j,
                    sig,
                );
            }
        }
    };
    for (j, &sigma) in levels.iter().enumerate().skip(from) {
        let reach = crate::blur::reach_px(sigma, REGION_TOLERANCE / range);
        let regions = tiles.regions(j, reach);
        let blur_region = |scratch: &mut Vec<f32>, region: &Region| {
            let [x0, x1, y0, y1] = region.crop;
            let (cw, ch) = (x1 - x0, y1 - y0);
            if crate::blur::uses_exact_kernel(sigma, cw, ch) {
                // The pass writes every sample of its output: the buffer only grows, it
                // is not cleared for each region.
                if scratch.len() < cw * ch {
                    scratch.resize(cw * ch, 0.0);
                }
                crate::blur::exact_pass(
                    sigma,
                    cw,
                    ch,
                    [&mut scratch[..cw * ch]],
                    false,
                    |y, _, [row]| row.copy_from_slice(&source[(y0 + y) * width + x0..][..cw]),
                    |y, [row]| add_row(region, j, y0 + y, row),
                    |(), ()| (),
                );
                return;
            }
            // Exactly the rectangle (no growth beyond it).
            scratch.clear();
            scratch.reserve_exact(cw * ch);
            for y in y0..y1 {
                scratch.extend_from_slice(&source[y * width + x0..y * width + x1]);
            }
            crate::blur::gaussian_blur_planes(&mut [scratch.as_mut_slice()], cw, ch, sigma);
            let row = |y: usize| add_row(region, j, y, &scratch[(y - y0) * cw..][..cw]);
            let (ry0, ry1) = region
                .pieces
                .iter()
                .fold((height, 0), |(a, b), r| (a.min(r[2]), b.max(r[3])));
            #[cfg(feature = "rayon")]
            {
                use rayon::prelude::*;
                (ry0..ry1).into_par_iter().for_each(row);
            }
            #[cfg(not(feature = "rayon"))]
            (ry0..ry1).for_each(row);
        };
        #[cfg(feature = "rayon")]
        {
            use rayon::prelude::*;
            regions.par_iter().for_each_init(Vec::new, blur_region);
        }
        #[cfg(not(feature = "rayon"))]
        {
            let mut scratch = Vec::new();
            for region in &regions {
                blur_region(&mut scratch, region);
            }
        }
    }
}

/// The smallest `f32` at or above [`MIN_BLUR_SIGMA_PX`]: for an `f32` sigma `s`,
/// `s >= min_blur_sigma_f32()` exactly when `f64::from(s) >= MIN_BLUR_SIGMA_PX`.
fn min_blur_sigma_f32() -> f32 {
    let t = MIN_BLUR_SIGMA_PX as f32;
    if f64::from(t) < MIN_BLUR_SIGMA_PX {
        f32::from_bits(t.to_bits() + 1)
    } else {
        t
    }
}

/// Largest minus smallest (`+∞` when not all values are finite).
fn span(lo: f32, hi: f32, finite: bool) -> f64 {
    if finite {
        f64::from(hi) - f64::from(lo)
    } else {
        f64::INFINITY
    }
}

/// `plane` where the blur starts: 0 for the pixels that are blurred (sigma at or above
/// `min_sigma`), `source`'s value for the others; returns `source`'s [`range_kernel`],
/// measured right after, while the band's samples are in cache (a second loop, not a
/// second trip through memory).
#[inline(always)]
fn unblurred(
    plane: &mut [f32],
    source: &[f32],
    sigma_px: &[f32],
    min_sigma: f32,
) -> (f32, f32, bool) {
    for ((v, &x), &s) in plane.iter_mut().zip(source).zip(sigma_px) {
        *v = if s >= min_sigma { 0.0 } else { x };
    }
    range_kernel(source)
}

/// A rectangle `[x0, x1, y0, y1]` (half-open), pixels.
type Rect = [usize; 4];

/// One blur of a level: the rectangle blurred (`crop`) and the parts of it whose pixels
/// take the level (`pieces`, each at least the level's reach inside `crop` or at the
/// image's edge).
struct Region {
    crop: Rect,
    pieces: Vec<Rect>,
}

/// Per tile, the range of levels its pixels take.
struct Tiles {
    width: usize,
    height: usize,
    /// Tiles per row.
    across: usize,
    /// Tiles per column.
    down: usize,
    /// Per tile, the range of its blurred sigmas.
    sigmas: Vec<SigmaRange>,
    /// Per tile, the first and last level with weight for some pixel in it (`None`: no
    /// pixel is blurred).
    levels: Vec<Option<(usize, usize)>>,
}

/// The sigma ranges of a band's tiles (`out`, one per [`TILE_PX`] columns) joined with
/// those of its `rows` (`width` wide): [`SigmaRange::of`] each column of the band first
/// (elementwise down the rows, as selects on `f32` with `min_sigma` from
/// [`min_blur_sigma_f32`], the same test as the `f64` one, so that the loop vectorises
/// across columns), then each tile's columns. The same ranges: a smallest and a largest
/// value do not depend on the order in which they are found (no NaN and no zero is kept).
#[inline(always)]
fn tile_ranges(out: &mut [SigmaRange], rows: &[f32], width: usize, min_sigma: f32) {
    let mut lo = vec![f32::INFINITY; width];
    let mut hi = vec![SigmaRange::EMPTY.max; width];
    let mut infinite = vec![0u8; width];
    for row in rows.chunks_exact(width) {
        for (((l, h), inf), &s) in lo.iter_mut().zip(&mut hi).zip(&mut infinite).zip(row) {
            let blurred = s >= min_sigma;
            let finite = blurred & s.is_finite();
            *l = if finite & (s < *l) { s } else { *l };
            *h = if finite & (s > *h) { s } else { *h };
            *inf |= u8::from(blurred & !s.is_finite());
        }
    }
    let columns = lo
        .chunks(TILE_PX)
        .zip(hi.chunks(TILE_PX))
        .zip(infinite.chunks(TILE_PX));
    for (tile, ((lo, hi), infinite)) in out.iter_mut().zip(columns) {
        let (mut min, mut max, mut inf) = (tile.min, tile.max, tile.infinite);
        for ((&l, &h), &i) in lo.iter().zip(hi).zip(infinite) {
            min = if l < min { l } else { min };
            max = if h > max { h } else { max };
            inf |= i != 0;
        }
        *tile = SigmaRange {
            min,
            max,
            infinite: inf,
        };
    }
}

impl Tiles {
    /// The sigma range of every tile, in one pass over the sigmas.
    fn new(sigma_px: &[f32], width: usize, height: usize) -> Self {
        let (across, down) = (width.div_ceil(TILE_PX), height.div_ceil(TILE_PX));
        let min_sigma = min_blur_sigma_f32();
        let band = |ty: usize| -> Vec<SigmaRange> {
            let mut out = vec![SigmaRange::EMPTY; across];
            let rows = &sigma_px[ty * TILE_PX * width..((ty + 1) * TILE_PX).min(height) * width];
            widest!(tile_ranges(&mut out, rows, width, min_sigma));
            out
        };
        #[cfg(feature = "rayon")]
        let bands: Vec<_> = {
            use rayon::prelude::*;
            (0..down).into_par_iter().map(band).collect()
        };
        #[cfg(not(feature = "rayon"))]
        let bands: Vec<_> = (0..down).map(band).collect();
        Tiles {
            width,
            height,
            across,
            down,
            sigmas: bands.concat(),
            levels: Vec::new(),
        }
    }

    /// The stack's levels for all tiles, and each tile's range of them.
    fn stack(&mut self) -> Vec<f32> {
        let all = self
            .sigmas
            .iter()
            .fold(SigmaRange::EMPTY, |a, &t| a.join(t));
        let levels = levels_for(all.min, all.max);
        if !levels.is_empty() {
            self.levels = self.sigmas.iter().map(|t| t.levels(&levels)).collect();
        }
        levels
    }

    /// The range of levels the tiles of band `ty` take (`None`: no pixel of the band is
    /// blurred).
    fn band_levels(&self, ty: usize) -> Option<(usize, usize)> {
        self.levels[ty * self.across..][..self.across]
            .iter()
            .flatten()
            .fold(None, |acc, &(a, b)| match acc {
                None => Some((a, b)),
                Some((lo, hi)) => Some((lo.min(a), hi.max(b))),
            })
    }

    /// The columns `[x0, x1)` of the runs of tiles of band `ty` that take level `j`, two
    /// runs joined when the blur's `reach` around them would overlap.
    fn runs(&self, ty: usize, j: usize, reach: usize) -> Vec<[usize; 2]> {
        let mut runs: Vec<[usize; 2]> = Vec::new();
        for tx in 0..self.across {
            let takes = self.levels[ty * self.across + tx].is_some_and(|(a, b)| a <= j && j <= b);
            if !takes {
                continue;
            }
            let (x0, x1) = (tx * TILE_PX, ((tx + 1) * TILE_PX).min(self.width));
            match runs.last_mut() {
                Some(last) if x0 <= last[1].saturating_add(reach.saturating_mul(2)) => {
                    last[1] = x1;
                }
                _ => runs.push([x0, x1]),
            }
        }
        runs
    }

    /// The rectangles over which level `j` is blurred, for a blur reaching `reach` pixels:
    /// per band of tiles the runs of tiles that take the level (joined when their reaches
    /// overlap), gathered into one rectangle while that costs no more area than blurring
    /// them apart.
    fn regions(&self, j: usize, reach: usize) -> Vec<Region> {
        let (w, h) = (self.width, self.height);
        let grow = |[x0, x1, y0, y1]: Rect| -> Rect {
            [
                x0.saturating_sub(reach),
                x1.saturating_add(reach).min(w),
                y0.saturating_sub(reach),
                y1.saturating_add(reach).min(h),
            ]
        };
        let area = |[x0, x1, y0, y1]: Rect| (x1 - x0) * (y1 - y0);
        let union = |a: Rect, b: Rect| {
            [
                a[0].min(b[0]),
                a[1].max(b[1]),
                a[2].min(b[2]),
                a[3].max(b[3]),
            ]
        };
        let mut regions: Vec<Region> = Vec::new();
        for ty in 0..self.down {
            let (y0, y1) = (ty * TILE_PX, ((ty + 1) * TILE_PX).min(h));
            let runs = self
                .runs(ty, j, reach)
                .into_iter()
                .map(|[x0, x1]| [x0, x1, y0, y1]);
            for piece in runs {
                let crop = grow(piece);
                let joined = regions
                    .iter_mut()
                    .rev()
                    .take(4)
                    .find(|r| area(union(r.crop, crop)) <= area(r.crop) + area(crop));
                match joined {
                    Some(r) => {
                        r.crop = union(r.crop, crop);
                        r.pieces.push(piece);
                    }
                    None => regions.push(Region {
                        crop,
                        pieces: vec![piece],
                    }),
                }
            }
        }
        regions
    }
}

/// `out += w_j(σ)·level` per pixel (where the weight is not 0), with the weights of
/// `weight` (the tests' reference) in a branch-free form the compiler vectorises (the
/// same operations, so the same values; tested).
fn accumulate(out: &mut [f32], level: &[f32], levels: &[f32], j: usize, sigma_px: &[f32]) {
    widest!(accumulate_kernel(out, level, levels, j, sigma_px))
}

/// [`accumulate`]'s loop.
#[inline(always)]
fn accumulate_kernel(out: &mut [f32], level: &[f32], levels: &[f32], j: usize, sigma_px: &[f32]) {
    let here = levels[j];
    let h2 = here * here;
    // The rising side from the level below (none for the first level), the falling side to
    // the level above (for the last level, every sigma above it takes it whole).
    let below = if j > 0 { levels[j - 1] } else { here };
    let b2 = below * below;
    let last = j + 1 >= levels.len();
    let above = if last { here } else { levels[j + 1] };
    let a2 = above * above;
    for ((o, &l), &s) in out.iter_mut().zip(level).zip(sigma_px) {
        let v = s * s;
        let rising = (v - b2) / (h2 - b2);
        let falling = if last {
            1.0
        } else {
            1.0 - (v - h2) / (a2 - h2)
        };
        let w = if s == here {
            1.0
        } else if s > below && s < here {
            rising
        } else if s > here && (last || s < above) {
            falling
        } else {
            // Including NaN and every sigma below the first level (so below the
            // operator's minimum): not blurred.
            0.0
        };
        *o = if w != 0.0 { *o + w * l } else { *o };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference weight of level `j` of `levels` for a pixel of sigma `s` (the hat function in variance
    /// of the module docs); the unblurred image is "level −1" with sigma 0 and takes the pixels
    /// below [`MIN_BLUR_SIGMA_PX`].
    fn weight(levels: &[f32], j: usize, s: f32) -> f32 {
        // NaN and small sigmas: not blurred.
        if f64::from(s).is_nan() || f64::from(s) < MIN_BLUR_SIGMA_PX {
            return 0.0;
        }
        let v = s * s;
        let here = levels[j] * levels[j];
        if s == levels[j] {
            return 1.0;
        }
        if s < levels[j] {
            if j == 0 {
                return 0.0;
            }
            let below = levels[j - 1] * levels[j - 1];
            if s <= levels[j - 1] {
                return 0.0;
            }
            (v - below) / (here - below)
        } else {
            if j + 1 >= levels.len() {
                // Above the largest level (cannot happen with `levels`' range): take it.
                return 1.0;
            }
            let above = levels[j + 1] * levels[j + 1];
            if s >= levels[j + 1] {
                return 0.0;
            }
            1.0 - (v - here) / (above - here)
        }
    }

    /// The stack as it was first written, the reference the restricted one is pinned to:
    /// every level blurred over the whole plane and added with [`weight`].
    fn reference_blur(plane: &mut [f32], width: usize, height: usize, sigma_px: &[f32]) {
        let levels = levels(sigma_px);
        if levels.is_empty() {
            return;
        }
        let source = plane.to_vec();
        for (v, &s) in plane.iter_mut().zip(sigma_px) {
            if f64::from(s) >= MIN_BLUR_SIGMA_PX {
                *v = 0.0;
            }
        }
        for (j, &sigma) in levels.iter().enumerate() {
            let mut level = source.clone();
            crate::blur::gaussian_blur(&mut level, width, height, sigma);
            for ((o, &l), &s) in plane.iter_mut().zip(&level).zip(sigma_px) {
                let w = weight(&levels, j, s);
                if w != 0.0 {
                    *o += w * l;
                }
            }
        }
    }

    /// A test scene: noise over a bright block (a range of `peak`), and a sigma field that
    /// grows across the image and jumps at an edge, with unblurred and NaN pixels.
    fn scene(w: usize, h: usize, peak: f32, sigma_lo: f32, sigma_hi: f32) -> (Vec<f32>, Vec<f32>) {
        let mut seed = 99u32;
        let mut plane = Vec::with_capacity(w * h);
        let mut sigma = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let noise = (seed >> 8) as f32 / (1u32 << 24) as f32;
                let block = (x / 50 + y / 40) % 3 == 0;
                plane.push(if block { peak * noise } else { noise });
                let u = x as f32 / w as f32;
                let mut s = sigma_lo * (sigma_hi / sigma_lo).powf(u);
                if y > h / 2 && x > w / 3 {
                    s *= 0.5;
                }
                if (x + 3 * y) % 97 == 0 {
                    s = 0.01;
                }
                if (x * 7 + y) % 389 == 0 {
                    s = f32::NAN;
                }
                sigma.push(s);
            }
        }
        (plane, sigma)
    }

    /// The restricted stack against the reference: bit for bit when every level uses the
    /// exact kernel (at full rate only, then with half-rate levels too), within
    /// [`REGION_TOLERANCE`] (plus f32 rounding of the sums) when the recursive one is
    /// used, for an HDR range of 1e4.
    #[test]
    fn restricted_stack_matches_the_whole_plane_stack() {
        let (w, h) = (420, 300);
        // The largest level's kind: 0 full rate, 1 half rate, 2 the recursive filter.
        for (lo, hi, top_kind) in [
            (0.3f32, 2.3f32, 0),
            (0.8, 4.0, 1),
            (0.6, 6.0, 2),
            (2.0, 20.0, 2),
        ] {
            let (plane, sigma) = scene(w, h, 1e4, lo, hi);
            let top = *levels(&sigma).last().expect("levels");
            let kind = [
                crate::blur::MULTIRATE_MIN_SIGMA_PX,
                crate::blur::IIR_MIN_SIGMA_PX,
            ]
            .iter()
            .filter(|&&t| top >= t)
            .count();
            assert_eq!(kind, top_kind, "σ {lo}..{hi}: top level {top}");
            let exact = kind < 2;
            let mut want = plane.clone();
            reference_blur(&mut want, w, h, &sigma);
            let mut got = plane.clone();
            varying_gaussian_blur(&mut [got.as_mut_slice()], w, h, &sigma);
            // The form over vectors (each plane blurred into the memory of a spare one, then
            // the previous plane's) gives the same samples, on two planes of other content.
            let other: Vec<f32> = plane.iter().rev().copied().collect();
            let mut other_got = other.clone();
            varying_gaussian_blur(&mut [other_got.as_mut_slice()], w, h, &sigma);
            let (mut a, mut b) = (plane.clone(), other.clone());
            varying_gaussian_blur_vecs(&mut [&mut a, &mut b], w, h, &sigma);
            for (x, y) in a.iter().zip(&got).chain(b.iter().zip(&other_got)) {
                assert_eq!(x.to_bits(), y.to_bits(), "σ {lo}..{hi}: by vectors {x} {y}");
            }
            let mut worst = 0f64;
            for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                if exact {
                    assert_eq!(a.to_bits(), b.to_bits(), "σ {lo}..{hi}: pixel {i}: {a} {b}");
                }
                // f32 rounding of the level sums (values up to 1e4) beside the tolerance.
                let rounding = 4.0 * f64::from(f32::EPSILON) * f64::from(b.abs());
                worst = worst.max(f64::from((a - b).abs()) - rounding);
            }
            assert!(worst <= REGION_TOLERANCE, "σ {lo}..{hi}: {worst:e}");
        }
    }

    /// The tiles' sigma ranges (found with `f32` selects, [`tile_ranges`]) are those of
    /// [`SigmaRange::of`] over each tile's pixels, on sigmas that include NaN, ±∞,
    /// negative values and the values either side of [`MIN_BLUR_SIGMA_PX`], on an image
    /// whose last tiles are partial.
    #[test]
    fn tile_ranges_are_those_of_each_tiles_pixels() {
        let (w, h) = (2 * TILE_PX + 37, TILE_PX + 5);
        let t = min_blur_sigma_f32();
        let below = f32::from_bits(t.to_bits() - 1);
        let special = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1.0,
            0.0,
            below,
            t,
        ];
        let mut seed = 99u32;
        let sigma: Vec<f32> = (0..w * h)
            .map(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let r = seed >> 8;
                if r.is_multiple_of(50) {
                    special[(r / 50) as usize % special.len()]
                } else {
                    0.3 + (r % 1000) as f32 * 0.02
                }
            })
            .collect();
        // The first tile: nothing blurred (just below the threshold) but its first
        // column, which holds every special value, of which only `t` and +∞ count.
        let mut sigma = sigma;
        for y in 0..TILE_PX {
            for x in 0..TILE_PX {
                sigma[y * w + x] = if x == 0 {
                    special[y % special.len()]
                } else {
                    below
                };
            }
        }
        let tiles = Tiles::new(&sigma, w, h);
        for ty in 0..tiles.down {
            for tx in 0..tiles.across {
                let mut want = SigmaRange::EMPTY;
                for y in ty * TILE_PX..((ty + 1) * TILE_PX).min(h) {
                    let x0 = tx * TILE_PX;
                    want = want.join(SigmaRange::of(
                        &sigma[y * w + x0..y * w + (x0 + TILE_PX).min(w)],
                    ));
                }
                let got = tiles.sigmas[ty * tiles.across + tx];
                assert_eq!(
                    (got.min.to_bits(), got.max.to_bits(), got.infinite),
                    (want.min.to_bits(), want.max.to_bits(), want.infinite),
                    "tile ({tx}, {ty}): {got:?} against {want:?}"
                );
            }
        }
        // The special tile: only `t` and +∞ are blurred there.
        let first = tiles.sigmas[0];
        assert_eq!((first.min, first.max, first.infinite), (t, t, true));
    }

    /// Several planes blurred in one call, each of its own range: every plane is its
    /// whole-plane stack, bit for bit with the exact kernel, within [`REGION_TOLERANCE`]
    /// with the recursive one.
    #[test]
    fn planes_blurred_together_each_match_the_whole_plane_stack() {
        let (w, h) = (300, 200);
        for (lo, hi, exact) in [(0.3f32, 2.3f32, true), (2.0, 20.0, false)] {
            let planes: Vec<(Vec<f32>, Vec<f32>)> = [1e4f32, 1.0, 30.0]
                .iter()
                .map(|&peak| scene(w, h, peak, lo, hi))
                .collect();
            let sigma = planes[0].1.clone();
            let mut got: Vec<Vec<f32>> = planes.iter().map(|(p, _)| p.clone()).collect();
            let mut views: Vec<&mut [f32]> = got.iter_mut().map(|p| p.as_mut_slice()).collect();
            varying_gaussian_blur(&mut views, w, h, &sigma);
            for ((plane, _), got) in planes.iter().zip(&got) {
                let mut want = plane.clone();
                reference_blur(&mut want, w, h, &sigma);
                let mut worst = 0f64;
                for (a, b) in got.iter().zip(&want) {
                    if exact {
                        assert_eq!(a.to_bits(), b.to_bits(), "σ {lo}..{hi}: {a} {b}");
                    }
                    let rounding = 4.0 * f64::from(f32::EPSILON) * f64::from(b.abs());
                    worst = worst.max(f64::from((a - b).abs()) - rounding);
                }
                assert!(worst <= REGION_TOLERANCE, "σ {lo}..{hi}: {worst:e}");
            }
        }
    }

    /// The regions are what makes it cheap: with a sigma field spanning ten levels, each
    /// level is blurred over a small part of the image (the sum over levels, with the
    /// reaches, under four images, against one image per level for the whole-plane stack).
    #[test]
    fn regions_cover_about_two_images_in_total() {
        let (w, h) = (1280, 320);
        let (_, sigma) = scene(w, h, 1.0, 0.6, 6.0);
        let mut tiles = Tiles::new(&sigma, w, h);
        let lv = tiles.stack();
        assert!(lv.len() >= 10, "{}", lv.len());
        let total: usize = (0..lv.len())
            .map(|j| {
                let reach = crate::blur::reach_px(lv[j], REGION_TOLERANCE);
                tiles
                    .regions(j, reach)
                    .iter()
                    .map(|r| (r.crop[1] - r.crop[0]) * (r.crop[3] - r.crop[2]))
                    .sum::<usize>()
            })
            .sum();
        let images = total as f64 / (w * h) as f64;
        assert!(
            images < 4.0,
            "{images} images blurred over {} levels",
            lv.len()
        );
    }

    /// Worst transfer-function error of a two-level mixture for the stack's ratio, in
    /// closed form over the mixing weight and frequency (the module docs' 1.43 %).
    #[test]
    fn mixture_transfer_function_error_is_bounded() {
        let r2 = SIGMA_RATIO * SIGMA_RATIO;
        let mut worst = 0f64;
        for wi in 1..200 {
            let w = f64::from(wi) / 200.0;
            for ui in 1..2000 {
                // u = 2π²σ_a²f².
                let u = f64::from(ui) / 200.0;
                let mix = (1.0 - w) * (-u).exp() + w * (-u * r2).exp();
                let exact = (-u * (1.0 - w + w * r2)).exp();
                worst = worst.max((mix - exact).abs());
            }
        }
        assert!(worst < 0.0145 && worst > 0.014, "{worst}");
    }

    #[test]
    fn weights_sum_to_one_and_match_the_variance() {
        let lv = levels(&[0.5, 3.7, 1.0]);
        assert_eq!(lv[0], 0.5);
        assert!(*lv.last().unwrap() >= 3.7);
        for k in 0..500 {
            let s = 0.5 + 3.2 * k as f32 / 499.0;
            let ws: Vec<f32> = (0..lv.len()).map(|j| weight(&lv, j, s)).collect();
            let sum: f32 = ws.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5, "{s}: {ws:?}");
            let var: f32 = ws.iter().zip(&lv).map(|(w, l)| w * l * l).sum();
            assert!((var / (s * s) - 1.0).abs() < 1e-4, "{s}");
        }
        assert_eq!(weight(&lv, 0, 0.01), 0.0);
    }

    /// The stack against the exact Gaussian: a noise image blurred with one sigma between
    /// two levels everywhere equals the library's Gaussian of that sigma to within the
    /// module's bound (1.43 % of the image's full contrast).
    #[test]
    fn stack_matches_the_exact_gaussian_between_levels() {
        let (w, h) = (96, 80);
        let mut seed = 12345u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let src: Vec<f32> = (0..w * h).map(|_| noise()).collect();
        for sigma in [0.3f32, 0.9, 1.7, 2.6, 4.1] {
            // Levels start at 1.0 (a pixel with that sigma is in the corner) so that most
            // pixels fall between two levels.
            let mut sig = vec![sigma; w * h];
            sig[0] = 0.2;
            let mut got = src.clone();
            varying_gaussian_blur(&mut [got.as_mut_slice()], w, h, &sig);
            let mut want = src.clone();
            crate::blur::gaussian_blur(&mut want, w, h, sigma);
            let worst = got
                .iter()
                .zip(&want)
                .skip(1)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            // Noise spans 0..1: the bound is relative to full contrast 1.
            assert!(worst < 0.0143, "σ {sigma}: {worst}");
        }
    }

    #[test]
    fn the_f32_threshold_is_the_f64_one() {
        let t = min_blur_sigma_f32();
        assert!(f64::from(t) >= MIN_BLUR_SIGMA_PX);
        let below = f32::from_bits(t.to_bits() - 1);
        assert!(f64::from(below) < MIN_BLUR_SIGMA_PX);
    }

    #[test]
    fn uniform_sigma_is_the_global_blur_exactly() {
        let (w, h) = (40, 30);
        let src: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 101) as f32).collect();
        for sigma in [0.7f32, 5.0] {
            let mut got = src.clone();
            varying_gaussian_blur(&mut [got.as_mut_slice()], w, h, &vec![sigma; w * h]);
            let mut want = src.clone();
            crate::blur::gaussian_blur(&mut want, w, h, sigma);
            assert_eq!(got, want);
        }
        // No blur below the operator's minimum.
        let mut got = src.clone();
        varying_gaussian_blur(&mut [got.as_mut_slice()], w, h, &vec![0.01; w * h]);
        assert_eq!(got, src);
    }
}
