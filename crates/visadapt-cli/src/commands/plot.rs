//! `visadapt plot NAME -o FILE.svg|png`: the paper's model figures, drawn from the library's
//! own functions (nothing is read from stored numbers but the CIE tables).
//!
//! * `luminous-efficiency` (Fig. 2): CIE 1924/1931 V(λ) and CIE 1951 V'(λ)
//!   ([`visadapt::spectral`], Sprague-interpolated to 1 nm);
//! * `tvi` (Fig. 3): the cone and rod threshold-versus-intensity curves, Eq. 4 and Eq. 5
//!   ([`visadapt::tvi`]);
//! * `spectral-sensitivity` (Fig. 4): rod, cone and system sensitivity to monochromatic
//!   light at scotopic, mesopic and photopic levels, derived from Eq. 4–6 and the
//!   luminous efficiency functions ([`visadapt::spectral::sensitivity`] explains how);
//! * `acuity` (Fig. 7): the highest resolvable grating frequency against luminance (the
//!   Shaler fit of [`visadapt::acuity`]);
//! * `timecourse` (Figs. 8–10): the threshold after a change of light, rods (Adelson) and
//!   cones (Baker) light-adapting, and dark adaptation with its rod–cone break (Hecht)
//!   ([`visadapt::timecourse::figure_8`] and the two after it).

use crate::cli::{PlotArgs, PlotName};
use crate::graphics::{self, FAMILY, PictureFormat};
use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use visadapt::spectral::sensitivity::{
    FIG4_MESOPIC_CD_M2, FIG4_PHOTOPIC_CD_M2, FIG4_SCOTOPIC_CD_M2, spectral_sensitivity,
};
use visadapt::spectral::{interpolate, tables};
use visadapt::{acuity, timecourse, tvi};

/// Colour of the cone (photopic) curves.
const CONES: RGBColor = RGBColor(200, 40, 30);
/// Colour of the rod (scotopic) curves.
const RODS: RGBColor = RGBColor(30, 70, 200);

pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    let format = PictureFormat::from_path(&args.output)?;
    super::check_output_folder(&args.output)?;
    render(args.name, format, &args.output)?;
    println!("wrote {} ({})", args.output.display(), title(args.name));
    Ok(())
}

/// Draw figure `name` into `path` in `format`, atomically.
pub fn render(name: PlotName, format: PictureFormat, path: &std::path::Path) -> anyhow::Result<()> {
    graphics::register_font();
    let size = match name {
        PlotName::SpectralSensitivity | PlotName::Timecourse => (1500, 560),
        _ => (900, 600),
    };
    match format {
        PictureFormat::Svg => {
            let mut svg = String::new();
            {
                let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
                draw(&root, name)?;
                root.present().map_err(plot_error)?;
            }
            graphics::write_text(path, &svg)
        }
        PictureFormat::Png => {
            let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
            {
                let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
                draw(&root, name)?;
                root.present().map_err(plot_error)?;
            }
            graphics::write_rgb_png(path, size.0, size.1, &rgb)
        }
    }
}

fn title(name: PlotName) -> &'static str {
    match name {
        PlotName::LuminousEfficiency => {
            "Fig. 2: photopic V(λ) and scotopic V'(λ) luminous efficiency"
        }
        PlotName::Tvi => "Fig. 3: threshold versus intensity of the rod and cone systems",
        PlotName::SpectralSensitivity => {
            "Fig. 4: spectral sensitivity at three levels of adaptation"
        }
        PlotName::Acuity => "Fig. 7: visual acuity against luminance",
        PlotName::Timecourse => "Figs. 8-10: the time course of light and dark adaptation",
    }
}

fn plot_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e:?}")
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, name: PlotName) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(plot_error)?;
    match name {
        PlotName::LuminousEfficiency => luminous_efficiency(root),
        PlotName::Tvi => tvi_curves(root),
        PlotName::SpectralSensitivity => spectral(root),
        PlotName::Acuity => acuity_curve(root),
        PlotName::Timecourse => timecourse_curves(root),
    }
}

fn line(colour: RGBColor, width: u32) -> ShapeStyle {
    ShapeStyle {
        color: colour.to_rgba(),
        filled: false,
        stroke_width: width,
    }
}

/// The frame of one chart: its caption, axis ranges, axis titles and tick decimals, in the
/// style of a whole figure or of one of its panels.
struct Axes<'t> {
    caption: &'t str,
    panel: bool,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    x_desc: &'t str,
    y_desc: &'t str,
    x_decimals: usize,
    y_decimals: usize,
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

impl Axes<'_> {
    /// Build the chart on `area` and draw its mesh and axis titles.
    fn draw<'a, DB: DrawingBackend>(
        &self,
        area: &'a DrawingArea<DB, Shift>,
    ) -> anyhow::Result<Chart<'a, DB>> {
        // (caption, margin, x label area, y label area, tick labels, axis titles) in points.
        let (caption, margin, x_area, y_area, ticks, titles) = if self.panel {
            (18, 12, 45, 60, 13, 15)
        } else {
            (22, 20, 50, 70, 15, 17)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(self.caption, (FAMILY, caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(self.x.clone(), self.y.clone())
            .map_err(plot_error)?;
        let (xd, yd) = (self.x_decimals, self.y_decimals);
        chart
            .configure_mesh()
            .x_desc(self.x_desc)
            .y_desc(self.y_desc)
            .x_label_formatter(&|x| format!("{x:.xd$}"))
            .y_label_formatter(&|y| format!("{y:.yd$}"))
            .label_style((FAMILY, ticks))
            .axis_desc_style((FAMILY, titles))
            .draw()
            .map_err(plot_error)?;
        Ok(chart)
    }
}

/// Draw one labelled curve with its legend swatch.
fn curve<DB: DrawingBackend, S>(
    chart: &mut Chart<'_, DB>,
    series: S,
    label: &str,
    style: ShapeStyle,
) -> anyhow::Result<()>
where
    S: IntoIterator,
    S::Item: Drawable<DB>,
    for<'b> &'b S::Item: PointCollection<'b, (f64, f64)>,
{
    chart
        .draw_series(series)
        .map_err(plot_error)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    Ok(())
}

/// Wavelengths 380–780 nm in 1 nm steps.
fn wavelengths() -> impl Iterator<Item = f64> + Clone {
    (380..=780).map(f64::from)
}

/// Fig. 2.
fn luminous_efficiency<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
    let mut chart = Axes {
        caption: title(PlotName::LuminousEfficiency),
        panel: false,
        x: 380.0..780.0,
        y: 0.0..1.05,
        x_desc: "wavelength λ (nm)",
        y_desc: "relative luminous efficiency",
        x_decimals: 0,
        y_decimals: 1,
    }
    .draw(root)?;
    let curves = [
        (
            "scotopic V'(λ), CIE 1951 (rods)",
            &tables::CIE1951_V_PRIME,
            RODS,
        ),
        (
            "photopic V(λ), CIE 1924 = ȳ of CIE 1931 (cones)",
            &tables::CIE1931_Y_BAR,
            CONES,
        ),
    ];
    for (label, table, colour) in curves {
        let points = wavelengths().filter_map(|nm| interpolate(table, nm).map(|v| (nm, v)));
        curve(
            &mut chart,
            LineSeries::new(points, line(colour, 3)),
            label,
            line(colour, 3),
        )?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight)
}

fn legend<'a, DB: DrawingBackend + 'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    position: SeriesLabelPosition,
) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font((FAMILY, 15))
        .draw()
        .map_err(plot_error)
}

/// Fig. 3.
fn tvi_curves<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
    let (lo, hi) = (-6.0, 5.0);
    let mut chart = Axes {
        caption: title(PlotName::Tvi),
        panel: false,
        x: lo..hi,
        y: -3.5..5.0,
        x_desc: "log₁₀ adaptation luminance La (cd/m²; scotopic cd/m² for rods)",
        y_desc: "log₁₀ threshold ΔL (same units)",
        x_decimals: 0,
        y_decimals: 0,
    }
    .draw(root)?;
    let xs = (0..=1100).map(move |i| lo + i as f64 * (hi - lo) / 1100.0);
    type Curve = (&'static str, fn(f64) -> f64, RGBColor);
    let curves: [Curve; 2] = [
        ("rods, Eq. 5 (scotopic cd/m²)", tvi::log_rod_threshold, RODS),
        ("cones, Eq. 4 (cd/m²)", tvi::log_cone_threshold, CONES),
    ];
    for (label, f, colour) in curves {
        let series = LineSeries::new(xs.clone().map(|x| (x, f(x))), line(colour, 3));
        curve(&mut chart, series, label, line(colour, 3))?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// Fig. 7.
fn acuity_curve<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
    let (lo, hi) = (-4.0, 4.0);
    let mut chart = Axes {
        caption: title(PlotName::Acuity),
        panel: false,
        x: lo..hi,
        y: 0.0..60.0,
        x_desc: "log₁₀ adaptation luminance (cd/m²)",
        y_desc: "highest resolvable frequency (cycles/degree)",
        x_decimals: 0,
        y_decimals: 0,
    }
    .draw(root)?;
    let xs = (0..=800).map(move |i| lo + i as f64 * (hi - lo) / 800.0);
    let black = RGBColor(20, 20, 20);
    let points = xs.map(|x| (x, acuity::cutoff_cycles_per_degree(10f64.powf(x))));
    let series = LineSeries::new(points, line(black, 3));
    let label = "Shaler (1937), fit of Ward Larson et al. (1997)";
    curve(&mut chart, series, label, line(black, 3))?;
    // Snellen equivalents at the paper's two anchors (Sec. 3.4).
    for x in [3.0f64, -3.3] {
        let f = acuity::cutoff_cycles_per_degree(10f64.powf(x));
        let text = format!("{f:.1} c/deg ≈ {}", acuity::snellen(f));
        chart
            .draw_series([Circle::new((x, f), 5, ShapeStyle::from(&black).filled())])
            .map_err(plot_error)?;
        let (dx, dy) = if x > 0.0 { (-2.3, 4.0) } else { (0.3, -1.0) };
        chart
            .draw_series([Text::new(text, (x + dx, f + dy), (FAMILY, 15))])
            .map_err(plot_error)?;
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// Fig. 4: three panels.
fn spectral<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
    let root = root
        .titled(title(PlotName::SpectralSensitivity), (FAMILY, 22))
        .map_err(plot_error)?;
    let panels = root.split_evenly((1, 3));
    let levels = [
        ("(a) scotopic", FIG4_SCOTOPIC_CD_M2),
        ("(b) mesopic", FIG4_MESOPIC_CD_M2),
        ("(c) photopic", FIG4_PHOTOPIC_CD_M2),
    ];
    // One vertical scale for the three panels, so the loss of absolute sensitivity shows.
    let mut all = Vec::new();
    for &(_, level) in &levels {
        let row: Vec<_> = (400..=700)
            .map(|nm| spectral_sensitivity(level, f64::from(nm)))
            .collect::<Result<_, _>>()?;
        all.push(row);
    }
    let top = all
        .iter()
        .flatten()
        .map(|s| s.log_system())
        .fold(f64::MIN, f64::max)
        .ceil()
        + 0.5;
    let bottom = top - 9.0;
    for ((panel, (name, level)), row) in panels.iter().zip(levels).zip(&all) {
        let mut chart = Axes {
            caption: &format!("{name}, {level} cd/m²"),
            panel: true,
            x: 400.0..700.0,
            y: bottom..top,
            x_desc: "wavelength λ (nm)",
            y_desc: "log₁₀ sensitivity (sr·m²/W)",
            x_decimals: 0,
            y_decimals: 0,
        }
        .draw(panel)?;
        let clip = |v: f64| v.max(bottom);
        let rods: Vec<(f64, f64)> = row
            .iter()
            .filter_map(|s| s.log_rod.map(|r| (s.wavelength_nm, clip(r))))
            .collect();
        if !rods.is_empty() {
            let series = DashedLineSeries::new(rods, 8, 5, line(RODS, 2));
            curve(
                &mut chart,
                series,
                "rods (Eq. 5, weighted by k of Eq. 6)",
                line(RODS, 2),
            )?;
        }
        let cones = row.iter().map(|s| (s.wavelength_nm, clip(s.log_cone)));
        let series = DashedLineSeries::new(cones, 8, 5, line(CONES, 2));
        curve(&mut chart, series, "cones (Eq. 4)", line(CONES, 2))?;
        let black = RGBColor(20, 20, 20);
        let system = row.iter().map(|s| (s.wavelength_nm, clip(s.log_system())));
        let series = LineSeries::new(system, line(black, 3));
        curve(
            &mut chart,
            series,
            "visual system (the more sensitive)",
            line(black, 3),
        )?;
        legend(&mut chart, SeriesLabelPosition::LowerMiddle)?;
    }
    Ok(())
}

/// Figs. 8–10: three panels drawn from the time-course model's figure data.
fn timecourse_curves<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
    let root = root
        .titled(title(PlotName::Timecourse), (FAMILY, 22))
        .map_err(plot_error)?;
    let panels = root.split_evenly((1, 3));
    let figures = [
        (
            timecourse::figure_8(),
            "(a) Fig. 8: rods, dark to 0.5 log cd/m²",
            "s",
            1.0,
        ),
        (
            timecourse::figure_9(),
            "(b) Fig. 9: cones, dark to 3.75 log cd/m²",
            "min",
            60.0,
        ),
        (
            timecourse::figure_10(),
            "(c) Fig. 10: 2.3 log cd/m² to dark",
            "min",
            60.0,
        ),
    ];
    let black = RGBColor(20, 20, 20);
    for (panel, (figure, caption, unit, per_unit)) in panels.iter().zip(figures) {
        let points = || figure.curves.iter().flat_map(|c| c.points.iter());
        let t_max = points().map(|p| p.0).fold(0.0, f64::max) / per_unit;
        let y_lo = points().map(|p| p.1).fold(f64::MAX, f64::min);
        let y_hi = points().map(|p| p.1).fold(f64::MIN, f64::max);
        let pad = 0.1 * (y_hi - y_lo).max(0.5);
        let mut chart = Axes {
            caption,
            panel: true,
            x: 0.0..t_max,
            y: (y_lo - pad)..(y_hi + pad),
            x_desc: &format!("time after the change ({unit})"),
            y_desc: "log₁₀ threshold (cd/m²; scotopic for rods)",
            x_decimals: 0,
            y_decimals: 1,
        }
        .draw(panel)?;
        for curve in &figure.curves {
            let (colour, width) = match curve.label {
                "rods" => (RODS, 2),
                "cones" => (CONES, 2),
                _ => (black, 4),
            };
            let style = line(colour, width);
            let points = curve.points.iter().map(|&(t, y)| (t / per_unit, y));
            self::curve(
                &mut chart,
                LineSeries::new(points, style),
                curve.label,
                style,
            )?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}
