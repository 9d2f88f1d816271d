//! `visadapt visible REF TEST`: how visible the difference between two HDR images of one
//! scene is to an observer adapted to the reference, in just-noticeable differences (JNDs),
//! with an optional heat map and colour bar. The model is [`visadapt::visibility`]
//! (Ferwerda et al. 1996, Eq. 4–7).

use crate::cli::VisibleArgs;
use crate::graphics;
use crate::numbers::{count, num};
use anyhow::{Context, bail};
use plotters::style::RGBColor;
use std::path::Path;
use visadapt::HdrImage;
use visadapt::io;
use visadapt::operator::{Report, ViewingConditions};
use visadapt::visibility::{self, Difference};

pub fn run(args: VisibleArgs) -> anyhow::Result<()> {
    // Everything that can be checked before reading is checked first.
    let map_format = match &args.output {
        Some(out) => {
            let format = MapFormat::from_path(out)?;
            io::output::refuse_same_file(out, &[&args.reference, &args.test])?;
            super::check_output_folder(out)?;
            Some(format)
        }
        None => None,
    };
    let conditions = args
        .viewing
        .conditions(None, Some(&args.world), Some(&args.view), None);
    conditions.validate()?;

    let limits = args.limits.limits();
    // `--scale` is applied by the decoders; `--peak` once the reference is read.
    let read = |path: &Path| {
        io::read_scaled(path, &limits, args.units.decoder_factor())
            .with_context(|| path.display().to_string())
    };
    let mut reference = read(&args.reference)?;
    let mut test = read(&args.test)?;
    if (reference.width, reference.height) != (test.width, test.height) {
        bail!(
            "{}: {}x{} pixels, but the reference {} is {}x{}; the images must be the same size",
            args.test.display(),
            test.width,
            test.height,
            args.reference.display(),
            reference.width,
            reference.height
        );
    }
    let scale = input_scale(&args, &reference, &test, conditions.hot_pixel_fraction)?;
    args.units.apply(&mut reference, scale);
    args.units.apply(&mut test, scale);
    let conditions = ViewingConditions {
        view: args.view.view(reference.width, reference.height),
        ..conditions
    };
    super::warn_if_default_view(&args.reference, &reference, &conditions);
    let (d, report) = visibility::compare(&reference, &test, &conditions)?;
    let report = &report;
    if d.non_finite_pixels > 0 {
        log::warn!(
            "{} with NaN or infinite values read as black",
            count(d.non_finite_pixels, "pixel", "pixels")
        );
    }
    if let (Some(out), Some(format)) = (&args.output, map_format) {
        match format {
            MapFormat::HeatMap => {
                let (w, h, rgb) = heat_map(&d)?;
                graphics::write_rgb_png(out, w, h, &rgb)?;
            }
            MapFormat::Exr => io::display::write_atomically(out, |w| {
                io::exr::write_plane(d.width, d.height, &d.jnd, w)
            })
            .with_context(|| out.display().to_string())?,
        }
    }

    if args.json {
        let map = args.output.as_ref().map(|p| p.display().to_string());
        let v = visadapt::report::difference_json(&d, report, scale, map.as_deref());
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", text_report(&d, report));
        if let Some(out) = &args.output {
            println!("wrote                         {}", out.display());
        }
    }
    Ok(())
}

/// The factor that turns both images into cd/m²: `--scale`, or `--peak` over the
/// reference's highest visible luminance, or 1.
fn input_scale(
    args: &VisibleArgs,
    reference: &HdrImage,
    test: &HdrImage,
    hot_pixel_fraction: f64,
) -> anyhow::Result<f64> {
    let scale = args
        .units
        .factor(&args.reference, reference, hot_pixel_fraction)?;
    if args.units.is_unset() {
        super::warn_if_relative(&args.test, test);
    }
    Ok(scale)
}

/// What `visible -o` writes, by the extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MapFormat {
    /// `.png`: the heat map with its colour bar.
    HeatMap,
    /// `.exr`: the JND of every pixel as 32-bit floats, one channel `Y`.
    Exr,
}

impl MapFormat {
    fn from_path(path: &Path) -> anyhow::Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("png") => Ok(MapFormat::HeatMap),
            Some("exr") => Ok(MapFormat::Exr),
            _ => bail!(
                "{}: the map is written as a PNG heat map or an OpenEXR of JNDs (use .png or .exr)",
                path.display()
            ),
        }
    }
}

fn text_report(d: &Difference, r: &Report) -> String {
    let blur = if !r.acuity_applied {
        "off (--no-acuity)".to_string()
    } else if r.mapping.blur_sigma_px > 0.0 {
        format!("sigma {:.3} px", r.mapping.blur_sigma_px)
    } else {
        "below a pixel's resolution".to_string()
    };
    format!(
        "images                        {}x{}\n\
         observer (Sec. 4.4)           adapted to {} cd/m² ({}), {} scotopic cd/m²\n\
         thresholds (Eq. 4, 5, 6)      cones {} cd/m², rods {} scotopic cd/m², rod weight k {:.3}\n\
         acuity (Eq. 7)                {:.2} cycles/degree, blur {} ({:.1} deg field)\n\
         visible difference            {:.3} % of the pixels at 1 JND or more\n\
         JND                           mean {:.4}, max {:.4}\n",
        d.width,
        d.height,
        num(r.world_adaptation_cd_m2),
        if r.world_adaptation_source == visadapt::operator::Source::Caller {
            "given"
        } else {
            "from the reference"
        },
        num(r.world_adaptation_scotopic_cd_m2),
        num(r.cone_threshold_cd_m2),
        num(r.rod_threshold_scotopic_cd_m2),
        r.mapping.rod_weight,
        r.acuity.cutoff_cycles_per_degree,
        blur,
        r.view.horizontal_deg,
        100.0 * d.visible_fraction,
        d.mean_jnd,
        d.max_jnd,
    )
}

/// Bottom of the colour scale, JND (smaller values take its colour).
pub const SCALE_MIN_JND: f32 = 0.1;
/// Top of the colour scale, JND (larger values take its colour).
pub const SCALE_MAX_JND: f32 = 100.0;

/// matplotlib's "inferno" colour map (S. van der Walt, N. Smith, 2015) sampled at 0, 1/4,
/// 1/2, 3/4 and 1 (its entries 0, 64, 128, 192, 255 as 8-bit sRGB), interpolated linearly
/// in between: dark to light, so it reads in grey too.
const INFERNO: [[f32; 3]; 5] = [
    [0.0, 0.0, 4.0],
    [87.0, 16.0, 110.0],
    [188.0, 55.0, 84.0],
    [249.0, 142.0, 9.0],
    [252.0, 255.0, 164.0],
];

/// Position on the colour scale (0 at [`SCALE_MIN_JND`], 1 at [`SCALE_MAX_JND`]),
/// logarithmic in JND.
fn scale_position(jnd: f32) -> f32 {
    let lo = SCALE_MIN_JND.log10();
    let hi = SCALE_MAX_JND.log10();
    let t = (jnd.max(SCALE_MIN_JND).log10() - lo) / (hi - lo);
    if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) }
}

/// The colour of position `t` in [0, 1] on the scale.
fn colour_at(t: f32) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * (INFERNO.len() - 1) as f32;
    let i = (x as usize).min(INFERNO.len() - 2);
    let f = x - i as f32;
    let (a, b) = (INFERNO[i], INFERNO[i + 1]);
    [0, 1, 2].map(|c| (a[c] + (b[c] - a[c]) * f).round() as u8)
}

/// The heat-map colour of a JND value.
pub fn jnd_colour(jnd: f32) -> [u8; 3] {
    colour_at(scale_position(jnd))
}

/// Smallest height of the picture, so that the colour bar and its labels fit.
const MIN_HEIGHT: usize = 240;
/// A map lower than [`MIN_HEIGHT`] is enlarged, but not beyond this width.
const MAX_ENLARGED_WIDTH: usize = 1024;

/// How many times a `w × h` map is enlarged (whole pixels, so each JND keeps its colour):
/// as often as it fits in [`MIN_HEIGHT`] and [`MAX_ENLARGED_WIDTH`], at least once.
fn enlargement(w: usize, h: usize) -> usize {
    (MIN_HEIGHT / h.max(1))
        .min(MAX_ENLARGED_WIDTH / w.max(1))
        .max(1)
}

/// The heat map of `d` (each image pixel a square of [`enlargement`] pixels, the map
/// centred vertically) with a logarithmic colour bar and its labels to the right, on
/// white: `(width, height, interleaved sRGB)`.
fn heat_map(d: &Difference) -> anyhow::Result<(u32, u32, Vec<u8>)> {
    let n = enlargement(d.width, d.height);
    let (w, h) = (d.width * n, d.height * n);
    let canvas_h = h.max(MIN_HEIGHT);
    let map_top = (canvas_h - h) / 2;
    // Text and bar grow with the picture, up to 4×.
    let s = (canvas_h as f64 / MIN_HEIGHT as f64).clamp(1.0, 4.0);
    let px = |v: f64| (v * s).round() as usize;
    let font = 13.0 * s;
    let panel = px(150.0);
    let canvas_w = w + panel;
    let too_big = || anyhow::anyhow!("{canvas_w}x{canvas_h} is too large for a PNG heat map");
    let (cw, ch) = (
        u32::try_from(canvas_w).map_err(|_| too_big())?,
        u32::try_from(canvas_h).map_err(|_| too_big())?,
    );
    let mut rgb = vec![255u8; canvas_w * canvas_h * 3];
    let mut put = |x: usize, y: usize, c: [u8; 3]| {
        let i = (y * canvas_w + x) * 3;
        rgb[i..i + 3].copy_from_slice(&c);
    };
    for y in 0..h {
        let row = &d.jnd[y / n * d.width..][..d.width];
        for x in 0..w {
            put(x, map_top + y, jnd_colour(row[x / n]));
        }
    }

    // The bar, top = SCALE_MAX_JND, with a black frame and tick marks.
    let (x0, x1) = (w + px(14.0), w + px(34.0));
    let (top, bottom) = (px(34.0), canvas_h - px(14.0));
    let y_of = |t: f32| bottom - (t * (bottom - top) as f32).round() as usize;
    for y in top..=bottom {
        let c = colour_at((bottom - y) as f32 / (bottom - top) as f32);
        for x in x0..x1 {
            put(x, y, c);
        }
    }
    let black = [0, 0, 0];
    for x in x0 - 1..=x1 {
        put(x, top - 1, black);
        put(x, bottom + 1, black);
    }
    for y in top - 1..=bottom + 1 {
        put(x0 - 1, y, black);
        put(x1, y, black);
    }
    let ticks = [
        (0.1f32, "0.1"),
        (1.0, "1  threshold"),
        (10.0, "10"),
        (100.0, "100"),
    ];
    for (v, _) in ticks {
        let y = y_of(scale_position(v));
        for x in x1..x1 + px(6.0) {
            put(x, y, black);
        }
    }
    let text_x = (x1 + px(9.0)) as i32;
    for (v, label) in ticks {
        let y = y_of(scale_position(v)) as i32 - (0.55 * font) as i32;
        graphics::draw_text(
            &mut rgb,
            (cw, ch),
            (text_x, y),
            font,
            RGBColor(0, 0, 0),
            &[label.to_string()],
        )?;
    }
    graphics::draw_text(
        &mut rgb,
        (cw, ch),
        ((x0 - px(6.0)) as i32, px(8.0) as i32),
        font,
        RGBColor(0, 0, 0),
        &["JND (log scale)".to_string()],
    )?;
    Ok((cw, ch, rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_maps_are_enlarged_to_the_bar_height_within_a_width() {
        assert_eq!(enlargement(64, 32), 7);
        assert_eq!(enlargement(128, 72), 3);
        assert_eq!(enlargement(800, 800), 1);
        assert_eq!(enlargement(600, 10), 1);
        assert_eq!(enlargement(1, 1), 240);
        assert_eq!(enlargement(0, 0), 240);
    }

    #[test]
    fn colour_scale_is_logarithmic_and_clamped() {
        assert_eq!(jnd_colour(0.0), [0, 0, 4]);
        assert_eq!(jnd_colour(f32::NAN), [0, 0, 4]);
        assert_eq!(jnd_colour(0.1), [0, 0, 4]);
        assert_eq!(jnd_colour(100.0), [252, 255, 164]);
        assert_eq!(jnd_colour(1e9), [252, 255, 164]);
        // 1 JND is a third of the way up (0.1 → 100 spans three decades).
        assert!((scale_position(1.0) - 1.0 / 3.0).abs() < 1e-6);
        assert!((scale_position(10.0) - 2.0 / 3.0).abs() < 1e-6);
        // Lightness rises along the scale.
        let luma = |c: [u8; 3]| 0.2126 * c[0] as f32 + 0.7152 * c[1] as f32 + 0.0722 * c[2] as f32;
        let mut prev = -1.0;
        for i in 0..=100 {
            let l = luma(colour_at(i as f32 / 100.0));
            assert!(l >= prev, "{i}");
            prev = l;
        }
    }
}
