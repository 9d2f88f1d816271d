//! The server's state: the decoded scene and what it keeps between requests (the scene at
//! the current light level, with glare its retinal image, the planned reports, preview
//! copies, with local adaptation the adaptation maps, the last frame), so that a slider
//! move costs one preview `apply` and a PNG encode. All model work is the library's: the
//! frames go through the operator's stages as `sequence` drives them (the scene stages and
//! the plan once per image and light level, `operator::prepare`; the local adaptation map
//! once per plan, `operator::local_map`; then the mapping of each frame).

use serde_json::{Value, json};
use std::path::PathBuf;
use visadapt::glare::{self, Glare};
use visadapt::local::{self, AdaptationMap, LocalAdaptation, LocalMapping, LocalReport};
use visadapt::operator::{self, AdaptationMode, Mapping, PixelStats, Report, ViewingConditions};
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
    /// Veiling glare in the observer's eye (the server's [`Glare`] options).
    pub glare: bool,
    /// Local adaptation (the server's [`LocalAdaptation`] options) instead of the paper's
    /// global adaptation.
    pub local: bool,
}

impl Params {
    /// The parameters the frame is made with: a plain exposure is a camera's picture of
    /// the scene, the same whatever the observer's glare and adaptation.
    fn effective(&self) -> Params {
        match self.rendering {
            Rendering::Model => self.clone(),
            Rendering::Exposure => Params {
                glare: false,
                local: false,
                ..self.clone()
            },
        }
    }
}

/// The defaults of the parameters (the `serve` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct Defaults {
    pub display_max_cd_m2: f64,
    /// The view of `--fov` and `--projection`; `None` for the file's.
    pub view: Option<View>,
    pub acuity: bool,
    /// `--glare`.
    pub glare: bool,
    /// `--adaptation local`.
    pub local: bool,
}

/// Exact keys for caches of f64 parameters: the light level's factor, the display
/// maximum, the field of view, acuity, glare.
type PlanKey = (u64, u64, Option<u64>, bool, bool);
/// A plan, the time course, the width, what is rendered, local adaptation.
type FrameKey = (PlanKey, Option<(u64, u64)>, usize, Rendering, bool);
/// The width, the level's factor, and with glare the plan whose retinal image it reduces.
type PreviewKey = (usize, u64, Option<PlanKey>);

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
    /// The conditions of the `serve` flags; a request sets display, view, acuity, glare and
    /// the adaptation mode.
    conditions: ViewingConditions,
    pub defaults: Defaults,
    /// The observer's eye when glare is on (`--age`, `--pigmentation`).
    glare: Glare,
    /// Local adaptation's options when it is on (`--adaptation-radius`).
    local: LocalAdaptation,
    /// [`HdrImage::peak_factor`] of `base` for the levels asked for.
    factors: Vec<(u64, f64)>,
    /// `base` times `scaled_factor`, at full resolution.
    scaled: HdrImage,
    scaled_factor: Option<f64>,
    /// With glare, the retinal image (`operator::prepare_reusing`) of the plan
    /// `retina_key`, and the glare stage's workspace (kept for the next plan: same size
    /// and view).
    retina: HdrImage,
    retina_key: Option<PlanKey>,
    scene_workspace: glare::Workspace,
    /// The local adaptation map of a plan's full-resolution scene.
    full_map: Option<(PlanKey, AdaptationMap)>,
    /// The local adaptation map of a plan's preview at a width.
    preview_map: Option<((PlanKey, usize), AdaptationMap)>,
    plans: Vec<(PlanKey, Report)>,
    /// Pixel counts of full-resolution model frames, for the report.
    stats: Vec<(FrameKey, PixelStats)>,
    /// `base` at preview widths.
    previews: Vec<HdrImage>,
    /// A preview times a factor (with glare, the retinal image reduced).
    preview_scaled: HdrImage,
    preview_scaled_key: Option<PreviewKey>,
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
        glare: Glare,
        local: LocalAdaptation,
    ) -> Self {
        Viewer {
            path,
            base,
            base_scale,
            conditions,
            defaults,
            glare,
            local,
            factors: Vec::new(),
            scaled: HdrImage::zeros(0, 0),
            scaled_factor: None,
            retina: HdrImage::zeros(0, 0),
            retina_key: None,
            scene_workspace: glare::Workspace::new(),
            full_map: None,
            preview_map: None,
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
        self.retina_key = None;
        self.full_map = None;
        self.preview_map = None;
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
            glare: p.glare.then_some(self.glare),
            adaptation: if p.local {
                AdaptationMode::Local(self.local)
            } else {
                AdaptationMode::Global
            },
            ..self.conditions.clone()
        }
    }

    /// The report of `operator::prepare` (the glare stage when `p` has it, then
    /// `operator::plan`) of the scene times `factor`, cached; with glare the retinal image
    /// it made is kept as the current one.
    fn plan(&mut self, factor: f64, p: &Params) -> Outcome<(PlanKey, Report)> {
        let key = (
            factor.to_bits(),
            p.display_max_cd_m2.to_bits(),
            p.fov_deg.map(f64::to_bits),
            p.acuity,
            p.glare,
        );
        if let Some(i) = self.plans.iter().position(|(k, _)| *k == key) {
            let entry = self.plans.remove(i);
            self.plans.push(entry.clone());
            return Ok(entry);
        }
        let report = self.prepare(factor, key, p)?;
        if self.plans.len() == PLANS_KEPT {
            self.plans.remove(0);
        }
        self.plans.push((key, report.clone()));
        Ok((key, report))
    }

    /// `operator::prepare` of the scene times `factor` under the conditions of `p`: the
    /// report, and with glare the retinal image, kept as that of `key`.
    fn prepare(&mut self, factor: f64, key: PlanKey, p: &Params) -> Outcome<Report> {
        let conditions = self.conditions(p);
        conditions.validate()?;
        self.ensure_scaled(factor);
        if !p.glare {
            return Ok(operator::plan(&self.scaled, &conditions)?);
        }
        self.retina_key = None;
        let (retina, report) =
            operator::prepare_reusing(&self.scaled, &conditions, &mut self.scene_workspace)?;
        self.retina.clone_from(retina);
        self.retina_key = Some(key);
        Ok(report)
    }

    /// The full-resolution scene the frame of `s` maps, at its light level: the rescaled
    /// scene, or with glare its retinal image (made again if another plan's replaced it).
    fn scene(&mut self, s: &Situation, p: &Params) -> Outcome<&HdrImage> {
        self.ensure_scaled(s.scale);
        if !p.glare {
            return Ok(&self.scaled);
        }
        if self.retina_key != Some(s.plan_key) {
            self.prepare(s.scale, s.plan_key, p)?;
        }
        Ok(&self.retina)
    }

    /// The local adaptation map of the full-resolution scene of `s`, cached per plan.
    fn full_map(&mut self, s: &Situation, p: &Params) -> Outcome<&AdaptationMap> {
        if self.full_map.as_ref().map(|(k, _)| *k) != Some(s.plan_key) {
            self.full_map = None;
            let conditions = self.conditions(p);
            let options = self.local;
            let image = self.scene(s, p)?;
            let map = operator::local_map(image, &s.after, &conditions, &options)?;
            self.full_map = Some((s.plan_key, map));
        }
        Ok(&self.full_map.as_ref().expect("just made").1)
    }

    fn situation(&mut self, p: &Params) -> Outcome<Situation> {
        let scale = self.factor(p.peak_cd_m2)?;
        // The level before a switch first, so that with glare the retinal image kept is
        // the current level's.
        let before = match p.switch {
            None => None,
            Some((from, _)) => {
                let before_scale = self.factor(Some(from))?;
                Some(self.plan(before_scale, p)?.1)
            }
        };
        let (plan_key, after) = self.plan(scale, p)?;
        let eye = match (p.switch, before) {
            (Some((_, t)), Some(before)) => {
                let mut eye = Adaptation::adapted(
                    before.world_adaptation_cd_m2,
                    before.world_adaptation_scotopic_cd_m2,
                )?;
                eye.step_to(0.0, &after)?;
                eye.step_to(t, &after)?;
                Some(eye)
            }
            _ => None,
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
        (s.plan_key, switch, width, p.rendering, p.local)
    }

    /// The per-pixel mapping of local adaptation for `s` on `map` (whose report, at the
    /// map's resolution, is `report`): the steady state, or the Eq. 8-9 mapping of the
    /// observer's state during a time course.
    fn local_mapping(&self, s: &Situation, map: &AdaptationMap, report: &Report) -> LocalMapping {
        let rods = self.local.rod_saturation;
        match &s.eye {
            Some(eye) => LocalMapping::for_time_course(map, eye, report, rods),
            None => LocalMapping::steady_state(map, report, rods),
        }
    }

    /// Map the full-resolution scene of `s` into `out` as `p` asks.
    fn map_full(
        &mut self,
        s: &Situation,
        p: &Params,
        out: &mut DisplayImage,
    ) -> Outcome<PixelStats> {
        if p.local {
            self.scene(s, p)?;
            self.full_map(s, p)?;
            let (_, map) = self.full_map.as_ref().expect("just made");
            let mapping = self.local_mapping(s, map, &s.after);
            let image = if p.glare { &self.retina } else { &self.scaled };
            return Ok(local::apply_into(image, map, &mapping, out));
        }
        let mapping = s.mapping(p.rendering);
        let image = self.scene(s, p)?;
        Ok(operator::apply_into(image, &mapping, out))
    }

    /// Map a preview `width` pixels wide of the scene of `s` into `out` as `p` asks: the
    /// scene (with glare its retinal image) reduced by a box average, the plan's report
    /// taken to the preview's pixels, and with local adaptation the preview's own map.
    fn map_preview(
        &mut self,
        s: &Situation,
        p: &Params,
        width: usize,
        out: &mut DisplayImage,
    ) -> Outcome<()> {
        let preview_key = (width, s.scale.to_bits(), p.glare.then_some(s.plan_key));
        if self.preview_scaled_key != Some(preview_key) {
            self.preview_scaled_key = None;
            if p.glare {
                self.scene(s, p)?;
                preview::downsample_into(&self.retina, width, &mut self.preview_scaled)?;
            } else {
                let i = self.preview(width)?;
                self.preview_scaled.clone_from(&self.previews[i]);
                self.preview_scaled.scale(s.scale as f32);
            }
            self.preview_scaled_key = Some(preview_key);
        }
        if !p.local {
            let mapping =
                preview::mapping_at_width(&s.mapping(p.rendering), self.base.width, width);
            operator::apply_into(&self.preview_scaled, &mapping, out);
            return Ok(());
        }
        let report = preview::report_at_width(&s.after, width);
        let map_key = (s.plan_key, width);
        if self.preview_map.as_ref().map(|(k, _)| *k) != Some(map_key) {
            self.preview_map = None;
            let map = operator::local_map(
                &self.preview_scaled,
                &report,
                &self.conditions(p),
                &self.local,
            )?;
            self.preview_map = Some((map_key, map));
        }
        let (_, map) = self.preview_map.as_ref().expect("just made");
        let mapping = self.local_mapping(s, map, &report);
        local::apply_into(&self.preview_scaled, map, &mapping, out);
        Ok(())
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
        let p = &p.effective();
        let s = self.situation(p)?;
        let width = self.width_of(p)?;
        let key = Self::frame_key(&s, p, width);
        if self.frame_key == Some(key) {
            return Ok(s);
        }
        self.frame_key = None;
        let mut frame = std::mem::take(&mut self.frame);
        let done = if width == self.base.width {
            self.map_full(&s, p, &mut frame).map(|stats| {
                if p.rendering == Rendering::Model {
                    self.remember_stats(key, stats);
                }
            })
        } else {
            self.map_preview(&s, p, width, &mut frame)
        };
        self.frame = frame;
        done?;
        self.frame_key = Some(key);
        Ok(s)
    }

    /// What a frame of `p` shows, in a few words (the page's status line).
    pub fn showing(&self, p: &Params) -> String {
        let p = p.effective();
        if p.rendering == Rendering::Exposure {
            return "plain exposure (no observer: no glare, no adaptation)".to_string();
        }
        let adaptation = if p.local {
            format!("local adaptation (radius {} deg)", self.local.radius_deg)
        } else {
            "global adaptation (the paper's)".to_string()
        };
        let glare = if p.glare {
            format!(
                "veiling glare (age {}, pigmentation {})",
                self.glare.age_years, self.glare.pigmentation
            )
        } else {
            "no glare".to_string()
        };
        format!("{adaptation}, {glare}")
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
        let p = &Params {
            rendering: Rendering::Model,
            ..p.clone()
        };
        let s = self.situation(p)?;
        let key = Self::frame_key(&s, p, self.base.width);
        let stats = match self.stats.iter().find(|(k, _)| *k == key) {
            Some((_, stats)) => *stats,
            None => {
                let mut scratch = std::mem::take(&mut self.scratch);
                let stats = self.map_full(&s, p, &mut scratch);
                self.scratch = scratch;
                let stats = stats?;
                self.remember_stats(key, stats);
                stats
            }
        };
        let mut after = s.after.clone();
        if p.local {
            let rods = self.local.rod_saturation;
            after.local = Some(LocalReport::of(self.full_map(&s, p)?, rods));
        }
        let mut json = visadapt::report::map_json(&after, &stats, self.base_scale * s.scale);
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
        self.render(p)?;
        // The observer's thresholds are the model's whatever the frame shows.
        let p = &Params {
            rendering: Rendering::Model,
            ..p.clone()
        };
        let s = self.situation(p)?;
        let sensitivity = if p.local {
            Sensitivity::local(self.full_map(&s, p)?, y * w + x, s.eye.as_ref())
        } else {
            s.sensitivity()
        };
        // With glare, the luminance reaching the retina there (the scene's plus the veil).
        let retinal = preview::probe(self.scene(&s, p)?, x, y, &sensitivity, change)?;
        self.ensure_scaled(s.scale);
        let probe = preview::probe(&self.scaled, x, y, &sensitivity, change)?;
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
            "retinal_cd_m2": retinal.luminance_cd_m2,
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
