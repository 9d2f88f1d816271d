//! The model's entry points: `map`, `observer`, `timecourse`, `visible`, `tolerance` and the
//! time-course state `Adaptation`. Each converts its arguments, calls the library without
//! the GIL and returns arrays and the library's JSON reports as dicts.

use crate::conditions::{Options, scaled};
use crate::convert::{interleave, json_to_py, to_array2, to_array3};
use crate::errors::{detached, to_py};
use crate::image::HdrImage;
use numpy::{PyArray2, PyArray3};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use visadapt::observer::Observer;
use visadapt::operator;
use visadapt::scotopic::EQUAL_ENERGY_SP_RATIO;
use visadapt::timecourse::{self as course, Adaptation as State};
use visadapt::visibility::{self, Observation, ToleranceSummary};
use visadapt::{DisplayImage, report};

type Display<'py> = Bound<'py, PyArray3<f32>>;

/// A display image's planes, interleaved for numpy (done without the GIL).
struct Interleaved {
    width: usize,
    height: usize,
    samples: Vec<f32>,
}

impl Interleaved {
    fn of(d: &DisplayImage) -> Self {
        Interleaved {
            width: d.width,
            height: d.height,
            samples: interleave([&d.r, &d.g, &d.b]),
        }
    }

    fn into_array(self, py: Python<'_>) -> PyResult<Display<'_>> {
        to_array3(py, self.width, self.height, self.samples)
    }
}

fn lib_err(e: visadapt::Error) -> PyErr {
    to_py(e, None)
}

/// Map an HDR image for display as the observer adapted to it sees it (Ferwerda et al.
/// 1996, Sec. 4): adaptation (Sec. 4.4), thresholds and scale factors (Eq. 3-5), the
/// mesopic rod weight (Eq. 6), the acuity blur (Eq. 7), clipping.
///
/// Args:
///     image: an HdrImage.
///     peak: rescale the image so that its highest visible luminance is `peak` cd/m²
///         (e.g. 0.05 for moonlight); excludes `scale`.
///     scale: multiply the image by this to get cd/m².
///     display_max: the display's maximum luminance L_dmax, cd/m² (default 80).
///     display_adaptation: the display observer's adaptation L_da, cd/m² (default
///         display_max / 2).
///     world_adaptation: the world observer's cone adaptation L_wa, cd/m² (default half the
///         highest visible luminance).
///     scotopic_adaptation: the world observer's rod adaptation, scotopic cd/m².
///     hot_pixel_fraction: fraction of pixels allowed above the "highest visible"
///         luminance (default 1e-3).
///     fov: horizontal field of view, degrees (default: the file's view, else 60).
///     projection: of `fov`: "perspective" (under 180 degrees, the default) or "fisheye"
///         (angular fisheye, up to 360 degrees).
///     acuity: apply the acuity blur (default True).
///     acuity_threshold: Eq. 7's threshold contrast: "pooled" (the JND metric's: a
///         full-contrast grating at the cutoff scores 1 JND; default) or "envelope" (the
///         paper's, the more sensitive system alone).
///     white_point: the scene white adapted to the display's D65 by CAT16: "auto" (the
///         file's, default), "none" (the paper's colours), "E", "D65" or "x,y".
///     adaptation: "global" (one level for the scene, the paper, default) or "local" (each
///         pixel adapted to its neighbourhood); adaptation_radius: its size, degrees.
///     glare: veiling glare in the eye (CIE 135/1), default False; age (years, default 25)
///         and pigmentation (0 very dark to 1.2 light blue, default 0.5) of its observer.
///     undershoot: time courses only: "clamped" (default) or "in-mapping" (the paper's
///         Eq. 8-9 during Baker's dip).
///
/// Returns:
///     (display, report): `display` is H x W x 3 float32 linear sRGB relative to the display
///     maximum (1.0 = display_max cd/m², as the linear EXR output); `report` the dict of
///     `visadapt map --json` (adaptation levels, thresholds, scale factors, acuity, view,
///     pixel counts).
#[pyfunction]
#[pyo3(signature = (image, **conditions))]
pub fn map<'py>(
    py: Python<'py>,
    image: &HdrImage,
    conditions: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Display<'py>, Bound<'py, PyAny>)> {
    let options = Options::parse("map", conditions)?;
    let (display, report) = detached(py, || {
        let p = options.prepare(&image.inner).map_err(lib_err)?;
        let out = operator::map(&p.image, &p.conditions).map_err(lib_err)?;
        let report = report::map_json(&out.report, &out.stats, p.scale);
        Ok((Interleaved::of(&out.image), report))
    })?;
    Ok((display.into_array(py)?, json_to_py(py, &report)?))
}

/// What an observer adapted to one luminance can see (`visadapt observer --json`).
///
/// Args:
///     luminance: the adaptation luminance, cd/m².
///     scotopic: the rod adaptation, scotopic cd/m² (default luminance x 2.261, an
///         equal-energy white).
///     display_max: the display's maximum luminance, cd/m².
///
/// Returns:
///     dict: thresholds (Eq. 4, 5), scale factors (Eq. 3), rod weight (Eq. 6), acuity
///     (Fig. 7), with the keys of `visadapt observer --json`.
#[pyfunction]
#[pyo3(signature = (luminance, scotopic = None, display_max = 80.0))]
pub fn observer(
    py: Python<'_>,
    luminance: f64,
    scotopic: Option<f64>,
    display_max: f64,
) -> PyResult<Bound<'_, PyAny>> {
    let o = Observer::new(luminance, scotopic, Some(display_max)).map_err(lib_err)?;
    json_to_py(py, &report::observer_json(&o))
}

/// The time course of adaptation (Sec. 3.5, Eq. 8-9): an observer adapted to `from_`
/// meets `to` at t = 0 (equal-energy white: scotopic = photopic x 2.261).
///
/// Args:
///     from_: the luminance adapted to before, cd/m².
///     to: the luminance from t = 0 on, cd/m².
///     times: sorted, non-negative times since the change, seconds.
///     display_max: the display's maximum luminance, cd/m².
///
/// Returns:
///     list of dict: one per time, the objects of `visadapt timecourse --json`
///     (thresholds, excess over steady state, scale factors, offsets, acuity).
#[pyfunction]
#[pyo3(signature = (from_, to, times, display_max = 80.0))]
pub fn timecourse(
    py: Python<'_>,
    from_: f64,
    to: f64,
    times: Vec<f64>,
    display_max: f64,
) -> PyResult<Bound<'_, PyAny>> {
    let sp = EQUAL_ENERGY_SP_RATIO;
    let moments = course::course(
        (from_, from_ * sp),
        (to, to * sp),
        &times,
        display_max,
        course::Undershoot::default(),
    )
    .map_err(lib_err)?;
    json_to_py(py, &report::timecourse_json(&moments))
}

/// How visible the difference between two images of one scene is to an observer adapted
/// to the reference, in just-noticeable differences (Eq. 4-7).
///
/// Args:
///     reference, test: HdrImages of the same size.
///     **conditions: as for `map` (`peak` rescales both images by the reference's peak).
///
/// Returns:
///     (jnd, summary): `jnd` is H x W float32, JNDs per pixel; `summary` the dict of
///     `visadapt visible --json` (visible fraction, mean and max JND, the observer).
#[pyfunction]
#[pyo3(signature = (reference, test, **conditions))]
pub fn visible<'py>(
    py: Python<'py>,
    reference: &HdrImage,
    test: &HdrImage,
    conditions: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyAny>)> {
    let options = Options::parse("visible", conditions)?;
    let (d, summary) = detached(py, || {
        let p = options.prepare(&reference.inner).map_err(lib_err)?;
        let test = scaled(&test.inner, p.scale);
        let (d, report) = visibility::compare(&p.image, &test, &p.conditions).map_err(lib_err)?;
        let summary = report::difference_json(&d, &report, p.scale, None);
        Ok((d, summary))
    })?;
    let jnd = to_array2(py, d.width, d.height, d.jnd)?;
    Ok((jnd, json_to_py(py, &summary)?))
}

/// Per pixel, the largest luminance error that stays invisible to an observer adapted to
/// the image (Eq. 4-6), in cd/m².
///
/// Args:
///     image: an HdrImage.
///     **conditions: as for `map` (the acuity does not enter the tolerance).
///
/// Returns:
///     (tolerance, summary): `tolerance` is H x W float32 in cd/m²; `summary` the dict of
///     `visadapt tolerance --json` (without `output`: null).
#[pyfunction]
#[pyo3(signature = (image, **conditions))]
pub fn tolerance<'py>(
    py: Python<'py>,
    image: &HdrImage,
    conditions: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyAny>)> {
    let options = Options::parse("tolerance", conditions)?;
    let (w, h) = (image.inner.width, image.inner.height);
    let (map, summary) = detached(py, || {
        let p = options.prepare(&image.inner).map_err(lib_err)?;
        // The tolerance holds for errors of any extent: acuity does not enter it (as the
        // CLI's `tolerance`).
        let conditions = visadapt::operator::ViewingConditions {
            acuity: false,
            ..p.conditions.clone()
        };
        let observation = Observation::for_image(&p.image, &conditions).map_err(lib_err)?;
        let map = visibility::tolerance_map(&p.image, &observation.viewer()).map_err(lib_err)?;
        let report = observation.report;
        let summary = ToleranceSummary::of(&map, &p.image.y)
            .map(|s| report::tolerance_json(&s, &report, p.scale, None))
            .ok_or_else(|| lib_err(visadapt::Error::invalid("image", "empty", "has no pixels")))?;
        Ok((map, summary))
    })?;
    Ok((to_array2(py, w, h, map)?, json_to_py(py, &summary)?))
}

/// The state of an observer whose eyes adapt over time (Sec. 3.5, Figs. 8-10): thresholds
/// that lag behind changes of the world luminance, for video and walk-throughs.
///
/// Args:
///     luminance: the world luminance the observer is fully adapted to now, cd/m².
///     scotopic: its scotopic luminance, scotopic cd/m² (default luminance x 2.261).
///
/// Example:
///     eye = visadapt.Adaptation(0.05)            # adapted to moonlight
///     eye.step(2.0, frame)                       # 2 s of `frame`, e.g. lights on
///     display, report = eye.map(frame)           # what the dazzled observer sees
#[pyclass(module = "visadapt")]
pub struct Adaptation {
    state: State,
}

#[pymethods]
impl Adaptation {
    #[new]
    #[pyo3(signature = (luminance, scotopic = None))]
    fn new(luminance: f64, scotopic: Option<f64>) -> PyResult<Self> {
        let scotopic = scotopic.unwrap_or(luminance * EQUAL_ENERGY_SP_RATIO);
        let state = State::adapted(luminance, scotopic).map_err(lib_err)?;
        Ok(Adaptation { state })
    }

    /// Let the observer view the current world for `dt_seconds`, then switch to a new one.
    ///
    /// Args:
    ///     dt_seconds: time spent in the current world, seconds (>= 0).
    ///     target: the new world: an HdrImage (its adaptation luminances as `map` finds
    ///         them, with **conditions), a report dict from `map` (its
    ///         `adaptation_cd_m2` and `scotopic_adaptation_cd_m2`), a luminance in cd/m²
    ///         (equal-energy white) or a (cd/m², scotopic cd/m²) pair.
    #[pyo3(signature = (dt_seconds, target, **conditions))]
    fn step(
        &mut self,
        py: Python<'_>,
        dt_seconds: f64,
        target: &Bound<'_, PyAny>,
        conditions: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<()> {
        let (l, ls) = if let Ok(image) = target.cast::<HdrImage>() {
            let options = Options::parse("step", conditions)?;
            let image = &image.get().inner;
            let report = detached(py, || {
                let p = options.prepare(image).map_err(lib_err)?;
                operator::plan(&p.image, &p.conditions).map_err(lib_err)
            })?;
            (
                report.world_adaptation_cd_m2,
                report.world_adaptation_scotopic_cd_m2,
            )
        } else if let Ok(d) = target.cast::<PyDict>() {
            let get = |k: &str| -> PyResult<f64> {
                d.get_item(k)?
                    .ok_or_else(|| PyTypeError::new_err(format!("the report has no '{k}'")))?
                    .extract()
            };
            (get("adaptation_cd_m2")?, get("scotopic_adaptation_cd_m2")?)
        } else if let Ok(l) = target.extract::<f64>() {
            (l, l * EQUAL_ENERGY_SP_RATIO)
        } else if let Ok(pair) = target.extract::<(f64, f64)>() {
            pair
        } else {
            return Err(PyTypeError::new_err(
                "target must be an HdrImage, a map report dict, a luminance or a (photopic, scotopic) pair",
            ));
        };
        self.state.step(dt_seconds, l, ls).map_err(lib_err)
    }

    /// The observer's state now.
    ///
    /// Returns:
    ///     dict: `cone_threshold_cd_m2` and `rod_threshold_scotopic_cd_m2` (the current
    ///     thresholds), `cone_excess_log` and `rod_excess_log` (log10 above steady state),
    ///     `acuity_cycles_per_degree`, the world luminances adapted to
    ///     (`world_adaptation_cd_m2`, `world_adaptation_scotopic_cd_m2`),
    ///     `seconds_since_change` and `adapted` (True once steady).
    fn thresholds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &report::adaptation_json(&self.state))
    }

    /// Map an image as this observer sees it now: `map`, with the thresholds of the
    /// current state (Eq. 8-9) instead of the steady state. Call `step(dt, image)` first
    /// to let the observer adapt towards the image.
    ///
    /// Returns:
    ///     (display, report): as `map`, the report's thresholds, scale factors and acuity
    ///     those of the current state, plus the offsets (`offset_cd_m2`,
    ///     `photopic_offset_cd_m2`, `scotopic_offset_cd_m2`), `cone_excess_log`,
    ///     `rod_excess_log` and `seconds_since_change`.
    #[pyo3(signature = (image, **conditions))]
    fn map<'py>(
        &self,
        py: Python<'py>,
        image: &HdrImage,
        conditions: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<(Display<'py>, Bound<'py, PyAny>)> {
        let options = Options::parse("map", conditions)?;
        let state = &self.state;
        let (display, report) = detached(py, || {
            let p = options.prepare(&image.inner).map_err(lib_err)?;
            let steady = operator::plan(&p.image, &p.conditions).map_err(lib_err)?;
            let mapping = state.mapping(&steady);
            let (display, stats) = operator::apply(&p.image, &mapping);
            let report = report::adapting_map_json(&steady, &stats, p.scale, state, &mapping);
            Ok((Interleaved::of(&display), report))
        })?;
        Ok((display.into_array(py)?, json_to_py(py, &report)?))
    }

    fn __repr__(&self) -> String {
        let s = &self.state;
        format!(
            "<visadapt.Adaptation to {:.4e} cd/m², {:.1} s since the change, cone threshold {:.4e} cd/m²>",
            s.world_cd_m2(),
            s.seconds_since_change(),
            s.cone_threshold_cd_m2()
        )
    }
}
