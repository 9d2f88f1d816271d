//! The adaptation map: per pixel, the photopic and scotopic luminance the eye is adapted to
//! when it looks there.
//!
//! # What it models
//!
//! The paper's observer adapts to one level for the whole scene (Sec. 4.4: half the highest
//! visible luminance); its future work says "the retina adapts locally" (Sec. 6). Looking
//! at a point, the eye is adapted to the light of the fovea and its surround, about a
//! degree around the point of regard (Ward Larson, Rushmeier & Piatko 1997 and Radiance's
//! `pcond` use 1° foveal samples). The map below is that foveal level for every pixel.
//!
//! # The neighbourhood: an edge-aware low-pass in degrees
//!
//! A plain low-pass of a scene with a bright region next to a dark one raises the adaptation
//! of the dark pixels near the edge, which the display then shows too dark: the *halo* that
//! is the known failure of local operators (Pattanaik et al. 1998, Reinhard et al. 2002,
//! Durand & Dorsey 2002, Ledda et al. 2004). Here the low-pass is the recursive-filter form
//! of the *domain transform* of Gastal & Oliveira (2011, "Domain transform for edge-aware
//! image and video processing", SIGGRAPH, Eq. 11 and Sec. 4.2): a signal is smoothed with
//! an exponential kernel along a curve whose length counts both distance and change, so
//! that pixels across a strong edge are far apart and do not mix. Our distance between
//! neighbouring samples `p` and `q` is
//!
//! `d(p, q) = θ(p, q) + D·|g(p) − g(q)|` degrees,
//!
//! with `θ` their angular separation (from the view: perspective and fisheye projections
//! alike, see [`pixel_size_deg`]), `g` the log10 photopic luminance (the guide) and
//! `D` = [`EDGE_DEGREES_PER_LOG_UNIT`]: an edge of one log unit separates as much as `D`
//! degrees of uniform field. The filter is the domain transform's: for each of
//! [`ITERATIONS`] iterations `i` a causal and an anti-causal pass along every row, then
//! along every column, `J[n] = J[n−1] + (1 − a_i^d)(I[n] − J[n−1])` with
//! `a_i = exp(−√2/σ_i)` and `σ_i = σ·√3·2^(N−i)/√(4^N − 1)`, so that the kernel along a
//! uniform line has standard deviation `σ`, the **radius** of the neighbourhood in degrees.
//!
//! Unlike Gastal & Oliveira, who scale the edge term with the radius (`σ_s/σ_r`), the edge
//! term here is a fixed angle per log unit. So a wide neighbourhood sees through edges
//! and, as the radius grows without bound, the map becomes constant: the global model is the
//! limit of the local one (tested).
//!
//! The filtered signals are the log10 photopic and scotopic luminances (the log mean over
//! the foveal samples, as Ward Larson et al. 1997 and `pcond` take it); zero, negative and
//! non-finite pixels read as [`FLOOR_CD_M2`], far below every threshold of Eq. 4-5.
//!
//! # Anchored to the paper's level
//!
//! The map gives offsets from the global state rather than levels of its own: with `μ(x)`
//! the filtered log luminance and `μ_H` its high quantile (the same fraction of pixels as
//! the Sec. 4.4 "highest visible" rule), the local adaptation is
//!
//! `L_a(x) = L_wa · 10^(μ(x) − μ_H)`,
//!
//! and likewise for the rods with their own channel. The brightest neighbourhoods are adapted
//! as the paper's observer (half the highest visible luminance), every other neighbourhood
//! that many log units lower as it is darker. A uniform image, and any image in the limit of
//! an infinite radius, give offsets of exactly 0: the global model, pixels included. The
//! offsets are also what the time course needs (a global state plus local offsets, see
//! [`crate::local`]).
//!
//! # Cost
//!
//! The filter runs on a grid of samples [`grid step`](AdaptationMap::grid_step_px) pixels
//! apart (block means of the log luminance), at least [`SAMPLES_PER_RADIUS`] samples per
//! radius; the full-resolution map is a joint bilateral upsampling (Kopf, Cohen, Lischinski
//! & Uyttendaele 2007) of the grid, each pixel weighting the four grid samples around it by
//! distance and by how close their guide is to its own log luminance, so that the map
//! keeps edges sharp at full resolution. The image is read once: the block means leave
//! each pixel's log luminance in the map's photopic plane, where the upsampling reads it
//! as its guide before writing the offset over it. The per-pixel work (block means and
//! upsampling) is linear in the pixels and flat in the radius; the grid's (the domain
//! transform, in parallel over its two channels, and one acuity sigma per sample) grows
//! as the radius shrinks, with the number of samples: about 83,000 at 0.25° on a 1080p
//! frame 20° wide against 3,900 at 1° and 2,000 from 3° on (the step's cap). So the map
//! is not flat in the radius at small radii; neither is the acuity stage, whose blurs
//! cover more of the image where the sigmas vary faster.

use crate::acuity::AcuityFilter;
use crate::image::{Projection, Samples, View};
use crate::operator::{DEFAULT_FOV_DEG, MIN_BLUR_SIGMA_PX, Report};
use crate::scotopic;
use crate::{Error, HdrImage, Result};

/// An edge of one log10 unit separates samples as much as this many degrees of uniform
/// field (the `D` of the module docs). A project choice: with it a 1000:1 edge is 6° away,
/// six radii of the default neighbourhood, which keeps the bright side's weight on the dark
/// side's adaptation under 1e-3 (the halo test), while the gradual changes of a sky or a
/// lit wall (a log unit over tens of degrees) barely shorten the neighbourhood.
pub const EDGE_DEGREES_PER_LOG_UNIT: f64 = 2.0;

/// Iterations of the domain transform's recursive filter (Gastal & Oliveira 2011 use 3).
pub const ITERATIONS: usize = 3;

/// Luminance that zero, negative and non-finite pixels read as in the map, cd/m² (and
/// scotopic cd/m²): four log units below the rods' absolute threshold (Eq. 5 is flat below
/// 10^-3.94), so it changes no threshold.
pub const FLOOR_CD_M2: f32 = 1e-8;

/// The filter grid has at least this many samples per radius.
pub const SAMPLES_PER_RADIUS: f64 = 4.0;

/// The largest grid step, pixels.
pub const MAX_GRID_STEP_PX: usize = 32;

/// Width, log10 units, of the range weight of the upsampling: a grid sample whose guide
/// differs from the pixel's log luminance by this much weighs a quarter of one that
/// matches. Texture within about half a log unit is smoothed; edges are kept.
pub const UPSAMPLING_RANGE_LOG: f32 = 0.5;

/// Per pixel, the local adaptation as log10 offsets from the global world adaptation of an
/// [`operator::plan`](crate::operator::plan) report (see the module docs).
///
/// The [`Default`] map is empty (no pixels), a start for [`AdaptationMap::compute_into`].
#[derive(Clone, Default, PartialEq)]
pub struct AdaptationMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Per pixel, `log10(L_a(x) / L_wa)` for the cones (photopic).
    pub offset_log: Vec<f32>,
    /// Per pixel, `log10(L_a,s(x) / L_wa,s)` for the rods (scotopic).
    pub offset_scotopic_log: Vec<f32>,
    /// Per pixel, the standard deviation of the Eq. 7 acuity Gaussian at the local
    /// adaptation, pixels (0: no blur); `None` when the report's acuity was off or its view
    /// has no angles.
    pub acuity_sigma_px: Option<Vec<f32>>,
    /// The global photopic world adaptation `L_wa` the offsets are from, cd/m².
    pub world_adaptation_cd_m2: f64,
    /// The global scotopic world adaptation the scotopic offsets are from, scotopic cd/m².
    pub world_adaptation_scotopic_cd_m2: f64,
    /// The radius of the neighbourhood, degrees.
    pub radius_deg: f64,
    /// Pixels between the samples of the filter grid.
    pub grid_step_px: usize,
    /// The filter grid itself, for the stages that want values per sample.
    pub grid: Grid,
}

/// The filter grid: samples `step` pixels apart, row-major.
#[derive(Clone, Default, PartialEq)]
pub struct Grid {
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Per sample, the guide (block mean of log10 photopic luminance).
    pub guide_log: Vec<f32>,
    /// Per sample, the photopic offset (log10, as [`AdaptationMap::offset_log`]).
    pub offset_log: Vec<f32>,
    /// Per sample, the scotopic offset.
    pub offset_scotopic_log: Vec<f32>,
    /// Per sample, pixels per degree there (from the view).
    pub pixels_per_degree: Vec<f32>,
}

/// The map's size, levels, radius and grid, and of each plane its number of samples
/// (as for the images: [`HdrImage`]'s `Debug`).
impl std::fmt::Debug for AdaptationMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let AdaptationMap {
            width,
            height,
            offset_log,
            offset_scotopic_log,
            acuity_sigma_px,
            world_adaptation_cd_m2,
            world_adaptation_scotopic_cd_m2,
            radius_deg,
            grid_step_px,
            grid,
        } = self;
        f.debug_struct("AdaptationMap")
            .field("width", width)
            .field("height", height)
            .field("offset_log", &Samples(offset_log))
            .field("offset_scotopic_log", &Samples(offset_scotopic_log))
            .field("acuity_sigma_px", &acuity_sigma_px.as_deref().map(Samples))
            .field("world_adaptation_cd_m2", world_adaptation_cd_m2)
            .field(
                "world_adaptation_scotopic_cd_m2",
                world_adaptation_scotopic_cd_m2,
            )
            .field("radius_deg", radius_deg)
            .field("grid_step_px", grid_step_px)
            .field("grid", grid)
            .finish()
    }
}

/// The grid's size, and of each plane its number of samples.
impl std::fmt::Debug for Grid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Grid {
            width,
            height,
            guide_log,
            offset_log,
            offset_scotopic_log,
            pixels_per_degree,
        } = self;
        f.debug_struct("Grid")
            .field("width", width)
            .field("height", height)
            .field("guide_log", &Samples(guide_log))
            .field("offset_log", &Samples(offset_log))
            .field("offset_scotopic_log", &Samples(offset_scotopic_log))
            .field("pixels_per_degree", &Samples(pixels_per_degree))
            .finish()
    }
}

impl AdaptationMap {
    /// The local photopic adaptation of pixel `i`, cd/m².
    pub fn adaptation_cd_m2(&self, i: usize) -> f64 {
        self.world_adaptation_cd_m2 * 10f64.powf(f64::from(self.offset_log[i]))
    }

    /// The local scotopic adaptation of pixel `i`, scotopic cd/m².
    pub fn adaptation_scotopic_cd_m2(&self, i: usize) -> f64 {
        self.world_adaptation_scotopic_cd_m2 * 10f64.powf(f64::from(self.offset_scotopic_log[i]))
    }

    /// A map of given levels: per pixel the photopic (cd/m²) and scotopic (scotopic cd/m²)
    /// adaptation luminances, finite and non-negative (values below [`FLOOR_CD_M2`] read as
    /// it), without acuity sigmas. The offsets are from the first pixel's levels.
    pub fn from_levels(
        width: usize,
        height: usize,
        adaptation_cd_m2: &[f32],
        adaptation_scotopic_cd_m2: &[f32],
    ) -> Result<Self> {
        let n = width * height;
        let mut offsets = Vec::with_capacity(2);
        for (name, map) in [
            ("adaptation map", adaptation_cd_m2),
            ("scotopic adaptation map", adaptation_scotopic_cd_m2),
        ] {
            if map.len() != n {
                return Err(Error::invalid(
                    name,
                    format!("of {} values", map.len()),
                    format!("must hold one value per pixel ({n})"),
                ));
            }
            if let Some(v) = map.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(Error::invalid(
                    name,
                    v,
                    "values must be finite, non-negative luminances",
                ));
            }
            // Offsets from the first pixel's level: a uniform map is exactly offset 0.
            let anchor = f64::from(map.first().map_or(1.0, |v| v.max(FLOOR_CD_M2)));
            let o: Vec<f32> = map
                .iter()
                .map(|&v| (f64::from(v.max(FLOOR_CD_M2)) / anchor).log10() as f32)
                .collect();
            offsets.push((o, anchor));
        }
        let (offset_scotopic_log, anchor_s) = offsets.pop().expect("two maps");
        let (offset_log, anchor) = offsets.pop().expect("two maps");
        Ok(AdaptationMap {
            width,
            height,
            offset_log,
            offset_scotopic_log,
            acuity_sigma_px: None,
            world_adaptation_cd_m2: anchor,
            world_adaptation_scotopic_cd_m2: anchor_s,
            radius_deg: f64::NAN,
            grid_step_px: 0,
            grid: Grid::default(),
        })
    }

    /// The map of `image` for a neighbourhood of `radius_deg` degrees (positive; `+∞` for
    /// the global limit), anchored to the world adaptation of `report` (the
    /// [`operator::plan`](crate::operator::plan) of the same image) with its hot-pixel
    /// fraction `hot_pixel_fraction`.
    pub fn compute(
        image: &HdrImage,
        report: &Report,
        radius_deg: f64,
        hot_pixel_fraction: f64,
    ) -> Result<Self> {
        let mut map = AdaptationMap::default();
        map.compute_into(image, report, radius_deg, hot_pixel_fraction)?;
        Ok(map)
    }

    /// [`AdaptationMap::compute`] into this map, whose per-pixel planes are reused when
    /// they are large enough (a stream of frames of one size allocates them once): the
    /// same map, bit for bit. Fresh planes are written from pages the system hands out
    /// zeroed on first touch; at 1920 × 1080 their 24 MiB cost about 6,000 page faults
    /// per frame, which reuse avoids (see the README's performance section). On an error
    /// the map is left as it was.
    pub fn compute_into(
        &mut self,
        image: &HdrImage,
        report: &Report,
        radius_deg: f64,
        hot_pixel_fraction: f64,
    ) -> Result<()> {
        image.check_consistent()?;
        if radius_deg.is_nan() || radius_deg <= 0.0 {
            return Err(Error::invalid(
                "adaptation-radius",
                radius_deg,
                "must be a positive number of degrees",
            ));
        }
        let (w, h) = (image.width, image.height);
        let view = angular_view(&report.view, w, h);
        let centre_ppd = 1.0 / pixel_size_deg(&view, w, h, w as f64 / 2.0, h as f64 / 2.0);
        let step = grid_step(radius_deg * centre_ppd);
        let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));

        // The map's planes, reused when they can hold the image. The first is written
        // with each pixel's log photopic luminance by the block means, which the
        // upsampling reads as its guide and overwrites with the photopic offset.
        let mut planes = vec![
            std::mem::take(&mut self.offset_log),
            std::mem::take(&mut self.offset_scotopic_log),
        ];
        // The acuity sigmas need the view's pixels per degree (the same rule as the global
        // operator's).
        let acuity_ppd = report.pixels_per_degree.filter(|_| report.acuity_applied);
        let sigma_plane = self.acuity_sigma_px.take();
        if acuity_ppd.is_some() {
            planes.push(sigma_plane.unwrap_or_default());
        }
        for plane in planes.iter_mut() {
            if plane.capacity() < w * h {
                // Zeroed pages from the system, touched first by the parallel passes.
                *plane = vec![0f32; w * h];
            } else {
                plane.resize(w * h, 0.0);
            }
        }
        // Block means of the log luminances (the guide is the photopic one).
        let (guide, scot) = block_log_means(image, step, gw, gh, &mut planes[0]);
        let ppd = pixels_per_degree_grid(&view, w, h, step);
        let mut phot: Vec<f64> = guide.iter().map(|&v| f64::from(v)).collect();
        let mut scot: Vec<f64> = scot.iter().map(|&v| f64::from(v)).collect();
        let links = link_lengths_deg(
            |i| f64::from(guide[i]),
            |i| step as f64 / f64::from(ppd[i]),
            gw,
            gh,
        );
        domain_transform(&mut [&mut phot, &mut scot], links, gw, gh, radius_deg);
        let anchor = |v: &[f64]| high_quantile(v, hot_pixel_fraction);
        let (qp, qs) = (anchor(&phot), anchor(&scot));
        let offset_grid: Vec<f32> = phot.iter().map(|&v| (v - qp) as f32).collect();
        let offset_scotopic_grid: Vec<f32> = scot.iter().map(|&v| (v - qs) as f32).collect();
        // The acuity Gaussian of each sample's adaptation (Eq. 7), in pixels by the same rule
        // as the global operator (pixels per degree at the centre, capped at the image size).
        let sigma_grid: Option<Vec<f32>> = match acuity_ppd {
            Some(ppd) => {
                let (lwa, lwa_s) = (
                    report.world_adaptation_cd_m2,
                    report.world_adaptation_scotopic_cd_m2,
                );
                let rule = report.acuity.rule;
                let sigma = |dp: f32, ds: f32| {
                    let la = lwa * 10f64.powf(f64::from(dp));
                    let las = lwa_s * 10f64.powf(f64::from(ds));
                    let s = (AcuityFilter::with_rule(la, las, rule).sigma_deg * ppd)
                        .min(w.max(h) as f64);
                    if s >= MIN_BLUR_SIGMA_PX {
                        s as f32
                    } else {
                        0.0
                    }
                };
                let piece =
                    |(out, (dp, ds)): (&mut [f32], (&[f32], &[f32]))| by_runs(out, dp, ds, sigma);
                let mut sigmas = vec![0f32; offset_grid.len()];
                #[cfg(feature = "rayon")]
                {
                    use rayon::prelude::*;
                    sigmas
                        .par_chunks_mut(SIGMA_PIECE)
                        .zip(
                            offset_grid
                                .par_chunks(SIGMA_PIECE)
                                .zip(offset_scotopic_grid.par_chunks(SIGMA_PIECE)),
                        )
                        .for_each(piece);
                }
                #[cfg(not(feature = "rayon"))]
                sigmas
                    .chunks_mut(SIGMA_PIECE)
                    .zip(
                        offset_grid
                            .chunks(SIGMA_PIECE)
                            .zip(offset_scotopic_grid.chunks(SIGMA_PIECE)),
                    )
                    .for_each(piece);
                Some(sigmas)
            }
            None => None,
        };
        let grid = Grid {
            width: gw,
            height: gh,
            guide_log: guide,
            offset_log: offset_grid,
            offset_scotopic_log: offset_scotopic_grid,
            pixels_per_degree: ppd,
        };
        let mut channels: Vec<&[f32]> = vec![&grid.offset_log, &grid.offset_scotopic_log];
        channels.extend(sigma_grid.as_deref());
        upsample(w, &grid, step, &channels, &mut planes);
        let mut planes = planes.into_iter();
        *self = AdaptationMap {
            width: w,
            height: h,
            offset_log: planes.next().expect("photopic plane"),
            offset_scotopic_log: planes.next().expect("scotopic plane"),
            acuity_sigma_px: planes.next(),
            world_adaptation_cd_m2: report.world_adaptation_cd_m2,
            world_adaptation_scotopic_cd_m2: report.world_adaptation_scotopic_cd_m2,
            radius_deg,
            grid_step_px: step,
            grid,
        };
        Ok(())
    }
}

/// Pixels per degree at each sample of the grid of `step` over a `w × h` image in `view`
/// (at the centre of its block of pixels), row by row.
///
/// The trigonometry is per sample, so the rows run in parallel (a grid of step 1 on a
/// wide view has a sample per pixel), and where the grid is symmetric about the image's
/// centre only a quarter of it is computed: when `step` divides both sides, the samples
/// mirrored left to right (or top to bottom) are at positions mirrored exactly, and for
/// the projections built from the distance to the centre and the signed offsets along
/// each axis (all but the cylindrical one, which takes a sine of the signed angle) the
/// directions there are mirrored exactly too (one component's sign), so the pixel sizes
/// are the same bit for bit: the differences and the cross product change only in the
/// signs of some components, the norms not at all (tested against every sample
/// computed).
fn pixels_per_degree_grid(view: &View, w: usize, h: usize, step: usize) -> Vec<f32> {
    let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
    let centre = |g: usize, n: usize| {
        ((g * step) as f64 + (step.min(n - g * step)) as f64 / 2.0).min(n as f64)
    };
    let mirrored = !matches!(view.projection, Projection::Cylindrical)
        && w.is_multiple_of(step)
        && h.is_multiple_of(step);
    let (cw, ch) = if mirrored {
        (gw.div_ceil(2), gh.div_ceil(2))
    } else {
        (gw, gh)
    };
    let mut ppd = vec![0f32; gw * gh];
    let row = |(gy, row): (usize, &mut [f32])| {
        let cy = centre(gy, h);
        for (gx, p) in row.iter_mut().enumerate().take(cw) {
            *p = (1.0 / pixel_size_deg(view, w, h, centre(gx, w), cy)) as f32;
        }
        for gx in cw..gw {
            row[gx] = row[gw - 1 - gx];
        }
    };
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        ppd.par_chunks_mut(gw).enumerate().take(ch).for_each(row);
    }
    #[cfg(not(feature = "rayon"))]
    ppd.chunks_mut(gw).enumerate().take(ch).for_each(row);
    let (top, bottom) = ppd.split_at_mut(ch * gw);
    for (k, out) in bottom.chunks_exact_mut(gw).enumerate() {
        let gy = ch + k;
        out.copy_from_slice(&top[(gh - 1 - gy) * gw..][..gw]);
    }
    ppd
}

/// The grid step for a radius of `radius_px` pixels.
fn grid_step(radius_px: f64) -> usize {
    let s = (radius_px / SAMPLES_PER_RADIUS).floor();
    if s.is_nan() || s < 1.0 {
        1
    } else {
        (s as usize).min(MAX_GRID_STEP_PX)
    }
}

/// The view with angles: the image's, or for a view without angles (parallel) the default
/// perspective one.
fn angular_view(view: &View, w: usize, h: usize) -> View {
    if view.pixels_per_degree(w).is_some() {
        *view
    } else {
        View::perspective(DEFAULT_FOV_DEG, w, h)
    }
}

/// The direction (unit vector) seen at image position `(u, v)` (pixels from the top-left
/// corner, continuous) of a `w × h` image in `view`. The fisheyes' formulas hold beyond
/// the circle the horizontal angle spans (a frame wider than it is high, or a square
/// frame's corners, see more than the horizontal angle along the diagonal) up to where the
/// projection ends, as Radiance's views and [`crate::glare`] take them: the angular
/// fisheye at 180° from the axis, the hemispherical at 90°; a position beyond that is
/// taken on that rim. (They were taken on the circle of the horizontal angle, so that
/// the pixels in the corners of a 16:9 angular fisheye subtended almost nothing.)
fn direction(view: &View, w: usize, h: usize, u: f64, v: f64) -> [f64; 3] {
    let (half_w, half_h) = (w as f64 / 2.0, h as f64 / 2.0);
    let (dx, dy) = (u - half_w, v - half_h);
    let half_fov = (view.horizontal_deg / 2.0).to_radians();
    let normalise = |a: [f64; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        [a[0] / n, a[1] / n, a[2] / n]
    };
    let polar = |theta: f64| {
        let r = (dx * dx + dy * dy).sqrt();
        if r == 0.0 {
            return [0.0, 0.0, 1.0];
        }
        let (s, c) = theta.sin_cos();
        [s * dx / r, s * dy / r, c]
    };
    // The distance from the centre in units of the horizontal half-width.
    let r_rel = || (dx * dx + dy * dy).sqrt() / half_w;
    match view.projection {
        Projection::Perspective | Projection::Parallel => {
            let t = half_fov.tan() / half_w;
            normalise([dx * t, dy * t, 1.0])
        }
        Projection::AngularFisheye => polar((r_rel() * half_fov).min(std::f64::consts::PI)),
        Projection::HemisphericalFisheye => polar((r_rel() * half_fov.sin()).min(1.0).asin()),
        Projection::Planisphere => polar(2.0 * (r_rel() * (half_fov / 2.0).tan()).atan()),
        Projection::Cylindrical => {
            let phi = dx / half_w * half_fov;
            let vt = (view.vertical_deg / 2.0).to_radians().tan() / half_h;
            normalise([phi.sin(), dy * vt, phi.cos()])
        }
    }
}

/// The angular size of a pixel at image position `(u, v)`, degrees: the square root of its
/// solid angle (as `pcond` takes it), from the view's projection: the area spanned by the
/// direction changes across the pixel horizontally and vertically. Perspective, angular
/// and hemispherical fisheye, planisphere and cylindrical views; a view without angles
/// (parallel) is read as perspective. On a fisheye's rim, where the projection folds, the
/// larger of the two extents stands for both.
pub fn pixel_size_deg(view: &View, w: usize, h: usize, u: f64, v: f64) -> f64 {
    let d = |du: f64, dv: f64| direction(view, w, h, u + du, v + dv);
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let a = sub(d(0.5, 0.0), d(-0.5, 0.0));
    let b = sub(d(0.0, 0.5), d(0.0, -0.5));
    let cross = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    let area = norm(cross);
    let longest = norm(a).max(norm(b));
    let size = if area > 1e-6 * longest * longest {
        area.sqrt()
    } else if longest > 0.0 {
        longest
    } else {
        (view.horizontal_deg / w as f64).to_radians()
    };
    size.to_degrees()
}

/// log10 of a positive, finite, normal `f32`, to about 2e-6 (a bit split and a short
/// series in `t = (m − 1)/(m + 1)`), in a form the compiler vectorises.
#[inline(always)]
pub(crate) fn fast_log10(x: f32) -> f32 {
    const LOG10_2: f32 = std::f32::consts::LOG10_2;
    let bits = x.to_bits();
    let exponent = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000); // [1, 2)
    let mut e = exponent as f32;
    // Centre the mantissa on 1 ([0.707, 1.414)) so the series converges fast.
    if m > std::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1.0;
    }
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    // ln m = 2(t + t³/3 + t⁵/5 + t⁷/7), |t| < 0.172: the next term is below 1e-8.
    let ln_m = 2.0 * t * (1.0 + t2 * (1.0 / 3.0 + t2 * (1.0 / 5.0 + t2 * (1.0 / 7.0))));
    e * LOG10_2 + ln_m * std::f32::consts::LOG10_E
}

/// The map's reading of a luminance: non-finite, zero and negative values, and values below
/// [`FLOOR_CD_M2`], read as the floor.
#[inline(always)]
fn clean(v: f32, finite: bool) -> f32 {
    if finite && v > FLOOR_CD_M2 {
        v
    } else {
        FLOOR_CD_M2
    }
}

/// Per pixel the log10 photopic and scotopic luminance as the map reads them, for pixels
/// `start..start + out_p.len()` (one loop per kind of scotopic input, so that each
/// vectorises).
#[inline(always)]
fn log_luminances(image: &HdrImage, start: usize, out_p: &mut [f32], out_s: &mut [f32]) {
    let end = start + out_p.len();
    let (xs, ys, zs) = (
        &image.x[start..end],
        &image.y[start..end],
        &image.z[start..end],
    );
    match &image.scotopic {
        Some(s) => {
            let s = &s[start..end];
            for j in 0..out_p.len() {
                let finite =
                    xs[j].is_finite() & ys[j].is_finite() & zs[j].is_finite() & s[j].is_finite();
                out_p[j] = fast_log10(clean(ys[j], finite));
                out_s[j] = fast_log10(clean(s[j], finite));
            }
        }
        None => {
            for j in 0..out_p.len() {
                let (x, y, z) = (xs[j], ys[j], zs[j]);
                let finite = x.is_finite() & y.is_finite() & z.is_finite();
                let v = if finite {
                    scotopic::from_xyz(x.max(0.0), y.max(0.0), z.max(0.0))
                } else {
                    0.0
                };
                out_p[j] = fast_log10(clean(y, finite));
                out_s[j] = fast_log10(clean(v, finite));
            }
        }
    }
}

/// Block means (`step × step` pixels, smaller at the right and bottom edges) of the log
/// luminances. A mean of equal values is that value exactly (it is summed as differences
/// from the block's first pixel). Each pixel's log photopic luminance (the photopic half
/// of [`log_luminances`]) is written to `log_photopic_px` (one value per pixel) on the
/// way: the upsampling's guide, read there instead of from the image again.
fn block_log_means(
    image: &HdrImage,
    step: usize,
    gw: usize,
    gh: usize,
    log_photopic_px: &mut [f32],
) -> (Vec<f32>, Vec<f32>) {
    assert_eq!(log_photopic_px.len(), image.len(), "a value per pixel");
    let mut guide = vec![0f32; gw * gh];
    let mut scot = vec![0f32; gw * gh];
    let band = |gy: usize, guide: &mut [f32], scot: &mut [f32], lp: &mut [f32]| {
        widest!(block_band(image, step, gy, guide, scot, lp))
    };
    let band_px = step * image.width;
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        guide
            .par_chunks_mut(gw)
            .zip(scot.par_chunks_mut(gw))
            .zip(log_photopic_px.par_chunks_mut(band_px))
            .enumerate()
            .for_each(|(gy, ((g, s), lp))| band(gy, g, s, lp));
    }
    #[cfg(not(feature = "rayon"))]
    {
        let bands = guide
            .chunks_mut(gw)
            .zip(scot.chunks_mut(gw))
            .zip(log_photopic_px.chunks_mut(band_px));
        for (gy, ((g, s), lp)) in bands.enumerate() {
            band(gy, g, s, lp);
        }
    }
    (guide, scot)
}

/// Band `gy` of [`block_log_means`]: the means of its `guide.len()` blocks, and its rows'
/// log photopic luminances into `log_photopic_px`.
#[inline(always)]
fn block_band(
    image: &HdrImage,
    step: usize,
    gy: usize,
    guide: &mut [f32],
    scot: &mut [f32],
    log_photopic_px: &mut [f32],
) {
    let (w, h) = (image.width, image.height);
    let mut row_s = vec![0f32; w];
    // Per column, the sum over the band's rows of the differences from its block's first
    // pixel (independent columns: the loop vectorises), then per block the sum of its
    // columns.
    let mut col_p = vec![0f64; w];
    let mut col_s = vec![0f64; w];
    let mut first_p = vec![0f32; w];
    let mut first_s = vec![0f32; w];
    let rows = (gy * step)..((gy + 1) * step).min(h);
    let count_y = rows.len();
    for (k, y) in rows.enumerate() {
        let row_p = &mut log_photopic_px[k * w..][..w];
        log_luminances(image, y * w, row_p, &mut row_s);
        if k == 0 {
            for x in 0..w {
                let first = x - x % step;
                first_p[x] = row_p[first];
                first_s[x] = row_s[first];
            }
        }
        for x in 0..w {
            col_p[x] += f64::from(row_p[x] - first_p[x]);
            col_s[x] += f64::from(row_s[x] - first_s[x]);
        }
    }
    for (gx, (g, s)) in guide.iter_mut().zip(scot.iter_mut()).enumerate() {
        let cols = (gx * step)..((gx + 1) * step).min(w);
        let count = (count_y * cols.len()) as f64;
        let sp: f64 = col_p[cols.clone()].iter().sum();
        let ss: f64 = col_s[cols.clone()].iter().sum();
        *g = first_p[cols.start] + (sp / count) as f32;
        *s = first_s[cols.start] + (ss / count) as f32;
    }
}

/// The domain transform's link lengths in degrees on a `gw × gh` grid: `dh[i]` from
/// sample i−1 to i along the row, `dv[i]` from the sample above (0 on the first column
/// and row): the mean of the two samples' widths plus `EDGE_DEGREES_PER_LOG_UNIT` times
/// the guide's step between them.
///
/// `guide(i)` and `step_deg(i)` give sample `i`'s guide and width, so that they need not
/// be planes of their own (`f64`, on a wide view's grid of step 1 each would be 8 bytes
/// per pixel).
fn link_lengths_deg(
    guide: impl Fn(usize) -> f64,
    step_deg: impl Fn(usize) -> f64,
    gw: usize,
    gh: usize,
) -> (Vec<f64>, Vec<f64>) {
    let n = gw * gh;
    let mut dh = vec![0f64; n];
    let mut dv = vec![0f64; n];
    for y in 0..gh {
        for x in 0..gw {
            let i = y * gw + x;
            if x > 0 {
                dh[i] = 0.5 * (step_deg(i) + step_deg(i - 1))
                    + EDGE_DEGREES_PER_LOG_UNIT * (guide(i) - guide(i - 1)).abs();
            }
            if y > 0 {
                dv[i] = 0.5 * (step_deg(i) + step_deg(i - gw))
                    + EDGE_DEGREES_PER_LOG_UNIT * (guide(i) - guide(i - gw)).abs();
            }
        }
    }
    (dh, dv)
}

/// The domain transform's recursive filter (module docs) of `channels` in place, on a
/// `gw × gh` grid with the link lengths `(dh, dv)` of [`link_lengths_deg`].
fn domain_transform(
    channels: &mut [&mut Vec<f64>],
    (dh, dv): (Vec<f64>, Vec<f64>),
    gw: usize,
    gh: usize,
    sigma_deg: f64,
) {
    let iterations = ITERATIONS as i32;
    let norm = 3f64.sqrt() / (4f64.powi(iterations) - 1.0).sqrt();
    // Weight of the previous sample, `a_i^d = exp(−√2·d/σ_i)`; 1 (a constant signal) for
    // an infinite sigma. Each iteration halves `σ_i`, so its weights are the previous
    // iteration's squared: one exponential per link, not one per link and iteration. The
    // weights are squared in place after each iteration, so that one set is held.
    let sigma_0 = sigma_deg * norm * 2f64.powi(iterations - 1);
    let weight = |d: f64| (-std::f64::consts::SQRT_2 * d / sigma_0).exp();
    let mut wh = dh;
    let mut wv = dv;
    for_each_chunk(&mut wh, |w| w.iter_mut().for_each(|d| *d = weight(*d)));
    for_each_chunk(&mut wv, |w| w.iter_mut().for_each(|d| *d = weight(*d)));
    for i in 0..iterations {
        if i > 0 {
            for_each_chunk(&mut wh, |w| w.iter_mut().for_each(|a| *a = *a * *a));
            for_each_chunk(&mut wv, |w| w.iter_mut().for_each(|a| *a = *a * *a));
        }
        // The channels are independent: one per thread.
        #[cfg(feature = "rayon")]
        {
            use rayon::prelude::*;
            channels
                .par_iter_mut()
                .for_each(|c| recursive_pass(c, &wh, &wv, gw, gh));
        }
        #[cfg(not(feature = "rayon"))]
        for c in channels.iter_mut() {
            recursive_pass(c, &wh, &wv, gw, gh);
        }
    }
}

/// `f` over pieces of `v` (in parallel with the `rayon` feature).
fn for_each_chunk(v: &mut [f64], f: impl Fn(&mut [f64]) + Sync + Send) {
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        v.par_chunks_mut(4096).for_each(f);
    }
    #[cfg(not(feature = "rayon"))]
    f(v);
}

/// `out[i] = f(a[i], b[i])`, a sample whose inputs are the last one's (bit for bit)
/// taking its value instead of calling `f` again: the same values for a deterministic
/// `f`. For the grid's acuity sigmas (a dozen transcendental functions each), whose
/// offsets repeat over uniform areas (the dark corners of a fisheye image: a fifth of
/// the samples of `office-fisheye.hdr`).
fn by_runs(out: &mut [f32], a: &[f32], b: &[f32], f: impl Fn(f32, f32) -> f32) {
    let mut last: Option<([u32; 2], f32)> = None;
    for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
        let key = [x.to_bits(), y.to_bits()];
        *o = match last {
            Some((k, v)) if k == key => v,
            _ => {
                let v = f(x, y);
                last = Some((key, v));
                v
            }
        };
    }
}

/// Samples per piece of the grid's acuity sigmas (in parallel).
const SIGMA_PIECE: usize = 4096;

/// Rows whose recursions [`recursive_pass`] interleaves.
const ROWS_TOGETHER: usize = 8;

/// One iteration of the domain transform's recursive filter over a `gw × gh` grid `c`:
/// the causal and anti-causal passes along every row, then along every column, with the
/// weights `wh` (from the sample to the left) and `wv` (from the sample above).
fn recursive_pass(c: &mut [f64], wh: &[f64], wv: &[f64], gw: usize, gh: usize) {
    // Rows, [`ROWS_TOGETHER`] at a time, their recursions interleaved: each row's is a
    // chain of dependent operations, so that one row at a time waits on their latency.
    // Every sample takes the same operations in the same order.
    for (rows, wr) in c
        .chunks_mut(ROWS_TOGETHER * gw)
        .zip(wh.chunks(ROWS_TOGETHER * gw))
    {
        let n = rows.len() / gw;
        for x in 1..gw {
            for k in 0..n {
                let i = k * gw + x;
                rows[i] = rows[i - 1] + (1.0 - wr[i]) * (rows[i] - rows[i - 1]);
            }
        }
        for x in (0..gw.saturating_sub(1)).rev() {
            for k in 0..n {
                let i = k * gw + x;
                rows[i] = rows[i + 1] + (1.0 - wr[i + 1]) * (rows[i] - rows[i + 1]);
            }
        }
    }
    // Columns (the inner loop runs along a row: it vectorises).
    for y in 1..gh {
        for x in 0..gw {
            let i = y * gw + x;
            c[i] = c[i - gw] + (1.0 - wv[i]) * (c[i] - c[i - gw]);
        }
    }
    for y in (0..gh.saturating_sub(1)).rev() {
        for x in 0..gw {
            let i = y * gw + x;
            c[i] = c[i + gw] + (1.0 - wv[i + gw]) * (c[i] - c[i + gw]);
        }
    }
}

/// The value that at most `fraction` of `values` exceed (the rank rule of
/// [`crate::adaptation::highest_visible`]).
pub(crate) fn high_quantile(values: &[f64], fraction: f64) -> f64 {
    let mut v = values.to_vec();
    let n = v.len();
    let allowed = ((n as f64) * fraction.clamp(0.0, 1.0)).floor() as usize;
    // The value at that rank of the sorted order, found by selection (linear time) rather
    // than a whole sort: the same value (one rank of one total order).
    *v.select_nth_unstable_by(n - 1 - allowed.min(n - 1), f64::total_cmp)
        .1
}

/// Joint bilateral upsampling of grid `channels` to every pixel (module docs) into
/// `planes` (one per channel, rows of `w` pixels; every sample is written), row by row
/// (no interleaved copy). The first plane holds each pixel's log photopic luminance on
/// entry (the guide: [`block_log_means`] writes it there), read before it is
/// overwritten. Along a row the grid samples change every `step`
/// pixels; each run of pixels between the same four samples is computed with those
/// samples held, so the loops vectorise.
fn upsample(w: usize, grid: &Grid, step: usize, channels: &[&[f32]], planes: &mut [Vec<f32>]) {
    let h = planes.first().map_or(0, |p| p.len() / w.max(1));
    let (gw, gh) = (grid.width, grid.height);
    // Grid coordinates of a pixel centre: sample k's centre is at (k + 1/2)·step.
    let grid_pos = |p: usize, samples: usize| {
        let f = ((p as f32 + 0.5) / step as f32 - 0.5).clamp(0.0, (samples - 1) as f32);
        let k0 = (f as usize).min(samples - 1);
        (k0, (k0 + 1).min(samples - 1), f - k0 as f32)
    };
    // Per column the weight of the right-hand samples; runs of columns between the same
    // two grid columns: (x0, x1, first column, end).
    let tx: Vec<f32> = (0..w).map(|x| grid_pos(x, gw).2).collect();
    let mut runs: Vec<(usize, usize, usize, usize)> = Vec::new();
    for x in 0..w {
        let (x0, x1, _) = grid_pos(x, gw);
        match runs.last_mut() {
            Some(r) if r.0 == x0 => r.3 = x + 1,
            _ => runs.push((x0, x1, x, x + 1)),
        }
    }
    assert_eq!(planes.len(), channels.len(), "one plane per channel");
    for plane in planes.iter() {
        assert_eq!(plane.len(), w * h, "planes of one size");
    }
    let mut rows = plane_rows(planes, w);
    let row_fn = |y: usize, row: &mut [&mut [f32]]| {
        let at = grid_pos(y, gh);
        widest!(upsample_row(grid, channels, &runs, &tx, at, row))
    };
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        rows.par_iter_mut()
            .enumerate()
            .for_each(|(y, row)| row_fn(y, row));
    }
    #[cfg(not(feature = "rayon"))]
    {
        for (y, row) in rows.iter_mut().enumerate() {
            row_fn(y, row);
        }
    }
}

/// Pixels per piece of a run in [`upsample_row`]: the largest grid step
/// ([`MAX_GRID_STEP_PX`]), so that a piece's weights fit in fixed arrays.
const UPSAMPLE_PIECE: usize = MAX_GRID_STEP_PX;

/// A row of [`upsample`] into `row` (one slice per channel, the first holding the row's
/// log photopic luminances on entry): `runs` of columns between the same two grid
/// columns `(x0, x1, first column, end)`, `tx` per column the weight of the right-hand
/// samples, `(y0, y1, ty)` the grid rows around the row and the weight of the lower one.
/// Run by run (in pieces of at most [`UPSAMPLE_PIECE`] pixels), the four taps' weights
/// are computed once for all channels (from the piece's luminances, before the piece is
/// written), and each channel's four values are held in registers: nothing is spread
/// over the row first.
#[inline(always)]
fn upsample_row(
    grid: &Grid,
    channels: &[&[f32]],
    runs: &[(usize, usize, usize, usize)],
    tx: &[f32],
    (y0, y1, ty): (usize, usize, f32),
    row: &mut [&mut [f32]],
) {
    const P: usize = UPSAMPLE_PIECE;
    let gw = grid.width;
    let inv_range = 1.0 / UPSAMPLING_RANGE_LOG;
    let taps = |x0: usize, x1: usize| [y0 * gw + x0, y0 * gw + x1, y1 * gw + x0, y1 * gw + x1];
    let mut weights = [[0f32; P]; 4];
    let mut sum = [0f32; P];
    for &(x0, x1, start, end) in runs {
        let q = taps(x0, x1);
        let guide = q.map(|q| grid.guide_log[q]);
        for from in (start..end).step_by(P) {
            let to = end.min(from + P);
            let m = to - from;
            // The piece's luminances, read before the piece of the first plane is written.
            let (lp, tx) = (&row[0][from..to], &tx[from..to]);
            for x in 0..m {
                let t = tx[x];
                let bilinear = [
                    (1.0 - t) * (1.0 - ty),
                    t * (1.0 - ty),
                    (1.0 - t) * ty,
                    t * ty,
                ];
                let g = lp[x];
                let mut sw = 0f32;
                for k in 0..4 {
                    let r = (g - guide[k]) * inv_range;
                    let range = 1.0 / (1.0 + r * r);
                    let wq = bilinear[k] * range * range;
                    weights[k][x] = wq;
                    sw += wq;
                }
                sum[x] = sw;
            }
            let [w0, w1, w2, w3] = &weights;
            let (w0, w1, w2, w3, sum) = (&w0[..m], &w1[..m], &w2[..m], &w3[..m], &sum[..m]);
            for (out, c) in row.iter_mut().zip(channels) {
                let v = q.map(|q| c[q]);
                // A sum of differences from the first tap: equal taps give it exactly.
                let base = v[0];
                let d = v.map(|v| v - base);
                let out = &mut out[from..to];
                for x in 0..m {
                    let mut s = 0f32;
                    s += w0[x] * d[0];
                    s += w1[x] * d[1];
                    s += w2[x] * d[2];
                    s += w3[x] * d[3];
                    out[x] = base + s / sum[x];
                }
            }
        }
    }
}

/// Row `y` of every plane (`rows[y][c]`: row `y` of plane `c`, planes `width` samples
/// wide), so that rows of all the planes can be filled together, in parallel.
fn plane_rows(planes: &mut [Vec<f32>], width: usize) -> Vec<Vec<&mut [f32]>> {
    let height = planes.first().map_or(0, |p| p.len() / width.max(1));
    let mut rows: Vec<Vec<&mut [f32]>> = (0..height)
        .map(|_| Vec::with_capacity(planes.len()))
        .collect();
    for plane in planes.iter_mut() {
        for (row, r) in rows.iter_mut().zip(plane.chunks_mut(width)) {
            row.push(r);
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Per pixel the log10 photopic luminance as the map reads it, written on its own: the
    /// reference for the photopic half of [`log_luminances`] (the same values), for pixels `start..start + out.len()`.
    fn log_photopic(image: &HdrImage, start: usize, out: &mut [f32]) {
        let end = start + out.len();
        let (xs, ys, zs) = (
            &image.x[start..end],
            &image.y[start..end],
            &image.z[start..end],
        );
        let finite3 = |j: usize| xs[j].is_finite() & ys[j].is_finite() & zs[j].is_finite();
        match &image.scotopic {
            Some(s) => {
                let s = &s[start..end];
                for (j, o) in out.iter_mut().enumerate() {
                    *o = fast_log10(clean(ys[j], finite3(j) & s[j].is_finite()));
                }
            }
            None => {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = fast_log10(clean(ys[j], finite3(j)));
                }
            }
        }
    }

    /// `Debug` shows each plane's number of samples, not the samples.
    #[test]
    fn debug_shows_each_planes_size_not_its_samples() {
        let (w, h) = (640, 480);
        let map = AdaptationMap {
            width: w,
            height: h,
            offset_log: vec![-0.5; w * h],
            offset_scotopic_log: vec![-0.5; w * h],
            acuity_sigma_px: Some(vec![1.5; w * h]),
            grid_step_px: 4,
            grid: Grid {
                width: w / 4,
                height: h / 4,
                guide_log: vec![0.0; w * h / 16],
                offset_log: vec![0.0; w * h / 16],
                offset_scotopic_log: vec![0.0; w * h / 16],
                pixels_per_degree: vec![40.0; w * h / 16],
            },
            ..AdaptationMap::default()
        };
        let shown = format!("{map:?}");
        assert_eq!(shown.matches("<307200 samples>").count(), 3, "{shown}");
        assert_eq!(shown.matches("<19200 samples>").count(), 4, "{shown}");
        assert!(shown.len() < 700, "{shown}");
    }

    /// The domain transform as first written (serial, one exponential per link and
    /// iteration), the reference the parallel one is pinned to.
    fn reference_domain_transform(
        channels: &mut [&mut Vec<f64>],
        guide: &[f64],
        step_deg: &[f64],
        gw: usize,
        gh: usize,
        sigma_deg: f64,
    ) {
        let (dh, dv) = link_lengths_deg(|i| guide[i], |i| step_deg[i], gw, gh);
        let iterations = ITERATIONS as i32;
        let norm = 3f64.sqrt() / (4f64.powi(iterations) - 1.0).sqrt();
        for i in 0..iterations {
            let sigma_i = sigma_deg * norm * 2f64.powi(iterations - 1 - i);
            let weight = |d: f64| (-std::f64::consts::SQRT_2 * d / sigma_i).exp();
            let wh: Vec<f64> = dh.iter().map(|&d| weight(d)).collect();
            let wv: Vec<f64> = dv.iter().map(|&d| weight(d)).collect();
            for c in channels.iter_mut() {
                recursive_pass(c, &wh, &wv, gw, gh);
            }
        }
    }

    /// The parallel domain transform (weights squared from one iteration to the next,
    /// channels on their own threads) against the reference: within 1e-12 log units (the
    /// squared weights differ from the exponentials by a few units in the last place), and
    /// exactly a constant for an infinite radius.
    #[test]
    fn parallel_domain_transform_matches_the_serial_one() {
        let (gw, gh) = (97, 41);
        let mut seed = 3u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            f64::from(seed >> 8) / f64::from(1u32 << 24)
        };
        let guide: Vec<f64> = (0..gw * gh)
            .map(|i| 3.0 * noise() + if i % gw > gw / 3 { 3.0 } else { -1.0 })
            .collect();
        let scot: Vec<f64> = guide.iter().map(|g| g - 0.4 + 0.1 * noise()).collect();
        let step_deg: Vec<f64> = (0..gw * gh).map(|_| 0.2 + 0.05 * noise()).collect();
        for sigma in [0.25, 1.0, 16.0, f64::INFINITY] {
            let (mut a, mut b) = (guide.clone(), scot.clone());
            let (mut ra, mut rb) = (guide.clone(), scot.clone());
            let links = link_lengths_deg(|i| guide[i], |i| step_deg[i], gw, gh);
            domain_transform(&mut [&mut a, &mut b], links, gw, gh, sigma);
            reference_domain_transform(&mut [&mut ra, &mut rb], &guide, &step_deg, gw, gh, sigma);
            let worst = a
                .iter()
                .zip(&ra)
                .chain(b.iter().zip(&rb))
                .map(|(x, y)| (x - y).abs())
                .fold(0f64, f64::max);
            assert!(worst < 1e-12, "σ {sigma}: {worst:e}");
            if sigma.is_infinite() {
                assert!(a.iter().all(|&v| v == a[0]), "constant");
            }
        }
    }

    /// The block means as first written (each block summed row by row), the reference the
    /// column-wise sums are pinned to.
    fn reference_block_log_means(
        image: &HdrImage,
        step: usize,
        gw: usize,
        gh: usize,
    ) -> (Vec<f32>, Vec<f32>) {
        let (w, h) = (image.width, image.height);
        let mut guide = vec![0f32; gw * gh];
        let mut scot = vec![0f32; gw * gh];
        for gy in 0..gh {
            let mut row_p = vec![0f32; w];
            let mut row_s = vec![0f32; w];
            let mut sum_p = vec![0f64; gw];
            let mut sum_s = vec![0f64; gw];
            let mut first_p = vec![0f32; gw];
            let mut first_s = vec![0f32; gw];
            let rows = (gy * step)..((gy + 1) * step).min(h);
            let count_y = rows.len();
            for (k, y) in rows.enumerate() {
                log_luminances(image, y * w, &mut row_p, &mut row_s);
                for gx in 0..gw {
                    let cols = (gx * step)..((gx + 1) * step).min(w);
                    if k == 0 {
                        first_p[gx] = row_p[cols.start];
                        first_s[gx] = row_s[cols.start];
                    }
                    for x in cols {
                        sum_p[gx] += f64::from(row_p[x] - first_p[gx]);
                        sum_s[gx] += f64::from(row_s[x] - first_s[gx]);
                    }
                }
            }
            for gx in 0..gw {
                let count = (count_y * (((gx + 1) * step).min(w) - gx * step)) as f64;
                guide[gy * gw + gx] = first_p[gx] + (sum_p[gx] / count) as f32;
                scot[gy * gw + gx] = first_s[gx] + (sum_s[gx] / count) as f32;
            }
        }
        (guide, scot)
    }

    /// The column-wise block sums against the reference: the means differ by at most one
    /// unit in the last place of `f32` (the f64 sums are added in another order), and a
    /// uniform block is its value exactly.
    #[test]
    fn block_means_match_the_row_wise_sums() {
        let (w, h) = (157, 61);
        let mut seed = 11u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut image = HdrImage::zeros(w, h);
        for i in 0..w * h {
            let l = 10f32.powf(6.0 * noise() - 3.0);
            image.x[i] = 0.9 * l;
            image.y[i] = l;
            image.z[i] = 1.1 * l;
        }
        image.y[5] = f32::NAN;
        for step in [1usize, 3, 8, 23] {
            let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
            let mut lp = vec![f32::NAN; w * h];
            let (g, s) = block_log_means(&image, step, gw, gh, &mut lp);
            let (rg, rs) = reference_block_log_means(&image, step, gw, gh);
            for (a, b) in g.iter().zip(&rg).chain(s.iter().zip(&rs)) {
                let ulp = f32::EPSILON * a.abs().max(b.abs()).max(f32::MIN_POSITIVE);
                assert!((a - b).abs() <= ulp, "step {step}: {a} {b}");
            }
            // Each pixel's log photopic luminance, written on the way, bit for bit.
            let mut want = vec![0f32; w * h];
            log_photopic(&image, 0, &mut want);
            for (i, (a, b)) in lp.iter().zip(&want).enumerate() {
                assert_eq!(a.to_bits(), b.to_bits(), "step {step}: pixel {i}");
            }
        }
        let mut uniform = HdrImage::zeros(40, 30);
        uniform.y.fill(0.37);
        let (g, _) = block_log_means(&uniform, 7, 6, 5, &mut vec![0.0; 40 * 30]);
        assert!(g.iter().all(|&v| v == fast_log10(0.37)));
    }

    /// The upsampling as first written (one pixel at a time), the reference the run-wise
    /// one is pinned to.
    fn reference_upsample(
        image: &HdrImage,
        grid: &Grid,
        step: usize,
        channels: &[&[f32]],
    ) -> Vec<Vec<f32>> {
        let (w, h) = (image.width, image.height);
        let n = w * h;
        let (gw, gh) = (grid.width, grid.height);
        let inv_range = 1.0 / UPSAMPLING_RANGE_LOG;
        let mut planes: Vec<Vec<f32>> = channels.iter().map(|_| vec![0f32; n]).collect();
        let mut rows = plane_rows(&mut planes, w);
        let row_fn = |y: usize, row: &mut [&mut [f32]]| {
            let mut lp = vec![0f32; w];
            let mut ls = vec![0f32; w];
            log_luminances(image, y * w, &mut lp, &mut ls);
            // Grid coordinates of the pixel centre: sample k's centre is at (k + 1/2)·step.
            let fy = ((y as f32 + 0.5) / step as f32 - 0.5).clamp(0.0, (gh - 1) as f32);
            let y0 = (fy as usize).min(gh - 1);
            let y1 = (y0 + 1).min(gh - 1);
            let ty = fy - y0 as f32;
            for x in 0..w {
                let fx = ((x as f32 + 0.5) / step as f32 - 0.5).clamp(0.0, (gw - 1) as f32);
                let x0 = (fx as usize).min(gw - 1);
                let x1 = (x0 + 1).min(gw - 1);
                let tx = fx - x0 as f32;
                let taps = [
                    (y0 * gw + x0, (1.0 - tx) * (1.0 - ty)),
                    (y0 * gw + x1, tx * (1.0 - ty)),
                    (y1 * gw + x0, (1.0 - tx) * ty),
                    (y1 * gw + x1, tx * ty),
                ];
                let g = lp[x];
                let base = taps[0].0;
                let mut weights = [0f32; 4];
                let mut sw = 0f32;
                for (wq, (q, b)) in weights.iter_mut().zip(taps) {
                    let r = (g - grid.guide_log[q]) * inv_range;
                    let range = 1.0 / (1.0 + r * r);
                    *wq = b * range * range;
                    sw += *wq;
                }
                for (out, c) in row.iter_mut().zip(channels) {
                    let b = c[base];
                    let mut s = 0f32;
                    for (wq, (q, _)) in weights.iter().zip(taps) {
                        s += wq * (c[q] - b);
                    }
                    // A sum of differences from the first tap: equal taps give it exactly.
                    out[x] = b + s / sw;
                }
            }
        };
        {
            for (y, row) in rows.iter_mut().enumerate() {
                row_fn(y, row);
            }
        }
        drop(rows);
        planes
    }

    /// The run-wise upsampling gives the reference's values bit for bit (grid steps 1 to
    /// 23, sizes that are not multiples of the step, with and without a scotopic plane).
    #[test]
    fn upsampling_by_runs_matches_the_reference_bit_for_bit() {
        let (w, h) = (157, 61);
        let mut seed = 5u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut image = HdrImage::zeros(w, h);
        for i in 0..w * h {
            let l = 10f32.powf(4.0 * noise() - 2.0) * if i % w > w / 2 { 100.0 } else { 1.0 };
            image.x[i] = 0.95 * l;
            image.y[i] = l;
            image.z[i] = 1.09 * l;
        }
        image.y[7] = f32::NAN;
        image.x[w + 3] = -1.0;
        for scotopic in [false, true] {
            if scotopic {
                image.scotopic = Some(image.y.iter().map(|&v| 0.4 * v).collect());
            }
            // Runs of up to 1.5 steps at the edges: step 32 (the largest) gives runs of
            // 48 pixels, longer than a piece of `upsample_row`.
            for step in [1usize, 2, 5, 23, MAX_GRID_STEP_PX] {
                let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
                let guide: Vec<f32> = (0..gw * gh).map(|_| 4.0 * noise() - 2.0).collect();
                let a: Vec<f32> = (0..gw * gh).map(|_| noise() - 3.0).collect();
                let b: Vec<f32> = (0..gw * gh).map(|_| 2.0 * noise()).collect();
                let grid = Grid {
                    width: gw,
                    height: gh,
                    guide_log: guide,
                    offset_log: Vec::new(),
                    offset_scotopic_log: Vec::new(),
                    pixels_per_degree: Vec::new(),
                };
                let channels: [&[f32]; 2] = [&a, &b];
                // The first plane holds the pixels' log luminances, as the block means
                // leave them.
                let mut got = vec![vec![0f32; w * h]; channels.len()];
                block_log_means(&image, step, gw, gh, &mut got[0]);
                upsample(w, &grid, step, &channels, &mut got);
                let want = reference_upsample(&image, &grid, step, &channels);
                for (g, r) in got.iter().zip(&want) {
                    assert!(
                        g.iter().zip(r).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "step {step}, scotopic {scotopic}"
                    );
                }
            }
        }
    }

    #[test]
    fn fast_log10_is_accurate() {
        let mut worst = 0f64;
        let mut v = 1e-8f32;
        while v < 1e8 {
            let err = (f64::from(fast_log10(v)) - f64::from(v).log10()).abs();
            worst = worst.max(err);
            v *= 1.0137;
        }
        assert!(worst < 3e-6, "{worst}");
        assert_eq!(fast_log10(1.0), 0.0);
    }

    #[test]
    fn pixel_sizes_follow_the_projection() {
        // Perspective 90°: at the centre (W/2)/tan(45°)·π/180 pixels per degree.
        let v = View::perspective(90.0, 1000, 1000);
        let centre = pixel_size_deg(&v, 1000, 1000, 500.0, 500.0);
        let want = 1.0 / (500.0 * std::f64::consts::PI / 180.0);
        assert!((centre / want - 1.0).abs() < 1e-6, "{centre} {want}");
        // At the corner of a perspective view pixels subtend less (cos² θ radially, cos θ
        // tangentially, θ = atan(√2)).
        let corner = pixel_size_deg(&v, 1000, 1000, 0.5, 0.5);
        let c = (1.0 / 3f64.sqrt()).acos().cos();
        assert!(
            (corner / centre - c.powf(1.5)).abs() < 2e-3,
            "{}",
            corner / centre
        );
        // Angular fisheye 180°: radially uniform (fov / W), tangentially sin θ / θ.
        let f = View {
            projection: Projection::AngularFisheye,
            horizontal_deg: 180.0,
            vertical_deg: 180.0,
        };
        let c = pixel_size_deg(&f, 1000, 1000, 500.0, 500.0);
        assert!((c - 0.18).abs() < 1e-6, "{c}");
        let at60 = pixel_size_deg(&f, 1000, 1000, 500.0 + 1000.0 / 3.0, 500.0);
        let theta = 60f64.to_radians();
        assert!((at60 / (0.18 * (theta.sin() / theta).sqrt()) - 1.0).abs() < 1e-3);
        // Beyond the circle of the horizontal angle the projection goes on: the corner of
        // a 16:9 angular fisheye 66.7° wide (`mixtex.hdr`'s view) is 38.2° off the axis,
        // and the corner of the 180° square one 127.2°. (Taken on the circle's rim, the
        // first corner pixel here subtended 0.75× its size, and that of the 128 × 72
        // `mixtex.hdr` 0.0018° instead of 0.50°.)
        let wide = View {
            projection: Projection::AngularFisheye,
            horizontal_deg: 1280.0 / 19.2,
            vertical_deg: 37.5,
        };
        for (view, w, h) in [(wide, 1280, 720), (f, 1000, 1000)] {
            let (u, v) = (0.5, 0.5);
            let deg_per_px = view.horizontal_deg / w as f64;
            let r = ((w as f64 / 2.0 - u).powi(2) + (h as f64 / 2.0 - v).powi(2)).sqrt();
            let theta = (r * deg_per_px).to_radians();
            let want = deg_per_px * (theta.sin() / theta).sqrt();
            let got = pixel_size_deg(&view, w, h, u, v);
            assert!(
                (got / want - 1.0).abs() < 1e-3,
                "{w}×{h} corner: {got} {want}"
            );
        }
        // A hemispherical fisheye narrower than 180° goes on to 90°: 120° across a square
        // frame, its corner is at sin θ = √2·sin 60° (beyond 1: on the 90° rim, where the
        // radial extent vanishes and the tangential one stands for both).
        let hemi = View {
            projection: Projection::HemisphericalFisheye,
            horizontal_deg: 120.0,
            vertical_deg: 120.0,
        };
        // Between the circle and the rim: at r = 1.1 half-widths along the diagonal,
        // sin θ = 1.1·sin 60°, radially d(sin θ)/cos θ, tangentially sin θ / r per pixel.
        let (w, r_rel) = (1000.0, 1.1);
        let off = r_rel * 500.0 / 2f64.sqrt();
        let got = pixel_size_deg(&hemi, 1000, 1000, 500.0 + off, 500.0 + off);
        let per_px = 60f64.to_radians().sin() / (w / 2.0);
        let s = r_rel * 60f64.to_radians().sin();
        let radial = per_px / (1.0 - s * s).sqrt();
        let tangential = s / (r_rel * w / 2.0);
        let want = (radial * tangential).sqrt().to_degrees();
        assert!(
            (got / want - 1.0).abs() < 1e-3,
            "hemispherical: {got} {want}"
        );
    }

    /// The grid's pixels per degree, a quarter computed and mirrored where the grid is
    /// symmetric, are every sample's own ([`pixel_size_deg`] at its block's centre) bit
    /// for bit: every projection, odd and even sides, steps that divide the sides and
    /// steps that do not, wide and narrow views.
    #[test]
    fn mirrored_pixels_per_degree_are_each_samples_own() {
        use Projection::*;
        let projections = [
            Perspective,
            AngularFisheye,
            HemisphericalFisheye,
            Cylindrical,
            Planisphere,
            Parallel,
        ];
        let shapes = [
            (64, 48, 1),
            (63, 47, 1),
            (64, 48, 4),
            (66, 50, 4),
            (65, 45, 5),
            (20, 20, 3),
            (1, 1, 1),
            (2, 7, 2),
        ];
        let mut varying = 0;
        for projection in projections {
            for (fov_h, fov_v) in [(170.0, 120.0), (30.0, 20.0), (360.0, 360.0)] {
                for (w, h, step) in shapes {
                    let view = View {
                        projection,
                        horizontal_deg: fov_h,
                        vertical_deg: fov_v,
                    };
                    let got = pixels_per_degree_grid(&view, w, h, step);
                    let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
                    assert_eq!(got.len(), gw * gh);
                    let centre = |g: usize, n: usize| {
                        ((g * step) as f64 + (step.min(n - g * step)) as f64 / 2.0).min(n as f64)
                    };
                    for gy in 0..gh {
                        for gx in 0..gw {
                            let size = pixel_size_deg(&view, w, h, centre(gx, w), centre(gy, h));
                            let want = (1.0 / size) as f32;
                            let got = got[gy * gw + gx];
                            assert_eq!(
                                got.to_bits(),
                                want.to_bits(),
                                "{projection:?} {fov_h}° {w}×{h} step {step} ({gx}, {gy}): \
                                 {got} against {want}"
                            );
                        }
                    }
                    // Not a constant scale, which any mirroring would give right.
                    if gw > 2 && got[0] != got[gw / 2] {
                        varying += 1;
                    }
                }
            }
        }
        assert!(varying > 20, "{varying} grids with a varying scale");
    }

    /// [`by_runs`] gives every sample `f` of its own inputs, and calls `f` once per run
    /// of samples whose two inputs repeat bit for bit: runs broken by either input alone,
    /// by a zero of the other sign and by a NaN of another payload; a NaN repeated is a
    /// run.
    #[test]
    fn by_runs_is_each_samples_own_value() {
        let nan2 = f32::from_bits(f32::NAN.to_bits() | 1);
        let a = [
            1.0,
            1.0,
            1.0,
            2.0,
            2.0,
            0.0,
            -0.0,
            f32::NAN,
            f32::NAN,
            nan2,
            3.0,
            3.0,
        ];
        let b = [5.0, 5.0, 6.0, 6.0, 6.0, 7.0, 7.0, 8.0, 8.0, 8.0, 9.0, 9.0];
        let calls = std::cell::Cell::new(0);
        let f = |x: f32, y: f32| {
            calls.set(calls.get() + 1);
            // Tells every input apart: a NaN's payload and a zero's sign included.
            f32::from_bits(x.to_bits().rotate_left(7) ^ y.to_bits())
        };
        let mut out = [0f32; 12];
        by_runs(&mut out, &a, &b, f);
        for i in 0..a.len() {
            let want = f32::from_bits(a[i].to_bits().rotate_left(7) ^ b[i].to_bits());
            assert_eq!(out[i].to_bits(), want.to_bits(), "sample {i}");
        }
        // Runs: (1,5)×2, (1,6), (2,6)×2, (0,7), (−0,7), (NaN,8)×2, (NaN',8), (3,9)×2.
        assert_eq!(calls.get(), 8);
    }

    /// The quantile by selection is the sorted order's value at the rank, for values with
    /// ties and signs, at fractions from none to all.
    #[test]
    fn high_quantile_is_the_sorted_rank() {
        let mut seed = 11u32;
        let values: Vec<f64> = (0..5001)
            .map(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                f64::from((seed >> 20) as i32 - 2048) / 16.0
            })
            .collect();
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for fraction in [0.0, 1e-4, 1e-3, 0.25, 0.5, 0.999, 1.0, 2.0] {
            let allowed = ((5001.0 * f64::min(fraction, 1.0)).floor() as usize).min(5000);
            assert_eq!(
                high_quantile(&values, fraction),
                sorted[5000 - allowed],
                "{fraction}"
            );
        }
        assert_eq!(high_quantile(&[3.0], 0.5), 3.0);
    }

    #[test]
    fn grid_steps() {
        assert_eq!(grid_step(2.0), 1);
        assert_eq!(grid_step(32.0), 8);
        assert_eq!(grid_step(f64::INFINITY), MAX_GRID_STEP_PX);
    }
}
