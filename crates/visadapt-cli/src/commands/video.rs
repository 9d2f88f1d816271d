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
//! The work is the library's pipeline ([`visadapt::video::run`]): decoder threads read
//! frames n+1, n+2 while the operator maps frame n and encoder threads encode and write
//! frames n−1, n−2 (`--decoders`, `--encoders`). The operator is one thread, so the state
//! is stepped in frame order, and every frame is written atomically and in order; the
//! output is the same, byte for byte, as doing one frame after another. HDR frames,
//! display images and file buffers go round and are reused, so memory does not grow with
//! the number of frames. On an error, the frames before it are written, nothing after it
//! is, and the error names its frame. `--timings` prints where the time went.

use crate::cli::{PngLevel, VideoArgs, VideoFormat};
use crate::numbers::count;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use visadapt::io::raw::{FrameReader, RawFormat};
use visadapt::io::{self, OutputFormat};
use visadapt::operator::ViewingConditions;
use visadapt::video::{self, Observer};
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
    if args.png.png_compression.is_some() && args.format != VideoFormat::Png {
        let name = clap::ValueEnum::to_possible_value(&args.format)
            .map_or_else(String::new, |v| v.get_name().to_owned());
        bail!("--png-compression applies to PNG frames only, not to --format {name}");
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
                _ => (
                    OutputFormat::png(8).with_png_compression(args.png.level(PngLevel::Fdeflate)),
                    "png",
                ),
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
    let scale = args.scale.map(|s| s as f32);
    let (frames, total, reader) = match &source {
        Source::Files(frames) => {
            let take = args.max_frames.map_or(frames.len(), |m| {
                frames.len().min(usize::try_from(m).unwrap_or(usize::MAX))
            });
            let reader = Reader::Files {
                frames: &frames[..take],
                limits: &limits,
                scale: scale.unwrap_or(1.0),
            };
            (&frames[..take], Some(take as u64), reader)
        }
        Source::Stream { width, height } => {
            // The size is checked before anything is read or allocated.
            let stream = FrameReader::new(std::io::stdin(), STDIN, *width, *height, &limits)?
                .with_scale(scale.unwrap_or(1.0));
            let reader = Reader::Stream {
                stream: Mutex::new(stream),
                max_frames: args.max_frames,
            };
            (&[][..], args.max_frames, reader)
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
    let writer = Writer {
        sink,
        frames,
        progress: progress.clone(),
    };
    // The frame `k`-th of the run is (its number, the file it came from).
    let frame_of = |k: u64| -> (u64, PathBuf) {
        match usize::try_from(k).ok().and_then(|k| frames.get(k)) {
            Some((n, path)) => (*n, path.clone()),
            None => (k, PathBuf::from("-")),
        }
    };
    let mut eye: Option<Observer> = None;
    let mut warned_units = false;
    let operator =
        |k: u64, hdr: &mut HdrImage, display: &mut DisplayImage| -> anyhow::Result<Mapped> {
            let (n, input) = frame_of(k);
            let name = if input.as_os_str() == "-" {
                STDIN.to_string()
            } else {
                input.display().to_string()
            };
            let what = || format!("frame {n} ({name})");
            if scale.is_none() && !hdr.absolute_units && !warned_units {
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
            let eye = match eye.as_mut() {
                Some(eye) => eye,
                None => {
                    // The view --fov gives is that of the first frame's size (all frames have it).
                    let conditions = ViewingConditions {
                        view: args.view.view(hdr.width, hdr.height),
                        ..conditions.clone()
                    };
                    super::warn_if_default_view(Path::new(&name), hdr, &conditions);
                    eye.insert(Observer::new(conditions, args.fps)?)
                }
            };
            let frame = eye.frame(hdr, display).with_context(what)?;
            let out = writer.sink.path(&input, n);
            let json = args
                .json
                .then(|| json_line(n, &input, out.as_deref(), &frame));
            Ok(Mapped { path: out, json })
        };
    let threads = video::Threads {
        decoders: args.decoders.get(),
        encoders: args.encoders.get(),
    };
    let timings = video::run(&reader, operator, &writer, threads)?;
    progress.finish_and_clear();
    if args.timings {
        eprintln!("{}", describe(&timings));
    }
    if !args.json {
        let to = if stdout {
            "standard output".to_string()
        } else {
            args.output.display().to_string()
        };
        let frames = usize::try_from(timings.frames).unwrap_or(usize::MAX);
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

/// The `--json` line of a frame.
fn json_line(n: u64, input: &Path, out: Option<&Path>, frame: &video::Frame) -> String {
    let (report, mapping, state) = (&frame.report, &frame.mapping, &frame.state);
    let offset = mapping.photopic_offset_cd_m2 + mapping.rod_weight * mapping.scotopic_offset_cd_m2;
    serde_json::json!({
        "frame": n,
        "t_seconds": frame.t_seconds,
        "input": input.display().to_string(),
        "output": out.map(|o| o.display().to_string()),
        "world_adaptation_cd_m2": report.world_adaptation_cd_m2,
        "world_adaptation_scotopic_cd_m2": report.world_adaptation_scotopic_cd_m2,
        "cone_threshold_cd_m2": state.cone_threshold_cd_m2(),
        "rod_threshold_scotopic_cd_m2": state.rod_threshold_scotopic_cd_m2(),
        "photopic_scale": mapping.photopic_scale,
        "scotopic_scale": mapping.scotopic_scale,
        "rod_weight": mapping.rod_weight,
        "offset_cd_m2": offset,
        "acuity_cycles_per_degree": state.acuity_cycles_per_degree(),
        "glare": visadapt::report::glare_json(report),
    })
    .to_string()
}

/// The `--timings` summary: the frame rate, each stage's time per frame, and the
/// operator's waits, which tell the stage that bounds the rate.
fn describe(t: &video::Timings) -> String {
    let per = |d: std::time::Duration| {
        format!("{:.1} ms", d.as_secs_f64() * 1e3 / t.frames.max(1) as f64)
    };
    let bound = if t.operator_waiting_for_frames > t.operator_waiting_for_encoders {
        "decoding"
    } else if t.operator_waiting_for_encoders > t.operator_waiting_for_frames {
        "encoding"
    } else {
        "the operator"
    };
    let bound = if t.operator_waiting_for_frames + t.operator_waiting_for_encoders < t.operator / 10
    {
        "the operator"
    } else {
        bound
    };
    format!(
        "timings: {} in {:.2} s, {:.1} frames/s; per frame: decoding {} ({} threads), \
         operator {}, encoding {} ({} threads), writing {}; the operator waited {} for \
         frames and {} for encoders (the rate is bound by {bound})",
        count(
            usize::try_from(t.frames).unwrap_or(usize::MAX),
            "frame",
            "frames"
        ),
        t.wall.as_secs_f64(),
        t.frames_per_second(),
        per(t.decoding),
        t.threads.0,
        per(t.operator),
        per(t.encoding),
        t.threads.1,
        per(t.writing),
        per(t.operator_waiting_for_frames),
        per(t.operator_waiting_for_encoders),
    )
}

/// The frames' reader, for [`video::run`]: files (read by several decoder threads) or raw
/// frames on standard input (read in order). `--scale` is applied as a frame is decoded,
/// in the decoder's own conversion pass.
enum Reader<'a> {
    Files {
        frames: &'a [(u64, PathBuf)],
        limits: &'a visadapt::Limits,
        scale: f32,
    },
    Stream {
        stream: Mutex<FrameReader<std::io::Stdin>>,
        max_frames: Option<u64>,
    },
}

impl video::Source<anyhow::Error> for Reader<'_> {
    fn read(&self, k: u64, bytes: &mut Vec<u8>, hdr: &mut HdrImage) -> anyhow::Result<bool> {
        match self {
            Reader::Files {
                frames,
                limits,
                scale,
            } => {
                let Some((n, input)) = usize::try_from(k).ok().and_then(|k| frames.get(k)) else {
                    return Ok(false);
                };
                io::read_scaled_into(input, limits, *scale, bytes, hdr)
                    .with_context(|| format!("frame {n} ({})", input.display()))?;
                Ok(true)
            }
            Reader::Stream { stream, max_frames } => {
                if max_frames.is_some_and(|m| k >= m) {
                    return Ok(false);
                }
                let mut stream = stream.lock().unwrap_or_else(|e| e.into_inner());
                Ok(stream.read_into(hdr)?)
            }
        }
    }

    fn in_order(&self) -> bool {
        matches!(self, Reader::Stream { .. })
    }
}

/// A mapped frame's way out: the file it goes to (`None` on a stream) and its JSON line,
/// printed once the file is written (`--json`).
struct Mapped {
    path: Option<PathBuf>,
    json: Option<String>,
}

/// The frames' writer, for [`video::run`]: encoded by several threads, written (files
/// atomically, or onto standard output) in order, then counted on the progress bar.
struct Writer<'a> {
    sink: Sink<'a>,
    /// The input frames (empty for a stream), to name a frame's file in errors.
    frames: &'a [(u64, PathBuf)],
    progress: ProgressBar,
}

impl video::Sink<anyhow::Error> for Writer<'_> {
    type Frame = Mapped;

    fn encode(&self, k: u64, display: &DisplayImage, bytes: &mut Vec<u8>) -> anyhow::Result<()> {
        match self.sink {
            Sink::Folder { format, .. } => format.encode_into(display, bytes).with_context(|| {
                let (n, input) = usize::try_from(k)
                    .ok()
                    .and_then(|k| self.frames.get(k))
                    .map_or((k, Path::new("-")), |(n, p)| (*n, p.as_path()));
                self.sink
                    .path(input, n)
                    .map_or_else(|| format!("frame {k}"), |p| p.display().to_string())
            }),
            Sink::Stream(raw) => io::raw::encode_frame(display, raw, bytes)
                .with_context(|| format!("frame {k}: standard output")),
        }
    }

    fn write(&self, k: u64, bytes: &[u8], frame: Mapped) -> anyhow::Result<()> {
        match (self.sink, &frame.path) {
            (Sink::Folder { .. }, Some(path)) => {
                video::write_file(path, bytes).with_context(|| path.display().to_string())?;
            }
            (Sink::Stream(_), _) => {
                let mut out = std::io::stdout().lock();
                out.write_all(bytes)
                    .and_then(|()| out.flush())
                    .with_context(|| format!("frame {k}: standard output"))?;
            }
            (Sink::Folder { .. }, None) => unreachable!("a file frame has a path"),
        }
        if let Some(line) = frame.json {
            println!("{line}");
        }
        self.progress.inc(1);
        Ok(())
    }
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
