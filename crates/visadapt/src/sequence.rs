//! Image sequences of the time course of adaptation, as in the paper's Fig. 12, and a
//! streaming animated-PNG writer for them.
//!
//! Ferwerda et al. 1996, Sec. 5 and Fig. 12: a scene is lit at one level until the observer
//! is adapted, then switched to another; the frames show the scene at intervals after the
//! switch, each through the Eq. 8–9 mapping of the observer's state at that moment
//! ([`timecourse`](crate::timecourse)). "Lit at L" means, as for `visadapt map --peak`,
//! that the scene is rescaled so that its highest visible photopic luminance
//! ([`highest_visible`]) is `L` cd/m²; the world adaptation of each level then follows
//! Sec. 4.4 ([`operator::plan`]).
//!
//! The first frame (index 0) shows the scene at the first level, fully adapted (the first
//! frame of each row of Fig. 12); frame `i ≥ 1` shows it `times_seconds[i−1]` after the
//! switch. The paper gives the levels and the last time of its two sequences; the
//! intermediate times of [`Sequence::figure_12a`] and [`Sequence::figure_12b`] are ours.
//!
//! Memory does not grow with the number of frames: the scene, rescaled in place
//! ([`render_owned`]; [`render`] works on a copy), and one display image are reused, and
//! each frame is handed to the caller as soon as it is done.

use crate::adaptation::highest_visible;
use crate::io::display::{png_error, to_srgb8};
use crate::io::output::PendingFile;
use crate::local::AdaptationMap;
use crate::operator::{self, AdaptationMode, Mapping, PixelStats, Report, ViewingConditions};
use crate::timecourse::{Adaptation, check_times};
use crate::{DisplayImage, Error, HdrImage, Result};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Fig. 12a, first level: "the scene is illuminated to a level of 0.1 cd/m²" (Sec. 5).
pub const FIGURE_12A_FROM_CD_M2: f64 = 0.1;
/// Fig. 12a, second level: "the light level has just been raised to 5623 cd/m²" (Sec. 5;
/// 10^3.75, Baker's background of Fig. 9).
pub const FIGURE_12A_TO_CD_M2: f64 = 5623.0;
/// Fig. 12a, frame times after the switch, seconds. The paper's last frame is "after 75
/// seconds of light adaptation" (Sec. 5); the others are spaced by us to show the fast
/// cone recovery.
pub const FIGURE_12A_TIMES_SECONDS: [f64; 6] = [0.0, 1.0, 4.0, 15.0, 30.0, 75.0];
/// Fig. 12b, first level: "illuminated to a level of 1412 cd/m²" (Sec. 5).
pub const FIGURE_12B_FROM_CD_M2: f64 = 1412.0;
/// Fig. 12b, second level: "just been reduced to 0.1 cd/m²" (Sec. 5).
pub const FIGURE_12B_TO_CD_M2: f64 = 0.1;
/// Fig. 12b, frame times after the switch, seconds. The paper's last frame is "after more
/// than 3 minutes of dark adaptation" (Sec. 5): 3.5 min; the others are ours.
pub const FIGURE_12B_TIMES_SECONDS: [f64; 6] = [0.0, 20.0, 45.0, 90.0, 150.0, 210.0];

/// A scene lit at one level, then switched to another, seen at a list of times after the
/// switch.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// Highest visible luminance before the switch, cd/m².
    pub from_cd_m2: f64,
    /// Highest visible luminance after the switch, cd/m².
    pub to_cd_m2: f64,
    /// Times after the switch, seconds, sorted, non-negative.
    pub times_seconds: Vec<f64>,
}

impl Sequence {
    /// A sequence, with its values checked: positive finite levels, sorted non-negative
    /// finite times.
    pub fn new(from_cd_m2: f64, to_cd_m2: f64, times_seconds: Vec<f64>) -> Result<Self> {
        for (name, v) in [("from", from_cd_m2), ("to", to_cd_m2)] {
            crate::check_luminance(name, v)?;
        }
        check_times(&times_seconds)?;
        Ok(Sequence {
            from_cd_m2,
            to_cd_m2,
            times_seconds,
        })
    }

    /// The paper's light-adaptation sequence, Fig. 12a: 0.1 → 5623 cd/m², up to 75 s.
    pub fn figure_12a() -> Self {
        Sequence {
            from_cd_m2: FIGURE_12A_FROM_CD_M2,
            to_cd_m2: FIGURE_12A_TO_CD_M2,
            times_seconds: FIGURE_12A_TIMES_SECONDS.to_vec(),
        }
    }

    /// The paper's dark-adaptation sequence, Fig. 12b: 1412 → 0.1 cd/m², up to 3.5 min.
    pub fn figure_12b() -> Self {
        Sequence {
            from_cd_m2: FIGURE_12B_FROM_CD_M2,
            to_cd_m2: FIGURE_12B_TO_CD_M2,
            times_seconds: FIGURE_12B_TIMES_SECONDS.to_vec(),
        }
    }

    /// Number of frames [`render`] produces: the adapted first frame plus one per time.
    pub fn frame_count(&self) -> usize {
        self.times_seconds.len() + 1
    }

    /// The label of frame `index` for [`crate::label::draw`]: the light level (the scene's
    /// highest visible luminance) and the time after the switch, e.g. `"0.1 cd/m², adapted"`
    /// for frame 0 and `"5623 cd/m², t = 75 s"` (`"t = 3.5 min"` from 2 minutes on) for
    /// the others; `None` past the last frame.
    ///
    /// ```
    /// use visadapt::sequence::Sequence;
    /// let s = Sequence::figure_12b();
    /// assert_eq!(s.frame_label(0).unwrap(), "1412 cd/m², adapted");
    /// assert_eq!(s.frame_label(2).unwrap(), "0.1 cd/m², t = 20 s");
    /// assert_eq!(s.frame_label(6).unwrap(), "0.1 cd/m², t = 3.5 min");
    /// # Ok::<(), visadapt::Error>(())
    /// ```
    pub fn frame_label(&self, index: usize) -> Option<String> {
        if index == 0 {
            return Some(format!("{} cd/m², adapted", self.from_cd_m2));
        }
        let t = *self.times_seconds.get(index - 1)?;
        let when = if t < 120.0 {
            format!("{t} s")
        } else {
            let minutes = t / 60.0;
            if minutes.fract() == 0.0 {
                format!("{minutes} min")
            } else {
                format!("{minutes:.1} min")
            }
        };
        Some(format!("{} cd/m², t = {when}", self.to_cd_m2))
    }

    /// How an animation of the sequence lasting about `playback_seconds` shows its frames:
    /// in the real time of the sequence, sped up by one factor.
    ///
    /// Frame `i ≥ 1` (at `times_seconds[i−1]`) stays until the next frame's time, so its
    /// delay is the time step to the next frame divided by [`Playback::speedup`]. The first
    /// frame (the adapted state before the switch) and the last (the state the sequence
    /// ends in, with no next time) have no time step of their own: each is held for
    /// [`PLAYBACK_HOLD_FRACTION`] of the playback, and the frames between share the rest in
    /// proportion to their time steps. A sequence whose times span no time (one time, or
    /// all equal) shows every frame for the same share. No delay is shorter than
    /// [`MIN_FRAME_DELAY_MS`] (a step that short is lengthened, and the playback with
    /// it), and `playback_seconds` must lie in [`PLAYBACK_SECONDS_RANGE`].
    ///
    /// ```
    /// use visadapt::sequence::Sequence;
    /// // Fig. 12a: 0, 1, 4, 15, 30 and 75 s after the switch, played in 6 s.
    /// let p = Sequence::figure_12a().playback(6.0)?;
    /// assert_eq!(p.delays_ms, [1000, 53, 160, 587, 800, 2400, 1000]);
    /// assert_eq!(p.speedup, Some(18.75)); // 75 s of the sequence in 4 s
    /// # Ok::<(), visadapt::Error>(())
    /// ```
    pub fn playback(&self, playback_seconds: f64) -> Result<Playback> {
        if !PLAYBACK_SECONDS_RANGE.contains(&playback_seconds) {
            return Err(Error::invalid(
                "playback seconds",
                playback_seconds,
                format!(
                    "must be between {} and {}",
                    PLAYBACK_SECONDS_RANGE.start(),
                    PLAYBACK_SECONDS_RANGE.end()
                ),
            ));
        }
        check_times(&self.times_seconds)?;
        let total_ms = 1000.0 * playback_seconds;
        let ms = |d: f64| d.round().max(f64::from(MIN_FRAME_DELAY_MS)) as u16;
        let t = &self.times_seconds;
        let span = match (t.first(), t.last()) {
            (Some(first), Some(last)) if last > first => last - first,
            _ => {
                let share = ms(total_ms / self.frame_count() as f64);
                return Ok(Playback {
                    delays_ms: vec![share; self.frame_count()],
                    speedup: None,
                });
            }
        };
        let hold_ms = PLAYBACK_HOLD_FRACTION * total_ms;
        // Seconds of the sequence per second of the playback between the holds.
        let speedup = span / ((total_ms - 2.0 * hold_ms) / 1000.0);
        let mut delays_ms = Vec::with_capacity(self.frame_count());
        delays_ms.push(ms(hold_ms));
        delays_ms.extend(t.windows(2).map(|w| ms(1000.0 * (w[1] - w[0]) / speedup)));
        delays_ms.push(ms(hold_ms));
        Ok(Playback {
            delays_ms,
            speedup: Some(speedup),
        })
    }
}

/// Share of an animation's playback for which its first frame (before the switch) and its
/// last frame are each held (see [`Sequence::playback`]): a sixth, 1 s of the default 6 s,
/// so that the two states the sequence goes between are seen, and two thirds of the
/// playback is the sequence's own time. A project choice.
pub const PLAYBACK_HOLD_FRACTION: f64 = 1.0 / 6.0;

/// The shortest frame delay of an animation, ms: browsers play GIF and APNG frames of 10 ms
/// or less at 100 ms (Chromium's and Firefox's long-standing GIF rule, applied to APNG
/// too), so a shorter real-time step would be shown ten times too long; 20 ms is also
/// the frame time of a 50 Hz display.
pub const MIN_FRAME_DELAY_MS: u16 = 20;

/// The playback lengths [`Sequence::playback`] accepts, seconds: up to a minute, so that
/// a frame's delay (at most two thirds of it) fits the APNG's 16-bit milliseconds.
pub const PLAYBACK_SECONDS_RANGE: std::ops::RangeInclusive<f64> = 0.1..=60.0;

/// The frame delays of an animated [`Sequence`] ([`Sequence::playback`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Playback {
    /// Per frame, how long it is shown, ms (one per [`Sequence::frame_count`]).
    pub delays_ms: Vec<u16>,
    /// Seconds of the sequence per second of playback, for the frames between the first
    /// and the last; `None` when the times span no time.
    pub speedup: Option<f64>,
}

impl Playback {
    /// The length of the animation, seconds: the sum of its delays.
    pub fn seconds(&self) -> f64 {
        self.delays_ms.iter().map(|&d| f64::from(d)).sum::<f64>() / 1000.0
    }
}

/// One rendered frame of a [`Sequence`].
#[derive(Debug)]
pub struct Frame<'a> {
    /// 0 for the adapted first frame, `i` for `times_seconds[i−1]`.
    pub index: usize,
    /// Seconds after the switch; `None` for the first frame.
    pub t_seconds: Option<f64>,
    /// The display image.
    pub image: &'a DisplayImage,
    /// The mapping it was made with.
    pub mapping: Mapping,
    /// The observer's state.
    pub adaptation: &'a Adaptation,
    /// The steady-state report of the scene at the current level.
    pub report: &'a Report,
    /// Pixels that needed a rule applied.
    pub stats: PixelStats,
}

/// Render a [`Sequence`] of `scene` (any units: it is rescaled to each level), calling
/// `on_frame` for each frame as soon as it is done (frame 0 first). Stops at the first
/// error, from the model or from `on_frame`.
///
/// ```
/// use visadapt::{HdrImage, operator::ViewingConditions, sequence::{render, Sequence}};
/// let mut scene = HdrImage::zeros(16, 16);
/// for i in 0..scene.len() {
///     let l = if i % 2 == 0 { 1.0 } else { 0.2 };
///     (scene.x[i], scene.y[i], scene.z[i]) = (0.95 * l, l, 1.09 * l);
/// }
/// let mut means = Vec::new();
/// render(&scene, &Sequence::figure_12a(), &ViewingConditions::default(), |f| {
///     means.push(f.image.g.iter().sum::<f32>() / f.image.len() as f32);
///     Ok(())
/// })?;
/// assert_eq!(means.len(), 7);
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn render(
    scene: &HdrImage,
    sequence: &Sequence,
    conditions: &ViewingConditions,
    on_frame: impl FnMut(&Frame<'_>) -> Result<()>,
) -> Result<()> {
    scene.check_consistent()?;
    conditions.validate()?;
    render_owned(scene.clone(), sequence, conditions, on_frame)
}

/// [`render`], consuming the scene: it is rescaled to each level in place (the second
/// level from the first, one more rounding of each sample: at most 1 unit in the last place
/// of f32) instead of into a copy, so that the working set is the scene and one display
/// image (with glare, and a copy for the first level's veil).
pub fn render_owned(
    mut scene: HdrImage,
    sequence: &Sequence,
    conditions: &ViewingConditions,
    mut on_frame: impl FnMut(&Frame<'_>) -> Result<()>,
) -> Result<()> {
    scene.check_consistent()?;
    conditions.validate()?;
    let sequence = Sequence::new(
        sequence.from_cd_m2,
        sequence.to_cd_m2,
        sequence.times_seconds.clone(),
    )?;
    let hv = f64::from(highest_visible(&scene.y, conditions.hot_pixel_fraction));
    if hv <= 0.0 {
        return Err(Error::invalid(
            "image",
            format!("{}x{}", scene.width, scene.height),
            "has no visible luminance to rescale",
        ));
    }
    let mut out = DisplayImage::default();

    scene.scale((sequence.from_cd_m2 / hv) as f32);
    scene.absolute_units = true;
    let mut eye = {
        // With glare the veiled scene is a copy: the unveiled one is needed for the second
        // level.
        let (retina, before) = operator::prepare(&scene, conditions)?;
        let eye = Adaptation::adapted(
            before.world_adaptation_cd_m2,
            before.world_adaptation_scotopic_cd_m2,
        )?
        .with_undershoot(conditions.undershoot);
        let (mapping, stats) =
            operator::apply_state_into(&retina, &before, &eye, conditions, &mut out)?;
        drop(retina);
        on_frame(&Frame {
            index: 0,
            t_seconds: None,
            image: &out,
            mapping,
            adaptation: &eye,
            report: &before,
            stats,
        })?;
        eye
    };

    scene.scale((sequence.to_cd_m2 / sequence.from_cd_m2) as f32);
    let (retina, after) = operator::prepare_owned(scene, conditions)?;
    // Every frame from here on is this retina under this plan, so local adaptation's map
    // is the same for all of them: computed once (the first frame's is dropped by now, so
    // the two are never held together).
    let mut map = AdaptationMap::default();
    if let AdaptationMode::Local(options) = conditions.adaptation {
        operator::local_map_into(&retina, &after, conditions, &options, &mut map)?;
    }
    eye.step_to(0.0, &after)?;
    let mut now = 0.0;
    for (i, &t) in sequence.times_seconds.iter().enumerate() {
        eye.step_to(t - now, &after)?;
        now = t;
        let (mapping, stats) =
            operator::apply_state_with_map(&retina, &after, &eye, conditions, &map, &mut out)?;
        on_frame(&Frame {
            index: i + 1,
            t_seconds: Some(t),
            image: &out,
            mapping,
            adaptation: &eye,
            report: &after,
            stats,
        })?;
    }
    Ok(())
}

/// The most frames an [`ApngWriter`] takes: a bound on what a caller's count allocates
/// (2^20, 16 minutes at 1000 frames per second, far beyond a sequence of states).
pub const MAX_APNG_FRAMES: u32 = 1 << 20;

/// An animated PNG (APNG) written one frame at a time, 8-bit sRGB: the file appears, complete,
/// only when [`ApngWriter::finish`] succeeds (it is written to a temporary file beside
/// `path` and renamed, as every output of the library).
pub struct ApngWriter {
    path: PathBuf,
    tmp: PendingFile,
    writer: png::Writer<BufWriter<File>>,
    width: usize,
    height: usize,
    frames: u32,
    pushed: u32,
    delays_ms: Vec<u16>,
}

impl std::fmt::Debug for ApngWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ApngWriter")
            .field("path", &self.path)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frames", &self.frames)
            .field("pushed", &self.pushed)
            .finish()
    }
}

impl ApngWriter {
    /// Start an APNG of `frames` frames of `width × height` pixels, each shown for
    /// `delay_ms` milliseconds, looping forever.
    pub fn create(
        path: &Path,
        width: usize,
        height: usize,
        frames: u32,
        delay_ms: u16,
    ) -> Result<Self> {
        if frames > MAX_APNG_FRAMES {
            return Err(Error::invalid(
                "apng",
                frames,
                format!("frames is more than {MAX_APNG_FRAMES}"),
            ));
        }
        Self::with_delays(path, width, height, &vec![delay_ms; frames as usize])
    }

    /// Start an APNG of `width × height` pixels with one frame per delay, frame `i` shown
    /// for `delays_ms[i]` milliseconds (e.g. [`Playback::delays_ms`]), looping forever.
    pub fn with_delays(
        path: &Path,
        width: usize,
        height: usize,
        delays_ms: &[u16],
    ) -> Result<Self> {
        let too_big = || Error::Unsupported(format!("{width}x{height} is too large for PNG"));
        let (w, h) = (
            u32::try_from(width).map_err(|_| too_big())?,
            u32::try_from(height).map_err(|_| too_big())?,
        );
        let frames = u32::try_from(delays_ms.len())
            .ok()
            .filter(|&n| n <= MAX_APNG_FRAMES)
            .ok_or_else(|| {
                Error::invalid(
                    "apng",
                    delays_ms.len(),
                    format!("frames is more than {MAX_APNG_FRAMES}"),
                )
            })?;
        if frames == 0 || delays_ms.contains(&0) || width == 0 || height == 0 {
            return Err(Error::invalid(
                "apng",
                format!("{frames} frames of {width}x{height}, delays {delays_ms:?} ms"),
                "needs at least one non-empty frame and positive delays",
            ));
        }
        let tmp = PendingFile::create(path)?;
        let file = tmp.file().try_clone()?;
        let mut enc = png::Encoder::new(BufWriter::new(file), w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        enc.set_compression(png::Compression::Fast);
        enc.set_animated(frames, 0).map_err(png_error)?;
        enc.set_frame_delay(delays_ms[0], 1000).map_err(png_error)?;
        let writer = enc.write_header().map_err(png_error)?;
        Ok(ApngWriter {
            path: path.to_path_buf(),
            tmp,
            writer,
            width,
            height,
            frames,
            pushed: 0,
            delays_ms: delays_ms.to_vec(),
        })
    }

    /// Append the next frame; it must have the size given to [`ApngWriter::create`].
    pub fn push(&mut self, image: &DisplayImage) -> Result<()> {
        if (image.width, image.height) != (self.width, self.height) {
            return Err(Error::invalid(
                "apng frame",
                format!("{}x{}", image.width, image.height),
                format!(
                    "differs from the animation's {}x{}",
                    self.width, self.height
                ),
            ));
        }
        if self.pushed == self.frames {
            return Err(Error::invalid(
                "apng frame",
                self.pushed + 1,
                format!("is one more than the {} announced", self.frames),
            ));
        }
        self.writer
            .set_frame_delay(self.delays_ms[self.pushed as usize], 1000)
            .map_err(png_error)?;
        self.writer
            .write_image_data(&to_srgb8(image))
            .map_err(png_error)?;
        self.pushed += 1;
        Ok(())
    }

    /// Close the animation (all announced frames must have been pushed) and move it into
    /// place.
    pub fn finish(self) -> Result<()> {
        let ApngWriter {
            tmp,
            writer,
            frames,
            pushed,
            ..
        } = self;
        if pushed != frames {
            // Dropping `tmp` removes the temporary file.
            return Err(Error::invalid(
                "apng",
                format!("{pushed} frames"),
                format!("{frames} were announced"),
            ));
        }
        writer.finish().map_err(png_error)?;
        tmp.commit()?;
        Ok(())
    }
}
