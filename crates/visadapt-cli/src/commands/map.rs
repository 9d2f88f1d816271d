//! `visadapt map`: read an HDR image, run the operator, write the display image.

use crate::cli::MapArgs;
use crate::report;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use visadapt::io::{self, OutputFormat};
use visadapt::operator::{self, ViewingConditions};

pub fn run(args: MapArgs) -> anyhow::Result<()> {
    // Everything that can be checked before reading is checked first.
    io::output::refuse_same_file(&args.output, &[&args.input])?;
    super::check_output_folder(&args.output)?;
    let format = output_format(&args)?;
    let conditions = args.viewing.conditions(
        Some(&args.display),
        Some(&args.world),
        Some(&args.view),
        Some(&args.colour),
    );
    conditions.validate()?;

    let progress = ProgressBar::new(3).with_style(
        ProgressStyle::with_template("{spinner} [{pos}/{len}] {msg}").expect("valid template"),
    );
    progress.set_message(format!("reading {}", args.input.display()));
    let mut image = io::read(&args.input, &args.limits.limits())
        .with_context(|| args.input.display().to_string())?;

    let scale = args
        .units
        .factor(&args.input, &image, conditions.hot_pixel_fraction)?;
    if scale != 1.0 {
        image.scale(scale as f32);
    }
    let conditions = ViewingConditions {
        view: args.view.view(image.width, image.height),
        ..conditions
    };
    super::warn_if_default_view(&args.input, &image, &conditions);

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
        OutputFormat::Png { .. } => OutputFormat::Png {
            bits: args.bits.unwrap_or(8),
        },
        OutputFormat::Jpeg { .. } => OutputFormat::Jpeg {
            quality: args.quality.unwrap_or(90),
        },
        f => f,
    })
}
