//! Visibility of luminance differences: the threshold at each pixel, the difference between
//! two HDR images of one scene in just-noticeable differences (JNDs), a tolerance map and
//! a convergence test for renderers.
//!
//! Ferwerda et al. 1996 built their model on threshold data, so that it "can be used to
//! predict the visibility and appearance of scene features" and serve "as the basis of
//! perceptually-based error metrics for limiting the precision of global illumination
//! computations" (abstract, Sec. 6). This module is that use of the model's Eq. 4–7.
//!
//! # The observer
//!
//! A [`Viewer`] is a state of adaptation plus the acuity Gaussian of Eq. 7 in pixels.
//! The state is plain values, so that it can come from anywhere:
//!
//! * from an image by the paper's rule (Sec. 4.4, half the highest visible luminance):
//!   [`Viewer::for_image`], or from an [`operator::plan`] report: [`Viewer::from_report`];
//! * from given adaptation luminances: [`Viewer::steady_state`];
//! * from a time-varying adaptation state ([`crate::timecourse::Adaptation`]):
//!   [`Sensitivity::from_time_course`], or any thresholds filled into a [`Sensitivity`];
//! * per pixel ([`Adaptation::Local`], [`Viewer::local`]): the operator's adaptation map
//!   ([`crate::local`], what `--adaptation local` uses), or any map of levels, where
//!   Eq. 4–7 are evaluated at each pixel's own levels, with the same tables as the operator.
//!
//! In the paper's model the observer is adapted to one level for the whole scene, so by
//! default the thresholds are the same everywhere: a 1 cd/m² change is as visible in the
//! shadows as in the highlights. Note what the Sec. 4.4 rule implies for a uniform field at
//! luminance `L`: the observer adapts to `L/2`, so the threshold is `t(L/2)`, not `t(L)`.
//!
//! # From a difference to JNDs
//!
//! For a reference image `R` and a test image `T` of the same scene, at each pixel:
//!
//! 1. **Signals.** Photopic luminance `Y` (cd/m²) and scotopic luminance `V` (scotopic
//!    cd/m², the file's channel or [`scotopic::from_xyz`]) of both images, with the
//!    operator's bad-pixel rule (a pixel with a NaN or infinite channel reads as black,
//!    negative channels as 0). Their differences `ΔY = Y_T − Y_R`, `ΔV = V_T − V_R`.
//! 2. **Acuity (Eq. 7).** Both difference planes are filtered with the acuity Gaussian `G`,
//!    whose response at the cutoff frequency `ω_c(L_wa)` equals the threshold contrast
//!    of this metric, `c = 1/((1/c_p)^β + (k/c_s)^β)^(1/β)` with `c_p = t_p/L_wa` and
//!    `c_s = t_s/L_wa,s` (steps 3–4 for a change in the background's colour; the default
//!    [`AcuityThreshold::Pooled`](crate::acuity::AcuityThreshold), see
//!    [`acuity`](crate::acuity#the-threshold-contrast-c-beyond-the-paper-one-definition-with-the-jnd-metric)).
//!    Filtering the difference is filtering both images and subtracting (the filter is
//!    linear). So a full-contrast grating at `ω_c` on a background at the adaptation
//!    luminance comes out at 1 JND at every level where Eq. 7 has a solution, a finer one
//!    below, a coarser one above: detail above the acuity cutoff is invisible. (Below the
//!    rod Weber range, under 0.016 cd/m², the blur's fallback passes a little less: 0.91
//!    JND at 0.01 cd/m².)
//! 3. **Each mechanism in its threshold units.**
//!    cones `d_c = |G∗ΔY| / t_p`, with `t_p` the cone threshold (Eq. 4) in cd/m²;
//!    rods `d_r = k·|G∗ΔV| / t_s`, with `t_s` the rod threshold (Eq. 5) in scotopic cd/m²
//!    and `k` the rod weight of Eq. 6.
//! 4. **Pooling.** `JND = (d_c^β + d_r^β)^(1/β)` with `β` = [`POOLING_EXPONENT`] = 3.5.
//! 5. **Visible** when `JND ≥ 1` ([`VISIBLE_JND`]).
//!
//! ## Why the rods are weighted by `k`
//!
//! Eq. 5 has no saturation: its Weber branch goes on to any luminance, while the paper says
//! rods are "shutting down due to saturation" at high mesopic levels (Sec. 4) and lets `k`
//! (Eq. 6) express that. Weighting the rod signal by `k` also makes the JND agree with what
//! the operator shows: on the display a pure cone change `ΔY` becomes
//! `m_p·ΔY = t_p(L_da)·ΔY/t_p(L_wa)`, i.e. exactly `d_c` display-observer JNDs, and a pure
//! rod change becomes `k·m_s·ΔV = t_p(L_da)·k·ΔV/t_s(L_wa,s)`, exactly `d_r` (Eq. 3, 6).
//!
//! ## Why probability summation
//!
//! The operator adds the two signals on the display (`d_c + d_r`, with signs), but the rods
//! and the cones are separate detectors: a change that raises `Y` and lowers `V` (a blue
//! surface turning red) would cancel in a signed sum although each system sees it. Two
//! independent detectors with Weibull psychometric functions of slope `β` combine by
//! probability summation into a Minkowski sum of exponent `β` (Quick 1974; Graham 1989,
//! *Visual Pattern Analyzers*, p. 165). The result lies between the envelope of the rod and
//! cone curves (`β → ∞`, the paper's Sec. 3.2: "the visual system's threshold sensitivity
//! can be described by the envelope of the rod and cone t.v.i. curves") and the operator's
//! sum (`β = 1`): a change seen by one system alone scores that system's JNDs, and two
//! systems at threshold together reach `2^(1/3.5)` = 1.22 JND.
//!
//! # Tolerance map
//!
//! [`tolerance_map`] gives, per pixel, the luminance threshold `T` in cd/m²: the size of a
//! luminance change *in the pixel's own colour* (its X, Y, Z and scotopic values scaled
//! together, so `ΔV = r·ΔY` with `r = V/Y`) that reaches 1 JND over an area large against
//! the acuity Gaussian:
//! `T = 1 / ((1/t_p)^β + (k·r/t_s)^β)^(1/β)`.
//! With a global adaptation, an error smaller than `T` at every pixel is invisible whatever
//! its spatial extent (the acuity Gaussian is a positive kernel of unit sum and the pooling is
//! a norm, so filtering can only lower the JNDs), so `T` is the largest error a renderer can
//! allow without knowing how its errors are correlated.
//! Black pixels take `r` of equal-energy white, 2.261 (the paper's illuminant).
//!
//! # Convergence test
//!
//! [`converged`] asks whether the difference between two successive estimates of an image
//! is invisible: every pixel under 1 JND. For a progressive Monte Carlo estimate that
//! doubles its samples, the difference between the estimates after `N` and `2N` samples has
//! the standard deviation of the error of the `2N` estimate itself, so this also says that
//! the remaining noise is (just) invisible.

use crate::acuity::AcuityFilter;
use crate::local::{AdaptationMap, Table, offset_range};
use crate::mesopic::rod_weight;
use crate::operator::{self, MIN_BLUR_SIGMA_PX, Report, ViewingConditions};
use crate::scotopic::{self, EQUAL_ENERGY_SP_RATIO};
use crate::tvi::{cone_threshold_cd_m2, rod_threshold_scotopic_cd_m2};
use crate::{Error, HdrImage, Result};
use std::borrow::Cow;

/// Exponent `β` of the probability summation of the rod and cone signals: the slope of a
/// Weibull psychometric function for contrast detection. 3.5 is the value of Daly's Visible
/// Differences Predictor (Daly 1993), inside the range 2–4 reported for detection (Graham
/// 1989, p. 165).
pub const POOLING_EXPONENT: f64 = 3.5;

/// Differences up to this (cd/m²) go through the acuity blur as they are; larger ones are
/// scaled down by a power of two first (2^100, far above any real scene and far below
/// the f32 range the blur's sums need).
const SAFE_DIFFERENCE: f32 = 1.267_650_6e30;

/// A difference is visible from this many JNDs on (the threshold itself).
pub const VISIBLE_JND: f32 = 1.0;

/// The thresholds of an observer in one state of adaptation: plain values, so that a steady
/// state (Eq. 4–6) or a time-varying state can supply them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensitivity {
    /// Cone increment threshold, cd/m² (Eq. 4 in steady state).
    pub cone_threshold_cd_m2: f64,
    /// Rod increment threshold, scotopic cd/m² (Eq. 5 in steady state).
    pub rod_threshold_scotopic_cd_m2: f64,
    /// Weight of the rod signal, `k` of Eq. 6: 1 below the mesopic range, 0 above it.
    pub rod_weight: f64,
}

impl Sensitivity {
    /// Steady state: Eq. 4 at the photopic adaptation `adaptation_cd_m2`, Eq. 5 and Eq. 6 at
    /// the scotopic adaptation `adaptation_scotopic_cd_m2`.
    pub fn steady_state(adaptation_cd_m2: f64, adaptation_scotopic_cd_m2: f64) -> Self {
        Sensitivity {
            cone_threshold_cd_m2: cone_threshold_cd_m2(adaptation_cd_m2),
            rod_threshold_scotopic_cd_m2: rod_threshold_scotopic_cd_m2(adaptation_scotopic_cd_m2),
            rod_weight: rod_weight(adaptation_scotopic_cd_m2),
        }
    }

    /// The thresholds an [`operator::plan`] report used.
    pub fn from_report(report: &Report) -> Self {
        Sensitivity {
            cone_threshold_cd_m2: report.cone_threshold_cd_m2,
            rod_threshold_scotopic_cd_m2: report.rod_threshold_scotopic_cd_m2,
            rod_weight: report.mapping.rod_weight,
        }
    }

    /// The thresholds of a time-varying adaptation state at this moment: raised above Eq. 4
    /// and 5 while adaptation is under way, equal to [`Sensitivity::steady_state`] once it is
    /// complete; `k` (Eq. 6) at the state's scotopic world luminance, as its display mapping
    /// uses.
    pub fn from_time_course(state: &crate::timecourse::Adaptation) -> Self {
        Sensitivity {
            cone_threshold_cd_m2: state.cone_threshold_cd_m2(),
            rod_threshold_scotopic_cd_m2: state.rod_threshold_scotopic_cd_m2(),
            rod_weight: rod_weight(state.world_scotopic_cd_m2()),
        }
    }

    /// The thresholds at pixel `i` of a local adaptation map ([`operator::local_map`]):
    /// Eq. 4-6 at the pixel's own photopic and scotopic adaptation; during a time course
    /// (`state`, stepped to the frame's global world adaptation), each threshold raised by
    /// the state's current log excess, the same for every pixel: the rule of
    /// [`crate::local`]'s time course (a global state plus local offsets), with `k` at the
    /// pixel's scotopic adaptation as [`LocalMapping::for_time_course`](crate::local::LocalMapping::for_time_course)
    /// maps it. At a pixel whose offsets are 0 this is [`Sensitivity::steady_state`] of the
    /// map's global levels, or (floors aside) [`Sensitivity::from_time_course`].
    ///
    /// # Panics
    /// If `i` is outside the map.
    pub fn local(
        map: &AdaptationMap,
        i: usize,
        state: Option<&crate::timecourse::Adaptation>,
    ) -> Self {
        let (la, las) = (map.adaptation_cd_m2(i), map.adaptation_scotopic_cd_m2(i));
        let steady = Sensitivity::steady_state(la, las);
        let Some(state) = state else { return steady };
        Sensitivity {
            cone_threshold_cd_m2: steady.cone_threshold_cd_m2 * 10f64.powf(state.cone_excess_log()),
            rod_threshold_scotopic_cd_m2: steady.rod_threshold_scotopic_cd_m2
                * 10f64.powf(state.rod_excess_log()),
            rod_weight: steady.rod_weight,
        }
    }

    /// Check that both thresholds are positive and at most `f32::MAX` (the range of the
    /// planes they divide; an image's own adaptation can reach it, e.g. values of 1e38
    /// cd/m²) and `k` is in [0, 1].
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("cone-threshold", self.cone_threshold_cd_m2),
            ("rod-threshold", self.rod_threshold_scotopic_cd_m2),
        ] {
            if !(v > 0.0 && v <= f64::from(f32::MAX)) {
                return Err(Error::invalid(
                    name,
                    v,
                    "must be a positive threshold of at most 3.4e38 (the f32 planes' range)",
                ));
            }
        }
        if !(0.0..=1.0).contains(&self.rod_weight) {
            return Err(Error::invalid(
                "rod-weight",
                self.rod_weight,
                "must be in [0, 1]",
            ));
        }
        Ok(())
    }

    /// JNDs of a change of `delta_cd_m2` photopic and `delta_scotopic_cd_m2` scotopic
    /// luminance that covers an area large against the acuity Gaussian (steps 3–4 of the
    /// module docs).
    pub fn jnd(&self, delta_cd_m2: f64, delta_scotopic_cd_m2: f64) -> f64 {
        pool(
            delta_cd_m2.abs() / self.cone_threshold_cd_m2,
            self.rod_weight * delta_scotopic_cd_m2.abs() / self.rod_threshold_scotopic_cd_m2,
        )
    }

    /// The luminance threshold (cd/m²) of a change of a colour whose scotopic/photopic
    /// luminance ratio is `sp_ratio` (2.261 for equal-energy white): the `ΔY` for which
    /// [`jnd`](Self::jnd)`(ΔY, sp_ratio·ΔY)` is 1.
    pub fn threshold_cd_m2(&self, sp_ratio: f64) -> f64 {
        1.0 / pool(
            1.0 / self.cone_threshold_cd_m2,
            self.rod_weight * sp_ratio.max(0.0) / self.rod_threshold_scotopic_cd_m2,
        )
    }

    /// Per-unit sensitivities `(1/t_p, k/t_s)` as f32, the form the pixel loops use
    /// (at most `f32::MAX`: finite for any valid threshold).
    fn gains(&self) -> (f32, f32) {
        let f = |v: f64| v.min(f64::from(f32::MAX)) as f32;
        (
            f(1.0 / self.cone_threshold_cd_m2),
            f(self.rod_weight / self.rod_threshold_scotopic_cd_m2),
        )
    }
}

/// Probability summation of two detectabilities: `(a^β + b^β)^(1/β)`, computed without
/// overflow as `m·(1 + (n/m)^β)^(1/β)` with `m = max(a, b)`, `n = min(a, b)`.
pub(crate) fn pool(a: f64, b: f64) -> f64 {
    let (m, n) = if a >= b { (a, b) } else { (b, a) };
    if m == 0.0 {
        return 0.0;
    }
    m * (1.0 + (n / m).powf(POOLING_EXPONENT)).powf(1.0 / POOLING_EXPONENT)
}

/// [`pool`] in f32, for the pixel loops. When one signal is under 1 % of the other (one
/// system alone: daylight with `k` = 0, or deep night) the other adds less than
/// `0.01^3.5/3.5` = 3e-8 of the result, below f32 precision, and the powers are skipped.
#[inline]
fn pool_f32(a: f32, b: f32) -> f32 {
    const BETA: f32 = POOLING_EXPONENT as f32;
    const INV_BETA: f32 = (1.0 / POOLING_EXPONENT) as f32;
    let (m, n) = if a >= b { (a, b) } else { (b, a) };
    if n <= 0.01 * m {
        return m;
    }
    m * (1.0 + (n / m).powf(BETA)).powf(INV_BETA)
}

/// Where the observer's thresholds come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Adaptation<'a> {
    /// One state for the whole field of view: the paper's observer adapted to `L_wa`
    /// (Sec. 4.4), or a time-varying state.
    Global(Sensitivity),
    /// Local adaptation: each pixel's own photopic and scotopic adaptation, in steady state
    /// (Eq. 4-6 at each pixel), from the operator's adaptation map
    /// ([`operator::local_map`], the same map `map --adaptation local` shows) or any map of
    /// levels ([`AdaptationMap::from_levels`]). The map's per-pixel acuity Gaussian, when it
    /// has one, replaces [`Viewer::acuity_sigma_px`].
    Local(&'a AdaptationMap),
}

/// Per-pixel `(1/t_p, k/t_s)` of a local map, tabulated against its offsets as the
/// operator's coefficients are ([`crate::local`]; offset 0 is the global value exactly).
struct LocalGains {
    cone: Table<1>,
    rod: Table<1>,
}

impl LocalGains {
    fn new(map: &AdaptationMap) -> Self {
        let (lp, hp) = offset_range(&map.offset_log);
        let (ls, hs) = offset_range(&map.offset_scotopic_log);
        let (lwa, lwa_s) = (
            map.world_adaptation_cd_m2,
            map.world_adaptation_scotopic_cd_m2,
        );
        LocalGains {
            cone: Table::new(lp, hp, |d| {
                [(1.0 / cone_threshold_cd_m2(lwa * 10f64.powf(d))) as f32]
            }),
            rod: Table::new(ls, hs, |d| {
                let l = lwa_s * 10f64.powf(d);
                [(rod_weight(l) / rod_threshold_scotopic_cd_m2(l)) as f32]
            }),
        }
    }
}

impl Adaptation<'_> {
    /// The per-pixel gains' tables (`None` for a global state).
    fn local_gains(&self) -> Option<LocalGains> {
        match self {
            Adaptation::Global(_) => None,
            Adaptation::Local(map) => Some(LocalGains::new(map)),
        }
    }

    /// `(1/t_p, k/t_s)` at pixel `i`.
    #[inline]
    fn gains_at(&self, global: (f32, f32), local: Option<&LocalGains>, i: usize) -> (f32, f32) {
        match (self, local) {
            (Adaptation::Local(map), Some(g)) => (
                g.cone.at(map.offset_log[i])[0],
                g.rod.at(map.offset_scotopic_log[i])[0],
            ),
            _ => global,
        }
    }

    fn global_gains(&self) -> (f32, f32) {
        match self {
            Adaptation::Global(s) => s.gains(),
            Adaptation::Local(_) => (0.0, 0.0),
        }
    }

    fn validate(&self, pixels: usize) -> Result<()> {
        match self {
            Adaptation::Global(s) => s.validate(),
            Adaptation::Local(map) => {
                if map.offset_log.len() != pixels || map.offset_scotopic_log.len() != pixels {
                    return Err(Error::invalid(
                        "adaptation map",
                        format!("of {} values", map.offset_log.len()),
                        format!("must hold one value per pixel ({pixels})"),
                    ));
                }
                if let Some(v) = map
                    .offset_log
                    .iter()
                    .chain(&map.offset_scotopic_log)
                    .find(|v| !v.is_finite())
                {
                    return Err(Error::invalid(
                        "adaptation map",
                        v,
                        "offsets must be finite",
                    ));
                }
                Ok(())
            }
        }
    }
}

/// An observer looking at an image: a state of adaptation and the acuity Gaussian.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Viewer<'a> {
    /// The thresholds, global or per pixel.
    pub adaptation: Adaptation<'a>,
    /// Standard deviation of the acuity Gaussian of Eq. 7, pixels; 0 for no acuity limit.
    pub acuity_sigma_px: f64,
}

impl Viewer<'static> {
    /// The observer the operator would use for `image` under `conditions` (adaptation by
    /// Sec. 4.4 or as given, acuity from the view, raised by the veil when the conditions
    /// switch glare on), with the report of [`operator::prepare`].
    pub fn for_image(image: &HdrImage, conditions: &ViewingConditions) -> Result<(Self, Report)> {
        if let operator::AdaptationMode::Local(_) = conditions.adaptation {
            return Err(Error::invalid(
                "adaptation",
                "local",
                "needs its adaptation map: use Observation::for_image",
            ));
        }
        let report = Observation::for_image(image, conditions)?.report;
        Ok((Viewer::from_report(&report), report))
    }

    /// The observer of an [`operator::plan`] report: its thresholds, and its acuity blur
    /// (none when the report's acuity was off or below [`MIN_BLUR_SIGMA_PX`]).
    pub fn from_report(report: &Report) -> Self {
        Viewer {
            adaptation: Adaptation::Global(Sensitivity::from_report(report)),
            acuity_sigma_px: report.mapping.blur_sigma_px,
        }
    }

    /// A steady-state observer adapted to `adaptation_cd_m2` (cones) and
    /// `adaptation_scotopic_cd_m2` (rods), looking at an image with `pixels_per_degree`
    /// (`None`: no acuity limit). The acuity Gaussian is Eq. 7 at that adaptation, skipped
    /// below [`MIN_BLUR_SIGMA_PX`] as the operator does.
    pub fn steady_state(
        adaptation_cd_m2: f64,
        adaptation_scotopic_cd_m2: f64,
        pixels_per_degree: Option<f64>,
    ) -> Self {
        let sigma = pixels_per_degree.map_or(0.0, |ppd| {
            AcuityFilter::new(adaptation_cd_m2, adaptation_scotopic_cd_m2).sigma_deg * ppd
        });
        Viewer {
            adaptation: Adaptation::Global(Sensitivity::steady_state(
                adaptation_cd_m2,
                adaptation_scotopic_cd_m2,
            )),
            acuity_sigma_px: if sigma >= MIN_BLUR_SIGMA_PX {
                sigma
            } else {
                0.0
            },
        }
    }
}

impl<'a> Viewer<'a> {
    /// A steady-state observer adapted locally, pixel by pixel, as `map` says (the
    /// operator's adaptation map of the image, [`operator::local_map`]), with the map's
    /// per-pixel acuity Gaussian (none when the map has no sigmas).
    pub fn local(map: &'a AdaptationMap) -> Self {
        Viewer {
            adaptation: Adaptation::Local(map),
            acuity_sigma_px: 0.0,
        }
    }
}

impl Viewer<'_> {
    /// Check the thresholds, the maps' sizes against `pixels`, and the blur size.
    pub fn validate(&self, pixels: usize) -> Result<()> {
        self.adaptation.validate(pixels)?;
        if !(self.acuity_sigma_px.is_finite() && self.acuity_sigma_px >= 0.0) {
            return Err(Error::invalid(
                "acuity-sigma",
                self.acuity_sigma_px,
                "must be a finite, non-negative number of pixels",
            ));
        }
        Ok(())
    }
}

/// The observer the operator would use for an image, global or local: its [`Report`] and,
/// with [`AdaptationMode::Local`](operator::AdaptationMode::Local), its adaptation map
/// (the report's `local` part filled in). [`Observation::viewer`] is the [`Viewer`].
#[derive(Debug, Clone)]
pub struct Observation {
    /// What the model used (the [`operator::prepare`] report of the image).
    pub report: Report,
    /// The adaptation map, with local adaptation.
    pub map: Option<AdaptationMap>,
}

impl Observation {
    /// The observation of `image` under `conditions` (adaptation by Sec. 4.4 or as given,
    /// globally or locally, acuity from the view; with glare, of the veiled retinal image,
    /// as [`operator::prepare`] makes it).
    pub fn for_image(image: &HdrImage, conditions: &ViewingConditions) -> Result<Self> {
        Ok(Observation::with_retina(image, conditions)?.1)
    }

    /// [`Observation::for_image`] with the retinal image it observed (the image itself
    /// without glare, its veiled copy with it).
    fn with_retina<'a>(
        image: &'a HdrImage,
        conditions: &ViewingConditions,
    ) -> Result<(Cow<'a, HdrImage>, Self)> {
        let (retina, mut report) = operator::prepare(image, conditions)?;
        let map = match conditions.adaptation {
            operator::AdaptationMode::Global => None,
            operator::AdaptationMode::Local(options) => {
                let map = operator::local_map(&retina, &report, conditions, &options)?;
                report.local = Some(crate::local::LocalReport::of(&map, options.rod_saturation));
                Some(map)
            }
        };
        Ok((retina, Observation { report, map }))
    }

    /// The viewer: per pixel with a map, else the report's global state.
    pub fn viewer(&self) -> Viewer<'_> {
        match &self.map {
            Some(map) => Viewer::local(map),
            None => Viewer::from_report(&self.report),
        }
    }
}

/// How visible `test` is against `reference` to the observer the operator would use for
/// `reference` under `conditions` ([`Observation::for_image`]: global or local adaptation,
/// acuity from the view), with that observer's report. With glare
/// ([`ViewingConditions::glare`]) the two images are compared as they reach the retina,
/// each with its own veil ([`operator::prepare`]), by the observer adapted to the
/// reference's: a bright light in the field of view then hides what lies near it.
///
/// This is `visadapt visible` and the Python package's `visible`.
pub fn compare(
    reference: &HdrImage,
    test: &HdrImage,
    conditions: &ViewingConditions,
) -> Result<(Difference, Report)> {
    // The reference's retinal image is the one its observer was made from (veiled once).
    let (retina, observation) = Observation::with_retina(reference, conditions)?;
    let viewer = observation.viewer();
    let d = if conditions.glare.is_some() {
        let (t, _) = operator::prepare(test, conditions)?;
        difference(&retina, &t, &viewer)?
    } else {
        difference(reference, test, &viewer)?
    };
    Ok((d, observation.report))
}

/// The difference between two images in JNDs, per pixel and summarised.
#[derive(Clone, PartialEq)]
pub struct Difference {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// JNDs per pixel, row-major (see the module docs for the definition).
    pub jnd: Vec<f32>,
    /// Fraction of pixels at or above [`VISIBLE_JND`].
    pub visible_fraction: f64,
    /// Mean JNDs over all pixels.
    pub mean_jnd: f64,
    /// Largest JNDs of any pixel.
    pub max_jnd: f64,
    /// Pixels with a NaN or infinite channel, counted in each image (read as black, as the
    /// operator shows them).
    pub non_finite_pixels: usize,
}

/// The size and the summary, and of the per-pixel plane its number of samples (as for
/// the images: [`HdrImage`]'s `Debug`).
impl std::fmt::Debug for Difference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Difference {
            width,
            height,
            jnd,
            visible_fraction,
            mean_jnd,
            max_jnd,
            non_finite_pixels,
        } = self;
        f.debug_struct("Difference")
            .field("width", width)
            .field("height", height)
            .field("jnd", &crate::image::Samples(jnd))
            .field("visible_fraction", visible_fraction)
            .field("mean_jnd", mean_jnd)
            .field("max_jnd", max_jnd)
            .field("non_finite_pixels", non_finite_pixels)
            .finish()
    }
}

impl Difference {
    /// True when no pixel differs visibly (every pixel under [`VISIBLE_JND`]).
    pub fn is_invisible(&self) -> bool {
        self.max_jnd < f64::from(VISIBLE_JND)
    }
}

/// The difference between `reference` and `test` (same scene, same size) in JNDs for
/// `viewer`, per pixel, with its visible fraction, mean and maximum.
///
/// ```
/// use visadapt::{HdrImage, operator::ViewingConditions, visibility};
/// // A grey scene at 100 cd/m² and the same scene 2 % brighter on its left half.
/// let mut reference = HdrImage::zeros(32, 32);
/// reference.x.fill(100.0); reference.y.fill(100.0); reference.z.fill(100.0);
/// let mut test = reference.clone();
/// for i in (0..test.len()).filter(|i| i % 32 < 16) {
///     test.x[i] *= 1.02; test.y[i] *= 1.02; test.z[i] *= 1.02;
/// }
/// let (viewer, report) = visibility::Viewer::for_image(&reference, &ViewingConditions::default())?;
/// let d = visibility::difference(&reference, &test, &viewer)?;
/// // Adapted to 50 cd/m² (Sec. 4.4), the cones' threshold is 3.08 cd/m²: 2 cd/m² is 0.65 JND.
/// assert!((report.cone_threshold_cd_m2 - 3.08).abs() < 0.01);
/// assert!((d.max_jnd - 0.65).abs() < 0.01 && d.is_invisible());
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn difference(reference: &HdrImage, test: &HdrImage, viewer: &Viewer) -> Result<Difference> {
    check_pair(reference, test)?;
    let n = reference.len();
    viewer.validate(n)?;
    let (width, height) = (reference.width, reference.height);

    // Steps 1–2: the photopic and scotopic difference planes, then the acuity Gaussian.
    let mut dy = vec![0f32; n];
    let mut dv = vec![0f32; n];
    let non_finite = par_chunks2(&mut dy, &mut dv, |start, dy, dv| {
        accumulate(reference, start, -1.0, dy, dv) + accumulate(test, start, 1.0, dy, dv)
    });
    // Huge finite differences (an image of 1e38 cd/m²) would overflow inside the blur (its
    // kernels add pairs of samples and run on deviations): scale them by an exact power of
    // two into range, and the sensitivities up by the same factor (the blur is linear).
    let largest = dy.iter().chain(dv.iter()).fold(0f32, |m, v| m.max(v.abs()));
    let up = if largest > SAFE_DIFFERENCE {
        let e = (largest / SAFE_DIFFERENCE).log2().ceil() as i32;
        let down = 2f32.powi(-e);
        dy.iter_mut().chain(dv.iter_mut()).for_each(|v| *v *= down);
        2f32.powi(e)
    } else {
        1.0
    };
    match &viewer.adaptation {
        Adaptation::Local(AdaptationMap {
            acuity_sigma_px: Some(sigma),
            ..
        }) => crate::local::acuity::varying_gaussian_blur_vecs(
            &mut [&mut dy, &mut dv],
            width,
            height,
            sigma,
        ),
        _ if viewer.acuity_sigma_px > 0.0 => crate::blur::gaussian_blur_planes(
            &mut [dy.as_mut_slice(), dv.as_mut_slice()],
            width,
            height,
            viewer.acuity_sigma_px as f32,
        ),
        _ => {}
    }

    // Steps 3–4: each mechanism in its threshold units, pooled. The result goes into `dy`.
    let adaptation = &viewer.adaptation;
    let global = adaptation.global_gains();
    let local = adaptation.local_gains();
    par_chunks2(&mut dy, &mut dv, |start, dy, dv| {
        for (j, (d, v)) in dy.iter_mut().zip(dv.iter()).enumerate() {
            let (cone, rod) = adaptation.gains_at(global, local.as_ref(), start + j);
            let (cone, rod) = ((cone * up).min(f32::MAX), (rod * up).min(f32::MAX));
            // JNDs beyond f32's range saturate at f32::MAX.
            *d = pool_f32(d.abs() * cone, v.abs() * rod).min(f32::MAX);
        }
        0
    });
    let jnd = dy;
    let (visible, sum, max) = summarise(&jnd);
    Ok(Difference {
        width,
        height,
        visible_fraction: visible as f64 / n as f64,
        mean_jnd: sum / n as f64,
        max_jnd: f64::from(max),
        jnd,
        non_finite_pixels: non_finite,
    })
}

/// The convergence test for a progressive renderer: is the difference between `current`
/// and `previous` invisible to `viewer` (every pixel under 1 JND)?
pub fn converged(previous: &HdrImage, current: &HdrImage, viewer: &Viewer) -> Result<bool> {
    Ok(difference(previous, current, viewer)?.is_invisible())
}

/// Per pixel, the luminance threshold in cd/m²: the largest luminance error, in the pixel's
/// own colour, that stays invisible to `viewer` whatever its spatial extent (see the module
/// docs). The acuity Gaussian only makes fine-grained errors less visible still, so it is not
/// used here.
///
/// With glare (a viewer from [`Observation::for_image`] under
/// [`ViewingConditions::glare`](operator::ViewingConditions::glare)) the thresholds are
/// those of the veiled retinal image, and the error itself is taken unveiled: the glare
/// spread function conserves energy, so an error spread over a region reaches the retina
/// almost whole (only a point-like error loses the scattered fraction to its halo), and a
/// tolerance that must hold for errors of any extent is set by the extended case.
pub fn tolerance_map(image: &HdrImage, viewer: &Viewer) -> Result<Vec<f32>> {
    image.check_consistent()?;
    let n = image.len();
    viewer.validate(n)?;
    let adaptation = &viewer.adaptation;
    let global = adaptation.global_gains();
    let local = adaptation.local_gains();
    let mut out = vec![0f32; n];
    // The scotopic luminance, a piece at a time (a plane of it would be 4 bytes per pixel).
    const PIECE: usize = 1024;
    par_chunks1(&mut out, |start, out| {
        let mut v = [0f32; PIECE];
        for (k, out) in out.chunks_mut(PIECE).enumerate() {
            let start = start + k * PIECE;
            let v = &mut v[..out.len()];
            v.fill(0.0);
            accumulate(image, start, 1.0, out, v);
            for (j, (o, v)) in out.iter_mut().zip(v.iter()).enumerate() {
                let ratio = if *o > 0.0 {
                    v / *o
                } else {
                    EQUAL_ENERGY_SP_RATIO as f32
                };
                let (cone, rod) = adaptation.gains_at(global, local.as_ref(), start + j);
                *o = 1.0 / pool_f32(cone, rod * ratio);
            }
        }
    });
    Ok(out)
}

/// The range of a [`tolerance_map`] and its median relative to the pixels' luminance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToleranceSummary {
    /// Smallest tolerance, cd/m².
    pub min_cd_m2: f32,
    /// Median tolerance (the upper median), cd/m².
    pub median_cd_m2: f32,
    /// Largest tolerance, cd/m².
    pub max_cd_m2: f32,
    /// Median of tolerance / luminance over the pixels with a positive, finite luminance;
    /// `None` when there is none.
    pub median_relative: Option<f32>,
}

impl ToleranceSummary {
    /// Summarise `tolerance` (from [`tolerance_map`]) of an image whose luminance plane is
    /// `luminance_cd_m2`. `None` for an empty map or planes of different lengths.
    pub fn of(tolerance: &[f32], luminance_cd_m2: &[f32]) -> Option<Self> {
        if tolerance.is_empty() || tolerance.len() != luminance_cd_m2.len() {
            return None;
        }
        // One copy at a time (4 bytes per pixel), selected rather than sorted.
        let upper_median = |mut v: Vec<f32>| {
            let middle = v.len() / 2;
            (!v.is_empty()).then(|| *v.select_nth_unstable_by(middle, f32::total_cmp).1)
        };
        let min_cd_m2 = tolerance.iter().copied().min_by(f32::total_cmp)?;
        let max_cd_m2 = tolerance.iter().copied().max_by(f32::total_cmp)?;
        let median_cd_m2 = upper_median(tolerance.to_vec())?;
        // Sized once (a growing vector would hold two buffers while it moves).
        let mut relative = Vec::with_capacity(tolerance.len());
        relative.extend(
            tolerance
                .iter()
                .zip(luminance_cd_m2)
                .filter(|(_, y)| y.is_finite() && **y > 0.0)
                .map(|(t, y)| t / y),
        );
        Some(ToleranceSummary {
            min_cd_m2,
            median_cd_m2,
            max_cd_m2,
            median_relative: upper_median(relative),
        })
    }
}

/// Both images consistent and of the same size.
fn check_pair(reference: &HdrImage, test: &HdrImage) -> Result<()> {
    reference.check_consistent()?;
    test.check_consistent()?;
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(Error::invalid(
            "image size",
            format!("{}x{}", test.width, test.height),
            format!(
                "differs from the reference image's {}x{}",
                reference.width, reference.height
            ),
        ));
    }
    Ok(())
}

/// Add `sign` times the photopic and scotopic luminance of the pixels
/// `start..start + dy.len()` of `image` to `dy` and `dv`, under the operator's bad-pixel rule
/// (a pixel with a non-finite channel is black, negative channels read as 0); returns how
/// many of those pixels were non-finite. One branch-free loop per layout, so each vectorises.
fn accumulate(image: &HdrImage, start: usize, sign: f32, dy: &mut [f32], dv: &mut [f32]) -> usize {
    let end = start + dy.len();
    let (xs, ys, zs) = (
        &image.x[start..end],
        &image.y[start..end],
        &image.z[start..end],
    );
    let out = dy.iter_mut().zip(dv.iter_mut());
    let mut bad = 0;
    match &image.scotopic {
        Some(s) => {
            let xyzs = xs.iter().zip(ys).zip(zs).zip(&s[start..end]);
            for ((((x, y), z), s), (dy, dv)) in xyzs.zip(out) {
                let finite = x.is_finite() & y.is_finite() & z.is_finite() & s.is_finite();
                bad += usize::from(!finite);
                *dy += sign * if finite { y.max(0.0) } else { 0.0 };
                *dv += sign * if finite { s.max(0.0) } else { 0.0 };
            }
        }
        None => {
            for (((x, y), z), (dy, dv)) in xs.iter().zip(ys).zip(zs).zip(out) {
                let finite = x.is_finite() & y.is_finite() & z.is_finite();
                bad += usize::from(!finite);
                let [x, y, z] = [*x, *y, *z].map(|c| if finite { c.max(0.0) } else { 0.0 });
                *dy += sign * y;
                *dv += sign * scotopic::from_xyz(x, y, z);
            }
        }
    }
    bad
}

/// Pixels at or above [`VISIBLE_JND`], the sum (f64) and the maximum of a JND plane.
fn summarise(jnd: &[f32]) -> (usize, f64, f32) {
    let chunk = |c: &[f32]| {
        c.iter().fold((0usize, 0f64, 0f32), |(n, s, m), &j| {
            (
                n + usize::from(j >= VISIBLE_JND),
                s + f64::from(j),
                m.max(j),
            )
        })
    };
    let add = |a: (usize, f64, f32), b: (usize, f64, f32)| (a.0 + b.0, a.1 + b.1, a.2.max(b.2));
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        // Added in chunk order, as without rayon: a parallel reduction's order (and so the
        // rounding of the f64 sum) follows the work stealing.
        let chunks: Vec<(usize, f64, f32)> = jnd.par_chunks(CHUNK).map(chunk).collect();
        chunks.into_iter().fold((0, 0.0, 0.0), add)
    }
    #[cfg(not(feature = "rayon"))]
    {
        jnd.chunks(CHUNK).map(chunk).fold((0, 0.0, 0.0), add)
    }
}

/// Samples per parallel work item.
const CHUNK: usize = 1 << 14;

/// Run `f(start, chunk)` over chunks of a plane, in parallel with the `rayon` feature.
fn par_chunks1(a: &mut [f32], f: impl Fn(usize, &mut [f32]) + Sync) {
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        a.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, a)| f(c * CHUNK, a));
    }
    #[cfg(not(feature = "rayon"))]
    {
        a.chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, a)| f(c * CHUNK, a));
    }
}

/// Run `f(start, a_chunk, b_chunk)` over matching chunks of two planes of the same length,
/// in parallel with the `rayon` feature; sums `f`'s results.
fn par_chunks2(
    a: &mut [f32],
    b: &mut [f32],
    f: impl Fn(usize, &mut [f32], &mut [f32]) -> usize + Sync,
) -> usize {
    debug_assert_eq!(a.len(), b.len());
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (a, b))| f(c * CHUNK, a, b))
            .sum()
    }
    #[cfg(not(feature = "rayon"))]
    {
        a.chunks_mut(CHUNK)
            .zip(b.chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (a, b))| f(c * CHUNK, a, b))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Debug` shows the summary and the per-pixel plane's size, not its samples.
    #[test]
    fn debug_shows_the_summary_and_the_planes_size() {
        let d = Difference {
            width: 640,
            height: 480,
            jnd: vec![0.5; 640 * 480],
            visible_fraction: 0.25,
            mean_jnd: 0.5,
            max_jnd: 3.0,
            non_finite_pixels: 0,
        };
        let shown = format!("{d:?}");
        assert!(shown.contains("jnd: <307200 samples>"), "{shown}");
        assert!(
            shown.contains("max_jnd: 3.0") && shown.len() < 250,
            "{shown}"
        );
    }

    #[test]
    fn pooling_is_the_envelope_for_one_system_and_sums_two_at_threshold() {
        assert_eq!(pool(0.0, 0.0), 0.0);
        assert_eq!(pool(2.5, 0.0), 2.5);
        assert_eq!(pool(0.0, 0.7), 0.7);
        // Two systems at threshold: 2^(1/3.5) = 1.2190.
        assert!((pool(1.0, 1.0) - 1.219_0).abs() < 1e-4);
        assert!((pool_f32(1.0, 1.0) - 1.219_0).abs() < 1e-4);
        // No overflow for huge signals.
        assert!((pool(1e300, 1e300) / 1e300 - 1.219_0).abs() < 1e-4);
        assert!(pool_f32(1e30, 2e30).is_finite());
    }

    /// Per pixel, the local thresholds are Eq. 4-6 at the pixel's own levels; during a time
    /// course they are raised by the state's excess, so that at the global level they are
    /// the time course's own thresholds.
    #[test]
    fn local_thresholds_follow_each_pixels_adaptation() {
        // Pixel 0 at the map's anchor (offset 0), pixel 1 a hundred times darker.
        let map = AdaptationMap::from_levels(2, 1, &[10.0, 0.1], &[22.61, 0.2261]).unwrap();
        // (The map holds its levels as f32: relative errors of 1e-7.)
        let rel = |a: f64, b: f64| (a / b - 1.0).abs();
        let s0 = Sensitivity::local(&map, 0, None);
        let want = Sensitivity::steady_state(10.0, 22.61);
        assert!(
            rel(s0.cone_threshold_cd_m2, want.cone_threshold_cd_m2) < 1e-6,
            "{s0:?}"
        );
        assert!(
            rel(
                s0.rod_threshold_scotopic_cd_m2,
                want.rod_threshold_scotopic_cd_m2
            ) < 1e-6
        );
        assert_eq!(s0.rod_weight, want.rod_weight);
        let s1 = Sensitivity::local(&map, 1, None);
        let want = Sensitivity::steady_state(0.1, 0.2261);
        assert!(
            rel(s1.cone_threshold_cd_m2, want.cone_threshold_cd_m2) < 1e-6,
            "{s1:?}"
        );
        assert!(
            rel(
                s1.rod_threshold_scotopic_cd_m2,
                want.rod_threshold_scotopic_cd_m2
            ) < 1e-6
        );
        assert!((s1.rod_weight - want.rod_weight).abs() < 1e-6);
        // Eq. 4 at 10 and 0.1 cd/m²: 1.07 and 0.232 cd/m².
        assert!(s1.cone_threshold_cd_m2 < 0.25 * s0.cone_threshold_cd_m2);
        // Lights switched from 1000 to 10 cd/m² 20 s ago: the thresholds are still raised.
        let mut eye = crate::timecourse::Adaptation::adapted(1000.0, 2261.0).unwrap();
        eye.step(0.0, 10.0, 22.61).unwrap();
        eye.step(20.0, 10.0, 22.61).unwrap();
        assert!(eye.cone_excess_log() > 0.1, "{}", eye.cone_excess_log());
        let t0 = Sensitivity::local(&map, 0, Some(&eye));
        let global = Sensitivity::from_time_course(&eye);
        assert!(
            rel(t0.cone_threshold_cd_m2, global.cone_threshold_cd_m2) < 1e-6,
            "{t0:?}"
        );
        assert!(
            rel(
                t0.rod_threshold_scotopic_cd_m2,
                global.rod_threshold_scotopic_cd_m2
            ) < 1e-6
        );
        assert_eq!(t0.rod_weight, global.rod_weight);
        let t1 = Sensitivity::local(&map, 1, Some(&eye));
        let raised = 10f64.powf(eye.cone_excess_log());
        assert!(rel(t1.cone_threshold_cd_m2, s1.cone_threshold_cd_m2 * raised) < 1e-9);
    }

    #[test]
    fn daylight_threshold_is_the_cone_threshold() {
        // 100 cd/m² (k = 0): Eq. 4 Weber branch, 10^(2 − 1.255) = 5.559 cd/m².
        let s = Sensitivity::steady_state(100.0, 226.1);
        assert_eq!(s.rod_weight, 0.0);
        assert!((s.threshold_cd_m2(2.261) - 5.559).abs() < 1e-3);
        assert!((s.jnd(5.559, 100.0) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn starlight_threshold_is_set_by_the_rods() {
        // 1e-3 cd/m², 2.261e-3 scotopic (k = 1): rods at 10^((0.405·log(2.261e-3) + 1.6)^2.18
        // − 2.86) = 2.4491e-3 scotopic cd/m²; per photopic cd/m² of white that is
        // 2.4491e-3 / 2.261 = 1.0832e-3 cd/m², far below the cones' 10^-0.72 = 0.1905.
        let s = Sensitivity::steady_state(1e-3, 2.261e-3);
        assert_eq!(s.rod_weight, 1.0);
        assert!((s.rod_threshold_scotopic_cd_m2 / 2.449_1e-3 - 1.0).abs() < 1e-4);
        let t = s.threshold_cd_m2(2.261);
        let rod_only = s.rod_threshold_scotopic_cd_m2 / 2.261;
        // The cones add (1.0832e-3/0.1905)^3.5 ≈ 1.4e-8 of pooled signal: negligible.
        assert!((t / rod_only - 1.0).abs() < 1e-6, "{t} vs {rod_only}");
        // A red surface with no scotopic signal is seen by the cones alone.
        assert!((s.threshold_cd_m2(0.0) - 10f64.powf(-0.72)).abs() < 1e-9);
        assert!((s.jnd(t, 2.261 * t) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn validation_catches_bad_states() {
        let good = Sensitivity::steady_state(1.0, 2.261);
        assert!(good.validate().is_ok());
        for bad in [
            Sensitivity {
                cone_threshold_cd_m2: 0.0,
                ..good
            },
            Sensitivity {
                rod_threshold_scotopic_cd_m2: f64::NAN,
                ..good
            },
            Sensitivity {
                rod_weight: 1.5,
                ..good
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        let map = AdaptationMap::from_levels(3, 1, &[1.0; 3], &[2.0; 3]).unwrap();
        let local = Adaptation::Local(&map);
        assert!(local.validate(4).is_err());
        assert!(local.validate(3).is_ok());
        assert!(AdaptationMap::from_levels(3, 1, &[1.0; 3], &[f32::NAN; 3]).is_err());
        assert!(AdaptationMap::from_levels(3, 1, &[1.0; 2], &[1.0; 3]).is_err());
    }
}
