//! The server's state: the decoded scene and what it keeps between requests (the scene at
//! the current light level, the planned reports, preview copies, the last frame), so that a
//! slider move costs one preview `apply` and a PNG encode. All model work is the library's.

use serde_json::{Value, json};
use std::path::PathBuf;
use visadapt::operator::{self, Mapping, PixelStats, Report, ViewingConditions};
use visadapt::preview;
use visadapt::timecourse::Adaptation;
use visadapt::visibility::Sensitivity;
use visadapt::{DisplayImage, HdrImage, View};

/// How many planned reports, preview sizes and full-resolution pixel counts are kept.
const PLANS_KEPT: usize = 16;
const PREVIEWS_KEPT: usize = 3;

/// What a request fails with: the caller's fault (HTTP 400) or ours (500).
#[derive(Debug)]
pub enum Failure {
    BadRequest(String),
    Internal(String),
}

impl From<visadapt::Error> for Failure {
    fn from(e: visadapt::Error) -> Self {
        match e {
            visadapt::Error::InvalidParameter { .. } | visadapt::Error::Unsupported(_) => {
                Failure::BadRequest(e.to_string())
            }
            e => Failure::Internal(e.to_string()),
        }
    }
}

pub type Outcome<T> = Result<T, Failure>;

/// What the frame shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rendering {
    /// The model (steady state, or the time course when `t` is given).
    Model,
    /// A plain exposure ([`preview::exposure`]), for the A/B split.
    Exposure,
}

/// The parameters of a frame, a report or a pixel (the query of `/api/...`).
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// The scene's highest visible luminance, cd/m²; `None` for the file's own level.
    pub peak_cd_m2: Option<f64>,
    /// The time course: the level the observer was adapted to, and the seconds since the
    /// switch to `peak_cd_m2`.
    pub switch: Option<(f64, f64)>,
    pub display_max_cd_m2: f64,
    /// A perspective view of this horizontal angle; `None` for the server's default.
    pub fov_deg: Option<f64>,
    pub acuity: bool,
    /// Width of the frame in pixels; `None` for the full resolution.
    pub width: Option<usize>,
    pub rendering: Rendering,
}

/// The defaults of the parameters (the `serve` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct Defaults {
    pub display_max_cd_m2: f64,
    /// The view of `--fov` and `--projection`; `None` for the file's.
    pub view: Option<View>,
    pub acuity: bool,
}

/// Exact keys for caches of f64 parameters.
type PlanKey = (u64, u64, Option<u64>, bool);
type FrameKey = (PlanKey, Option<(u64, u64)>, usize, Rendering);

/// The global quantities of one frame.
struct Situation {
    /// Factor from the file's values to the frame's cd/m² (the report's `input_scale`).
    scale: f64,
    /// The steady state at the frame's level.
    after: Report,
    /// The observer's state during a time course.
    eye: Option<Adaptation>,
    /// The mapping of the model at full resolution.
    model: Mapping,
    plan_key: PlanKey,
}

impl Situation {
    fn sensitivity(&self) -> Sensitivity {
        match &self.eye {
            Some(eye) => Sensitivity::from_time_course(eye),
            None => Sensitivity::from_report(&self.after),
        }
    }

    fn mapping(&self, rendering: Rendering) -> Mapping {
        match rendering {
            Rendering::Model => self.model,
            Rendering::Exposure => preview::exposure(&self.after),
        }
    }
}

pub struct Viewer {
    path: PathBuf,
    /// The decoded file, times `--scale`.
    base: HdrImage,
    /// The factor `--scale` or `--peak` applied to the file (1 without them).
    base_scale: f64,
    /// The conditions of the `serve` flags; a request sets display, view and acuity.
    conditions: ViewingConditions,
    pub defaults: Defaults,
    /// [`HdrImage::peak_factor`] of `base` for the levels asked for.
    factors: Vec<(u64, f64)>,
    /// `base` times `scaled_factor`, at full resolution.
    scaled: HdrImage,
    scaled_factor: Option<f64>,
    plans: Vec<(PlanKey, Report)>,
    /// Pixel counts of full-resolution model frames, for the report.
    stats: Vec<(FrameKey, PixelStats)>,
    /// `base` at preview widths.
    previews: Vec<HdrImage>,
    /// A preview times a factor.
    preview_scaled: HdrImage,
    preview_scaled_key: Option<(usize, u64)>,
    /// The last frame, for the pixel inspector.
    frame: DisplayImage,
    frame_key: Option<FrameKey>,
    /// Scratch display image for full-resolution pixel counts.
    scratch: DisplayImage,
}

impl Viewer {
    pub fn new(
        path: PathBuf,
        base: HdrImage,
        base_scale: f64,
        conditions: ViewingConditions,
        defaults: Defaults,
    ) -> Self {
        Viewer {
            path,
            base,
            base_scale,
            conditions,
            defaults,
            factors: Vec::new(),
            scaled: HdrImage::zeros(0, 0),
            scaled_factor: None,
            plans: Vec::new(),
            stats: Vec::new(),
            previews: Vec::new(),
            preview_scaled: HdrImage::zeros(0, 0),
            preview_scaled_key: None,
            frame: DisplayImage::default(),
            frame_key: None,
            scratch: DisplayImage::default(),
        }
    }

    pub fn width(&self) -> usize {
        self.base.width
    }

    /// Forget every cached result (after a request panicked half-way).
    pub fn clear_caches(&mut self) {
        self.scaled_factor = None;
        self.factors.clear();
        self.plans.clear();
        self.stats.clear();
        self.previews.clear();
        self.preview_scaled_key = None;
        self.frame_key = None;
    }

    /// The factor that puts the scene at `level` (its highest visible luminance),
    /// [`HdrImage::peak_factor`] as `visadapt map --peak` uses it; 1 for the level the
    /// server started at.
    fn factor(&mut self, level: Option<f64>) -> Outcome<f64> {
        let Some(level) = level else { return Ok(1.0) };
        if let Some((_, f)) = self.factors.iter().find(|(k, _)| *k == level.to_bits()) {
            return Ok(*f);
        }
        let f = self
            .base
            .peak_factor(level, self.conditions.hot_pixel_fraction)
            .map_err(|e| match e {
                visadapt::Error::InvalidParameter { reason, .. } => {
                    Failure::BadRequest(format!("{}: peak {level}: {reason}", self.path.display()))
                }
                e => e.into(),
            })?;
        if self.factors.len() == PLANS_KEPT {
            self.factors.remove(0);
        }
        self.factors.push((level.to_bits(), f));
        Ok(f)
    }

    fn ensure_scaled(&mut self, factor: f64) {
        if self.scaled_factor != Some(factor) {
            self.scaled.clone_from(&self.base);
            if factor != 1.0 {
                self.scaled.scale(factor as f32);
            }
            self.scaled_factor = Some(factor);
        }
    }

    fn conditions(&self, p: &Params) -> ViewingConditions {
        ViewingConditions {
            display_max_cd_m2: p.display_max_cd_m2,
            acuity: p.acuity,
            view: p
                .fov_deg
                .map(|fov| View::perspective(fov, self.base.width, self.base.height))
                .or(self.defaults.view),
            ..self.conditions.clone()
        }
    }

    /// `operator::plan` of the scene times `factor`, cached.
    fn plan(&mut self, factor: f64, p: &Params) -> Outcome<(PlanKey, Report)> {
        let key = (
            factor.to_bits(),
            p.display_max_cd_m2.to_bits(),
            p.fov_deg.map(f64::to_bits),
            p.acuity,
        );
        if let Some(i) = self.plans.iter().position(|(k, _)| *k == key) {
            let entry = self.plans.remove(i);
            self.plans.push(entry.clone());
            return Ok(entry);
        }
        let conditions = self.conditions(p);
        conditions.validate()?;
        self.ensure_scaled(factor);
        let report = operator::plan(&self.scaled, &conditions)?;
        if self.plans.len() == PLANS_KEPT {
            self.plans.remove(0);
        }
        self.plans.push((key, report.clone()));
        Ok((key, report))
    }

    fn situation(&mut self, p: &Params) -> Outcome<Situation> {
        let scale = self.factor(p.peak_cd_m2)?;
        let (plan_key, after) = self.plan(scale, p)?;
        let eye = match p.switch {
            None => None,
            Some((from, t)) => {
                let before_scale = self.factor(Some(from))?;
                let (_, before) = self.plan(before_scale, p)?;
                let mut eye = Adaptation::adapted(
                    before.world_adaptation_cd_m2,
                    before.world_adaptation_scotopic_cd_m2,
                )?;
                eye.step_to(0.0, &after)?;
                eye.step_to(t, &after)?;
                Some(eye)
            }
        };
        let model = eye.as_ref().map_or(after.mapping, |e| e.mapping(&after));
        Ok(Situation {
            scale,
            after,
            eye,
            model,
            plan_key,
        })
    }

    fn frame_key(s: &Situation, p: &Params, width: usize) -> FrameKey {
        let switch = p.switch.map(|(f, t)| (f.to_bits(), t.to_bits()));
        (s.plan_key, switch, width, p.rendering)
    }

    fn width_of(&self, p: &Params) -> Outcome<usize> {
        match p.width {
            None => Ok(self.base.width),
            Some(w) if (1..=self.base.width).contains(&w) => Ok(w),
            Some(w) => Err(Failure::BadRequest(format!(
                "invalid width {w}: must be between 1 and the image width {}",
                self.base.width
            ))),
        }
    }

    /// Render the frame of `p` into `self.frame` (or find it there).
    fn render(&mut self, p: &Params) -> Outcome<Situation> {
        let s = self.situation(p)?;
        let width = self.width_of(p)?;
        let key = Self::frame_key(&s, p, width);
        if self.frame_key == Some(key) {
            return Ok(s);
        }
        self.frame_key = None;
        let mapping = s.mapping(p.rendering);
        if width == self.base.width {
            self.ensure_scaled(s.scale);
            let stats = operator::apply_into(&self.scaled, &mapping, &mut self.frame);
            if p.rendering == Rendering::Model {
                self.remember_stats(key, stats);
            }
        } else {
            let preview_key = (width, s.scale.to_bits());
            if self.preview_scaled_key != Some(preview_key) {
                let i = self.preview(width)?;
                self.preview_scaled.clone_from(&self.previews[i]);
                self.preview_scaled.scale(s.scale as f32);
                self.preview_scaled_key = Some(preview_key);
            }
            let mapping = preview::mapping_at_width(&mapping, self.base.width, width);
            operator::apply_into(&self.preview_scaled, &mapping, &mut self.frame);
        }
        self.frame_key = Some(key);
        Ok(s)
    }

    /// Index in `self.previews` of `base` at `width` pixels wide.
    fn preview(&mut self, width: usize) -> Outcome<usize> {
        if let Some(i) = self.previews.iter().position(|p| p.width == width) {
            return Ok(i);
        }
        let mut small = if self.previews.len() == PREVIEWS_KEPT {
            self.previews.remove(0)
        } else {
            HdrImage::zeros(0, 0)
        };
        preview::downsample_into(&self.base, width, &mut small)?;
        self.previews.push(small);
        Ok(self.previews.len() - 1)
    }

    fn remember_stats(&mut self, key: FrameKey, stats: PixelStats) {
        if !self.stats.iter().any(|(k, _)| *k == key) {
            if self.stats.len() == PLANS_KEPT {
                self.stats.remove(0);
            }
            self.stats.push((key, stats));
        }
    }

    /// The frame of `p` as an 8-bit sRGB PNG.
    pub fn frame_png(&mut self, p: &Params) -> Outcome<Vec<u8>> {
        self.render(p)?;
        let mut png = Vec::new();
        visadapt::io::display::write_png(&self.frame, 8, &mut png)
            .map_err(|e| Failure::Internal(e.to_string()))?;
        Ok(png)
    }

    /// The report of `p`: the keys and values of `visadapt map --json` for the scene at the
    /// frame's level (pixel counts at full resolution), and during a time course the
    /// observer's state under `time_course`.
    pub fn report(&mut self, p: &Params) -> Outcome<Value> {
        let s = self.situation(p)?;
        let key = Self::frame_key(&s, p, self.base.width);
        let key = (key.0, key.1, key.2, Rendering::Model);
        let stats = match self.stats.iter().find(|(k, _)| *k == key) {
            Some((_, stats)) => *stats,
            None => {
                self.ensure_scaled(s.scale);
                let stats = operator::apply_into(&self.scaled, &s.model, &mut self.scratch);
                self.remember_stats(key, stats);
                stats
            }
        };
        let mut json = visadapt::report::map_json(&s.after, &stats, self.base_scale * s.scale);
        if let (Some(eye), Some((from, t))) = (&s.eye, p.switch) {
            let m = &s.model;
            json["time_course"] = json!({
                "from_cd_m2": from,
                "to_cd_m2": p.peak_cd_m2.unwrap_or(s.after.highest_visible_cd_m2),
                "t_seconds": t,
                "adapted": eye.is_adapted(),
                "cone_threshold_cd_m2": eye.cone_threshold_cd_m2(),
                "rod_threshold_scotopic_cd_m2": eye.rod_threshold_scotopic_cd_m2(),
                "cone_excess_log": eye.cone_excess_log(),
                "rod_excess_log": eye.rod_excess_log(),
                "photopic_scale": m.photopic_scale,
                "scotopic_scale": m.scotopic_scale,
                "rod_weight": m.rod_weight,
                "photopic_offset_cd_m2": m.photopic_offset_cd_m2,
                "scotopic_offset_cd_m2": m.scotopic_offset_cd_m2,
                "acuity_cycles_per_degree": eye.acuity_cycles_per_degree(),
                "snellen": visadapt::acuity::snellen(eye.acuity_cycles_per_degree()),
            });
        }
        Ok(json)
    }

    /// Pixel (`x`, `y`) of the full-resolution scene: its luminances, what the frame of `p`
    /// shows there, and how visible a change of `change` times its luminance is.
    pub fn pixel(&mut self, p: &Params, x: usize, y: usize, change: f64) -> Outcome<Value> {
        let (w, h) = (self.base.width, self.base.height);
        if x >= w || y >= h {
            return Err(Failure::BadRequest(format!(
                "invalid pixel ({x}, {y}): outside the {w}x{h} image"
            )));
        }
        let s = self.render(p)?;
        self.ensure_scaled(s.scale);
        let probe = preview::probe(&self.scaled, x, y, &s.sensitivity(), change)?;
        let (fx, fy) = (
            (x * self.frame.width / w).min(self.frame.width - 1),
            (y * self.frame.height / h).min(self.frame.height - 1),
        );
        let shown = preview::displayed(&self.frame, fx, fy)?;
        Ok(json!({
            "x": x,
            "y": y,
            "luminance_cd_m2": probe.luminance_cd_m2,
            "scotopic_cd_m2": probe.scotopic_cd_m2,
            "threshold_cd_m2": probe.threshold_cd_m2,
            "change": probe.relative_change,
            "change_jnd": probe.change_jnd,
            "change_visible": probe.change_visible,
            "display": {
                "x": fx,
                "y": fy,
                "linear_rgb": shown.linear_rgb,
                "srgb8": shown.srgb8,
                "luminance_cd_m2": shown.luminance_cd_m2,
            },
        }))
    }
}
