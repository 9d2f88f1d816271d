//! Local adaptation: every pixel seen by an eye adapted to its own neighbourhood.
//!
//! The paper's observer adapts to one level for the whole scene (Sec. 4.4); its future work
//! says "the retina adapts locally" (Sec. 6). With one level, in daylight everything below
//! about 1 % of the adaptation level is shown black although an observer looking there
//! would see it, and at night a small coloured light is weighted by the rods of the dark
//! street around it (`k ≈ 1`) and turns white. With
//! [`AdaptationMode::Local`](crate::operator::AdaptationMode::Local) the operator's stages
//! become:
//!
//! 1. **adaptation map** ([`map`]): per pixel the photopic and scotopic luminance the eye is
//!    adapted to when it looks there, an edge-aware low-pass over a neighbourhood of
//!    [`LocalAdaptation::radius_deg`] degrees, anchored so that the brightest neighbourhoods
//!    keep the paper's level (half the highest visible luminance);
//! 2. **thresholds and scales per pixel** ([`LocalMapping`]): Eq. 3 (`m_p`, `m_s`), Eq. 4-5
//!    (the thresholds inside them), Eq. 6 (`k`) and Eq. 7 (the acuity cutoff and its
//!    Gaussian) at each pixel's own adaptation; with **rod saturation**
//!    ([`ROD_SATURATION_SCOTOPIC_CD_M2`]);
//! 3. **mapping**: `m_p(x)·XYZ + k(x)·m_s(x)·V·white` per pixel (Eq. 6), as the global
//!    operator with per-pixel coefficients;
//! 4. **acuity** ([`acuity`]): the Eq. 7 Gaussian with a per-pixel sigma;
//! 5. **clip**, as the global operator.
//!
//! # Exactly the paper's model in the limit
//!
//! On a uniform image, and for any image as the radius grows without bound, every offset of
//! the map is 0 and the local operator is the global one, pixels included (bit for bit: the
//! per-pixel coefficients at offset 0 are the global coefficients; tested). With a finite
//! radius the differences are the local model's.
//!
//! # Per-pixel coefficients from tables
//!
//! The coefficients depend on the pixel only through its two offsets, so they are tabulated
//! at [`TABLE_STEPS_PER_LOG_UNIT`] nodes per log unit and interpolated linearly: Eq. 3-6 are
//! evaluated a few thousand times per image, not per pixel. Offset 0 is a node, so the
//! global coefficients are reproduced exactly; between nodes the relative error of a
//! coefficient is below 5e-5 (the curvature of `10^x` over 1/128 log unit: `(ln 10/128)²/8
//! = 4e-5`; tested).
//!
//! # Rod saturation
//!
//! "At levels above 2 log cd/m² the [rod t.v.i.] curve approaches a vertical asymptote ...
//! the rod system is being overloaded" (Sec. 3.2, Fig. 3; Aguilar & Stiles 1954): rods
//! cannot signal luminance beyond about 10² scotopic cd/m². With local adaptation a pixel
//! can be far brighter than the neighbourhood its rods are weighted by (a light a few
//! pixels wide in a dark street); its rod signal is then limited to
//! [`ROD_SATURATION_SCOTOPIC_CD_M2`]. Without it, the rods of a dark neighbourhood (`k` near
//! 1, `m_s` large) would add the light's full scotopic luminance as grey and turn it white,
//! the failure the global model shows. In the limits above no pixel's rods are both
//! weighted and saturated (on a uniform image `k > 0` needs a luminance under 45 scotopic
//! cd/m²), except with an infinite radius and a scene brighter than that somewhere while
//! the whole is mesopic; [`LocalAdaptation::rod_saturation`] turns the rule off.
//!
//! # Time course: a global state plus local offsets
//!
//! For video and sequences the observer's state is the global one of
//! [`crate::timecourse::Adaptation`], stepped to each frame's global world adaptation; each
//! pixel's threshold is its steady-state local threshold raised by the state's current log
//! excess (the same for every pixel), and Eq. 8-9 are applied per pixel with the pixel's
//! own adaptation luminance. So a pixel's display value of its own adaptation luminance stays
//! constant over time as Eq. 9 requires, the whole field recovers together after a change
//! of the light (the eye moves over the scene faster than it adapts), and once adapted the
//! mapping is the steady local one exactly. See [`LocalMapping::for_time_course`].

/// `kernel(args)` compiled for the widest instruction set of the processor
/// ([`crate::simd::Isa`]), for the per-pixel loops of local adaptation (`kernel` is an
/// `#[inline(always)]` function, dispatched by [`crate::simd::at_level!`]). None of these
/// loops fuses a multiply-add, so every instruction set gives the same values, bit for
/// bit (tested).
macro_rules! widest {
    ($f:ident ( $($a:expr),* $(,)? )) => {
        crate::simd::at_level!(crate::simd::Isa::detect(), $f($($a),*))
    };
}

pub mod acuity;
pub mod map;

pub use map::AdaptationMap;

use crate::mesopic::rod_weight;
use crate::operator::{self, Mapping, PixelStats, Report};
use crate::scale::{photopic_scale, scotopic_scale};
use crate::scotopic;
use crate::simd::{Avx2, Isa};
use crate::{DisplayImage, Error, HdrImage, Result};

/// Default radius of the adaptation neighbourhood, degrees: the fovea and its immediate
/// surround (Ward Larson, Rushmeier & Piatko 1997 adapt to 1° foveal samples; Radiance's
/// `pcond` likewise).
pub const DEFAULT_ADAPTATION_RADIUS_DEG: f64 = 1.0;

/// Scotopic luminance above which rods signal nothing more, scotopic cd/m²: the vertical
/// asymptote of the rod t.v.i. curve at 2 log cd/m² (paper Sec. 3.2, Fig. 3; Aguilar &
/// Stiles 1954, rod saturation).
pub const ROD_SATURATION_SCOTOPIC_CD_M2: f32 = 100.0;

/// Nodes per log10 unit of offset in the coefficient tables (a power of two, so that
/// offset 0 is exactly a node).
pub const TABLE_STEPS_PER_LOG_UNIT: f32 = 128.0;

/// Options of local adaptation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalAdaptation {
    /// Radius of the adaptation neighbourhood, degrees (the standard deviation of the
    /// map's kernel along a uniform line; see [`map`]). `+∞` is the global model.
    pub radius_deg: f64,
    /// Limit each pixel's rod signal to [`ROD_SATURATION_SCOTOPIC_CD_M2`] (default on).
    pub rod_saturation: bool,
}

impl Default for LocalAdaptation {
    fn default() -> Self {
        LocalAdaptation {
            radius_deg: DEFAULT_ADAPTATION_RADIUS_DEG,
            rod_saturation: true,
        }
    }
}

impl LocalAdaptation {
    /// Check the radius.
    pub fn validate(&self) -> Result<()> {
        if self.radius_deg > 0.0 {
            Ok(())
        } else {
            Err(Error::invalid(
                "adaptation-radius",
                self.radius_deg,
                "must be a positive number of degrees",
            ))
        }
    }
}

/// [`range_kernel`] of no values.
pub(crate) const EMPTY_RANGE: (f32, f32, bool) = (f32::INFINITY, f32::NEG_INFINITY, true);

/// The [`range_kernel`] of two pieces joined, with its selects (so the same bounds as one
/// pass over both).
pub(crate) fn join_ranges(a: (f32, f32, bool), b: (f32, f32, bool)) -> (f32, f32, bool) {
    (
        if b.0 < a.0 { b.0 } else { a.0 },
        if b.1 > a.1 { b.1 } else { a.1 },
        a.2 & b.2,
    )
}

/// Lanes of [`range_kernel`]'s running bounds: one AVX-512 vector, two AVX2 ones.
const RANGE_LANES: usize = 16;

/// Smallest and largest value of a plane other than NaN, and whether all are finite
/// (`+∞`, `−∞` and true when it is empty; `+∞`, `−∞` and false when all are NaN).
///
/// The bounds are kept per lane over blocks of [`RANGE_LANES`] samples, then joined, so
/// that the loop is vectorised. With one running bound (a select per sample that waits
/// for the one before) it compiled to scalar code bound by that chain: about 10 % of the
/// varying blur at 1080p, and 0.5 ms per 1080p plane of offsets for the tables. The
/// selects are [`join_ranges`]'s, so a NaN never replaces a bound (`finite` records it)
/// and the bounds are the values of one pass in order, but for the sign of a zero bound
/// when both `0` and `-0` occur (the span, which is what the blur uses, is the same).
#[inline(always)]
pub(crate) fn range_kernel(plane: &[f32]) -> (f32, f32, bool) {
    let mut lo = [EMPTY_RANGE.0; RANGE_LANES];
    let mut hi = [EMPTY_RANGE.1; RANGE_LANES];
    // Per lane, whether a sample was NaN or infinite: an integer mask, so that it stays
    // in vector registers.
    let mut bad = [0u32; RANGE_LANES];
    let blocks = plane.chunks_exact(RANGE_LANES);
    let tail = blocks.remainder();
    for block in blocks {
        let block: &[f32; RANGE_LANES] = block.try_into().expect("a block of lanes");
        for l in 0..RANGE_LANES {
            let v = block[l];
            lo[l] = if v < lo[l] { v } else { lo[l] };
            hi[l] = if v > hi[l] { v } else { hi[l] };
            bad[l] |= u32::from(!v.is_finite());
        }
    }
    let lanes = (0..RANGE_LANES).map(|l| (lo[l], hi[l], bad[l] == 0));
    let samples = tail.iter().map(|&v| (v, v, v.is_finite()));
    lanes
        .chain(samples)
        .fold(EMPTY_RANGE, |r, (a, b, f)| join_ranges(r, (a, b, f)))
}

/// The offsets a map's tables cover: the smallest and largest of `offsets` other than
/// NaN, widened to include 0 (the global level, a node of every table).
pub(crate) fn offset_range(offsets: &[f32]) -> (f32, f32) {
    let (lo, hi, _) = widest!(range_kernel(offsets));
    (lo.min(0.0), hi.max(0.0))
}

/// One tabulated coefficient set: values at nodes `start + j/TABLE_STEPS_PER_LOG_UNIT`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Table<const K: usize> {
    start: f32,
    values: Vec<[f32; K]>,
    /// Per node the difference to the next node's values (the last node's: 0), so that
    /// a look-up reads one entry of each vector.
    deltas: Vec<[f32; K]>,
    /// The values again, coefficient by coefficient (`value_columns[k·stride + node]`,
    /// `stride` = nodes + [`LOOKUP_LANES`], the last node repeated after it), so that
    /// [`Table::at_lanes_permuted`] loads [`LOOKUP_LANES`] consecutive nodes of one
    /// coefficient from any node of the table.
    value_columns: Vec<f32>,
    /// The deltas likewise.
    delta_columns: Vec<f32>,
}

impl<const K: usize> Table<K> {
    /// Nodes covering `min..=max` (and 0), each `f(offset)`.
    pub(crate) fn new(min: f32, max: f32, f: impl Fn(f64) -> [f32; K]) -> Self {
        let steps = TABLE_STEPS_PER_LOG_UNIT;
        let below = (-min.min(0.0) * steps).ceil();
        let above = (max.max(0.0) * steps).ceil();
        let count = (below + above) as usize + 2;
        let values: Vec<[f32; K]> = (0..count)
            .map(|j| f((j as f64 - f64::from(below)) / f64::from(steps)))
            .collect();
        let deltas = (0..count)
            .map(|j| match values.get(j + 1) {
                Some(b) => std::array::from_fn(|k| b[k] - values[j][k]),
                None => [0.0; K],
            })
            .collect();
        let columns = |rows: &Vec<[f32; K]>| -> Vec<f32> {
            let last = rows.last().copied().unwrap_or([0.0; K]);
            (0..K)
                .flat_map(|k| {
                    let padding = std::iter::repeat_n(last[k], LOOKUP_LANES);
                    rows.iter().map(move |r| r[k]).chain(padding)
                })
                .collect()
        };
        Table {
            start: -below / steps,
            value_columns: columns(&values),
            delta_columns: columns(&deltas),
            values,
            deltas,
        }
    }

    /// Linear interpolation at `offset` (clamped to the table): `a + t·(b − a)` between
    /// the nodes `a` and `b` around it. Written without a panicking path (the entries are
    /// read with `get`, always in range), so that loops over pixels vectorise (gathers).
    #[inline(always)]
    pub(crate) fn at(&self, offset: f32) -> [f32; K] {
        let (i, t) = self.locate(offset);
        // `i` is a whole number in `0..=last`, or NaN (→ 0).
        let i = i as usize;
        let a = self.values.get(i).copied().unwrap_or([0.0; K]);
        let d = self.deltas.get(i).copied().unwrap_or([0.0; K]);
        std::array::from_fn(|k| a[k] + t * d[k])
    }

    /// The node below `offset` (clamped to the table), as a whole `f32`, and the fraction
    /// `t` of the way to the next one, as [`Table::at`] interpolates them. Kept in `f32`
    /// so that a loop over lanes vectorises (Rust's saturating float-to-integer
    /// conversion does not).
    #[inline(always)]
    fn locate(&self, offset: f32) -> (f32, f32) {
        let last = self.values.len().saturating_sub(2) as f32;
        let top = last + 1.0;
        let p = (offset - self.start) * TABLE_STEPS_PER_LOG_UNIT;
        // `clamp` without its assertion (NaN stays NaN, as with `clamp`).
        let p = if p < 0.0 {
            0.0
        } else if p > top {
            top
        } else {
            p
        };
        // `floor` for `0 ≤ p < 2²³` (far more nodes than a table has) in two exact
        // additions and a select, so that it vectorises at every level (SSE2 has no
        // rounding instruction). NaN stays NaN.
        let round = (p + TWO_23) - TWO_23;
        let i = if round > p { round - 1.0 } else { round };
        let i = if i > last { last } else { i };
        (i, p - i)
    }

    /// [`Table::at`] for a block of offsets into `out` (`out[k][lane]`):
    /// [`Table::at_lanes_permuted`] with a proof of AVX2 (`permute`), else
    /// [`Table::at_lanes`], where it applies; else the general look-up one offset at a
    /// time. The same values every way.
    #[inline(always)]
    fn lanes_into(
        &self,
        permute: Option<Avx2>,
        offsets: &[f32; LOOKUP_LANES],
        out: &mut [[f32; LOOKUP_LANES]; K],
    ) {
        let done = match permute {
            Some(p) => self.at_lanes_permuted(p, offsets, out),
            None => self.at_lanes(offsets, out),
        };
        if !done {
            for (l, &d) in offsets.iter().enumerate() {
                for (k, c) in self.at(d).into_iter().enumerate() {
                    out[k][l] = c;
                }
            }
        }
    }

    /// [`Table::at`] for `N` offsets at once into `out`, coefficient by coefficient
    /// (`out[k][lane]`), when their nodes lie within [`LOOKUP_SPAN`] consecutive ones of
    /// the table (else false, and `out` is left as it was).
    /// The map's offsets are smooth, so neighbouring pixels have neighbouring nodes: then
    /// the look-up is those rows of the table and a per-lane select, which vectorises,
    /// where the general look-up is a gather of `K` values per pixel that the compiler
    /// leaves scalar. Each value is `a + t·d` of the same `a`, `d` and `t` as
    /// [`Table::at`]'s, so the same bit for bit.
    #[inline(always)]
    fn at_lanes<const N: usize>(&self, offsets: &[f32; N], out: &mut [[f32; N]; K]) -> bool {
        let mut node = [0f32; N];
        let mut t = [0f32; N];
        for l in 0..N {
            (node[l], t[l]) = self.locate(offsets[l]);
        }
        // The rows: the span from the lower of the end lanes' nodes (the lowest node of a
        // monotonic block), moved inside the table. A NaN node (a NaN offset) fails the
        // test below.
        let span = LOOKUP_SPAN as f32;
        let Some(highest) = self.values.len().checked_sub(LOOKUP_SPAN) else {
            return false;
        };
        let first = if node[N - 1] < node[0] {
            node[N - 1]
        } else {
            node[0]
        };
        let first = if first > 0.0 { first } else { 0.0 };
        let first = if first < highest as f32 {
            first
        } else {
            highest as f32
        };
        let mut step = [0f32; N];
        let mut inside = true;
        for l in 0..N {
            step[l] = node[l] - first;
            inside &= (step[l] >= 0.0) & (step[l] < span);
        }
        if !inside {
            return false;
        }
        // A whole number in `0..=highest` (clamped above; NaN became 0).
        let rows = first as usize..first as usize + LOOKUP_SPAN;
        let (Some(a), Some(d)) = (self.values.get(rows.clone()), self.deltas.get(rows)) else {
            return false;
        };
        for (k, out) in out.iter_mut().enumerate() {
            let mut al = [a[0][k]; N];
            let mut dl = [d[0][k]; N];
            for w in 1..LOOKUP_SPAN {
                let (aw, dw) = (a[w][k], d[w][k]);
                for l in 0..N {
                    let here = step[l] == w as f32;
                    al[l] = if here { aw } else { al[l] };
                    dl[l] = if here { dw } else { dl[l] };
                }
            }
            for l in 0..N {
                out[l] = al[l] + t[l] * dl[l];
            }
        }
        true
    }

    /// [`Table::at_lanes`] with a lane permute (`vpermps`, [`Avx2::permute8`]): when the
    /// block's nodes lie within [`LOOKUP_SPAN`] consecutive ones (else false, and `out`
    /// is left as it was), each coefficient's rows are one load of [`LOOKUP_SPAN`]
    /// consecutive nodes from its column and, for each 8 lanes of the block, one permute
    /// by each lane's step from the first, in place of [`LOOKUP_SPAN`]` − 1` selects and
    /// broadcasts per row. Each value is `a + t·d` of the same `a`, `d` and `t` as
    /// [`Table::at`]'s, so the same bit for bit.
    #[inline(always)]
    fn at_lanes_permuted(
        &self,
        p: Avx2,
        offsets: &[f32; LOOKUP_LANES],
        out: &mut [[f32; LOOKUP_LANES]; K],
    ) -> bool {
        const N: usize = LOOKUP_LANES;
        // The permute's lanes: the span the look-up takes.
        const W: usize = LOOKUP_SPAN;
        let mut node = [0f32; N];
        let mut t = [0f32; N];
        for l in 0..N {
            (node[l], t[l]) = self.locate(offsets[l]);
        }
        // The lower of the end lanes' nodes (the lowest of a monotonic block); a node is
        // at most the table's last but one, and the columns run `N` beyond the last.
        let first = if node[N - 1] < node[0] {
            node[N - 1]
        } else {
            node[0]
        };
        let mut step = [0u32; N];
        let mut inside = first >= 0.0;
        for l in 0..N {
            let s = node[l] - first;
            inside &= (s >= 0.0) & (s < W as f32);
            // A whole `s` in `0..W` is the low bits of `s + 2²³` (exact): the index
            // without a float-to-integer conversion, which Rust saturates (scalar code).
            step[l] = (s + TWO_23).to_bits() & (W as u32 - 1);
        }
        if !inside {
            return false;
        }
        // A whole number in `0..=last` (a NaN node failed the test above).
        let first = first as usize;
        let stride = self.values.len() + N;
        // The last coefficient's `W` nodes lie inside its padded column (`first` is at
        // most the last node but one); checked before any lane is written, so that `out`
        // is left as it was if not, and so that the loop below has no failing path.
        let Some(all) = (K - 1)
            .checked_mul(stride)
            .map(|a| a + first + W)
            .filter(|&end| end <= self.value_columns.len())
        else {
            return false;
        };
        let (values, deltas) = (&self.value_columns[..all], &self.delta_columns[..all]);
        for (k, out) in out.iter_mut().enumerate() {
            let at = k * stride + first;
            let a: &[f32; W] = values[at..at + W].try_into().expect("W values");
            let d: &[f32; W] = deltas[at..at + W].try_into().expect("W values");
            for ((out, t), step) in out
                .chunks_exact_mut(W)
                .zip(t.chunks_exact(W))
                .zip(step.chunks_exact(W))
            {
                let step: &[u32; W] = step.try_into().expect("W lanes");
                let (a, d) = (p.permute8(a, step), p.permute8(d, step));
                for l in 0..W {
                    out[l] = a[l] + t[l] * d[l];
                }
            }
        }
        true
    }
}

/// The per-pixel mapping of local adaptation: tables of the global operator's coefficients
/// (display-relative) against the map's offsets (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct LocalMapping {
    /// Against the photopic offset: the 3×3 XYZ → linear sRGB matrix times `m_p/L_dmax`
    /// (row-major), then `b_p/L_dmax`.
    cone: Table<10>,
    /// Against the scotopic offset: `k·m_s/L_dmax`, `k·b_s/L_dmax`.
    rod: Table<2>,
    /// `L_dmax`, cd/m².
    display_max_cd_m2: f64,
    /// Limit the rod signal (see the module docs).
    rod_saturation: bool,
    /// Largest input channel value (cd/m²) whose mapped value stays within
    /// [`operator::MAX_DISPLAY_RELATIVE`] at any table entry: brighter pixels are scaled
    /// down to it first, as in the global operator (counted as saturated).
    max_input: f32,
}

impl LocalMapping {
    /// Tables for `map` and the display and colour of the `global` mapping, with
    /// `cone(L) = (m_p, b_p)` for a cone adaptation luminance `L`
    /// (cd/m²) and `rod(L_s) = (m_s, b_s)` for a rod adaptation `L_s` (scotopic cd/m²), in
    /// display cd/m² per world unit and display cd/m²; `k` is Eq. 6 at `L_s`.
    pub fn new(
        map: &AdaptationMap,
        global: &Mapping,
        rod_saturation: bool,
        cone: impl Fn(f64) -> (f64, f64),
        rod: impl Fn(f64) -> (f64, f64),
    ) -> Self {
        let (lp, hp) = offset_range(&map.offset_log);
        let (ls, hs) = offset_range(&map.offset_scotopic_log);
        let display_max_cd_m2 = global.display_max_cd_m2;
        let bound = f64::from(operator::MAX_DISPLAY_RELATIVE);
        let (lwa, lwa_s) = (
            map.world_adaptation_cd_m2,
            map.world_adaptation_scotopic_cd_m2,
        );
        let cone = Table::new(lp, hp, |d| {
            // `10^0` is exactly 1, so offset 0 is the global level exactly.
            let (m, b) = cone(lwa * 10f64.powf(d));
            let rows = operator::cone_rows(global, m);
            let mut out = [0f32; 10];
            for (r, row) in rows.iter().enumerate() {
                out[3 * r..3 * r + 3].copy_from_slice(row);
            }
            out[9] = (b / display_max_cd_m2).clamp(-bound, bound) as f32;
            out
        });
        let rod = Table::new(ls, hs, |d| {
            let l = lwa_s * 10f64.powf(d);
            let (m, b) = rod(l);
            let k = rod_weight(l);
            [
                (k * m / display_max_cd_m2).clamp(-bound, bound) as f32,
                (k * b / display_max_cd_m2).clamp(-bound, bound) as f32,
            ]
        });
        // The largest gain from a channel to an output over all table entries (as the
        // global operator's: a cone row's absolute sum plus four times the rod coefficient).
        let cone_gain = cone.values.iter().fold(0f64, |g, v| {
            (0..3).fold(g, |g, r| {
                g.max(v[3 * r..3 * r + 3].iter().map(|c| f64::from(c.abs())).sum())
            })
        });
        let rod_gain = rod
            .values
            .iter()
            .fold(0f64, |g, v| g.max(f64::from(v[0].abs())));
        LocalMapping {
            cone,
            rod,
            display_max_cd_m2,
            rod_saturation,
            max_input: operator::max_input_for_gain(cone_gain + 4.0 * rod_gain),
        }
    }

    /// The steady-state mapping (Eq. 3-6 at each pixel's adaptation) for the display of a
    /// [`operator::plan`] report.
    pub fn steady_state(map: &AdaptationMap, report: &Report, rod_saturation: bool) -> Self {
        let lda = report.display_adaptation_cd_m2;
        LocalMapping::new(
            map,
            &report.mapping,
            rod_saturation,
            |l| (photopic_scale(l, lda), 0.0),
            |l| (scotopic_scale(l, lda), 0.0),
        )
    }

    /// The Eq. 8-9 mapping of a time-varying state at each pixel's adaptation (module docs:
    /// a global state plus local offsets), for the display of a steady-state report of the
    /// current frame.
    pub fn for_time_course(
        map: &AdaptationMap,
        state: &crate::timecourse::Adaptation,
        report: &Report,
        rod_saturation: bool,
    ) -> Self {
        let lda = report.display_adaptation_cd_m2;
        let display_threshold = crate::tvi::cone_threshold_cd_m2(lda);
        // The excess the display mapping follows (Baker's dip clamped unless the state's
        // rule is the paper's, see `timecourse::Undershoot`).
        let cone_excess = 10f64.powf(state.mapping_cone_excess_log());
        let rod_excess = 10f64.powf(state.mapping_rod_excess_log());
        let cone_floor = 10f64.powf(crate::tvi::CONE_FLOOR_LOG);
        let rod_floor = 10f64.powf(crate::tvi::ROD_FLOOR_LOG);
        LocalMapping::new(
            map,
            &report.mapping,
            rod_saturation,
            |l| {
                let t = (crate::tvi::cone_threshold_cd_m2(l) * cone_excess).max(cone_floor);
                let m = display_threshold / t;
                (m, l * (photopic_scale(l, lda) - m))
            },
            |l| {
                let t = (crate::tvi::rod_threshold_scotopic_cd_m2(l) * rod_excess).max(rod_floor);
                let m = display_threshold / t;
                (m, l * (scotopic_scale(l, lda) - m))
            },
        )
    }
}

/// Apply a [`LocalMapping`] with its [`AdaptationMap`] to an image: the per-pixel mapping,
/// the per-pixel acuity Gaussian (when the map has sigmas), and the global operator's
/// clipping rule (see [`operator::apply`]).
///
/// # Panics
/// If the image's planes are inconsistent or the map is of another size.
pub fn apply_into(
    image: &HdrImage,
    map: &AdaptationMap,
    mapping: &LocalMapping,
    out: &mut DisplayImage,
) -> PixelStats {
    assert_eq!((map.width, map.height), (image.width, image.height));
    let (width, height) = (image.width, image.height);
    let [r, g, b] = operator::display_planes(out, width, height, mapping.display_max_cd_m2);
    let blur = acuity_blur(map, width, height);
    let stats = operator::map_pass(r, g, b, blur.is_none(), |start, r, g, b| {
        let end = start + r.len();
        let xyz = [
            &image.x[start..end],
            &image.y[start..end],
            &image.z[start..end],
        ];
        let scotopic = image.scotopic.as_ref().map(|s| &s[start..end]);
        let offsets = [
            &map.offset_log[start..end],
            &map.offset_scotopic_log[start..end],
        ];
        map_chunk(mapping, xyz, scotopic, offsets, r, g, b)
    });
    operator::blur_and_clip(stats, [r, g, b], blur)
}

/// [`apply_into`], consuming the image: the display is written over its X, Y, Z planes
/// (as [`operator::apply_owned`] does for the global mapping), so that no second image is
/// allocated. Same result as [`apply_into`], bit for bit.
///
/// # Panics
/// As [`apply_into`].
pub fn apply_owned(
    image: HdrImage,
    map: &AdaptationMap,
    mapping: &LocalMapping,
) -> (DisplayImage, PixelStats) {
    assert_eq!((map.width, map.height), (image.width, image.height));
    let (width, height) = (image.width, image.height);
    let ([mut r, mut g, mut b], scotopic) = image.into_planes();
    let blur = acuity_blur(map, width, height);
    let stats = operator::map_pass(&mut r, &mut g, &mut b, blur.is_none(), |start, r, g, b| {
        let end = start + r.len();
        let s = scotopic.as_ref().map(|s| &s[start..end]);
        let (dp, ds) = (
            &map.offset_log[start..end],
            &map.offset_scotopic_log[start..end],
        );
        operator::map_in_place(r, g, b, |lo, xyz, or, og, ob| {
            let hi = lo + or.len();
            let s = s.map(|s| &s[lo..hi]);
            map_chunk(mapping, xyz, s, [&dp[lo..hi], &ds[lo..hi]], or, og, ob)
        })
    });
    drop(scotopic);
    let stats = operator::blur_and_clip(stats, [&mut r, &mut g, &mut b], blur);
    let display = DisplayImage {
        width,
        height,
        r,
        g,
        b,
        display_max_cd_m2: mapping.display_max_cd_m2 as f32,
    };
    (display, stats)
}

/// The acuity stage of a local mapping: the Eq. 7 Gaussian at each pixel's own sigma, or
/// `None` when the map has none (or all are 0).
fn acuity_blur(
    map: &AdaptationMap,
    width: usize,
    height: usize,
) -> Option<impl FnOnce([&mut Vec<f32>; 3]) + '_> {
    map.acuity_sigma_px
        .as_deref()
        .filter(|s| s.iter().any(|&v| v > 0.0))
        .map(|sigma| {
            move |mut planes: [&mut Vec<f32>; 3]| {
                acuity::varying_gaussian_blur_vecs(&mut planes, width, height, sigma)
            }
        })
}

/// The local mapping of the pixels of `xyz` (and their `scotopic` samples and
/// `[photopic, scotopic]` map offsets) into `r`, `g`, `b`, compiled for the widest
/// instruction set of the processor (the same result on every one: no multiply-add is
/// fused). The table look-ups are vectorised where neighbouring pixels share their nodes
/// ([`Table::at_lanes`]).
fn map_chunk(
    mapping: &LocalMapping,
    xyz: [&[f32]; 3],
    scotopic: Option<&[f32]>,
    offsets: [&[f32]; 2],
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) -> PixelStats {
    // The AVX2 build also where the processor has AVX-512: on this project's machine
    // (Zen 4, whose 512-bit operations are two 256-bit halves) the AVX-512 build of the
    // pass took 6.0 ms at 1080p against 4.8-5.0 ms for the AVX2 one (a scratch timing of
    // local `apply` without acuity, minima of 30 passes, three rounds in turn), with
    // either width of permute (see the performance log).
    let isa = Isa::detect().at_most_avx2();
    let permute = isa.avx2();
    crate::simd::at_level!(
        isa,
        map_chunk_kernel(mapping, permute, xyz, scotopic, offsets, r, g, b)
    )
}

/// [`map_chunk`]'s loop: one copy per kind of scotopic input, each branch-free; the
/// table look-ups with lane permutes when `permute` ([`Table::at_lanes_permuted`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn map_chunk_kernel(
    mapping: &LocalMapping,
    permute: Option<Avx2>,
    xyz: [&[f32]; 3],
    scotopic: Option<&[f32]>,
    offsets: [&[f32]; 2],
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) -> PixelStats {
    let mut counts = [0u32; 3];
    match scotopic {
        Some(s) => map_pixels::<true>(mapping, permute, xyz, s, offsets, [r, g, b], &mut counts),
        None => map_pixels::<false>(mapping, permute, xyz, &[], offsets, [r, g, b], &mut counts),
    }
    let [non_finite, negative, saturated] = counts.map(|c| c as usize);
    PixelStats {
        non_finite,
        negative,
        clipped: 0,
        saturated,
    }
}

/// Pixels per block of [`map_pixels`]' table look-ups: one AVX-512 vector of `f32` (two
/// AVX2 vectors, four SSE2 ones). Our choice.
const LOOKUP_LANES: usize = 16;

/// 2²³: adding and subtracting it rounds a non-negative `f32` below it to a whole number.
const TWO_23: f32 = 8_388_608.0;

/// Consecutive table nodes a block's pixels may use for [`Table::at_lanes`]: 8 nodes are
/// 1/16 log unit ([`TABLE_STEPS_PER_LOG_UNIT`]), i.e. a gradient of up to 0.004 log units
/// per pixel over a block of [`LOOKUP_LANES`]. Our choice (measured on the `local`
/// benchmark's frame, whose offsets span four log units).
const LOOKUP_SPAN: usize = 8;

/// The pixels of [`map_chunk_kernel`], with the file's scotopic samples `s` when
/// `FILE_SCOTOPIC` (else estimated from XYZ); adds to `[non-finite, negative, saturated]`.
///
/// Pixels are mapped in blocks of [`LOOKUP_LANES`] (the last one padded with zeros).
/// A block whose table nodes lie within [`LOOKUP_SPAN`] consecutive ones (nearly all:
/// the map is smooth) takes its coefficients as vectors ([`Table::at_lanes`]; with AVX2,
/// by lane permutes, [`Table::at_lanes_permuted`]);
/// the others, one pixel at a time. All give the same values.
#[inline(always)]
fn map_pixels<const FILE_SCOTOPIC: bool>(
    mapping: &LocalMapping,
    permute: Option<Avx2>,
    [xs, ys, zs]: [&[f32]; 3],
    s: &[f32],
    [dp, ds]: [&[f32]; 2],
    [r, g, b]: [&mut [f32]; 3],
    counts: &mut [u32; 3],
) {
    const N: usize = LOOKUP_LANES;
    let n = r.len();
    let (xs, ys, zs, dp, ds) = (&xs[..n], &ys[..n], &zs[..n], &dp[..n], &ds[..n]);
    let s = if FILE_SCOTOPIC { &s[..n] } else { s };
    let (g, b) = (&mut g[..n], &mut b[..n]);
    let saturation = if mapping.rod_saturation {
        ROD_SATURATION_SCOTOPIC_CD_M2
    } else {
        f32::INFINITY
    };
    let mut total = *counts;
    let blocks = n / N;
    let mut cone = [[0f32; N]; 10];
    let mut rod = [[0f32; N]; 2];
    for block in 0..blocks {
        let at = block * N..(block + 1) * N;
        let lanes = |v: &[f32]| -> [f32; N] { v[at.clone()].try_into().expect("a block") };
        let (dpb, dsb) = (lanes(dp), lanes(ds));
        mapping.cone.lanes_into(permute, &dpb, &mut cone);
        mapping.rod.lanes_into(permute, &dsb, &mut rod);
        let (r, g, b) = (&mut r[at.clone()], &mut g[at.clone()], &mut b[at.clone()]);
        let out: [&mut [f32; N]; 3] = [r, g, b].map(|o| o.try_into().expect("a block"));
        let sv = if FILE_SCOTOPIC { lanes(s) } else { [0.0; N] };
        let input = [lanes(xs), lanes(ys), lanes(zs), sv];
        let flags = map_lanes::<FILE_SCOTOPIC, N>(mapping, saturation, &input, &cone, &rod, out);
        for (t, f) in total.iter_mut().zip(flags) {
            *t += f;
        }
    }
    // The last pixels, in a block padded with zeros (whose outputs are dropped).
    let rest = blocks * N..n;
    if !rest.is_empty() {
        let pad = |v: &[f32]| -> [f32; N] {
            std::array::from_fn(|l| v.get(rest.start + l).copied().unwrap_or(0.0))
        };
        mapping.cone.lanes_into(permute, &pad(dp), &mut cone);
        mapping.rod.lanes_into(permute, &pad(ds), &mut rod);
        let sv = if FILE_SCOTOPIC { pad(s) } else { [0.0; N] };
        let input = [pad(xs), pad(ys), pad(zs), sv];
        let mut out = [[0f32; N]; 3];
        let [ro, go, bo] = out.each_mut();
        let flags =
            map_lanes::<FILE_SCOTOPIC, N>(mapping, saturation, &input, &cone, &rod, [ro, go, bo]);
        let m = rest.len();
        for (t, f) in total.iter_mut().zip(flags) {
            *t += f;
        }
        r[rest.clone()].copy_from_slice(&out[0][..m]);
        g[rest.clone()].copy_from_slice(&out[1][..m]);
        b[rest].copy_from_slice(&out[2][..m]);
    }
    *counts = total;
}

/// `N` pixels of [`map_pixels`] (`input`: X, Y, Z and the file's scotopic samples), with
/// their cone coefficients `cone[k][lane]` and rod `[gain, offset][lane]`, lane by lane
/// (so that it vectorises); returns how many were `[non-finite, negative, saturated]`.
/// Zeros (padding) count as none of them.
#[inline(always)]
fn map_lanes<const FILE_SCOTOPIC: bool, const N: usize>(
    mapping: &LocalMapping,
    saturation: f32,
    input: &[[f32; N]; 4],
    cone: &[[f32; N]; 10],
    rod: &[[f32; N]; 2],
    [r, g, b]: [&mut [f32; N]; 3],
) -> [u32; 3] {
    let mut flags = [0u32; 3];
    for l in 0..N {
        let sj = if FILE_SCOTOPIC { input[3][l] } else { 0.0 };
        let (finite, neg, v) = operator::sanitize([input[0][l], input[1][l], input[2][l], sj]);
        let (sat, [x, y, z, sv]) = operator::saturate(v, mapping.max_input);
        flags[0] += u32::from(!finite);
        flags[1] += u32::from(neg);
        flags[2] += u32::from(sat);
        let v = if FILE_SCOTOPIC {
            sv
        } else {
            scotopic::from_xyz(x, y, z)
        };
        let c = |k: usize| cone[k][l];
        // The same expression, in the same order, as the global operator's pixel.
        let grey = rod[0][l] * v.min(saturation) + (c(9) + rod[1][l]);
        r[l] = c(0) * x + c(1) * y + c(2) * z + grey;
        g[l] = c(3) * x + c(4) * y + c(5) * z + grey;
        b[l] = c(6) * x + c(7) * y + c(8) * z + grey;
    }
    flags
}

/// Quantiles of a local adaptation level over the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantiles {
    /// Lowest value.
    pub min: f64,
    /// 1st percentile.
    pub p01: f64,
    /// 10th percentile.
    pub p10: f64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Highest value.
    pub max: f64,
}

impl Quantiles {
    fn of(mut v: Vec<f64>) -> Self {
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        Quantiles {
            min: v[0],
            p01: q(0.01),
            p10: q(0.1),
            p50: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            max: v[v.len() - 1],
        }
    }
}

/// What local adaptation used: its options and the spread of the map.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalReport {
    /// Radius of the neighbourhood, degrees.
    pub radius_deg: f64,
    /// Pixels between the samples of the map's filter grid.
    pub grid_step_px: usize,
    /// Whether the rod signal was limited to [`ROD_SATURATION_SCOTOPIC_CD_M2`].
    pub rod_saturation: bool,
    /// The local photopic adaptation over the image, cd/m² (quantiles over pixels).
    pub adaptation_cd_m2: Quantiles,
    /// The local scotopic adaptation, scotopic cd/m².
    pub adaptation_scotopic_cd_m2: Quantiles,
    /// The rod weight `k` (Eq. 6) at the local scotopic adaptation.
    pub rod_weight: Quantiles,
    /// The acuity Gaussian's sigma, pixels; `None` without acuity.
    pub acuity_sigma_px: Option<Quantiles>,
}

impl LocalReport {
    /// The report of a map (quantiles over a subsample of at most about 2^16 pixels).
    pub fn of(map: &AdaptationMap, rod_saturation: bool) -> Self {
        let n = map.width * map.height;
        let stride = (n / 65_536).max(1);
        let idx = || (0..n).step_by(stride);
        let la = Quantiles::of(idx().map(|i| map.adaptation_cd_m2(i)).collect());
        let las: Vec<f64> = idx().map(|i| map.adaptation_scotopic_cd_m2(i)).collect();
        let k = Quantiles::of(las.iter().map(|&l| rod_weight(l)).collect());
        LocalReport {
            radius_deg: map.radius_deg,
            grid_step_px: map.grid_step_px,
            rod_saturation,
            adaptation_cd_m2: la,
            adaptation_scotopic_cd_m2: Quantiles::of(las),
            rod_weight: k,
            acuity_sigma_px: map
                .acuity_sigma_px
                .as_ref()
                .map(|s| Quantiles::of(idx().map(|i| f64::from(s[i])).collect())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The look-up as first written (`a + t·(b − a)` from two entries, with `clamp`), the
    /// reference the branch-free one is pinned to, bit for bit.
    fn reference_at<const K: usize>(t: &Table<K>, offset: f32) -> [f32; K] {
        let last = t.values.len() - 2;
        let p = ((offset - t.start) * TABLE_STEPS_PER_LOG_UNIT).clamp(0.0, last as f32 + 1.0);
        let i = (p as usize).min(last);
        let f = p - i as f32;
        let (a, b) = (&t.values[i], &t.values[i + 1]);
        std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
    }

    #[test]
    fn table_look_ups_are_the_reference_bit_for_bit() {
        let t = Table::<2>::new(-3.3, 2.1, |d| [10f64.powf(-d) as f32, d.sin() as f32]);
        for k in 0..20_000 {
            let d = -5.0 + 9.0 * k as f32 / 19_999.0;
            let (got, want) = (t.at(d), reference_at(&t, d));
            assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "{d}");
        }
    }

    /// [`Table::at_lanes`] gives [`Table::at`]'s values bit for bit wherever it applies,
    /// and applies to every block of a slow ramp: lanes on one node, on two, spread over
    /// the span, past the ends of the table, and with NaN (where it must decline).
    #[test]
    fn lane_look_ups_are_the_single_ones_bit_for_bit() {
        // Slopes in table nodes per pixel: 0 (one node), 0.05, 0.4 (within the span of 8
        // over 16 lanes), 2 (beyond it); starts inside and beyond both ends.
        let (taken, declined) = check_block_look_up(
            |t, offsets, out| t.at_lanes(offsets, out),
            &[0.0, 0.05, 0.4, 2.0, -0.4],
            &[-2.6, -1.99, -0.5, 0.0, 0.77, 1.49, 2.2],
            0.5,
        );
        // Declined: the four blocks of slope 2 (30 nodes) inside the table; the other
        // three of that slope lie (nearly) all beyond an end, clamped onto a node or two.
        assert_eq!((taken, declined), (31, 4));
    }

    /// [`Table::at_lanes_permuted`] likewise (AVX2's 8-lane permute, two per block), with
    /// its span of 8 nodes, up to both ends of the table (where its columns' padding is
    /// loaded but never selected).
    #[test]
    fn permuted_look_ups_of_eight_lanes_are_the_single_ones_bit_for_bit() {
        let Some(p) = Isa::Avx2Fma.avx2() else {
            eprintln!("no AVX2 on this processor: the 8-lane permuted look-up is not run");
            return;
        };
        let (taken, declined) = check_block_look_up(
            |t, offsets, out| t.at_lanes_permuted(p, offsets, out),
            &[0.0, 0.05, 0.4, 2.0, -0.4],
            &[-2.6, -1.99, -0.5, 0.0, 0.77, 1.40, 1.49, 2.2],
            0.5,
        );
        // Declined: the blocks of slope 2 (30 nodes) from −1.99, −0.5, 0, 0.77 and 1.40
        // (from there 12 nodes are left to the table's end, more than the 8); from −2.6
        // the block is clamped onto the first node, from 1.49 and 2.2 it spans at most
        // the 2 nodes left. Slope 0.4 spans 6 nodes, within the 8.
        assert_eq!((taken, declined), (35, 5));
    }

    /// A block look-up (`look_up`) of a test table against its single look-ups, over
    /// blocks of 16 offsets rising by `slopes` table nodes per pixel from `starts`: a
    /// block taken gives [`Table::at`]'s values bit for bit; a declined one leaves `out`
    /// as it was and has a slope steeper than `declined_above`; a block with a NaN is
    /// declined. Returns how many blocks were taken and declined.
    fn check_block_look_up(
        look_up: impl Fn(&Table<3>, &[f32; 16], &mut [[f32; 16]; 3]) -> bool,
        slopes: &[f32],
        starts: &[f32],
        declined_above: f32,
    ) -> (usize, usize) {
        let t = Table::<3>::new(-2.0, 1.5, |d| {
            [10f64.powf(-d) as f32, d.cos() as f32, (0.3 * d) as f32]
        });
        let (mut taken, mut declined) = (0, 0);
        for &slope in slopes {
            for &start in starts {
                let offsets: [f32; 16] =
                    std::array::from_fn(|l| start + slope * l as f32 / TABLE_STEPS_PER_LOG_UNIT);
                let mut out = [[7f32; 16]; 3];
                if look_up(&t, &offsets, &mut out) {
                    taken += 1;
                    for (l, &d) in offsets.iter().enumerate() {
                        let want = t.at(d);
                        for k in 0..3 {
                            assert_eq!(
                                out[k][l].to_bits(),
                                want[k].to_bits(),
                                "{slope} {start} {l}"
                            );
                        }
                    }
                } else {
                    declined += 1;
                    assert_eq!(out, [[7f32; 16]; 3], "left as it was");
                    assert!(slope.abs() > declined_above, "{slope} {start}");
                }
            }
        }
        let mut nan = [0.3f32; 16];
        nan[5] = f32::NAN;
        assert!(!look_up(&t, &nan, &mut [[0f32; 16]; 3]));
        (taken, declined)
    }

    /// The mapping pass (blocks through [`Table::at_lanes`] and the general look-up, and
    /// the last pixels) gives the per-pixel loop's values and counts bit for bit, on
    /// smooth offsets and on noise, with and without a scotopic plane, bad pixels and
    /// NaN offsets included.
    #[test]
    fn mapping_pass_blocks_are_the_per_pixel_loop_bit_for_bit() {
        let n = 16 * 40 + 11;
        let mapping = test_mapping();
        let mut noise = noise(5);
        let planes = test_planes(n, &mut noise);
        // A slow ramp, a steep one, noise, and a NaN.
        let mut dp: Vec<f32> = (0..n).map(|j| -3.0 + 0.0004 * j as f32).collect();
        let mut ds: Vec<f32> = (0..n).map(|j| 1.0 - 0.01 * j as f32).collect();
        for d in &mut dp[300..400] {
            *d = 6.0 * noise() - 4.0;
        }
        dp[77] = f32::NAN;
        ds[500] = f32::INFINITY;
        for scotopic in [None, Some(planes[3].as_slice())] {
            let xyz = [planes[0].as_slice(), &planes[1], &planes[2]];
            let mut want = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
            let mut want_counts = [0u32; 3];
            for j in 0..n {
                let sj = scotopic.map_or(0.0, |s| s[j]);
                let (finite, neg, v) = operator::sanitize([xyz[0][j], xyz[1][j], xyz[2][j], sj]);
                let (sat, [x, y, z, sv]) = operator::saturate(v, mapping.max_input);
                want_counts[0] += u32::from(!finite);
                want_counts[1] += u32::from(neg);
                want_counts[2] += u32::from(sat);
                let v = if scotopic.is_some() {
                    sv
                } else {
                    scotopic::from_xyz(x, y, z)
                };
                let c = mapping.cone.at(dp[j]);
                let [rod, rod_offset] = mapping.rod.at(ds[j]);
                let grey = rod * v.min(ROD_SATURATION_SCOTOPIC_CD_M2) + (c[9] + rod_offset);
                want[0][j] = c[0] * x + c[1] * y + c[2] * z + grey;
                want[1][j] = c[3] * x + c[4] * y + c[5] * z + grey;
                want[2][j] = c[6] * x + c[7] * y + c[8] * z + grey;
            }
            let mut got = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
            let [r, g, b] = got.each_mut().map(|v| v.as_mut_slice());
            let stats = map_chunk(&mapping, xyz, scotopic, [&dp, &ds], r, g, b);
            let [non_finite, negative, saturated] = want_counts.map(|c| c as usize);
            assert_eq!(
                (stats.non_finite, stats.negative, stats.saturated),
                (non_finite, negative, saturated)
            );
            for c in 0..3 {
                for j in 0..n {
                    let (a, b) = (got[c][j], want[c][j]);
                    assert!(
                        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                        "{c} {j}: {a} {b}"
                    );
                }
            }
        }
    }

    /// Uniform numbers in `[0, 1)` from `seed` (a linear congruential generator).
    fn noise(mut seed: u32) -> impl FnMut() -> f32 {
        move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        }
    }

    /// X, Y, Z and scotopic planes of `n` samples over eight log units, with a NaN, a
    /// negative and a huge sample among the first dozen, for the mapping tests.
    fn test_planes(n: usize, noise: &mut impl FnMut() -> f32) -> Vec<Vec<f32>> {
        let mut planes: Vec<Vec<f32>> = (0..4)
            .map(|_| (0..n).map(|_| 10f32.powf(8.0 * noise() - 4.0)).collect())
            .collect();
        planes[0][7] = f32::NAN;
        planes[1][9] = -2.0;
        planes[2][11] = 1e30;
        planes
    }

    /// Tables over offsets −4 to 2 with distinct coefficients, for the mapping tests.
    fn test_mapping() -> LocalMapping {
        LocalMapping {
            cone: Table::new(-4.0, 2.0, |d| {
                std::array::from_fn(|k| ((k as f64 + 1.0) * 0.1 * 10f64.powf(-0.7 * d)) as f32)
            }),
            rod: Table::new(-4.0, 2.0, |d| {
                [(0.3 * 10f64.powf(-0.9 * d)) as f32, (0.01 * d) as f32]
            }),
            display_max_cd_m2: 100.0,
            rod_saturation: true,
            max_input: 1e6,
        }
    }

    /// The mapping pass compiled for each instruction set this processor runs, with its
    /// look-ups (selects on the baseline, with and without permutes at the others), gives
    /// the baseline build's values bit for bit, as does the pass as dispatched (with and
    /// without a scotopic plane, bad pixels included).
    #[test]
    fn mapping_pass_is_the_same_on_every_instruction_set() {
        let n = 3000;
        let mut noise = noise(21);
        let planes = test_planes(n, &mut noise);
        // Offsets at random (the general look-up) and smooth ones (the block look-ups).
        let rough = |noise: &mut dyn FnMut() -> f32| -> Vec<f32> {
            (0..n).map(|_| 6.0 * noise() - 4.0).collect()
        };
        let smooth = |phase: f32| -> Vec<f32> {
            (0..n)
                .map(|i| 2.5 * (i as f32 * 0.002 + phase).sin() - 1.0)
                .collect()
        };
        let offsets = [
            (rough(&mut noise), rough(&mut noise)),
            (smooth(0.0), smooth(1.0)),
        ];
        let mapping = test_mapping();
        for ((dp, ds), scotopic) in offsets
            .iter()
            .flat_map(|o| [(o, None), (o, Some(planes[3].as_slice()))])
        {
            let xyz = [planes[0].as_slice(), &planes[1], &planes[2]];
            let mut want = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
            let [r, g, b] = want.each_mut().map(|v| v.as_mut_slice());
            let ws = map_chunk_kernel(&mapping, None, xyz, scotopic, [dp, ds], r, g, b);
            // Each level with and without its permute, then the pass as dispatched.
            let levels = Isa::all_available()
                .into_iter()
                .flat_map(|isa| [(isa, None), (isa, isa.at_most_avx2().avx2())]);
            for run in levels.map(Some).chain([None]) {
                let name = format!("{run:?}");
                let mut got = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
                let [r, g, b] = got.each_mut().map(|v| v.as_mut_slice());
                let gs = match run {
                    Some((isa, permute)) => crate::simd::at_level!(
                        isa,
                        map_chunk_kernel(&mapping, permute, xyz, scotopic, [dp, ds], r, g, b)
                    ),
                    None => map_chunk(&mapping, xyz, scotopic, [dp, ds], r, g, b),
                };
                assert_eq!(ws, gs, "{name}");
                for (a, b) in got.iter().flatten().zip(want.iter().flatten()) {
                    assert_eq!(a.to_bits(), b.to_bits(), "{name}");
                }
            }
        }
    }

    /// The plane's range by lanes ([`range_kernel`]) is that of one select per sample in
    /// order ([`join_ranges`] from [`EMPTY_RANGE`]) on every length around the lane
    /// count (the tail included) and on a long plane, with NaN, ±∞ and both zeros among
    /// finite values; a NaN anywhere makes it not finite, never a bound. The tables' span
    /// ([`offset_range`]) is that of `f32::min`/`max` from 0.
    #[test]
    fn plane_range_by_lanes_is_the_serial_one() {
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let special = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0];
        let mut value = |rare: u32| {
            let r = next();
            if r % rare == 0 {
                special[(r / rare) as usize % special.len()]
            } else {
                (r % 20_000) as f32 * 0.37 - 3000.0
            }
        };
        let serial = |v: &[f32]| {
            v.iter()
                .fold(EMPTY_RANGE, |r, &x| join_ranges(r, (x, x, x.is_finite())))
        };
        let mut lens: Vec<usize> = (0..3 * RANGE_LANES + 3).collect();
        lens.push(4099);
        for (k, &n) in lens.iter().enumerate() {
            // Every third plane has no special values, so that finite planes are tested.
            let rare = if k % 3 == 0 { u32::MAX } else { 97 };
            let plane: Vec<f32> = (0..n).map(|_| value(rare)).collect();
            let (a, b) = (range_kernel(&plane), serial(&plane));
            // `==`, so that 0 and -0 are the same bound.
            assert!(
                a.0 == b.0 && a.1 == b.1 && a.2 == b.2,
                "n = {n}: {a:?} against {b:?}"
            );
            assert!(!a.0.is_nan() && !a.1.is_nan(), "n = {n}: a NaN bound");
            // The tables' span: the same bounds as `f32::min`/`max` from 0.
            let fold = plane
                .iter()
                .fold((0f32, 0f32), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            let span = offset_range(&plane);
            assert!(
                span.0 == fold.0 && span.1 == fold.1,
                "n = {n}: {span:?}, {fold:?}"
            );
        }
        assert_eq!(offset_range(&[f32::NAN, 2.0, 0.5]), (0.0, 2.0));
        assert_eq!(offset_range(&[-1.5, f32::NAN, -0.25]), (-1.5, 0.0));
        let plane = [1.0, f32::NAN, -2.0, 5.0];
        assert_eq!(range_kernel(&plane), (-2.0, 5.0, false));
        let nan = [f32::NAN; RANGE_LANES + 3];
        assert_eq!(
            range_kernel(&nan),
            (f32::INFINITY, f32::NEG_INFINITY, false)
        );
        assert_eq!(range_kernel(&[]), EMPTY_RANGE);
        let mut long = vec![0.5f32; 3 * RANGE_LANES + 1];
        long[RANGE_LANES + 3] = -7.0;
        long[2 * RANGE_LANES] = 9.0;
        assert_eq!(range_kernel(&long), (-7.0, 9.0, true));
        long[3 * RANGE_LANES] = f32::NEG_INFINITY;
        assert_eq!(range_kernel(&long), (f32::NEG_INFINITY, 9.0, false));
    }

    #[test]
    fn tables_hit_zero_exactly_and_interpolate_closely() {
        let f = |d: f64| [10f64.powf(-d) as f32];
        let t = Table::<1>::new(-3.3, 2.1, f);
        assert_eq!(t.at(0.0), f(0.0));
        let mut worst = 0f64;
        for k in 0..10_000 {
            let d = -3.3 + 5.4 * f64::from(k) / 9999.0;
            let got = f64::from(t.at(d as f32)[0]);
            let want = 10f64.powf(-(d as f32) as f64);
            worst = worst.max((got / want - 1.0).abs());
        }
        assert!(worst < 5e-5, "{worst}");
        // Beyond the ends: the end values.
        assert_eq!(t.at(-10.0), t.values[0]);
    }
}
