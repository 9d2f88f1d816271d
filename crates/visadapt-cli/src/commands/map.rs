//! `visadapt map`: read an HDR image, run the operator, write the display image.

use crate::cli::MapArgs;
use crate::report;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use visadapt::io::{self, OutputFormat};
use visadapt::operator::{self, ViewingConditions};
use visadapt::{Limits, View};

pub fn run(args: MapArgs) -> anyhow::Result<()> {
    // Everything that can be checked before reading is checked first.
    refuse_to_overwrite_input(&args.input, &args.output)?;
    let format = output_format(&args)?;
    for (name, v) in [
        ("--scale", args.scale),
        ("--peak", args.peak),
        ("--fov", args.fov),
    ] {
        if let Some(v) = v
            && !(v.is_finite() && v > 0.0)
        {
            bail!("invalid {name} {v}: must be a positive, finite number");
        }
    }
    let conditions = ViewingConditions {
        display_max_cd_m2: args.display_max,
        world_adaptation_cd_m2: args.world_adaptation,
        world_adaptation_scotopic_cd_m2: args.scotopic_adaptation,
        hot_pixel_fraction: args.hot_pixel_fraction,
        acuity: !args.no_acuity,
        view: None,
        ..ViewingConditions::default()
    };
    conditions.validate()?;

    let progress = ProgressBar::new(3).with_style(
        ProgressStyle::with_template("{spinner} [{pos}/{len}] {msg}").expect("valid template"),
    );
    progress.set_message(format!("reading {}", args.input.display()));
    let limits = Limits {
        max_pixels: args.max_pixels,
    };
    let mut image =
        io::read(&args.input, &limits).with_context(|| args.input.display().to_string())?;

    let scale = super::input_scale(
        &args.input,
        &image,
        args.scale,
        args.peak,
        args.hot_pixel_fraction,
    )?;
    if scale != 1.0 {
        image.scale(scale as f32);
    }
    let conditions = ViewingConditions {
        view: args
            .fov
            .map(|fov| View::perspective(fov, image.width, image.height)),
        ..conditions
    };

    progress.inc(1);
    progress.set_message("applying the model");
    let out = operator::map(&image, &conditions)?;
    let stats = out.stats;
    if stats.non_finite > 0 {
        log::warn!(
            "{}: {} pixels with NaN or infinite values shown black",
            args.input.display(),
            stats.non_finite
        );
    }
    if stats.negative > 0 {
        log::warn!(
            "{}: {} pixels with negative values, read as 0",
            args.input.display(),
            stats.negative
        );
    }

    progress.inc(1);
    progress.set_message(format!("writing {}", args.output.display()));
    io::write_display(&out.image, &args.output, format)
        .with_context(|| args.output.display().to_string())?;
    progress.finish_and_clear();

    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&visadapt::report::map_json(&out.report, &stats, scale))?
        );
    } else {
        print!("{}", report::map_text(&out.report, &stats));
        println!("wrote                         {}", args.output.display());
    }
    Ok(())
}

fn output_format(args: &MapArgs) -> anyhow::Result<OutputFormat> {
    Ok(match OutputFormat::from_path(&args.output)? {
        OutputFormat::Png { .. } => OutputFormat::Png { bits: args.bits },
        OutputFormat::Jpeg { .. } => OutputFormat::Jpeg {
            quality: args.quality,
        },
        f => f,
    })
}

/// The output must never replace the input.
fn refuse_to_overwrite_input(input: &Path, output: &Path) -> anyhow::Result<()> {
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize())
        && a == b
    {
        bail!("{}: output would overwrite the input", output.display());
    }
    Ok(())
}
