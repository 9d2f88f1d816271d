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
//! Pipes (ffmpeg's raw video, [`visadapt::io::raw`]): input `-` reads raw `gbrpf32le`
//! frames of `--size WxH` from standard input until the stream ends (or `--max-frames`),
//! numbered from 0 (to `OUT_DIR/frame_000000.<format>`, ...); `-o -` writes raw `rgb48le`
//! or `rgb24` frames to standard output, and the progress bar and the report then go to
//! standard error.
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
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use visadapt::io::raw::{FrameReader, RawFormat};
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

/// Where the frames come from.
enum Source {
    /// Numbered files, `(number, path)` in order.
    Files(Vec<(u64, PathBuf)>),
    /// Raw `gbrpf32le` frames of this size on standard input.
    Stream { width: u64, height: u64 },
}

/// Where the mapped frames go.
#[derive(Clone, Copy)]
enum Sink<'a> {
    /// Files `dir/<input stem>.<ext>`.
    Folder {
        dir: &'a Path,
        format: OutputFormat,
        ext: &'static str,
    },
    /// Raw frames on standard output.
    Stream(RawFormat),
}

impl Sink<'_> {
    /// The file frame `n` from `input` goes to: `<input stem>.<ext>`, or
    /// `frame_<n, 6 digits>.<ext>` for a frame of standard input (`-`); `None` on a stream.
    fn path(&self, input: &Path, n: u64) -> Option<PathBuf> {
        match self {
            Sink::Folder { dir, ext, .. } if input.as_os_str() == "-" => {
                Some(dir.join(format!("frame_{n:06}.{ext}")))
            }
            Sink::Folder { dir, ext, .. } => Some(
                dir.join(input.file_stem().unwrap_or_default())
                    .with_extension(ext),
            ),
            Sink::Stream(_) => None,
        }
    }
}

/// The name of standard input in messages.
const STDIN: &str = "standard input";

pub fn run(args: VideoArgs) -> anyhow::Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!(
            "invalid --fps {}: must be a positive, finite number of frames per second",
            args.fps
        );
    }
    let stdin = args.pattern == "-";
    let stdout = args.output.as_os_str() == "-";
    let source = match (stdin, args.size) {
        (true, Some((width, height))) => Source::Stream { width, height },
        (true, None) => bail!(
            "input - (raw gbrpf32le frames on standard input) needs --size WxH, e.g. --size 1920x1080"
        ),
        (false, Some(_)) => bail!(
            "--size is for raw frames on standard input (input -); {} names files, whose size is in them",
            args.pattern
        ),
        (false, None) => Source::Files(Pattern::parse(&args.pattern)?.frames(&args.pattern)?),
    };
    let sink = match (stdout, args.format.raw()) {
        (true, Some(raw)) => Sink::Stream(raw),
        (true, None) => bail!(
            "-o - (standard output) carries raw frames: use --format rgb48le or --format rgb24"
        ),
        (false, Some(raw)) => bail!(
            "--format {} is a raw stream for -o - (standard output), not for files in {}",
            raw.pix_fmt(),
            args.output.display()
        ),
        (false, None) => {
            let (format, ext) = match args.format {
                VideoFormat::Jpg => (OutputFormat::Jpeg { quality: 90 }, "jpg"),
                VideoFormat::Exr => (OutputFormat::Exr, "exr"),
                _ => (OutputFormat::Png { bits: 8 }, "png"),
            };
            Sink::Folder {
                dir: &args.output,
                format,
                ext,
            }
        }
    };
    if stdout && args.json {
        bail!("--json prints on standard output, which carries the frames with -o -");
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
    let limits = args.limits.limits();
    let (frames, total) = match &source {
        Source::Files(frames) => {
            let take = args.max_frames.map_or(frames.len(), |m| {
                frames.len().min(usize::try_from(m).unwrap_or(usize::MAX))
            });
            (&frames[..take], Some(take as u64))
        }
        Source::Stream { width, height } => {
            // The size is checked before anything is read or allocated.
            FrameReader::new(std::io::empty(), STDIN, *width, *height, &limits)?;
            (&[][..], args.max_frames)
        }
    };
    // Never overwrite an input frame (under any name: every output against every input).
    let inputs: Vec<&Path> = frames.iter().map(|(_, p)| p.as_path()).collect();
    for (n, input) in frames {
        if let Some(out) = sink.path(input, *n) {
            io::output::refuse_same_file(&out, &inputs)?;
        }
    }
    if !stdout {
        std::fs::create_dir_all(&args.output).with_context(|| {
            format!(
                "{}: cannot create the output directory",
                args.output.display()
            )
        })?;
    }

    let dt = 1.0 / args.fps;
    let progress = match total {
        Some(n) => ProgressBar::new(n).with_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg}")
                .expect("valid template"),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("{spinner} {pos} frames {per_sec}")
                .expect("valid template"),
        ),
    };
    // Three stages overlap: the reader decodes frame n+1 while the operator maps frame n and
    // the writer encodes frame n-1. The operator stays one thread, in frame order, because
    // the adaptation state is stepped from each frame to the next.
    let (to_operator, decoded) = mpsc::sync_channel::<anyhow::Result<Decoded>>(QUEUE);
    let (free_hdr, reused_hdr) = mpsc::channel::<HdrImage>();
    let (to_writer, mapped) = mpsc::sync_channel::<Mapped>(QUEUE);
    let (free_display, reused_display) = mpsc::channel::<DisplayImage>();
    let written = std::thread::scope(|s| {
        let source = &source;
        s.spawn(move || match source {
            Source::Files(_) => read_files(frames, &limits, &to_operator, &reused_hdr),
            Source::Stream { width, height } => read_stream(
                (*width, *height),
                args.max_frames,
                &limits,
                &to_operator,
                &reused_hdr,
            ),
        });
        let writer = s.spawn({
            let progress = progress.clone();
            move || write_frames(&mapped, &free_display, sink, &progress)
        });
        let operated = map_frames(
            &args,
            &conditions,
            dt,
            (&decoded, &free_hdr),
            (&to_writer, &reused_display),
            sink,
        );
        // No more frames for the writer: it finishes those it has, then ends.
        drop(to_writer);
        drop(decoded);
        let written = writer.join().expect("the writer thread does not panic");
        // The writer's error is for an earlier frame than the operator's (a frame reaches
        // the writer only after the operator is done with it): report the first one.
        let written = written?;
        operated.map(|()| written)
    })?;
    progress.finish_and_clear();
    if !args.json {
        let to = if stdout {
            "standard output".to_string()
        } else {
            args.output.display().to_string()
        };
        let frames = usize::try_from(written).unwrap_or(usize::MAX);
        let report = format!("wrote {} to {to}", count(frames, "frame", "frames"));
        // Standard output carries the frames with -o -: the report goes to standard error.
        if stdout {
            eprintln!("{report}");
        } else {
            println!("{report}");
        }
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

/// A decoded frame on its way to the operator.
struct Decoded {
    /// The frame's number (in the file name, or from 0 on a stream).
    n: u64,
    /// The file it came from (`-` for standard input).
    input: PathBuf,
    hdr: HdrImage,
}

/// A mapped frame on its way to the writer.
struct Mapped {
    display: DisplayImage,
    /// The file it goes to (`None` on a stream).
    path: Option<PathBuf>,
    /// The frame's JSON line, printed once the file is written (`--json`).
    json: Option<String>,
}

/// The reader of numbered files: decode every frame in order, into images the operator
/// hands back, and pass each on (or the first error, naming the frame, then stop). Ends
/// early when the operator stops listening.
fn read_files(
    frames: &[(u64, PathBuf)],
    limits: &visadapt::Limits,
    to_operator: &mpsc::SyncSender<anyhow::Result<Decoded>>,
    reused: &mpsc::Receiver<HdrImage>,
) {
    let mut bytes = Vec::new();
    for (n, input) in frames {
        let mut hdr = reused.try_recv().unwrap_or_else(|_| HdrImage::zeros(0, 0));
        let read = io::read_into(input, limits, &mut bytes, &mut hdr)
            .with_context(|| format!("frame {n} ({})", input.display()));
        let failed = read.is_err();
        let frame = read.map(|()| Decoded {
            n: *n,
            input: input.clone(),
            hdr,
        });
        if to_operator.send(frame).is_err() || failed {
            return;
        }
    }
}

/// The reader of raw frames on standard input: as [`read_files`], until the stream ends
/// or `max_frames` have been read.
fn read_stream(
    (width, height): (u64, u64),
    max_frames: Option<u64>,
    limits: &visadapt::Limits,
    to_operator: &mpsc::SyncSender<anyhow::Result<Decoded>>,
    reused: &mpsc::Receiver<HdrImage>,
) {
    let reader = FrameReader::new(std::io::stdin().lock(), STDIN, width, height, limits);
    let mut reader = match reader {
        Ok(r) => r,
        Err(e) => {
            let _ = to_operator.send(Err(e.into()));
            return;
        }
    };
    while max_frames.is_none_or(|m| reader.frames_read() < m) {
        let n = reader.frames_read();
        let mut hdr = reused.try_recv().unwrap_or_else(|_| HdrImage::zeros(0, 0));
        let frame = match reader.read_into(&mut hdr) {
            Ok(false) => return,
            Ok(true) => Ok(Decoded {
                n,
                input: PathBuf::from("-"),
                hdr,
            }),
            Err(e) => Err(anyhow::Error::from(e)),
        };
        let failed = frame.is_err();
        if to_operator.send(frame).is_err() || failed {
            return;
        }
    }
}

/// The writer: write every mapped frame, atomically and in order (or onto the stream),
/// then hand its image back to the operator. Stops at the first error (the operator then
/// stops too, as its next frame finds no writer). Returns the number of frames written.
fn write_frames(
    mapped: &mpsc::Receiver<Mapped>,
    free: &mpsc::Sender<DisplayImage>,
    sink: Sink,
    progress: &ProgressBar,
) -> anyhow::Result<u64> {
    let mut written = 0;
    let mut buf = Vec::new();
    for frame in mapped {
        match (sink, &frame.path) {
            (Sink::Folder { format, .. }, Some(path)) => {
                io::write_display(&frame.display, path, format)
                    .with_context(|| path.display().to_string())?;
            }
            (Sink::Stream(raw), _) => {
                let mut out = std::io::stdout().lock();
                io::raw::write_frame(&frame.display, raw, &mut out, &mut buf)
                    .and_then(|()| Ok(out.flush()?))
                    .with_context(|| format!("frame {written}: standard output"))?;
            }
            (Sink::Folder { .. }, None) => unreachable!("a file frame has a path"),
        }
        if let Some(line) = frame.json {
            println!("{line}");
        }
        written += 1;
        progress.inc(1);
        // The operator may have finished: the image is then simply dropped.
        let _ = free.send(frame.display);
    }
    Ok(written)
}

/// The operator, on the calling thread: each decoded frame in order through the time
/// course (Sec. 4.4) and the mapping, into a reused display image for the writer.
fn map_frames(
    args: &VideoArgs,
    conditions: &ViewingConditions,
    dt: f64,
    (decoded, free_hdr): (
        &mpsc::Receiver<anyhow::Result<Decoded>>,
        &mpsc::Sender<HdrImage>,
    ),
    (to_writer, reused): (&mpsc::SyncSender<Mapped>, &mpsc::Receiver<DisplayImage>),
    sink: Sink,
) -> anyhow::Result<()> {
    let mut eye: Option<Adaptation> = None;
    let mut size = None;
    let mut warned_units = false;
    // The reader ends after sending every frame or an error.
    for (k, frame) in decoded.iter().enumerate() {
        let Decoded { n, input, mut hdr } = frame?;
        let what = || {
            let name = if input.as_os_str() == "-" {
                STDIN.into()
            } else {
                input.display().to_string()
            };
            format!("frame {n} ({name})")
        };
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
                    "{}: the {} does not say its units; values are taken as cd/m² (use --scale)",
                    what(),
                    if input.as_os_str() == "-" {
                        "stream"
                    } else {
                        "file"
                    }
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
            let name = if input.as_os_str() == "-" {
                Path::new(STDIN)
            } else {
                &input
            };
            super::warn_if_default_view(name, &hdr, &conditions);
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
        let out = sink.path(&input, n);
        let json = args.json.then(|| {
            let offset =
                mapping.photopic_offset_cd_m2 + mapping.rod_weight * mapping.scotopic_offset_cd_m2;
            serde_json::json!({
                "frame": n,
                "t_seconds": k as f64 * dt,
                "input": input.display().to_string(),
                "output": out.as_ref().map(|o| o.display().to_string()),
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
