//! `visadapt demo`: the paper's Fig. 11 in one command. Renders the built-in scene
//! ([`visadapt::chart`]) lit at each level, maps it for an observer adapted to it, writes the
//! panels and a labelled contact sheet, and prints what each observer can see, measured on
//! the rendered panels.

use crate::cli::DemoArgs;
use crate::graphics;
use crate::numbers::{count, sig};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::style::RGBColor;
use std::path::Path;
use visadapt::chart::{BLUE_PATCH, Chart, ChartOptions, RED_PATCH, Readings};
use visadapt::io::{self, OutputFormat};
use visadapt::operator::{self, Report, ViewingConditions};
use visadapt::sequence::{self, ApngWriter, Playback, Sequence};

/// One rendered level.
struct Panel {
    level: f64,
    report: Report,
    readings: Readings,
    /// sRGB, 8 bits, interleaved.
    rgb: Vec<u8>,
    width: usize,
    height: usize,
    /// The smallest Snellen line whose strokes are within the acuity limit.
    smallest_line: Option<u32>,
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    if args.levels.is_empty() {
        bail!("--levels: give at least one luminance");
    }
    for &l in &args.levels {
        super::timecourse::positive("--levels", l)?;
    }
    // The paper's observer, with veiling glare and local adaptation when asked for.
    let conditions = ViewingConditions {
        adaptation: args.adaptation.mode(),
        glare: args.glare.glare(),
        undershoot: args.time_course.undershoot(),
        ..ViewingConditions::default()
    };
    conditions.validate()?;
    std::fs::create_dir_all(&args.output).with_context(|| {
        format!(
            "{}: cannot create the output directory",
            args.output.display()
        )
    })?;

    let sequences = if args.no_sequences {
        Vec::new()
    } else {
        vec![
            ("fig12a", "light adaptation", Sequence::figure_12a()),
            ("fig12b", "dark adaptation", Sequence::figure_12b()),
        ]
    };
    let frames: usize = sequences.iter().map(|s| s.2.frame_count()).sum();
    let progress = ProgressBar::new((args.levels.len() + 1 + frames) as u64).with_style(
        ProgressStyle::with_template("{spinner} [{bar:20}] {pos}/{len} {msg}")
            .expect("valid template"),
    );
    let mut panels = Vec::with_capacity(args.levels.len());
    for &level in &args.levels {
        progress.set_message(format!("rendering the scene at {level} cd/m²"));
        let panel = render(level, &args.output, &conditions)?;
        panels.push(panel);
        progress.inc(1);
    }
    progress.set_message("writing the contact sheet");
    let sheet = args.output.join("contact-sheet.png");
    contact_sheet(&panels, &sheet)?;
    progress.inc(1);
    let mut written = Vec::new();
    if !sequences.is_empty() {
        // The scene at any level: each sequence rescales it so its white is at the level.
        let chart = Chart::new(&ChartOptions::default())?;
        for (name, what, seq) in &sequences {
            progress.set_message(format!(
                "{what}: {} to {} cd/m²",
                seq.from_cd_m2, seq.to_cd_m2
            ));
            let playback =
                render_sequence(&chart, name, seq, &args.output, &conditions, &progress)?;
            let pace = playback.speedup.map_or(String::new(), |x| {
                format!(" ({}x real time)", crate::numbers::num(x))
            });
            written.push(format!(
                "  {what} (Fig. 12): {} -> {} cd/m², frames {name}-0.png (adapted) to {name}-{}.png at {} s, animated {name}.apng{pace}",
                seq.from_cd_m2,
                seq.to_cd_m2,
                seq.times_seconds.len(),
                seq.times_seconds
                    .iter()
                    .map(|t| format!("{t}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            ));
        }
    }
    progress.finish_and_clear();

    print!("{}", table(&panels));
    println!(
        "wrote {} and contact-sheet.png in {}",
        count(panels.len(), "panel", "panels"),
        args.output.display()
    );
    for line in &written {
        println!("{line}");
    }
    Ok(())
}

/// Length of the demo's animated sequences, seconds (the real time steps sped up to it, as
/// `sequence --apng-seconds`'s default).
const SEQUENCE_PLAYBACK_SECONDS: f64 = 6.0;

/// Render one of the paper's Fig. 12 sequences on the built-in scene: numbered PNG frames
/// and an animated PNG, through [`visadapt::sequence::render`].
fn render_sequence(
    chart: &Chart,
    name: &str,
    seq: &Sequence,
    dir: &Path,
    conditions: &ViewingConditions,
    progress: &ProgressBar,
) -> anyhow::Result<Playback> {
    let path = dir.join(format!("{name}.apng"));
    let playback = seq.playback(SEQUENCE_PLAYBACK_SECONDS)?;
    let mut apng = ApngWriter::with_delays(
        &path,
        chart.image.width,
        chart.image.height,
        &playback.delays_ms,
    )
    .with_context(|| path.display().to_string())?;
    sequence::render(&chart.image, seq, conditions, |f| {
        let frame = dir.join(format!("{name}-{}.png", f.index));
        io::write_display(f.image, &frame, OutputFormat::png(8))?;
        apng.push(f.image)?;
        progress.inc(1);
        Ok(())
    })
    .with_context(|| format!("{name}: {}", dir.display()))?;
    apng.finish().with_context(|| path.display().to_string())?;
    Ok(playback)
}

/// The panel's file name, e.g. `panel-0.04.png`.
pub fn panel_name(level: f64) -> String {
    format!("panel-{level}.png")
}

fn render(level: f64, dir: &Path, conditions: &ViewingConditions) -> anyhow::Result<Panel> {
    let chart = Chart::new(&ChartOptions {
        white_cd_m2: level,
        ..ChartOptions::default()
    })?;
    let out = operator::map(&chart.image, conditions)?;
    let path = dir.join(panel_name(level));
    io::write_display(&out.image, &path, OutputFormat::png(8))
        .with_context(|| path.display().to_string())?;
    let readings = chart.read(&out.image)?;
    let cutoff = out.report.acuity.cutoff_cycles_per_degree;
    let smallest_line = chart
        .layout
        .lines
        .iter()
        .filter(|l| l.stroke_cycles_per_degree() <= cutoff)
        .map(|l| l.denominator)
        .next_back();
    Ok(Panel {
        level,
        rgb: io::display::to_srgb8(&out.image),
        width: out.image.width,
        height: out.image.height,
        report: out.report,
        readings,
        smallest_line,
    })
}

/// The state of the visual system by the rod weight `k` (Eq. 6).
fn state(k: f64) -> &'static str {
    if k <= 0.0 {
        "photopic (cones)"
    } else if k >= 1.0 {
        "scotopic (rods)"
    } else {
        "mesopic (rods and cones)"
    }
}

/// Mean CIELAB chroma of the 18 chromatic ColorChecker patches, as displayed.
fn mean_chroma(r: &Readings) -> f64 {
    r.patches[..18].iter().map(|p| p.chroma()).sum::<f64>() / 18.0
}

/// Words for a mean chroma. The thresholds are a project choice: C*ab of about 2.3 is one
/// just-noticeable difference (Sharma 2003), the ColorChecker's mean chroma in daylight is
/// about 50.
fn colour_word(c: f64) -> &'static str {
    if c >= 40.0 {
        "vivid"
    } else if c >= 10.0 {
        "reduced"
    } else if c >= 1.0 {
        "faint"
    } else {
        "none"
    }
}

/// Which of the red and blue patches is lighter on the display, and by how much.
fn red_blue(r: &Readings) -> String {
    let (red, blue) = (
        r.patches[RED_PATCH].luminance_cd_m2,
        r.patches[BLUE_PATCH].luminance_cd_m2,
    );
    if red >= blue {
        format!("red {:.1}x", red / blue)
    } else {
        format!("blue {:.1}x", blue / red)
    }
}

fn line_text(p: &Panel) -> String {
    match p.smallest_line {
        Some(d) => format!("20/{d}"),
        None => "none, forms only".to_string(),
    }
}

fn table(panels: &[Panel]) -> String {
    let mut s = format!(
        "{:<9} {:<12} {:<6} {:<16} {:<17} {:<16} {}\n",
        "white",
        "adapted to",
        "rods k",
        "acuity",
        "smallest line",
        "colour (mean C*)",
        "lighter: red or blue"
    );
    s += &format!(
        "{:<9} {:<12} {:<6} {:<16} {:<17} {:<16} {}\n",
        "cd/m²", "cd/m²", "Eq. 6", "c/deg (Snellen)", "resolved", "measured", "measured"
    );
    for p in panels {
        let r = &p.report;
        let c = mean_chroma(&p.readings);
        s += &format!(
            "{:<9} {:<12} {:<6.2} {:<16} {:<17} {:<16} {}\n",
            p.level,
            luminance(r.world_adaptation_cd_m2),
            r.mapping.rod_weight,
            format!("{:.1} ({})", r.acuity.cutoff_cycles_per_degree, r.snellen()),
            line_text(p),
            format!("{} ({c:.1})", colour_word(c)),
            red_blue(&p.readings),
        );
    }
    s
}

/// A luminance with three significant digits (500, 5, 0.02, 0.0005).
fn luminance(v: f64) -> String {
    sig(v, 3).to_string()
}

/// The labels of one panel on the contact sheet.
fn labels(p: &Panel) -> Vec<String> {
    let r = &p.report;
    let c = mean_chroma(&p.readings);
    vec![
        format!("{} cd/m²: {}", p.level, state(r.mapping.rod_weight)),
        format!(
            "adapted to {} cd/m² ({} scotopic cd/m²), rods k = {:.2}",
            luminance(r.world_adaptation_cd_m2),
            luminance(r.world_adaptation_scotopic_cd_m2),
            r.mapping.rod_weight
        ),
        format!(
            "acuity {:.1} c/deg ({}), smallest line resolved: {}",
            r.acuity.cutoff_cycles_per_degree,
            r.snellen(),
            line_text(p)
        ),
        format!(
            "colour: {} (mean chroma {c:.1}), lighter: {}",
            colour_word(c),
            red_blue(&p.readings)
        ),
    ]
}

/// Panels in a grid of two columns, each with its labels above it.
fn contact_sheet(panels: &[Panel], path: &Path) -> anyhow::Result<()> {
    const MARGIN: usize = 16;
    const TEXT: f64 = 21.0;
    let label_h = (4.0 * TEXT * 1.3).ceil() as usize + 12;
    let (pw, ph) = (
        panels.iter().map(|p| p.width).max().unwrap_or(0),
        panels.iter().map(|p| p.height).max().unwrap_or(0),
    );
    let cols = panels.len().min(2);
    let rows = panels.len().div_ceil(2);
    let (cell_w, cell_h) = (pw + 2 * MARGIN, ph + label_h + 2 * MARGIN);
    let (w, h) = (cols * cell_w, rows * cell_h);
    let background = 24u8;
    let mut rgb = vec![background; w * h * 3];
    for (k, p) in panels.iter().enumerate() {
        let (x0, y0) = ((k % 2) * cell_w + MARGIN, (k / 2) * cell_h + MARGIN);
        for j in 0..p.height {
            let src = &p.rgb[j * p.width * 3..(j + 1) * p.width * 3];
            let dst = ((y0 + label_h + j) * w + x0) * 3;
            rgb[dst..dst + src.len()].copy_from_slice(src);
        }
    }
    for (k, p) in panels.iter().enumerate() {
        let (x0, y0) = ((k % 2) * cell_w + MARGIN, (k / 2) * cell_h + MARGIN);
        graphics::draw_text(
            &mut rgb,
            (w as u32, h as u32),
            (x0 as i32, y0 as i32),
            TEXT,
            RGBColor(235, 235, 235),
            &labels(p),
        )?;
    }
    graphics::write_rgb_png(path, w as u32, h as u32, &rgb)
}
