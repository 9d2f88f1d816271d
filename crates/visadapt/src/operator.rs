//! The whole steady-state operator: an HDR image and viewing conditions in, the display
//! image and a report of everything the model used out.
//!
//! Ferwerda et al. 1996, Sec. 4, in this order:
//!
//! 0. optionally, veiling glare ([`glare`], beyond the paper, off by
//!    default): light scattered in the eye is added to the world luminance, so that it
//!    shows in the image and raises the adaptation of the next steps ([`prepare`]);
//! 1. adaptation luminances (Sec. 4.4, [`adaptation`](crate::adaptation)): the world
//!    observer's cones adapt to half the highest visible photopic luminance, the rods to
//!    half the highest visible scotopic luminance; the display observer to half `L_dmax`;
//! 2. scale factors (Eq. 1–3, [`scale`](crate::scale)): `m_p` for the cone image,
//!    `m_s` for the rod image;
//! 3. the mesopic rod weight `k` (Eq. 6, [`mesopic`](crate::mesopic));
//! 4. per pixel, the display colour `m_p·XYZ + k·m_s·V·white` (Eq. 6: the cone image keeps
//!    its chromaticity, "the chromatic channels follow the same mapping"; the rod image is
//!    grey, the display white), converted to linear sRGB relative to `L_dmax`. Beyond the
//!    paper, the cone image is first taken from the scene's adopted white to the display
//!    white by the CAT16 von Kries transform ([`colour`](crate::colour#chromatic-adaptation-beyond-the-paper),
//!    [`ViewingConditions::white_point`]; [`WhitePoint::Off`] is the paper's behaviour); it
//!    keeps neutrals' luminance exactly and is folded into the same per-pixel matrix;
//! 5. the acuity Gaussian (Eq. 7, [`acuity`]), a separate stage on the
//!    linear display planes. Because the mapping of step 4 is affine with coefficients
//!    shared by all pixels, blurring its output equals mapping the blurred scene;
//! 6. clipping to what the display can show (see [`apply`]).
//!
//! There is no renormalisation: the output is absolute, 1.0 = `L_dmax` cd/m², so a dim
//! scene stays dim. The mapping is linear in the scene (Eq. 1), so the display value of the
//! world adaptation luminance is `m_p·L_wa` (+ rods) whatever the image.
//!
//! The split into [`prepare`] (the scene stages and the global quantities, the
//! [`Report`]) and [`apply`] (per-pixel work with a given [`Mapping`]) lets a caller drive
//! the mapping itself, e.g. from a time-varying adaptation state. [`plan`] is `prepare`
//! without the scene stages.
//!
//! With [`AdaptationMode::Local`] the stages are those of [`crate::local`]: an adaptation
//! map after step 1, and steps 2-5 per pixel at each pixel's own adaptation (the global
//! level of step 1 anchors the map). The default, [`AdaptationMode::Global`], is the
//! paper's model.

use crate::acuity::{self, AcuityFilter, AcuityThreshold};
use crate::adaptation::{
    ADAPTATION_FRACTION, BLOCK, Blocks, DEFAULT_DISPLAY_MAX_CD_M2, DEFAULT_HOT_PIXEL_FRACTION,
    highest_visible_of,
};
use crate::colour::{
    self, D65, IDENTITY, Mat3, WhitePoint, Xy, mul_mat, xyz_to_linear_srgb_matrix,
};
use crate::glare::{self, Glare, VeilReport};
use crate::local::{self, AdaptationMap, LocalAdaptation, LocalMapping, LocalReport};
use crate::mesopic::rod_weight;
use crate::scale::{photopic_scale, scotopic_scale};
use crate::scotopic::{self, EQUAL_ENERGY_SP_RATIO};
use crate::simd::Isa;
use crate::timecourse::Undershoot;
use crate::tvi::{cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};
use crate::{DisplayImage, Error, HdrImage, Result, View};
use std::borrow::Cow;

/// Horizontal field of view assumed when neither the caller nor the file gives one: 60°,
/// a common rendering camera (a project choice, reported as such).
pub const DEFAULT_FOV_DEG: f64 = 60.0;

/// Blur smaller than this (pixels) is skipped: its response at the Nyquist frequency,
/// `exp(−2π²σ²/4)`, stays above 0.99 (a project choice).
pub const MIN_BLUR_SIGMA_PX: f64 = 0.045;

/// How the scene is viewed and displayed.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewingConditions {
    /// Display maximum luminance `L_dmax`, cd/m² (default 80, paper Sec. 4.4).
    pub display_max_cd_m2: f64,
    /// Display adaptation `L_da`, cd/m²; `None` for `L_dmax/2` (paper Sec. 4.4).
    pub display_adaptation_cd_m2: Option<f64>,
    /// World (cone) adaptation `L_wa`, cd/m²; `None` for half the highest visible
    /// photopic luminance (paper Sec. 4.4).
    pub world_adaptation_cd_m2: Option<f64>,
    /// World rod adaptation, scotopic cd/m²; `None` for half the highest visible scotopic
    /// luminance, or, when only `world_adaptation_cd_m2` is given, that value times the
    /// image's scotopic/photopic ratio of highest visible luminances.
    pub world_adaptation_scotopic_cd_m2: Option<f64>,
    /// Fraction of pixels allowed above the "highest visible" luminance
    /// (default [`DEFAULT_HOT_PIXEL_FRACTION`]).
    pub hot_pixel_fraction: f64,
    /// Apply the acuity blur (Eq. 7).
    pub acuity: bool,
    /// How Eq. 7's threshold contrast combines the rods and the cones: default
    /// [`AcuityThreshold::Pooled`], the visibility metric's (a full-contrast grating at the
    /// cutoff scores 1 JND); [`AcuityThreshold::Envelope`] for the paper's
    /// (see [`acuity`](crate::acuity#the-threshold-contrast-c-beyond-the-paper-one-definition-with-the-jnd-metric)).
    pub acuity_threshold: AcuityThreshold,
    /// The view, overriding the file's; `None` to use the file's or a
    /// [`DEFAULT_FOV_DEG`] perspective view.
    pub view: Option<View>,
    /// Veiling glare in the observer's eye ([`glare`]); `None` (the default,
    /// the paper's operator) for none.
    pub glare: Option<Glare>,
    /// The scene white the cone image is adapted from to the display's D65 (CAT16, see
    /// [`colour`](crate::colour#chromatic-adaptation-beyond-the-paper)); default
    /// [`WhitePoint::Auto`], the file's; [`WhitePoint::Off`] for the paper's behaviour.
    pub white_point: WhitePoint,
    /// For time courses ([`sequence::render`](crate::sequence::render), a video, the
    /// viewer): whether the Eq. 8–9 mapping follows a threshold below its steady state
    /// (Baker's dip). Default [`Undershoot::Clamped`]: never more contrast than the
    /// steady state, no shadows clipped; [`Undershoot::InMapping`] is the paper's rule (see
    /// [`timecourse`](crate::timecourse#bakers-dip-is-not-a-contrast-boost-undershoot-beyond-the-paper)).
    /// The static operator does not use it.
    pub undershoot: Undershoot,
    /// One adaptation level for the scene (the paper's, the default) or one per pixel.
    pub adaptation: AdaptationMode,
}

/// Where the world observer's adaptation comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AdaptationMode {
    /// One level for the whole scene: half the highest visible luminance (paper Sec. 4.4).
    #[default]
    Global,
    /// Each pixel adapted to its own neighbourhood ([`crate::local`]).
    Local(LocalAdaptation),
}

impl Default for ViewingConditions {
    fn default() -> Self {
        ViewingConditions {
            display_max_cd_m2: DEFAULT_DISPLAY_MAX_CD_M2,
            display_adaptation_cd_m2: None,
            world_adaptation_cd_m2: None,
            world_adaptation_scotopic_cd_m2: None,
            hot_pixel_fraction: DEFAULT_HOT_PIXEL_FRACTION,
            acuity: true,
            acuity_threshold: AcuityThreshold::Pooled,
            view: None,
            adaptation: AdaptationMode::Global,
            white_point: WhitePoint::Auto,
            glare: None,
            undershoot: Undershoot::Clamped,
        }
    }
}

impl ViewingConditions {
    /// Check every parameter's domain.
    pub fn validate(&self) -> Result<()> {
        let positive = |name, v: f64| crate::check_luminance(name, v).map(|_| ());
        positive("display-max", self.display_max_cd_m2)?;
        if let Some(v) = self.display_adaptation_cd_m2 {
            positive("display-adaptation", v)?;
        }
        if let Some(v) = self.world_adaptation_cd_m2 {
            positive("world-adaptation", v)?;
        }
        if let Some(v) = self.world_adaptation_scotopic_cd_m2 {
            positive("scotopic-adaptation", v)?;
        }
        if !(0.0..1.0).contains(&self.hot_pixel_fraction) {
            return Err(Error::invalid(
                "hot-pixel-fraction",
                self.hot_pixel_fraction,
                "must be in [0, 1)",
            ));
        }
        if let WhitePoint::Chromaticity(w) = self.white_point
            && !colour::is_valid_white(w)
        {
            return Err(Error::invalid(
                "white-point",
                format!("{},{}", w[0], w[1]),
                "must be a chromaticity x,y with x > 0, y > 0 and x + y < 1",
            ));
        }
        if let Some(v) = &self.view
            && !(v.horizontal_deg.is_finite()
                && v.horizontal_deg > 0.0
                && v.horizontal_deg <= 360.0)
        {
            return Err(Error::invalid(
                "fov",
                v.horizontal_deg,
                "must be in (0, 360] degrees",
            ));
        }
        // A planar perspective projection cannot span 180° or more (tan(fov/2) is
        // infinite): refuse it rather than drop the acuity blur without a word.
        if let Some(v) = &self.view
            && v.projection == crate::Projection::Perspective
            && v.horizontal_deg >= 180.0
        {
            return Err(Error::invalid(
                "fov",
                v.horizontal_deg,
                "a perspective view spans less than 180 degrees",
            ));
        }
        if let Some(g) = &self.glare {
            g.validate()?;
        }
        if let AdaptationMode::Local(l) = &self.adaptation {
            l.validate()?;
        }
        Ok(())
    }
}

/// Where a value the operator used came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Given by the caller.
    Caller,
    /// Read from the image file.
    File,
    /// Computed by the model from the image.
    Image,
    /// The library default.
    Default,
}

/// The linear mapping from world to display, everything [`apply`] needs.
///
/// `display = photopic_scale·XYZ + photopic_offset + rod_weight·(scotopic_scale·V +
/// scotopic_offset)·white`, in cd/m², then divided by `display_max_cd_m2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mapping {
    /// `m_p` (Eq. 3 with Eq. 4), display cd/m² per world cd/m².
    pub photopic_scale: f64,
    /// `m_s` (Eq. 3 with Eq. 5 world, Eq. 4 display), display cd/m² per scotopic cd/m².
    pub scotopic_scale: f64,
    /// `k` (Eq. 6).
    pub rod_weight: f64,
    /// Eq. 8 offset `b` of the cone image, display cd/m² (0 in steady state).
    pub photopic_offset_cd_m2: f64,
    /// Eq. 8 offset `b` of the rod image, display cd/m² (0 in steady state).
    pub scotopic_offset_cd_m2: f64,
    /// `L_dmax`, cd/m².
    pub display_max_cd_m2: f64,
    /// Standard deviation of the acuity Gaussian in pixels; 0 for no blur.
    pub blur_sigma_px: f64,
    /// The chromatic adaptation applied to the cone image's XYZ before it goes to the
    /// display (CAT16 from the scene white to D65; [`IDENTITY`] for none).
    pub chromatic_adaptation: Mat3,
}

/// Everything the operator used, with units.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Width of the image, pixels.
    pub width: usize,
    /// Height of the image, pixels.
    pub height: usize,
    /// Highest visible photopic luminance, cd/m² (the quantile of Sec. 4.4).
    pub highest_visible_cd_m2: f64,
    /// Highest visible scotopic luminance, scotopic cd/m².
    pub highest_visible_scotopic_cd_m2: f64,
    /// Whether the scotopic luminance came from the file or the XYZ estimate.
    pub scotopic_source: Source,
    /// World (cone) adaptation `L_wa`, cd/m².
    pub world_adaptation_cd_m2: f64,
    /// Where `world_adaptation_cd_m2` came from.
    pub world_adaptation_source: Source,
    /// World rod adaptation, scotopic cd/m².
    pub world_adaptation_scotopic_cd_m2: f64,
    /// Display adaptation `L_da`, cd/m².
    pub display_adaptation_cd_m2: f64,
    /// Cone threshold at the world adaptation (Eq. 4), cd/m².
    pub cone_threshold_cd_m2: f64,
    /// Rod threshold at the world rod adaptation (Eq. 5), scotopic cd/m².
    pub rod_threshold_scotopic_cd_m2: f64,
    /// The mapping applied.
    pub mapping: Mapping,
    /// The acuity filter of Eq. 7 at the world adaptation (computed even if not applied).
    pub acuity: AcuityFilter,
    /// Whether the acuity blur was requested.
    pub acuity_applied: bool,
    /// The view used to turn degrees into pixels.
    pub view: View,
    /// Where the view came from.
    pub view_source: Source,
    /// Pixels per degree at the image centre; `None` for a view without angles.
    pub pixels_per_degree: Option<f64>,
    /// With local adaptation, the spread of the adaptation map (set by [`map`]; `None`
    /// from [`plan`], which computes the global quantities only).
    pub local: Option<LocalReport>,
    /// The scene white the cone image was adapted from to D65; `None` when chromatic
    /// adaptation is off ([`WhitePoint::Off`]).
    pub scene_white: Option<Xy>,
    /// Where `scene_white` came from: the caller, the file, or the default (D65, no
    /// change, for an image that declares no white).
    pub scene_white_source: Source,
    /// What the glare stage did, when it ran ([`prepare`]).
    pub glare: Option<GlareEffect>,
}

/// The glare stage's effect on the operator.
#[derive(Debug, Clone, PartialEq)]
pub struct GlareEffect {
    /// The veil itself: its size at the fixation point (image centre), the scattered
    /// fraction, the grid.
    pub veil: VeilReport,
    /// World (cone) adaptation the scene would give without glare, cd/m² (the report's
    /// `world_adaptation_cd_m2` is with it).
    pub world_adaptation_without_glare_cd_m2: f64,
    /// World rod adaptation without glare, scotopic cd/m².
    pub world_adaptation_without_glare_scotopic_cd_m2: f64,
}

impl GlareEffect {
    /// The cone adaptation level with glare over the level without it (1 when the
    /// adaptation was given by the caller). Above 1 when the veil lifts a dark scene;
    /// below 1 when the few brightest pixels that set Sec. 4.4's "half the highest visible
    /// luminance" lose part of their light to their own halo (`GoldenGate.exr`: 0.861).
    pub fn adaptation_ratio(&self, report: &Report) -> f64 {
        report.world_adaptation_cd_m2 / self.world_adaptation_without_glare_cd_m2
    }
}

impl Report {
    /// The acuity as a Snellen fraction, e.g. "20/40".
    pub fn snellen(&self) -> String {
        acuity::snellen(self.acuity.cutoff_cycles_per_degree)
    }

    /// Display luminance of a neutral at the highest visible luminance, cd/m²: `m_p·L +
    /// b_p + k·(m_s·L_s + b_s)`. Above `display_max_cd_m2` the scene's whites clip. In the
    /// cone Weber range (`L_wa` ≥ 10^1.9 cd/m²) on the default 80 cd/m² display the rules
    /// of Sec. 4.4 put `2·L_wa` at `t_p(40)·10^1.255` = 94.1 cd/m²: the display observer at
    /// 40 cd/m² has a higher threshold contrast (Eq. 4's middle branch, 6.5 %) than the
    /// world observer (Weber, 5.6 %), so keeping the world's JNDs needs more range.
    pub fn highest_visible_display_cd_m2(&self) -> f64 {
        let m = &self.mapping;
        m.photopic_scale * self.highest_visible_cd_m2
            + m.photopic_offset_cd_m2
            + m.rod_weight
                * (m.scotopic_scale * self.highest_visible_scotopic_cd_m2 + m.scotopic_offset_cd_m2)
    }

    /// The smallest display maximum `L_dmax` (cd/m², adapted to `L_dmax/2` as in Sec. 4.4)
    /// that shows the highest visible luminance of this report's scene without clipping,
    /// with the same world adaptation; `None` if no display can (the display value of the
    /// highest visible luminance grows as fast as `L_dmax` once `L_dmax/2` is in Eq. 4's
    /// Weber range) or if this one already does.
    pub fn display_max_to_show_highest_visible(&self) -> Option<f64> {
        let m = &self.mapping;
        let shown = self.highest_visible_display_cd_m2();
        if shown.is_nan() || shown <= m.display_max_cd_m2 * (1.0 + 1e-9) {
            return None;
        }
        // Display value per unit of t_p(L_da): hv/t_p(L_wa) + k·hv_s/t_s(L_wa,s).
        let per_threshold = self.highest_visible_cd_m2 / self.cone_threshold_cd_m2
            + m.rod_weight * self.highest_visible_scotopic_cd_m2
                / self.rod_threshold_scotopic_cd_m2;
        // (With a relative slack of 1e-9: in Eq. 4's Weber range the value is exactly `d`.)
        let fits = |d: f64| {
            cone_threshold_cd_m2(ADAPTATION_FRACTION * d) * per_threshold <= d * (1.0 + 1e-9)
        };
        let (mut lo, mut hi) = (m.display_max_cd_m2, crate::MAX_LUMINANCE_CD_M2);
        if !fits(hi) {
            return None;
        }
        // t_p(D/2)/D never increases with D (Eq. 4's slope is at most 1): bisect in log D.
        for _ in 0..200 {
            let mid = (lo * hi).sqrt();
            if fits(mid) { hi = mid } else { lo = mid }
        }
        Some(hi)
    }
}

/// Counts of pixels that needed a rule applied.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PixelStats {
    /// Pixels with a NaN or infinite channel: shown black.
    pub non_finite: usize,
    /// Pixels with a negative channel (and otherwise finite): negative channels read as 0.
    pub negative: usize,
    /// Pixels brighter than the display can show, scaled down (see [`apply`]).
    pub clipped: usize,
    /// Pixels so bright (more than [`MAX_DISPLAY_RELATIVE`] times the display maximum)
    /// that they were scaled down, chromaticity kept, before the mapping and the blur, so
    /// that the f32 arithmetic stays finite. Also counted in `clipped`.
    pub saturated: usize,
}

impl PixelStats {
    /// The counts of both.
    fn add(self, other: PixelStats) -> PixelStats {
        PixelStats {
            non_finite: self.non_finite + other.non_finite,
            negative: self.negative + other.negative,
            clipped: self.clipped + other.clipped,
            saturated: self.saturated + other.saturated,
        }
    }
}

/// Largest display-relative value (1 = `L_dmax`) a pixel may have before the blur: pixels
/// beyond it are scaled down to it, chromaticity kept (counted in
/// [`PixelStats::saturated`]). Our bound: 1e30 leaves 3e8 of headroom below `f32::MAX`
/// for the blur's intermediate sums, and such a pixel is white after clipping either way;
/// its blurred light reaches only where the acuity Gaussian's weight exceeds 1e-30.
pub const MAX_DISPLAY_RELATIVE: f32 = 1e30;

/// The operator's result.
#[derive(Debug, Clone)]
pub struct Output {
    /// The display image.
    pub image: DisplayImage,
    /// What the model used.
    pub report: Report,
    /// Pixels that needed a rule applied.
    pub stats: PixelStats,
}

/// Run the whole operator: [`plan`], then [`apply`].
///
/// ```
/// use visadapt::{HdrImage, operator::{map, ViewingConditions}};
/// // A grey scene (D65) with a white patch at 0.1 cd/m²: a moonlit room.
/// let mut scene = HdrImage::zeros(64, 64);
/// for i in 0..scene.len() {
///     let l = if i % 64 < 32 { 0.1 } else { 0.02 };
///     scene.x[i] = 0.9505 * l; scene.y[i] = l; scene.z[i] = 1.089 * l;
/// }
/// let out = map(&scene, &ViewingConditions::default())?;
/// assert!((out.report.world_adaptation_cd_m2 - 0.05).abs() < 1e-6);
/// // Adapted to 0.05 cd/m² (0.12 scotopic cd/m²): low mesopic, the rods dominate.
/// assert!(out.report.mapping.rod_weight > 0.8);
/// assert!(out.image.g[0] < 0.5);                // and the display shows a dim scene
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn map(image: &HdrImage, conditions: &ViewingConditions) -> Result<Output> {
    let (scene, mut report) = prepare(image, conditions)?;
    let (display, stats) = match conditions.adaptation {
        AdaptationMode::Global => apply(&scene, &report.mapping),
        AdaptationMode::Local(options) => {
            let map = local_map(&scene, &report, conditions, &options)?;
            let mapping = LocalMapping::steady_state(&map, &report, options.rod_saturation);
            let mut out = DisplayImage::default();
            let stats = local::apply_into(&scene, &map, &mapping, &mut out);
            report.local = Some(LocalReport::of(&map, options.rod_saturation));
            (out, stats)
        }
    };
    Ok(Output {
        image: display,
        report,
        stats,
    })
}

/// [`map`], consuming the image: the display planes are written over its X, Y, Z planes
/// ([`apply_owned`], [`local::apply_owned`]) and the glare stage adds its veil in place
/// ([`prepare_owned`]), so that the working set is one image instead of two (12 bytes per
/// pixel, 16 with a scotopic plane, instead of 24–28; local adaptation adds its map, 12;
/// see the README's "Limits and safety"). The result is the same as [`map`]'s, bit for
/// bit.
pub fn map_owned(image: HdrImage, conditions: &ViewingConditions) -> Result<Output> {
    let (scene, mut report) = prepare_owned(image, conditions)?;
    let (display, stats) = match conditions.adaptation {
        AdaptationMode::Global => apply_owned(scene, &report.mapping),
        AdaptationMode::Local(options) => {
            let map = local_map(&scene, &report, conditions, &options)?;
            let mapping = LocalMapping::steady_state(&map, &report, options.rod_saturation);
            report.local = Some(LocalReport::of(&map, options.rod_saturation));
            local::apply_owned(scene, &map, &mapping)
        }
    };
    Ok(Output {
        image: display,
        report,
        stats,
    })
}

/// The frame stage of a time course: the Eq. 8-9 mapping of the observer's `state` applied
/// to `image` (whose [`plan`] under `conditions` is `report`), into `out`. With
/// [`AdaptationMode::Global`] this is `state.mapping(report)` and [`apply_into`]; with
/// local adaptation the adaptation map of `image` is computed and every pixel mapped at
/// its own level with the state's excess ([`LocalMapping::for_time_course`]: a global
/// state plus local offsets). Returns the global mapping (the one reports show) and the
/// pixel counts.
pub fn apply_state_into(
    image: &HdrImage,
    report: &Report,
    state: &crate::timecourse::Adaptation,
    conditions: &ViewingConditions,
    out: &mut DisplayImage,
) -> Result<(Mapping, PixelStats)> {
    let mut map = AdaptationMap::default();
    apply_state_reusing(image, report, state, conditions, &mut map, out)
}

/// [`apply_state_into`], with the adaptation map of local adaptation computed into `map`
/// ([`local_map_into`]), whose planes a stream of frames reuses (left as it was with
/// [`AdaptationMode::Global`]). The same result, bit for bit.
pub fn apply_state_reusing(
    image: &HdrImage,
    report: &Report,
    state: &crate::timecourse::Adaptation,
    conditions: &ViewingConditions,
    map: &mut AdaptationMap,
    out: &mut DisplayImage,
) -> Result<(Mapping, PixelStats)> {
    if let AdaptationMode::Local(options) = conditions.adaptation {
        local_map_into(image, report, conditions, &options, map)?;
    }
    apply_state_with_map(image, report, state, conditions, map, out)
}

/// [`apply_state_into`] with local adaptation's map given: `map` must be the adaptation
/// map of `image` under `report` and `conditions` ([`local_map`], [`local_map_into`]),
/// e.g. one map for the many frames of one image seen at different states
/// ([`crate::sequence`]). With [`AdaptationMode::Global`] it is not read. Refuses a map
/// of another size than the image.
pub fn apply_state_with_map(
    image: &HdrImage,
    report: &Report,
    state: &crate::timecourse::Adaptation,
    conditions: &ViewingConditions,
    map: &AdaptationMap,
    out: &mut DisplayImage,
) -> Result<(Mapping, PixelStats)> {
    let mapping = state.mapping(report);
    let stats = match conditions.adaptation {
        AdaptationMode::Global => apply_into(image, &mapping, out),
        AdaptationMode::Local(options) => {
            if (map.width, map.height) != (image.width, image.height) {
                return Err(Error::invalid(
                    "adaptation map",
                    format!("{}x{}", map.width, map.height),
                    format!(
                        "must be of the image's size, {}x{}",
                        image.width, image.height
                    ),
                ));
            }
            let local = LocalMapping::for_time_course(map, state, report, options.rod_saturation);
            local::apply_into(image, map, &local, out)
        }
    };
    Ok((mapping, stats))
}

/// The adaptation map of `image` for local adaptation `options`, anchored to its [`plan`]
/// `report` under `conditions`.
pub fn local_map(
    image: &HdrImage,
    report: &Report,
    conditions: &ViewingConditions,
    options: &LocalAdaptation,
) -> Result<AdaptationMap> {
    let mut map = AdaptationMap::default();
    local_map_into(image, report, conditions, options, &mut map)?;
    Ok(map)
}

/// [`local_map`] into `map`, reusing its planes ([`AdaptationMap::compute_into`]): for a
/// stream of frames. On an error `map` is left as it was.
pub fn local_map_into(
    image: &HdrImage,
    report: &Report,
    conditions: &ViewingConditions,
    options: &LocalAdaptation,
    map: &mut AdaptationMap,
) -> Result<()> {
    map.compute_into(
        image,
        report,
        options.radius_deg,
        conditions.hot_pixel_fraction,
    )
}

/// The operator's stages before the mapping: the scene stages the conditions switch on
/// (glare), then [`plan`] on their result. Returns the scene to [`apply`] the mapping to
/// (the input itself when no scene stage is on) and the report.
///
/// ```
/// use visadapt::{HdrImage, glare::Glare, operator::{prepare, ViewingConditions}};
/// // A night scene: 0.01 cd/m² everywhere and one headlight of 2e6 cd/m².
/// let (w, h) = (320, 180);
/// let mut scene = HdrImage::zeros(w, h);
/// for i in 0..w * h {
///     let l = if i == 90 * w + 200 { 2e6 } else { 0.01 };
///     scene.x[i] = 0.9505 * l; scene.y[i] = l; scene.z[i] = 1.089 * l;
/// }
/// let glare = ViewingConditions { glare: Some(Glare::default()), ..Default::default() };
/// let (retina, report) = prepare(&scene, &glare)?;
/// let effect = report.glare.as_ref().unwrap();
/// // The veil lifts the dark field near the light and raises the adaptation level.
/// assert!(retina.y[90 * w + 180] > 10.0 * scene.y[90 * w + 180]);
/// assert!(effect.adaptation_ratio(&report) > 1.5);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn prepare<'a>(
    image: &'a HdrImage,
    conditions: &ViewingConditions,
) -> Result<(Cow<'a, HdrImage>, Report)> {
    let Some(g) = &conditions.glare else {
        return Ok((Cow::Borrowed(image), plan(image, conditions)?));
    };
    let without = plan(image, conditions)?;
    let (retina, veil) = glare::apply(image, &without.view, g)?;
    let report = with_glare(plan(&retina, conditions)?, &without, veil);
    Ok((Cow::Owned(retina), report))
}

/// [`prepare`] for frames of one size and view (a video, the viewer's plans): the
/// scene stages keep what they can reuse from frame to frame in `workspace` (the glare
/// stage's looks, kernel and buffers, and the scene it returns), with the same results
/// bit for bit. Returns the scene to apply the mapping to (the input itself when no
/// scene stage is on) and the report.
///
/// ```
/// use visadapt::glare::{Glare, Workspace};
/// use visadapt::operator::{ViewingConditions, prepare, prepare_reusing};
/// use visadapt::HdrImage;
/// let (w, h) = (160, 90);
/// let conditions = ViewingConditions { glare: Some(Glare::default()), ..Default::default() };
/// let mut workspace = Workspace::new();
/// for level in [0.01, 0.02] {
///     let mut scene = HdrImage::zeros(w, h);
///     for i in 0..w * h {
///         let l = if i == 45 * w + 100 { 2e6 } else { level };
///         scene.x[i] = 0.9505 * l; scene.y[i] = l; scene.z[i] = 1.089 * l;
///     }
///     let (retina, report) = prepare_reusing(&scene, &conditions, &mut workspace)?;
///     let (fresh, fresh_report) = prepare(&scene, &conditions)?;
///     assert!(retina.y == fresh.y);
///     assert_eq!(report.world_adaptation_cd_m2, fresh_report.world_adaptation_cd_m2);
/// }
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn prepare_reusing<'a>(
    image: &'a HdrImage,
    conditions: &ViewingConditions,
    workspace: &'a mut glare::Workspace,
) -> Result<(&'a HdrImage, Report)> {
    let Some(g) = &conditions.glare else {
        return Ok((image, plan(image, conditions)?));
    };
    let without = plan(image, conditions)?;
    let (retina, veil) = workspace.apply(image, &without.view, g)?;
    let report = with_glare(plan(retina, conditions)?, &without, veil);
    Ok((retina, report))
}

/// [`prepare`], consuming the image: the glare stage adds its veil over the image's own
/// planes ([`glare::apply_in_place`]) instead of making a second image. Returns the scene
/// to apply the mapping to and the report, the same as [`prepare`]'s.
pub fn prepare_owned(
    mut image: HdrImage,
    conditions: &ViewingConditions,
) -> Result<(HdrImage, Report)> {
    let Some(g) = &conditions.glare else {
        let report = plan(&image, conditions)?;
        return Ok((image, report));
    };
    let without = plan(&image, conditions)?;
    let veil = glare::apply_in_place(&mut image, &without.view, g)?;
    let report = with_glare(plan(&image, conditions)?, &without, veil);
    Ok((image, report))
}

/// The photopic luminance `Y` (the image's own plane, not copied) and the scotopic
/// luminance derived from `X, Y, Z`, for [`highest_visible_of`].
struct LuminanceOfXyz<'a> {
    x: &'a [f32],
    y: &'a [f32],
    z: &'a [f32],
}

impl Blocks<2> for LuminanceOfXyz<'_> {
    #[inline(always)]
    fn block<'s>(
        &'s self,
        start: usize,
        len: usize,
        scratch: &'s mut [[f32; BLOCK]; 2],
    ) -> [&'s [f32]; 2] {
        let end = start + len;
        let (x, y, z) = (
            &self.x[start..end],
            &self.y[start..end],
            &self.z[start..end],
        );
        let s = &mut scratch[1][..len];
        for (o, ((x, y), z)) in s.iter_mut().zip(x.iter().zip(y).zip(z)) {
            *o = scotopic::from_xyz(*x, *y, *z);
        }
        [y, s]
    }
}

/// The report of the veiled scene `report`, completed from the report `without` glare.
fn with_glare(mut report: Report, without: &Report, veil: VeilReport) -> Report {
    // The glare stage writes a scotopic plane; where it came from is the input's business.
    report.scotopic_source = without.scotopic_source;
    report.view_source = without.view_source;
    report.glare = Some(GlareEffect {
        veil,
        world_adaptation_without_glare_cd_m2: without.world_adaptation_cd_m2,
        world_adaptation_without_glare_scotopic_cd_m2: without.world_adaptation_scotopic_cd_m2,
    });
    report
}

/// Compute the global quantities of the model for an image: adaptation levels, scale
/// factors, `k`, acuity and blur size. This does not run the scene stages (glare): see
/// [`prepare`].
pub fn plan(image: &HdrImage, conditions: &ViewingConditions) -> Result<Report> {
    image.check_consistent()?;
    conditions.validate()?;
    let fraction = conditions.hot_pixel_fraction;
    let (x, y, z) = (&image.x, &image.y, &image.z);
    let (hv, hv_s, scotopic_source) = match &image.scotopic {
        Some(s) => {
            let [hv, hv_s] = highest_visible_of(image.len(), [&y[..], &s[..]], fraction);
            (hv as f64, hv_s as f64, Source::File)
        }
        None => {
            let fill = LuminanceOfXyz { x, y, z };
            let [hv, hv_s] = highest_visible_of(image.len(), fill, fraction);
            (hv as f64, hv_s as f64, Source::Image)
        }
    };
    let (lwa, lwa_source) = match conditions.world_adaptation_cd_m2 {
        Some(l) => (l, Source::Caller),
        None => (ADAPTATION_FRACTION * hv, Source::Image),
    };
    let lwa_s = match (
        conditions.world_adaptation_scotopic_cd_m2,
        conditions.world_adaptation_cd_m2,
    ) {
        (Some(s), _) => s,
        (None, Some(l)) => {
            let ratio = if hv > 0.0 && hv_s > 0.0 {
                hv_s / hv
            } else {
                EQUAL_ENERGY_SP_RATIO
            };
            l * ratio
        }
        (None, None) => ADAPTATION_FRACTION * hv_s,
    };
    let lda = conditions
        .display_adaptation_cd_m2
        .unwrap_or(ADAPTATION_FRACTION * conditions.display_max_cd_m2);

    let (view, view_source) = match (&conditions.view, &image.view) {
        (Some(v), _) => (*v, Source::Caller),
        (None, Some(v)) => (*v, Source::File),
        (None, None) => (
            View::perspective(DEFAULT_FOV_DEG, image.width, image.height),
            Source::Default,
        ),
    };
    let ppd = view.pixels_per_degree(image.width);
    let (scene_white, scene_white_source) = match (conditions.white_point, image.adopted_white) {
        (WhitePoint::Off, _) => (None, Source::Caller),
        (WhitePoint::Chromaticity(w), _) => (Some(w), Source::Caller),
        (WhitePoint::Auto, Some(w)) => (Some(w), Source::File),
        (WhitePoint::Auto, None) => (Some(D65), Source::Default),
    };
    let chromatic_adaptation = match scene_white {
        Some(w) => colour::cat16(w, D65).ok_or_else(|| {
            Error::invalid(
                "white-point",
                format!("{},{}", w[0], w[1]),
                "is not a usable white chromaticity",
            )
        })?,
        None => IDENTITY,
    };
    let acuity = AcuityFilter::with_rule(lwa, lwa_s, conditions.acuity_threshold);
    let blur_sigma_px = match (conditions.acuity, ppd) {
        (true, Some(ppd)) => {
            // The Gaussian cannot usefully be wider than the image itself.
            let s = (acuity.sigma_deg * ppd).min(image.width.max(image.height) as f64);
            if s >= MIN_BLUR_SIGMA_PX { s } else { 0.0 }
        }
        _ => 0.0,
    };
    Ok(Report {
        width: image.width,
        height: image.height,
        highest_visible_cd_m2: hv,
        highest_visible_scotopic_cd_m2: hv_s,
        scotopic_source,
        world_adaptation_cd_m2: lwa,
        world_adaptation_source: lwa_source,
        world_adaptation_scotopic_cd_m2: lwa_s,
        display_adaptation_cd_m2: lda,
        cone_threshold_cd_m2: cone_threshold_cd_m2(lwa),
        rod_threshold_scotopic_cd_m2: rod_threshold_scotopic_cd_m2(lwa_s),
        mapping: Mapping {
            photopic_scale: photopic_scale(lwa, lda),
            scotopic_scale: scotopic_scale(lwa_s, lda),
            rod_weight: rod_weight(lwa_s),
            photopic_offset_cd_m2: 0.0,
            scotopic_offset_cd_m2: 0.0,
            display_max_cd_m2: conditions.display_max_cd_m2,
            blur_sigma_px,
            chromatic_adaptation,
        },
        acuity,
        acuity_applied: conditions.acuity,
        view,
        view_source,
        pixels_per_degree: ppd,
        local: None,
        glare: None,
        scene_white,
        scene_white_source,
    })
}

/// The rows of the cone image's matrix for `mapping` at a photopic scale `m_p`: linear sRGB
/// from XYZ after the mapping's chromatic adaptation, times `m_p / L_dmax`, as `f32`
/// (bounded by [`MAX_DISPLAY_RELATIVE`]). The one place the cone matrix is built, for the
/// global operator and for the per-pixel tables of [`crate::local`].
pub(crate) fn cone_rows(mapping: &Mapping, photopic_scale: f64) -> [[f32; 3]; 3] {
    let xyz2rgb = mul_mat(&xyz_to_linear_srgb_matrix(), &mapping.chromatic_adaptation);
    let s = photopic_scale / mapping.display_max_cd_m2;
    let bound = f64::from(MAX_DISPLAY_RELATIVE);
    xyz2rgb.map(|row| row.map(|v| (v * s).clamp(-bound, bound) as f32))
}

/// Per-pixel coefficients of the mapping, display-relative.
#[derive(Clone, Copy)]
struct Coefficients {
    /// Rows: linear sRGB from XYZ after the chromatic adaptation, times `m_p / L_dmax`.
    cone: [[f32; 3]; 3],
    /// `k·m_s / L_dmax`, added equally to R, G, B (grey of the display white).
    rod: f32,
    /// `(b_p + k·b_s) / L_dmax`, added equally to R, G, B.
    offset: f32,
    /// Largest input channel value (cd/m²) whose mapped value stays within
    /// [`MAX_DISPLAY_RELATIVE`]: brighter pixels are scaled down to it first.
    max_input: f32,
}

impl Coefficients {
    fn new(m: &Mapping) -> Self {
        let cone = cone_rows(m, m.photopic_scale);
        let bound = f64::from(MAX_DISPLAY_RELATIVE);
        let clamp = |v: f64| v.clamp(-bound, bound);
        let rod = clamp(m.rod_weight * m.scotopic_scale / m.display_max_cd_m2);
        let offset = clamp(
            (m.photopic_offset_cd_m2 + m.rod_weight * m.scotopic_offset_cd_m2)
                / m.display_max_cd_m2,
        );
        // The largest gain from a channel to an output: a row's absolute sum plus the rod
        // coefficient (the scotopic estimate is at most about 2.3 Y + X + Z).
        let gain = cone
            .iter()
            .map(|row| row.iter().map(|v| f64::from(v.abs())).sum::<f64>())
            .fold(0.0, f64::max)
            + 4.0 * rod.abs();
        let max_input = max_input_for_gain(gain);
        Coefficients {
            cone,
            rod: rod as f32,
            offset: offset as f32,
            max_input,
        }
    }
}

/// Apply a [`Mapping`] to an image.
///
/// Rules, in order:
/// * a pixel with a NaN or infinite channel is black; negative channels read as 0
///   (both counted in [`PixelStats`]);
/// * the scotopic luminance is the file's channel, or [`scotopic::from_xyz`];
/// * Eq. 6 in display space, then the acuity blur on the linear planes;
/// * clipping: negative linear sRGB components (colours outside the sRGB gamut) become 0;
///   then a pixel whose largest component exceeds 1 (`L_dmax`) is divided by that
///   component, which keeps its chromaticity and shows it as the brightest colour of that
///   chromaticity the display has (counted as clipped).
///
/// # Panics
/// If the image's planes are inconsistent (check with [`HdrImage::check_consistent`];
/// [`map`] and [`plan`] do).
pub fn apply(image: &HdrImage, mapping: &Mapping) -> (DisplayImage, PixelStats) {
    let mut out = DisplayImage::default();
    let stats = apply_into(image, mapping, &mut out);
    (out, stats)
}

/// [`apply`] writing into an existing display image, reusing its memory (for video:
/// no allocation per frame once the buffers have the right size).
pub fn apply_into(image: &HdrImage, mapping: &Mapping, out: &mut DisplayImage) -> PixelStats {
    let (w, h) = (image.width, image.height);
    let Some(sigma) = exact_blur_sigma(mapping, w, h) else {
        return apply_staged(image, mapping, out);
    };
    let c = Coefficients::new(mapping);
    let planes = display_planes(out, w, h, mapping.display_max_cd_m2).map(|p| p.as_mut_slice());
    let isa = Isa::detect();
    // Mapping, blur and clipping in one pass over the rows.
    crate::blur::exact_pass(
        sigma,
        w,
        h,
        planes,
        false,
        |y, _, [r, g, b]| {
            let rows = y * w..(y + 1) * w;
            let scotopic = image.scotopic.as_ref().map(|s| &s[rows.clone()]);
            let xyz = [
                &image.x[rows.clone()],
                &image.y[rows.clone()],
                &image.z[rows],
            ];
            map_row(isa, &c, xyz, scotopic, [r, g, b])
        },
        |_, [r, g, b]| clip_chunk(r, g, b),
        PixelStats::add,
    )
}

/// [`apply_into`] one stage after the other: the mapping pass (with the clipping when
/// there is no blur), the blur, the clipping.
fn apply_staged(image: &HdrImage, mapping: &Mapping, out: &mut DisplayImage) -> PixelStats {
    let c = Coefficients::new(mapping);
    let [r, g, b] = display_planes(out, image.width, image.height, mapping.display_max_cd_m2);
    let blur = acuity_blur(mapping, image.width, image.height);
    let stats = map_pass(r, g, b, blur.is_none(), |start, r, g, b| {
        let end = start + r.len();
        let scotopic = image.scotopic.as_ref().map(|s| &s[start..end]);
        let xyz = [
            &image.x[start..end],
            &image.y[start..end],
            &image.z[start..end],
        ];
        map_chunk(&c, xyz, scotopic, r, g, b)
    });
    blur_and_clip(stats, [r, g, b], blur)
}

/// The display planes of `out`, sized for a `width × height` image on a display of
/// `display_max_cd_m2` (their memory reused): the opening of every mapping into a display
/// image.
pub(crate) fn display_planes(
    out: &mut DisplayImage,
    width: usize,
    height: usize,
    display_max_cd_m2: f64,
) -> [&mut Vec<f32>; 3] {
    out.width = width;
    out.height = height;
    out.display_max_cd_m2 = display_max_cd_m2 as f32;
    let DisplayImage { r, g, b, .. } = out;
    [r, g, b].map(|plane| {
        let n = width * height;
        if plane.capacity() < n {
            // Fresh zeroed memory from the allocator (pages the kernel zeroes on first
            // touch) rather than a growth filled with zeros that are overwritten anyway.
            *plane = vec![0.0; n];
        } else {
            plane.resize(n, 0.0);
        }
        plane
    })
}

/// The mapping pass over the display planes `r`, `g`, `b`: `map_chunk(start, r, g, b)`
/// (pixels `start..start + r.len()`) over parallel chunks, with the clipping of [`apply`]
/// in the same pass (one trip through memory) when `clip` (no blur follows). Shared by the
/// global operator and [`crate::local`]; [`blur_and_clip`] is the rest.
pub(crate) fn map_pass(
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
    clip: bool,
    map_chunk: impl Fn(usize, &mut [f32], &mut [f32], &mut [f32]) -> PixelStats + Sync,
) -> PixelStats {
    par_chunks(r, g, b, |start, r, g, b| {
        let mut s = map_chunk(start, r, g, b);
        if clip {
            s.clipped = clip_chunk(r, g, b).clipped;
        }
        s
    })
}

/// A per-pixel mapping done in place: the X, Y, Z samples `x`, `y`, `z` become R, G, B.
/// `map(lo, [x, y, z], r, g, b)` maps the pixels `lo..lo + r.len()` of the slices; pieces
/// of a few KiB go through a buffer on the stack (in the L1 cache) and are copied back, so
/// no second set of planes is allocated.
pub(crate) fn map_in_place(
    x: &mut [f32],
    y: &mut [f32],
    z: &mut [f32],
    map: impl Fn(usize, [&[f32]; 3], &mut [f32], &mut [f32], &mut [f32]) -> PixelStats,
) -> PixelStats {
    const PIECE: usize = 1024;
    let mut stats = PixelStats::default();
    let mut buffer = [[0.0f32; PIECE]; 3];
    for lo in (0..x.len()).step_by(PIECE) {
        let hi = (lo + PIECE).min(x.len());
        let [or, og, ob] = &mut buffer;
        let (or, og, ob) = (&mut or[..hi - lo], &mut og[..hi - lo], &mut ob[..hi - lo]);
        let piece = map(lo, [&x[lo..hi], &y[lo..hi], &z[lo..hi]], or, og, ob);
        stats = stats.add(piece);
        x[lo..hi].copy_from_slice(or);
        y[lo..hi].copy_from_slice(og);
        z[lo..hi].copy_from_slice(ob);
    }
    stats
}

/// The stages after the [`map_pass`]: the acuity `blur` and the clipping after it (none:
/// the map pass clipped). The blur is handed the planes themselves, so it may exchange
/// their memory (the spatially varying one does: [`crate::local::acuity`]).
pub(crate) fn blur_and_clip(
    mut stats: PixelStats,
    [r, g, b]: [&mut Vec<f32>; 3],
    blur: Option<impl FnOnce([&mut Vec<f32>; 3])>,
) -> PixelStats {
    if let Some(blur) = blur {
        blur([&mut *r, &mut *g, &mut *b]);
        stats.clipped = par_chunks(r, g, b, |_, r, g, b| clip_chunk(r, g, b)).clipped;
    }
    stats
}

/// The acuity sigma of a global `mapping` when its blur is the exact kernel's, which
/// [`crate::blur::exact_pass`] runs fused with the mapping before it and the clipping
/// after it (the same result as the separate stages, bit for bit).
fn exact_blur_sigma(mapping: &Mapping, width: usize, height: usize) -> Option<f32> {
    let sigma = mapping.blur_sigma_px as f32;
    (mapping.blur_sigma_px > 0.0 && crate::blur::uses_exact_kernel(sigma, width, height))
        .then_some(sigma)
}

/// The acuity stage of a global `mapping` (Eq. 7: one Gaussian for the whole image), or
/// `None` when it has no blur.
fn acuity_blur(
    mapping: &Mapping,
    width: usize,
    height: usize,
) -> Option<impl FnOnce([&mut Vec<f32>; 3]) + use<>> {
    let sigma = mapping.blur_sigma_px;
    (sigma > 0.0).then_some(move |planes: [&mut Vec<f32>; 3]| {
        let mut planes = planes.map(|p| p.as_mut_slice());
        crate::blur::gaussian_blur_planes(&mut planes, width, height, sigma as f32)
    })
}

/// [`apply`], consuming the image: each piece of the X, Y, Z planes is mapped through a
/// small buffer and written back over itself as R, G, B, so no second set of planes is
/// allocated. Same result as [`apply`], bit for bit.
///
/// # Panics
/// As [`apply`].
pub fn apply_owned(image: HdrImage, mapping: &Mapping) -> (DisplayImage, PixelStats) {
    let c = Coefficients::new(mapping);
    let (width, height) = (image.width, image.height);
    let ([mut r, mut g, mut b], scotopic) = image.into_planes();
    let display = |r, g, b| DisplayImage {
        width,
        height,
        r,
        g,
        b,
        display_max_cd_m2: mapping.display_max_cd_m2 as f32,
    };
    if let Some(sigma) = exact_blur_sigma(mapping, width, height) {
        // Mapping, blur and clipping in one pass over the rows, in place.
        let isa = Isa::detect();
        let stats = crate::blur::exact_pass(
            sigma,
            width,
            height,
            [&mut r, &mut g, &mut b],
            true,
            |y, xyz, [r, g, b]| {
                let s = scotopic.as_ref().map(|s| &s[y * width..(y + 1) * width]);
                map_row(isa, &c, xyz, s, [r, g, b])
            },
            |_, [r, g, b]| clip_chunk(r, g, b),
            PixelStats::add,
        );
        return (display(r, g, b), stats);
    }
    let blur = acuity_blur(mapping, width, height);
    let stats = map_pass(&mut r, &mut g, &mut b, blur.is_none(), |start, r, g, b| {
        let s = scotopic.as_ref().map(|s| &s[start..start + r.len()]);
        map_in_place(r, g, b, |lo, xyz, or, og, ob| {
            map_chunk(&c, xyz, s.map(|s| &s[lo..lo + or.len()]), or, og, ob)
        })
    });
    drop(scotopic);
    let stats = blur_and_clip(stats, [&mut r, &mut g, &mut b], blur);
    (display(r, g, b), stats)
}

/// Samples per parallel work item.
const CHUNK: usize = 1 << 15;

pub(crate) fn par_chunks(
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
    f: impl Fn(usize, &mut [f32], &mut [f32], &mut [f32]) -> PixelStats + Sync,
) -> PixelStats {
    let add = PixelStats::add;
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        r.par_chunks_mut(CHUNK)
            .zip(g.par_chunks_mut(CHUNK))
            .zip(b.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(i, ((r, g), b))| f(i * CHUNK, r, g, b))
            .reduce(PixelStats::default, add)
    }
    #[cfg(not(feature = "rayon"))]
    {
        r.chunks_mut(CHUNK)
            .zip(g.chunks_mut(CHUNK))
            .zip(b.chunks_mut(CHUNK))
            .enumerate()
            .map(|(i, ((r, g), b))| f(i * CHUNK, r, g, b))
            .fold(PixelStats::default(), add)
    }
}

/// [`map_chunk`] compiled for the instruction set `isa` (the same result on every one:
/// it has no multiply-add to fuse), for the rows of the fused pass, whose closures the
/// compiler does not inline into the blur's own target-feature functions.
#[inline(always)]
fn map_row(
    isa: Isa,
    c: &Coefficients,
    xyz: [&[f32]; 3],
    scotopic: Option<&[f32]>,
    [r, g, b]: [&mut [f32]; 3],
) -> PixelStats {
    crate::simd::at_level!(isa, map_chunk(c, xyz, scotopic, r, g, b))
}

#[inline(always)]
fn map_chunk(
    c: &Coefficients,
    [xs, ys, zs]: [&[f32]; 3],
    scotopic: Option<&[f32]>,
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) -> PixelStats {
    let (mut non_finite, mut negative, mut saturated) = (0u32, 0u32, 0u32);
    // Two copies of one branch-free loop (file scotopic channel, or the XYZ estimate), so
    // that the compiler vectorises each.
    let out = r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut());
    match scotopic {
        Some(s) => {
            let xyzs = xs.iter().zip(ys).zip(zs).zip(s);
            for ((((x, y), z), s), ((r, g), b)) in xyzs.zip(out) {
                let (finite, neg, v) = sanitize([*x, *y, *z, *s]);
                let (sat, [x, y, z, s]) = c.saturate(v);
                non_finite += u32::from(!finite);
                negative += u32::from(neg);
                saturated += u32::from(sat);
                (*r, *g, *b) = c.pixel(x, y, z, s);
            }
        }
        None => {
            for (((x, y), z), ((r, g), b)) in xs.iter().zip(ys).zip(zs).zip(out) {
                let (finite, neg, v) = sanitize([*x, *y, *z, 0.0]);
                let (sat, [x, y, z, _]) = c.saturate(v);
                non_finite += u32::from(!finite);
                negative += u32::from(neg);
                saturated += u32::from(sat);
                (*r, *g, *b) = c.pixel(x, y, z, scotopic::from_xyz(x, y, z));
            }
        }
    }
    PixelStats {
        non_finite: non_finite as usize,
        negative: negative as usize,
        clipped: 0,
        saturated: saturated as usize,
    }
}

/// Scale a (sanitised, non-negative) pixel down to `max_input` when a channel exceeds it,
/// keeping the ratios of its channels; true when it did. Branch-free, to vectorise.
#[inline(always)]
pub(crate) fn saturate(v: [f32; 4], max_input: f32) -> (bool, [f32; 4]) {
    let m = v[0].max(v[1]).max(v[2]).max(v[3]);
    let over = m > max_input;
    let k = if over { max_input / m } else { 1.0 };
    (over, v.map(|c| c * k))
}

/// The largest input channel value whose mapped value stays within
/// [`MAX_DISPLAY_RELATIVE`] for a largest channel-to-output `gain` (display-relative per
/// cd/m²).
pub(crate) fn max_input_for_gain(gain: f64) -> f32 {
    let bound = f64::from(MAX_DISPLAY_RELATIVE);
    if gain > 0.0 {
        (bound / gain).min(f64::from(f32::MAX) / 4.0) as f32
    } else {
        f32::MAX / 4.0
    }
}

/// The bad-pixel rule: a pixel with any non-finite channel is black; negative channels
/// read as 0. Returns (all finite, any negative, cleaned channels). Written with
/// non-short-circuit operators and selects so that loops over it vectorise.
#[inline(always)]
pub(crate) fn sanitize(v: [f32; 4]) -> (bool, bool, [f32; 4]) {
    let finite = v[0].is_finite() & v[1].is_finite() & v[2].is_finite() & v[3].is_finite();
    let negative = finite & ((v[0] < 0.0) | (v[1] < 0.0) | (v[2] < 0.0) | (v[3] < 0.0));
    (
        finite,
        negative,
        v.map(|c| if finite { c.max(0.0) } else { 0.0 }),
    )
}

impl Coefficients {
    /// Scale a (sanitised, non-negative) pixel down to [`Coefficients::max_input`] when a
    /// channel exceeds it, keeping the ratios of its channels. Branch-free, to vectorise.
    #[inline(always)]
    fn saturate(&self, v: [f32; 4]) -> (bool, [f32; 4]) {
        saturate(v, self.max_input)
    }

    /// Eq. 6 in linear display RGB for one pixel.
    #[inline(always)]
    fn pixel(&self, x: f32, y: f32, z: f32, scotopic: f32) -> (f32, f32, f32) {
        let grey = self.rod * scotopic + self.offset;
        let m = &self.cone;
        (
            m[0][0] * x + m[0][1] * y + m[0][2] * z + grey,
            m[1][0] * x + m[1][1] * y + m[1][2] * z + grey,
            m[2][0] * x + m[2][1] * y + m[2][2] * z + grey,
        )
    }
}

/// Display-relative value above which a pixel counts as clipped in
/// [`PixelStats::clipped`]: 1 plus 2^-10, a quarter of an 8-bit step, so that whites the
/// model puts exactly at `L_dmax` (`2·L_wa` whenever both observers are on Eq. 4's Weber
/// branch) are not counted for rounding (a D65 neutral comes out of the XYZ-to-sRGB matrix
/// with red 4e-4 above green). Every pixel above 1 is still scaled down to it.
pub const CLIP_COUNT_ABOVE: f32 = 1.0 + 1.0 / 1024.0;

#[inline(always)]
pub(crate) fn clip_chunk(r: &mut [f32], g: &mut [f32], b: &mut [f32]) -> PixelStats {
    let mut clipped = 0u32;
    for ((r, g), b) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
        let (rr, gg, bb) = (r.max(0.0), g.max(0.0), b.max(0.0));
        let m = rr.max(gg).max(bb);
        let over = m > 1.0;
        clipped += u32::from(m > CLIP_COUNT_ABOVE);
        let scale = if over { 1.0 / m } else { 1.0 };
        (*r, *g, *b) = (rr * scale, gg * scale, bb * scale);
    }
    PixelStats {
        clipped: clipped as usize,
        ..PixelStats::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame with texture, a 1e6 highlight, NaN, negative and huge pixels.
    fn scene(w: usize, h: usize, scotopic: bool) -> HdrImage {
        let mut im = HdrImage::zeros(w, h);
        for i in 0..w * h {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let l = 0.02
                + 0.1 * ((x * 0.37).sin() * (y * 0.21).cos()).abs()
                + if (x - 20.0).abs() < 3.0 && (y - 9.0).abs() < 2.0 {
                    1e6
                } else {
                    0.0
                };
            im.x[i] = 0.9 * l;
            im.y[i] = l;
            im.z[i] = 1.1 * l * (1.0 + 0.3 * (x * 0.05).sin());
        }
        let n = w * h;
        im.x[(3 * w + 5) % n] = f32::NAN;
        im.y[(7 * w + 2) % n] = -1.0;
        im.z[n - 1] = 3e38;
        if scotopic {
            im.scotopic = Some(im.y.iter().map(|v| 2.0 * v.max(0.0)).collect());
        }
        im
    }

    /// The fused pass (mapping, exact-kernel blur and clipping in one trip through the
    /// rows) gives the staged operator's picture and counts, bit for bit, by reference
    /// and in place, with and without a scotopic plane, over sizes that split into
    /// several parallel segments and sizes that do not.
    #[test]
    fn fused_pass_equals_the_stages() {
        for (w, h) in [(97, 300), (1, 40), (40, 1), (5, 3), (300, 130)] {
            for scotopic in [false, true] {
                let im = scene(w, h, scotopic);
                let report = plan(&im, &ViewingConditions::default()).unwrap();
                for sigma in [0.3, 1.0, 2.19, 2.99, 4.38, 4.99] {
                    let m = Mapping {
                        blur_sigma_px: sigma,
                        ..report.mapping
                    };
                    assert!(exact_blur_sigma(&m, w, h).is_some());
                    let mut want = DisplayImage::default();
                    let want_stats = apply_staged(&im, &m, &mut want);
                    let mut got = DisplayImage::default();
                    let stats = apply_into(&im, &m, &mut got);
                    let (owned, owned_stats) = apply_owned(im.clone(), &m);
                    assert_eq!(stats, want_stats, "{w}x{h} σ {sigma}");
                    assert_eq!(owned_stats, want_stats, "{w}x{h} σ {sigma}");
                    assert!(want_stats.clipped > 0 && want_stats.non_finite == 1);
                    for (a, b, c) in [
                        (&want.r, &got.r, &owned.r),
                        (&want.g, &got.g, &owned.g),
                        (&want.b, &got.b, &owned.b),
                    ] {
                        let bits = |v: &Vec<f32>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(a), bits(b), "{w}x{h} σ {sigma}");
                        assert_eq!(bits(a), bits(c), "{w}x{h} σ {sigma} in place");
                    }
                }
            }
        }
    }
}
