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
use crate::operator::{self, Mapping, PixelStats, Report, ViewingConditions};
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
    eye.step_to(0.0, &after)?;
    let mut now = 0.0;
    for (i, &t) in sequence.times_seconds.iter().enumerate() {
        eye.step_to(t - now, &after)?;
        now = t;
        let (mapping, stats) =
            operator::apply_state_into(&retina, &after, &eye, conditions, &mut out)?;
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
        let too_big = || Error::Unsupported(format!("{width}x{height} is too large for PNG"));
        let (w, h) = (
            u32::try_from(width).map_err(|_| too_big())?,
            u32::try_from(height).map_err(|_| too_big())?,
        );
        if frames == 0 || delay_ms == 0 || width == 0 || height == 0 {
            return Err(Error::invalid(
                "apng",
                format!("{frames} frames of {width}x{height}, {delay_ms} ms"),
                "needs at least one non-empty frame and a positive delay",
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
        enc.set_frame_delay(delay_ms, 1000).map_err(png_error)?;
        let writer = enc.write_header().map_err(png_error)?;
        Ok(ApngWriter {
            path: path.to_path_buf(),
            tmp,
            writer,
            width,
            height,
            frames,
            pushed: 0,
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
