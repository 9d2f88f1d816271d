//! Machine-readable renderings of what the model used: the JSON objects that
//! `visadapt map --json`, `observer --json`, `timecourse --json` and `visible --json`
//! print, built here once so that the CLI, the Python package and the viewer give the same
//! keys and the same values.
//!
//! Keys carry their units (`_cd_m2`, `_scotopic_cd_m2`, `_deg`, `_px`,
//! `_cycles_per_degree`, `_seconds`); the README lists them per command. Numbers are the
//! `f64`s the model computed, printed by `serde_json` in the shortest form that reads back
//! to the same value.
//!
//! Available with the `json` feature (on by default).

use crate::Projection;
use crate::acuity::snellen;
use crate::local::{LocalReport, Quantiles};
use crate::observer::Observer;
use crate::operator::{Mapping, PixelStats, Report, Source};
use crate::timecourse::{Adaptation, Moment};
use crate::visibility::{Difference, POOLING_EXPONENT, ToleranceSummary};
use serde_json::{Value, json};

/// How a [`Source`] is named in reports.
pub fn source_label(s: Source) -> &'static str {
    match s {
        Source::Caller => "given",
        Source::File => "from the file",
        Source::Image => "from the image",
        Source::Default => "default",
    }
}

/// How a [`Projection`] is named in reports.
pub fn projection_label(p: Projection) -> &'static str {
    match p {
        Projection::Perspective => "perspective",
        Projection::AngularFisheye => "angular fisheye",
        Projection::HemisphericalFisheye => "hemispherical fisheye",
        Projection::Cylindrical => "cylindrical",
        Projection::Planisphere => "planisphere",
        Projection::Parallel => "parallel",
    }
}

/// The report of one [`operator::map`](crate::operator::map) run (`visadapt map --json`):
/// adaptation levels, thresholds, scale factors, acuity, view, the scene white the colours
/// were adapted from (`scene_white`: `"E"`, `"D65"`, `"x,y"` or null when off) and pixel
/// counts.
/// `input_scale` is the factor the caller applied to the file's values to get cd/m²
/// (1 when none).
///
/// ```
/// use visadapt::{HdrImage, operator::{map, ViewingConditions}, report};
/// let mut scene = HdrImage::zeros(8, 8);
/// scene.y.fill(10.0);
/// let out = map(&scene, &ViewingConditions::default())?;
/// let v = report::map_json(&out.report, &out.stats, 1.0);
/// assert_eq!(v["adaptation_cd_m2"], 5.0);
/// assert_eq!(v["view"]["source"], "default");
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn map_json(r: &Report, stats: &PixelStats, input_scale: f64) -> Value {
    let m = &r.mapping;
    json!({
        "width": r.width,
        "height": r.height,
        "input_scale": input_scale,
        "highest_visible_cd_m2": r.highest_visible_cd_m2,
        "highest_visible_scotopic_cd_m2": r.highest_visible_scotopic_cd_m2,
        "scotopic_source": source_label(r.scotopic_source),
        "adaptation_cd_m2": r.world_adaptation_cd_m2,
        "adaptation_source": source_label(r.world_adaptation_source),
        "scotopic_adaptation_cd_m2": r.world_adaptation_scotopic_cd_m2,
        "display_adaptation_cd_m2": r.display_adaptation_cd_m2,
        "display_max_cd_m2": m.display_max_cd_m2,
        "cone_threshold_cd_m2": r.cone_threshold_cd_m2,
        "rod_threshold_scotopic_cd_m2": r.rod_threshold_scotopic_cd_m2,
        "photopic_scale": m.photopic_scale,
        "scotopic_scale": m.scotopic_scale,
        "rod_weight": m.rod_weight,
        "acuity_cycles_per_degree": r.acuity.cutoff_cycles_per_degree,
        "snellen": r.snellen(),
        "threshold_contrast": r.acuity.threshold_contrast,
        "acuity_contrast_used": r.acuity.gain_at_cutoff,
        "acuity_fallback": r.acuity.fallback,
        "acuity_threshold": r.acuity.rule.name(),
        "acuity_extrapolated": r.acuity.extrapolated,
        "acuity_blur_sigma_deg": r.acuity.sigma_deg,
        "acuity_applied": r.acuity_applied,
        "blur_sigma_px": m.blur_sigma_px,
        "pixels_per_degree": r.pixels_per_degree,
        "view": {
            "projection": projection_label(r.view.projection),
            "horizontal_fov_deg": r.view.horizontal_deg,
            "source": source_label(r.view_source),
        },
        "glare": glare_json(r),
        "scene_white_xy": r.scene_white,
        "scene_white": r.scene_white.map(crate::colour::white_name),
        "scene_white_source": source_label(r.scene_white_source),
        "pixels_non_finite": stats.non_finite,
        "pixels_negative": stats.negative,
        "pixels_clipped": stats.clipped,
        "pixels_clipped_fraction": stats.clipped as f64 / (r.width * r.height).max(1) as f64,
        "highest_visible_display_cd_m2": r.highest_visible_display_cd_m2(),
        "display_max_to_show_highest_visible_cd_m2": r.display_max_to_show_highest_visible(),
        "adaptation": if r.local.is_some() { "local" } else { "global" },
        "local": r.local.as_ref().map(local_json),
    })
}

/// Quantiles as `{"min", "p01", "p10", "p50", "p90", "p99", "max"}`.
fn quantiles_json(q: &Quantiles) -> Value {
    json!({
        "min": q.min, "p01": q.p01, "p10": q.p10, "p50": q.p50,
        "p90": q.p90, "p99": q.p99, "max": q.max,
    })
}

/// The local-adaptation part of a report (`"local"` in `map --json`).
pub fn local_json(l: &LocalReport) -> Value {
    json!({
        "radius_deg": l.radius_deg,
        "grid_step_px": l.grid_step_px,
        "rod_saturation": l.rod_saturation,
        "rod_saturation_scotopic_cd_m2": crate::local::ROD_SATURATION_SCOTOPIC_CD_M2,
        "adaptation_cd_m2": quantiles_json(&l.adaptation_cd_m2),
        "scotopic_adaptation_cd_m2": quantiles_json(&l.adaptation_scotopic_cd_m2),
        "rod_weight": quantiles_json(&l.rod_weight),
        "blur_sigma_px": l.acuity_sigma_px.as_ref().map(quantiles_json),
    })
}

/// One file of a batch (`visadapt map a.hdr b.exr -o out/ --json`, one line each): the
/// input and output paths as given, then every key of [`map_json`].
///
/// ```
/// use visadapt::{HdrImage, operator::{map, ViewingConditions}, report};
/// let mut scene = HdrImage::zeros(8, 8);
/// scene.y.fill(10.0);
/// let out = map(&scene, &ViewingConditions::default())?;
/// let v = report::map_file_json("a.hdr", "out/a.png", &out.report, &out.stats, 1.0);
/// assert_eq!(v["input"], "a.hdr");
/// assert_eq!(v["output"], "out/a.png");
/// assert_eq!(v["adaptation_cd_m2"], 5.0);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn map_file_json(
    input: &str,
    output: &str,
    r: &Report,
    stats: &PixelStats,
    input_scale: f64,
) -> Value {
    let mut v = json!({ "input": input, "output": output });
    if let (Value::Object(head), Value::Object(rest)) = (&mut v, map_json(r, stats, input_scale)) {
        head.extend(rest);
    }
    v
}

/// What the glare stage did ([`operator::prepare`](crate::operator::prepare) with
/// `ViewingConditions::glare`), `null` when it was off: the observer, the veiling luminance
/// at the fixation point (the image centre), the adaptation without glare and how many
/// times the glare raised it, the fraction of every pixel's light scattered into the veil,
/// and the convolution grid's cell and near radius.
///
/// ```
/// use visadapt::{HdrImage, glare::Glare, operator::{map, ViewingConditions}, report};
/// let mut scene = HdrImage::zeros(64, 36);
/// scene.y.fill(0.01);
/// scene.y[18 * 64 + 40] = 1e6;
/// let conditions = ViewingConditions { glare: Some(Glare::default()), ..Default::default() };
/// let out = map(&scene, &conditions)?;
/// let v = report::map_json(&out.report, &out.stats, 1.0);
/// assert_eq!(v["glare"]["age_years"], 25.0);
/// assert!(v["glare"]["veil_at_fixation_cd_m2"].as_f64().unwrap() > 0.0);
/// assert!(v["glare"]["adaptation_ratio"].as_f64().unwrap() > 1.0);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn glare_json(r: &Report) -> Value {
    let Some(g) = &r.glare else {
        return Value::Null;
    };
    json!({
        "age_years": g.veil.glare.age_years,
        "pigmentation": g.veil.glare.pigmentation,
        "veil_at_fixation_cd_m2": g.veil.veil_at_centre_cd_m2,
        "veil_at_fixation_scotopic_cd_m2": g.veil.veil_at_centre_scotopic_cd_m2,
        "mean_veil_cd_m2": g.veil.mean_veil_cd_m2,
        "adaptation_without_glare_cd_m2": g.world_adaptation_without_glare_cd_m2,
        "scotopic_adaptation_without_glare_cd_m2": g.world_adaptation_without_glare_scotopic_cd_m2,
        "adaptation_ratio": g.adaptation_ratio(r),
        "scattered_fraction": g.veil.scattered_fraction,
        "cell_deg": g.veil.cell_deg,
        "near_radius_deg": g.veil.near_radius_deg,
    })
}

/// What an [`Observer`] adapted to one luminance sees (`visadapt observer --json`).
pub fn observer_json(o: &Observer) -> Value {
    json!({
        "adaptation_cd_m2": o.adaptation_cd_m2,
        "scotopic_adaptation_cd_m2": o.scotopic_adaptation_cd_m2,
        "display_max_cd_m2": o.display_max_cd_m2,
        "display_adaptation_cd_m2": o.display_adaptation_cd_m2,
        "cone_threshold_cd_m2": o.cone_threshold_cd_m2,
        "rod_threshold_scotopic_cd_m2": o.rod_threshold_scotopic_cd_m2,
        "photopic_scale": o.photopic_scale,
        "scotopic_scale": o.scotopic_scale,
        "rod_weight": o.rod_weight,
        "acuity_cycles_per_degree": o.acuity_cycles_per_degree(),
        "snellen": o.snellen(),
        "threshold_contrast": o.acuity.threshold_contrast,
        "acuity_contrast_used": o.acuity.gain_at_cutoff,
        "acuity_blur_sigma_deg": o.acuity.sigma_deg,
        "acuity_fallback": o.acuity.fallback,
        "acuity_threshold": o.acuity.rule.name(),
        "acuity_extrapolated": o.acuity.extrapolated,
    })
}

/// One [`Moment`] of a time course (an element of `visadapt timecourse --json`). The
/// offset `offset_cd_m2` is the total Eq. 8 offset `b_p + k·b_s` in display cd/m².
pub fn moment_json(m: &Moment) -> Value {
    let map = &m.mapping;
    json!({
        "t_seconds": m.t_seconds,
        "cone_threshold_cd_m2": m.cone_threshold_cd_m2,
        "rod_threshold_scotopic_cd_m2": m.rod_threshold_scotopic_cd_m2,
        "cone_excess_log": m.cone_excess_log,
        "rod_excess_log": m.rod_excess_log,
        "photopic_scale": map.photopic_scale,
        "scotopic_scale": map.scotopic_scale,
        "rod_weight": map.rod_weight,
        "offset_cd_m2": map.photopic_offset_cd_m2 + map.rod_weight * map.scotopic_offset_cd_m2,
        "photopic_offset_cd_m2": map.photopic_offset_cd_m2,
        "scotopic_offset_cd_m2": map.scotopic_offset_cd_m2,
        "acuity_cycles_per_degree": m.acuity_cycles_per_degree,
    })
}

/// The state of an adapting observer ([`Adaptation`], Sec. 3.5): the world luminances it
/// is exposed to, the current thresholds and their log10 excess over the steady state
/// (Eq. 4, 5), the current acuity, the seconds since the world last changed and whether
/// the adaptation is complete.
pub fn adaptation_json(a: &Adaptation) -> Value {
    json!({
        "world_adaptation_cd_m2": a.world_cd_m2(),
        "world_adaptation_scotopic_cd_m2": a.world_scotopic_cd_m2(),
        "seconds_since_change": a.seconds_since_change(),
        "adapted": a.is_adapted(),
        "cone_threshold_cd_m2": a.cone_threshold_cd_m2(),
        "rod_threshold_scotopic_cd_m2": a.rod_threshold_scotopic_cd_m2(),
        "cone_excess_log": a.cone_excess_log(),
        "rod_excess_log": a.rod_excess_log(),
        "acuity_cycles_per_degree": a.acuity_cycles_per_degree(),
    })
}

/// The report of an image mapped for an adapting observer: [`map_json`] of the
/// steady-state `report` of the frame, with the thresholds, scale factors, rod weight and
/// acuity of `state` and its Eq. 8–9 `mapping` (from [`Adaptation::mapping`]), plus the
/// offsets (`offset_cd_m2` = `b_p + k·b_s`, `photopic_offset_cd_m2`,
/// `scotopic_offset_cd_m2`, display cd/m²), `cone_excess_log`, `rod_excess_log` and
/// `seconds_since_change`. Once the adaptation is complete it equals [`map_json`] plus
/// zero offsets and excesses.
pub fn adapting_map_json(
    report: &Report,
    stats: &PixelStats,
    input_scale: f64,
    state: &Adaptation,
    mapping: &Mapping,
) -> Value {
    let now = Report {
        mapping: *mapping,
        cone_threshold_cd_m2: state.cone_threshold_cd_m2(),
        rod_threshold_scotopic_cd_m2: state.rod_threshold_scotopic_cd_m2(),
        ..report.clone()
    };
    let mut v = map_json(&now, stats, input_scale);
    let acuity = state.acuity_cycles_per_degree();
    let extra = json!({
        "acuity_cycles_per_degree": acuity,
        "snellen": snellen(acuity),
        "cone_excess_log": state.cone_excess_log(),
        "rod_excess_log": state.rod_excess_log(),
        "seconds_since_change": state.seconds_since_change(),
        "offset_cd_m2": mapping.photopic_offset_cd_m2
            + mapping.rod_weight * mapping.scotopic_offset_cd_m2,
        "photopic_offset_cd_m2": mapping.photopic_offset_cd_m2,
        "scotopic_offset_cd_m2": mapping.scotopic_offset_cd_m2,
    });
    if let (Value::Object(v), Value::Object(extra)) = (&mut v, extra) {
        v.extend(extra);
    }
    v
}

/// A whole time course (`visadapt timecourse --json`): one [`moment_json`] per time.
pub fn timecourse_json(moments: &[Moment]) -> Value {
    Value::Array(moments.iter().map(moment_json).collect())
}

/// The summary of a [`Difference`] between two images (`visadapt visible --json`), with
/// the observer's `report` (from [`Viewer::for_image`](crate::visibility::Viewer::for_image)
/// on the reference), the `input_scale` applied to both images and the path of the heat
/// map written, if any.
pub fn difference_json(d: &Difference, r: &Report, input_scale: f64, map: Option<&str>) -> Value {
    json!({
        "width": d.width,
        "height": d.height,
        "visible_fraction": d.visible_fraction,
        "visible_pixels": (d.visible_fraction * (d.width * d.height) as f64).round() as u64,
        "mean_jnd": d.mean_jnd,
        "max_jnd": d.max_jnd,
        "adaptation_cd_m2": r.world_adaptation_cd_m2,
        "adaptation_source": if r.world_adaptation_source == Source::Caller { "given" } else { "reference image" },
        "scotopic_adaptation_cd_m2": r.world_adaptation_scotopic_cd_m2,
        "cone_threshold_cd_m2": r.cone_threshold_cd_m2,
        "rod_threshold_scotopic_cd_m2": r.rod_threshold_scotopic_cd_m2,
        "rod_weight": r.mapping.rod_weight,
        "pooling_exponent": POOLING_EXPONENT,
        "acuity_cycles_per_degree": r.acuity.cutoff_cycles_per_degree,
        "acuity_applied": r.acuity_applied,
        "blur_sigma_px": r.mapping.blur_sigma_px,
        "pixels_per_degree": r.pixels_per_degree,
        "horizontal_fov_deg": r.view.horizontal_deg,
        "input_scale": input_scale,
        "non_finite_pixels": d.non_finite_pixels,
        "glare": glare_json(r),
        "map": map,
        "adaptation": if r.local.is_some() { "local" } else { "global" },
        "local": r.local.as_ref().map(local_json),
    })
}

/// The summary of a tolerance map (`visadapt tolerance --json`): the observer's `report`
/// (from [`Viewer::for_image`](crate::visibility::Viewer::for_image)), the map's
/// [`ToleranceSummary`], the `input_scale` applied to the image and the file the map was
/// written to, if any.
pub fn tolerance_json(
    summary: &ToleranceSummary,
    r: &Report,
    input_scale: f64,
    output: Option<&str>,
) -> Value {
    json!({
        "width": r.width,
        "height": r.height,
        "adaptation_cd_m2": r.world_adaptation_cd_m2,
        "adaptation_source": if r.world_adaptation_source == Source::Caller { "given" } else { "image" },
        "scotopic_adaptation_cd_m2": r.world_adaptation_scotopic_cd_m2,
        "cone_threshold_cd_m2": r.cone_threshold_cd_m2,
        "rod_threshold_scotopic_cd_m2": r.rod_threshold_scotopic_cd_m2,
        "rod_weight": r.mapping.rod_weight,
        "min_tolerance_cd_m2": summary.min_cd_m2,
        "median_tolerance_cd_m2": summary.median_cd_m2,
        "max_tolerance_cd_m2": summary.max_cd_m2,
        "median_relative_tolerance": summary.median_relative,
        "glare": glare_json(r),
        "input_scale": input_scale,
        "output": output,
        "adaptation": if r.local.is_some() { "local" } else { "global" },
        "local": r.local.as_ref().map(local_json),
    })
}
