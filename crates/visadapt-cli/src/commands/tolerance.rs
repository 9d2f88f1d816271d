//! `visadapt tolerance IN -o TOL.exr`: per pixel, the largest luminance error that stays
//! invisible to an observer adapted to the image ([`visadapt::visibility::tolerance_map`],
//! Ferwerda et al. 1996 Eq. 4–6), written as a one-channel OpenEXR in cd/m².

use crate::cli::ToleranceArgs;
use crate::numbers::num;
use anyhow::{Context, bail};
use std::path::Path;
use visadapt::io;
use visadapt::operator::{Source, ViewingConditions};
use visadapt::visibility::{self, Observation, ToleranceSummary};

pub fn run(args: ToleranceArgs) -> anyhow::Result<()> {
    // Everything that can be checked before reading is checked first.
    let is_exr = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if !is_exr {
        bail!(
            "{}: the tolerance map is written as OpenEXR (use .exr)",
            args.output.display()
        );
    }
    super::check_output_folder(&args.output)?;
    io::output::refuse_same_file(&args.output, &[&args.input])?;
    let conditions = ViewingConditions {
        // The tolerance holds for errors of any extent; acuity does not enter it.
        acuity: false,
        ..args.viewing.conditions(None, Some(&args.world), None, None)
    };
    conditions.validate()?;

    let (image, scale) = args.units.read(
        &args.input,
        &args.limits.limits(),
        conditions.hot_pixel_fraction,
    )?;
    let conditions = ViewingConditions {
        // The view sets the degrees of the glare spread function and of the local
        // adaptation radius.
        view: args.field.view(image.width, image.height),
        ..conditions
    };
    super::warn_if_default_view(&args.input, &image, &conditions);
    let observation = Observation::for_image(&image, &conditions)?;
    let (viewer, report) = (observation.viewer(), &observation.report);
    let tolerance = visibility::tolerance_map(&image, &viewer)?;

    let summary = ToleranceSummary::of(&tolerance, &image.y)
        .expect("one tolerance per pixel of a non-empty image");
    let (width, height) = (image.width, image.height);
    drop(image);
    write_luminance_exr(&args.output, width, height, tolerance)?;

    let given = report.world_adaptation_source == Source::Caller;
    if args.json {
        let output = args.output.display().to_string();
        let v = visadapt::report::tolerance_json(&summary, report, scale, Some(&output));
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "observer (Sec. 4.4)           adapted to {} cd/m² ({}), {} scotopic cd/m²",
            num(report.world_adaptation_cd_m2),
            if given { "given" } else { "from the image" },
            num(report.world_adaptation_scotopic_cd_m2)
        );
        println!(
            "thresholds (Eq. 4, 5, 6)      cones {} cd/m², rods {} scotopic cd/m², rod weight k {:.3}",
            num(report.cone_threshold_cd_m2),
            num(report.rod_threshold_scotopic_cd_m2),
            report.mapping.rod_weight
        );
        println!(
            "tolerance                     min {}, median {}, max {} cd/m²",
            num(summary.min_cd_m2),
            num(summary.median_cd_m2),
            num(summary.max_cd_m2)
        );
        if let Some(r) = summary.median_relative {
            println!(
                "                              median {:.2} % of the pixel's luminance",
                100.0 * r
            );
        }
        println!("wrote                         {}", args.output.display());
    }
    Ok(())
}

/// Write the tolerance plane (cd/m²) as a single-channel `Y` OpenEXR, atomically.
fn write_luminance_exr(
    path: &Path,
    width: usize,
    height: usize,
    y: Vec<f32>,
) -> anyhow::Result<()> {
    io::display::write_atomically(path, |w| io::exr::write_luminance(width, height, &y, w))
        .with_context(|| path.display().to_string())
}
