//! `visadapt video`: a stream of numbered HDR frames through the time course of adaptation.
//!
//! The input is a printf-style pattern with exactly one `%d` (no padding) or `%0Nd`
//! (zero-padded to N digits), as ffmpeg uses, e.g. `frames/f_%04d.exr`: the frames are the
//! files of that directory whose names the pattern produces for some number, in numerical
//! order. They must be consecutive (a gap would make the time step wrong) and all of one
//! size. Globs are not supported.
//!
//! Frame `n` is shown at `n/fps` seconds. The observer starts adapted to the first frame;
//! for every later frame the adaptation state is stepped by `1/fps` to that frame's world
//! adaptation (Sec. 4.4: half its highest visible luminance, photopic and scotopic), and
//! the frame is mapped with the state's Eq. 8–9 mapping. Each output frame is written,
//! atomically, as soon as it is done, to `OUT_DIR/<input stem>.<format>`.
//!
//! The work is a pipeline of three threads joined by bounded queues: a reader decodes
//! frame n+1 while the operator maps frame n and a writer encodes and writes frame n−1.
//! The operator is one thread, so the state is stepped in frame order; the output is the
//! same, byte for byte, as doing one frame after another. HDR frames, display images and
//! the file buffer go round and are reused, so memory does not grow with the number of
//! frames (at most two of each exist at once). On an error, the frames before it are
//! written, nothing after it is, and the error names its frame.

use crate::cli::{VideoArgs, VideoFormat};
use crate::numbers::count;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use visadapt::io::{self, OutputFormat};
use visadapt::operator::{self, ViewingConditions};
use visadapt::timecourse::Adaptation;
use visadapt::{DisplayImage, HdrImage};

/// Longest file name on the usual file systems (POSIX `NAME_MAX` on Linux, ext4, XFS,
/// Btrfs), in bytes: the largest padding a frame pattern can sensibly ask for.
const MAX_NAME_LEN: usize = 255;

/// A parsed frame pattern: `dir/prefix%0Ndsuffix`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pattern {
    dir: PathBuf,
    prefix: String,
    suffix: String,
    /// N of `%0Nd`; 0 for `%d`.
    width: usize,
}

impl Pattern {
    /// Parse a pattern; its file name must hold exactly one `%d` or `%0Nd`.
    pub fn parse(pattern: &str) -> anyhow::Result<Self> {
        let path = Path::new(pattern);
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .with_context(|| format!("{pattern}: the pattern has no file name"))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let bad = || {
            anyhow::anyhow!(
                "{pattern}: the file name must hold exactly one %d or %0Nd (e.g. f_%04d.exr)"
            )
        };
        let start = name.find('%').ok_or_else(bad)?;
        let rest = &name[start + 1..];
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        if !rest[digits.len()..].starts_with('d') {
            return Err(bad());
        }
        let width: usize = if digits.is_empty() {
            0
        } else if digits.starts_with('0') && digits.len() > 1 {
            digits[1..].parse().map_err(|_| bad())?
        } else {
            return Err(bad()); // %Nd pads with spaces: not a file-name pattern
        };
        if width > MAX_NAME_LEN {
            bail!(
                "{pattern}: %0{width}d pads to more digits than a file name can hold ({MAX_NAME_LEN} bytes)"
            );
        }
        let suffix = &rest[digits.len() + 1..];
        if suffix.contains('%') {
            return Err(bad());
        }
        Ok(Pattern {
            dir,
            prefix: name[..start].to_string(),
            suffix: suffix.to_string(),
            width,
        })
    }

    /// The file name the pattern gives for `n`.
    pub fn name(&self, n: u64) -> String {
        format!("{}{:0w$}{}", self.prefix, n, self.suffix, w = self.width)
    }

    /// The number `name` stands for, if the pattern produces exactly that name.
    pub fn number(&self, name: &str) -> Option<u64> {
        let middle = name
            .strip_prefix(&self.prefix)?
            .strip_suffix(&self.suffix)?;
        if middle.is_empty() || !middle.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        let n: u64 = middle.parse().ok()?;
        (self.name(n) == name).then_some(n)
    }

    /// The frames: `(number, path)` in order. Errors if none match or numbers are missing.
    pub fn frames(&self, pattern: &str) -> anyhow::Result<Vec<(u64, PathBuf)>> {
        let entries = std::fs::read_dir(&self.dir)
            .with_context(|| format!("{pattern}: cannot list {}", self.dir.display()))?;
        let mut numbers: Vec<u64> = Vec::new();
        for e in entries {
            let e = e.with_context(|| format!("{pattern}: cannot list {}", self.dir.display()))?;
            if let Some(n) = e.file_name().to_str().and_then(|s| self.number(s)) {
                numbers.push(n);
            }
        }
        numbers.sort_unstable();
        let (Some(&first), Some(&last)) = (numbers.first(), numbers.last()) else {
            bail!("{pattern}: the pattern matches no file");
        };
        if let Some(w) = numbers.windows(2).find(|w| w[1] != w[0] + 1) {
            bail!(
                "{pattern}: frame {} is missing (frames run from {first} to {last}; they must be consecutive)",
                w[0] + 1
            );
        }
        Ok(numbers
            .into_iter()
            .map(|n| (n, self.dir.join(self.name(n))))
            .collect())
    }
}

pub fn run(args: VideoArgs) -> anyhow::Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!(
            "invalid --fps {}: must be a positive, finite number of frames per second",
            args.fps
        );
    }
    let conditions = ViewingConditions {
        undershoot: args.time_course.undershoot(),
        ..args.viewing.conditions(
            Some(&args.display),
            None,
            Some(&args.view),
            Some(&args.colour),
        )
    };
    conditions.validate()?;
    let (format, ext) = match args.format {
        VideoFormat::Png => (OutputFormat::Png { bits: 8 }, "png"),
        VideoFormat::Jpg => (OutputFormat::Jpeg { quality: 90 }, "jpg"),
        VideoFormat::Exr => (OutputFormat::Exr, "exr"),
    };
    let pattern = Pattern::parse(&args.pattern)?;
    let frames = pattern.frames(&args.pattern)?;
    let out_path = |input: &Path| {
        let stem = input.file_stem().unwrap_or_default();
        args.output.join(stem).with_extension(ext)
    };
    // Never overwrite an input frame (under any name: every output against every input).
    let inputs: Vec<&Path> = frames.iter().map(|(_, p)| p.as_path()).collect();
    for (_, input) in &frames {
        io::output::refuse_same_file(&out_path(input), &inputs)?;
    }
    std::fs::create_dir_all(&args.output).with_context(|| {
        format!(
            "{}: cannot create the output directory",
            args.output.display()
        )
    })?;

    let limits = args.limits.limits();
    let dt = 1.0 / args.fps;
    let progress = ProgressBar::new(frames.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg}").expect("valid template"),
    );
    // Three stages overlap: the reader decodes frame n+1 while the operator maps frame n and
    // the writer encodes frame n-1. The operator stays one thread, in frame order, because
    // the adaptation state is stepped from each frame to the next.
    let (to_operator, decoded) = mpsc::sync_channel::<anyhow::Result<HdrImage>>(QUEUE);
    let (free_hdr, reused_hdr) = mpsc::channel::<HdrImage>();
    let (to_writer, mapped) = mpsc::sync_channel::<Mapped>(QUEUE);
    let (free_display, reused_display) = mpsc::channel::<DisplayImage>();
    std::thread::scope(|s| {
        let frames = &frames;
        s.spawn(move || read_frames(frames, &limits, &to_operator, &reused_hdr));
        let writer = s.spawn({
            let progress = progress.clone();
            move || write_frames(&mapped, &free_display, format, &progress)
        });
        let operated = map_frames(
            &args,
            &conditions,
            frames,
            dt,
            &out_path,
            (&decoded, &free_hdr),
            (&to_writer, &reused_display),
        );
        // No more frames for the writer: it finishes those it has, then ends.
        drop(to_writer);
        drop(decoded);
        let written = writer.join().expect("the writer thread does not panic");
        // The writer's error is for an earlier frame than the operator's (a frame reaches
        // the writer only after the operator is done with it): report the first one.
        written.and(operated)
    })?;
    progress.finish_and_clear();
    if !args.json {
        println!(
            "wrote {} to {}",
            count(frames.len(), "frame", "frames"),
            args.output.display()
        );
    }
    Ok(())
}

/// Frames each queue between two stages holds beyond the one handed over: none. A stage
/// hands its frame straight to the next (a rendezvous), so at most two decoded frames and
/// two display images exist at once, whatever the length of the video. Measured on 24
/// frames of 1920 × 1080 on two shared cores (whole process, medians of 7 interleaved
/// runs): a queue of one frame was 0-7 % faster, within the noise, for 25-50 MiB more
/// peak memory (168 against 121 MiB on Radiance frames).
const QUEUE: usize = 0;

/// A mapped frame on its way to the writer.
struct Mapped {
    display: DisplayImage,
    path: PathBuf,
    /// The frame's JSON line, printed once the file is written (`--json`).
    json: Option<String>,
}

/// The reader: decode every frame in order, into images the operator hands back, and pass
/// each on (or the first error, naming the frame, then stop). Ends early when the
/// operator stops listening.
fn read_frames(
    frames: &[(u64, PathBuf)],
    limits: &visadapt::Limits,
    to_operator: &mpsc::SyncSender<anyhow::Result<HdrImage>>,
    reused: &mpsc::Receiver<HdrImage>,
) {
    let mut bytes = Vec::new();
    for (n, input) in frames {
        let mut hdr = reused.try_recv().unwrap_or_else(|_| HdrImage::zeros(0, 0));
        let read = io::read_into(input, limits, &mut bytes, &mut hdr)
            .with_context(|| format!("frame {n} ({})", input.display()));
        let failed = read.is_err();
        if to_operator.send(read.map(|()| hdr)).is_err() || failed {
            return;
        }
    }
}

/// The writer: write every mapped frame, atomically and in order, then hand its image back
/// to the operator. Stops at the first error (the operator then stops too, as its next
/// frame finds no writer).
fn write_frames(
    mapped: &mpsc::Receiver<Mapped>,
    free: &mpsc::Sender<DisplayImage>,
    format: OutputFormat,
    progress: &ProgressBar,
) -> anyhow::Result<()> {
    for frame in mapped {
        io::write_display(&frame.display, &frame.path, format)
            .with_context(|| frame.path.display().to_string())?;
        if let Some(line) = frame.json {
            println!("{line}");
        }
        progress.inc(1);
        // The operator may have finished: the image is then simply dropped.
        let _ = free.send(frame.display);
    }
    Ok(())
}

/// The operator, on the calling thread: each decoded frame in order through the time
/// course (Sec. 4.4) and the mapping, into a reused display image for the writer.
fn map_frames(
    args: &VideoArgs,
    conditions: &ViewingConditions,
    frames: &[(u64, PathBuf)],
    dt: f64,
    out_path: &dyn Fn(&Path) -> PathBuf,
    (decoded, free_hdr): (
        &mpsc::Receiver<anyhow::Result<HdrImage>>,
        &mpsc::Sender<HdrImage>,
    ),
    (to_writer, reused): (&mpsc::SyncSender<Mapped>, &mpsc::Receiver<DisplayImage>),
) -> anyhow::Result<()> {
    let mut eye: Option<Adaptation> = None;
    let mut size = None;
    let mut warned_units = false;
    for (k, (n, input)) in frames.iter().enumerate() {
        let what = || format!("frame {n} ({})", input.display());
        // The reader ends only after sending every frame or an error.
        let Ok(hdr) = decoded.recv() else {
            return Ok(());
        };
        let mut hdr = hdr?;
        match size {
            None => size = Some((hdr.width, hdr.height)),
            Some((w, h)) if (w, h) != (hdr.width, hdr.height) => {
                bail!(
                    "{}: {}x{} differs from the first frame's {w}x{h}",
                    what(),
                    hdr.width,
                    hdr.height
                )
            }
            Some(_) => {}
        }
        match args.scale {
            Some(s) => hdr.scale(s as f32),
            None if !hdr.absolute_units && !warned_units => {
                log::warn!(
                    "{}: the file does not say its units; values are taken as cd/m² (use --scale)",
                    what()
                );
                warned_units = true;
            }
            None => {}
        }
        let conditions = ViewingConditions {
            view: args.view.view(hdr.width, hdr.height),
            ..conditions.clone()
        };
        if k == 0 {
            super::warn_if_default_view(input, &hdr, &conditions);
        }
        let (scene, report) = operator::prepare(&hdr, &conditions).with_context(what)?;
        let state = match eye.as_mut() {
            None => eye.insert(
                Adaptation::adapted(
                    report.world_adaptation_cd_m2,
                    report.world_adaptation_scotopic_cd_m2,
                )?
                .with_undershoot(conditions.undershoot),
            ),
            Some(state) => {
                state.step_to(dt, &report).with_context(what)?;
                state
            }
        };
        let mut display = reused.try_recv().unwrap_or_default();
        let (mapping, _) =
            operator::apply_state_into(&scene, &report, state, &conditions, &mut display)
                .with_context(what)?;
        drop(scene);
        // Back to the reader for a later frame (if it has finished, the image is dropped).
        let _ = free_hdr.send(hdr);
        let out = out_path(input);
        let json = args.json.then(|| {
            let offset =
                mapping.photopic_offset_cd_m2 + mapping.rod_weight * mapping.scotopic_offset_cd_m2;
            serde_json::json!({
                "frame": n,
                "t_seconds": k as f64 * dt,
                "input": input.display().to_string(),
                "output": out.display().to_string(),
                "world_adaptation_cd_m2": report.world_adaptation_cd_m2,
                "world_adaptation_scotopic_cd_m2": report.world_adaptation_scotopic_cd_m2,
                "cone_threshold_cd_m2": state.cone_threshold_cd_m2(),
                "rod_threshold_scotopic_cd_m2": state.rod_threshold_scotopic_cd_m2(),
                "photopic_scale": mapping.photopic_scale,
                "scotopic_scale": mapping.scotopic_scale,
                "rod_weight": mapping.rod_weight,
                "offset_cd_m2": offset,
                "acuity_cycles_per_degree": state.acuity_cycles_per_degree(),
                "glare": visadapt::report::glare_json(&report),
            })
            .to_string()
        });
        let frame = Mapped {
            display,
            path: out,
            json,
        };
        if to_writer.send(frame).is_err() {
            // The writer stopped at an error, which it reports.
            return Ok(());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_match_exactly_what_they_would_print() {
        let p = Pattern::parse("frames/f_%04d.exr").unwrap();
        assert_eq!(p.dir, PathBuf::from("frames"));
        assert_eq!(p.name(7), "f_0007.exr");
        assert_eq!(p.number("f_0007.exr"), Some(7));
        assert_eq!(p.number("f_12345.exr"), Some(12345));
        assert_eq!(p.number("f_007.exr"), None);
        assert_eq!(p.number("f_0007.hdr"), None);
        assert_eq!(p.number("f_00a7.exr"), None);
        let p = Pattern::parse("x%d.hdr").unwrap();
        assert_eq!(p.dir, PathBuf::from("."));
        assert_eq!(p.number("x10.hdr"), Some(10));
        assert_eq!(p.number("x010.hdr"), None);
        for bad in [
            "f.exr",
            "f_%04d_%d.exr",
            "f_%4d.exr",
            "f_%s.exr",
            "",
            "f_%0256d.hdr",
            "f_%065536d.hdr",
            "f_%099999999999999999999999d.hdr",
        ] {
            assert!(Pattern::parse(bad).is_err(), "{bad}");
        }
    }
}
