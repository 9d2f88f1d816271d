//! `visadapt chart`: write the built-in test scene (Fig. 11) as an EXR in the paper's own
//! layout (X, Y, Z in cd/m², scotopic in scotopic cd/m²).

use crate::cli::ChartArgs;
use crate::numbers::num;
use anyhow::{Context, bail};
use visadapt::chart::{Chart, ChartOptions};
use visadapt::io;

pub fn run(args: ChartArgs) -> anyhow::Result<()> {
    super::timecourse::positive("--white", args.white)?;
    let is_exr = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if !is_exr {
        bail!(
            "{}: chart writes OpenEXR; give the output a .exr name",
            args.output.display()
        );
    }
    super::check_output_folder(&args.output)?;
    let options = match args.fov {
        Some(fov) => ChartOptions::with_fov(args.white, fov, !args.no_gratings)?,
        None => ChartOptions {
            white_cd_m2: args.white,
            gratings: !args.no_gratings,
            ..ChartOptions::default()
        },
    };
    let chart = Chart::new(&options)?;
    io::display::write_atomically(&args.output, |w| io::exr::write_hdr(&chart.image, w))
        .with_context(|| args.output.display().to_string())?;

    let image = &chart.image;
    let view = image.view.expect("the chart has a view");
    let smallest = chart.layout.lines.last().expect("the chart has lines");
    println!(
        "chart                         {}x{} pixels, white {} cd/m² (scotopic {})",
        image.width,
        image.height,
        num(args.white),
        num(chart.layout.patches[visadapt::chart::WHITE_PATCH]
            .photometry
            .scotopic),
    );
    println!(
        "view                          {:.3} m away, {:.2} pixels/degree, horizontal fov {:.4} deg",
        options.viewing_distance_m, options.pixels_per_degree, view.horizontal_deg
    );
    println!(
        "Snellen lines                 20/200 to 20/10 (at this distance 20/10 tests {})",
        smallest.effective_snellen()
    );
    println!("wrote                         {}", args.output.display());
    println!(
        "map it with                   visadapt map {} --fov {:.4} -o OUT.png",
        args.output.display(),
        view.horizontal_deg
    );
    Ok(())
}
