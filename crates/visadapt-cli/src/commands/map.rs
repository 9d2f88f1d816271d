//! `visadapt map`: read HDR images, run the operator, write the display images.
//!
//! One input: the full report. Several (a batch, `-o` a folder): one line per file (or one
//! JSON object per line), a progress bar, every input tried even when some fail, and a
//! failure exit status if any did. `-` reads standard input (any of the formats, told by
//! its first bytes) or writes standard output (the format from `--format`, PNG by default);
//! the report then goes to standard error.

use crate::cli::{FormatArg, MapArgs, PngLevel};
use crate::numbers::count;
use crate::report;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use visadapt::io::{self, OutputFormat};
use visadapt::operator::{self, PixelStats, Report, ViewingConditions};

pub fn run(args: MapArgs) -> anyhow::Result<()> {
    // Everything that can be checked before reading is checked first.
    let folder = args.output_is_folder();
    let jobs = outputs(&args, folder)?;
    let inputs: Vec<&Path> = args.inputs.iter().map(PathBuf::as_path).collect();
    for (_, output) in &jobs {
        if !is_std(output) {
            io::output::refuse_same_file(output, &inputs)?;
        }
    }
    if folder {
        std::fs::create_dir_all(&args.output).with_context(|| {
            format!("cannot create the output folder {}", args.output.display())
        })?;
    } else {
        super::check_output_folder(&args.output)?;
    }
    let format = output_format(&args)?;
    let conditions = args.viewing.conditions(
        Some(&args.display),
        Some(&args.world),
        Some(&args.view),
        Some(&args.colour),
    );
    conditions.validate()?;

    if let [(input, output)] = jobs.as_slice() {
        return run_one(&args, &conditions, format, input, output);
    }
    run_batch(&args, &conditions, format, &jobs)
}

/// Each input with the file it is written to: `-o` itself, or the input's name with the
/// format's extension in the folder `-o`. Two inputs that would write one file are refused.
fn outputs(args: &MapArgs, folder: bool) -> anyhow::Result<Vec<(PathBuf, PathBuf)>> {
    if !folder {
        return Ok(vec![(args.inputs[0].clone(), args.output.clone())]);
    }
    let ext = args.format_kind().unwrap_or(FormatArg::Png).name();
    let mut seen: HashMap<PathBuf, &Path> = HashMap::new();
    let mut jobs = Vec::with_capacity(args.inputs.len());
    for input in &args.inputs {
        let stem = if is_std(input) {
            std::ffi::OsStr::new("stdin")
        } else if let Some(stem) = input.file_stem() {
            stem
        } else {
            bail!("{}: not a file name", input.display());
        };
        let mut name = stem.to_os_string();
        name.push(".");
        name.push(ext);
        let output = args.output.join(name);
        if let Some(first) = seen.insert(output.clone(), input) {
            bail!(
                "{} and {} would both be written to {}",
                first.display(),
                input.display(),
                output.display()
            );
        }
        jobs.push((input.clone(), output));
    }
    Ok(jobs)
}

/// What one file's mapping reports.
struct Mapped {
    report: Report,
    stats: PixelStats,
    scale: f64,
}

/// Read `input`, map it, write `output`; `step` is told what is being done.
fn map_file(
    args: &MapArgs,
    conditions: &ViewingConditions,
    format: OutputFormat,
    input: &Path,
    output: &Path,
    step: &dyn Fn(String),
) -> anyhow::Result<Mapped> {
    let hot_pixel_fraction = conditions.hot_pixel_fraction;
    let (image, scale) = if is_std(input) {
        let input = &shown(input, "standard input");
        step(format!("reading {}", input.display()));
        let limits = args.limits.limits();
        let mut image = io::read_scaled_from(
            std::io::stdin().lock(),
            &limits,
            args.units.decoder_factor(),
        )
        .with_context(|| input.display().to_string())?;
        let scale = args.units.factor(input, &image, hot_pixel_fraction)?;
        args.units.apply(&mut image, scale);
        (image, scale)
    } else {
        step(format!("reading {}", input.display()));
        args.units
            .read(input, &args.limits.limits(), hot_pixel_fraction)?
    };
    let input = &shown(input, "standard input");
    let conditions = ViewingConditions {
        view: args.view.view(image.width, image.height),
        ..conditions.clone()
    };
    super::warn_if_default_view(input, &image, &conditions);

    step(format!("applying the model to {}", input.display()));
    // The input's planes become the display's (one image in memory, not two).
    let out =
        operator::map_owned(image, &conditions).with_context(|| input.display().to_string())?;
    let stats = out.stats;
    if stats.non_finite > 0 {
        log::warn!(
            "{}: {} with NaN or infinite values shown black",
            input.display(),
            count(stats.non_finite, "pixel", "pixels")
        );
    }
    if stats.negative > 0 {
        log::warn!(
            "{}: {} with negative values, read as 0",
            input.display(),
            count(stats.negative, "pixel", "pixels")
        );
    }

    step(format!(
        "writing {}",
        shown(output, "standard output").display()
    ));
    if is_std(output) {
        io::write_display_to(&out.image, format, std::io::stdout().lock())
    } else {
        io::write_display(&out.image, output, format)
    }
    .with_context(|| shown(output, "standard output").display().to_string())?;
    Ok(Mapped {
        report: out.report,
        stats,
        scale,
    })
}

fn run_one(
    args: &MapArgs,
    conditions: &ViewingConditions,
    format: OutputFormat,
    input: &Path,
    output: &Path,
) -> anyhow::Result<()> {
    let progress = ProgressBar::new(3).with_style(
        ProgressStyle::with_template("{spinner} [{pos}/{len}] {msg}").expect("valid template"),
    );
    // Each step after the first completes the one before.
    let step = |msg: String| {
        if !progress.message().is_empty() {
            progress.inc(1);
        }
        progress.set_message(msg);
    };
    let m = map_file(args, conditions, format, input, output, &step)?;
    progress.finish_and_clear();

    let text = if args.json {
        serde_json::to_string_pretty(&visadapt::report::map_json(&m.report, &m.stats, m.scale))?
            + "\n"
    } else {
        report::map_text(&m.report, &m.stats)
            + &format!(
                "wrote                         {}\n",
                shown(output, "standard output").display()
            )
    };
    // Standard output holds the image: the report goes beside it, to standard error.
    if is_std(output) {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    Ok(())
}

/// Map every input of `jobs`, `--jobs` at a time, reporting in the inputs' order as they
/// complete.
fn run_batch(
    args: &MapArgs,
    conditions: &ViewingConditions,
    format: OutputFormat,
    jobs: &[(PathBuf, PathBuf)],
) -> anyhow::Result<()> {
    let n = jobs.len();
    let bar = ProgressBar::new(n as u64).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {wide_msg}").expect("valid template"),
    );
    let next = AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::channel::<(usize, anyhow::Result<Mapped>)>();
    let mut failed = 0usize;
    std::thread::scope(|scope| -> anyhow::Result<()> {
        for _ in 0..args.jobs.get().min(n) {
            let tx = tx.clone();
            let (next, bar) = (&next, &bar);
            std::thread::Builder::new()
                .name("map".into())
                .spawn_scoped(scope, move || {
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some((input, output)) = jobs.get(i) else {
                            break;
                        };
                        let step = |msg: String| bar.set_message(msg);
                        let result = map_file(args, conditions, format, input, output, &step);
                        if tx.send((i, result)).is_err() {
                            break;
                        }
                    }
                })
                .context("cannot start a worker thread")?;
        }
        drop(tx);
        // Results arrive in any order; they are printed in the inputs' order.
        let mut done = BTreeMap::new();
        let mut printed = 0;
        for (i, result) in rx {
            bar.inc(1);
            done.insert(i, result);
            while let Some(result) = done.remove(&printed) {
                let (input, output) = &jobs[printed];
                bar.suspend(|| match result {
                    Ok(m) if args.json => println!(
                        "{}",
                        visadapt::report::map_file_json(
                            &input.display().to_string(),
                            &output.display().to_string(),
                            &m.report,
                            &m.stats,
                            m.scale
                        )
                    ),
                    Ok(m) => println!("{}", report::map_line(input, output, &m.report)),
                    Err(e) => {
                        failed += 1;
                        eprintln!("visadapt: error: {e:#}");
                    }
                });
                printed += 1;
            }
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    if failed > 0 {
        bail!(
            "{failed} of {} failed ({} written)",
            count(n, "input", "inputs"),
            n - failed
        );
    }
    Ok(())
}

/// Whether a path is `-`: standard input or output.
pub fn is_std(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// A path as messages name it, `-` as `stream` (standard input or output).
fn shown(path: &Path, stream: &str) -> PathBuf {
    if is_std(path) {
        PathBuf::from(stream)
    } else {
        path.to_path_buf()
    }
}

fn output_format(args: &MapArgs) -> anyhow::Result<OutputFormat> {
    let format = match args.format_kind() {
        Some(FormatArg::Png) => OutputFormat::png(8),
        Some(FormatArg::Jpeg) => OutputFormat::Jpeg { quality: 90 },
        Some(FormatArg::Exr) => OutputFormat::Exr,
        Some(FormatArg::Tiff) => OutputFormat::Tiff,
        Some(FormatArg::Hdr) => OutputFormat::Radiance,
        None => OutputFormat::from_path(&args.output)?,
    };
    Ok(match format {
        OutputFormat::Png { .. } => OutputFormat::Png {
            bits: args.bits.unwrap_or(8),
            compression: args.png.level(PngLevel::Fast),
        },
        OutputFormat::Jpeg { .. } => OutputFormat::Jpeg {
            quality: args.quality.unwrap_or(90),
        },
        f => f,
    })
}
