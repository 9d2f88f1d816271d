//! Interactive viewing: the operator at a reduced resolution, a plain exposure to compare
//! it with, and what the model says about one pixel.
//!
//! An interactive viewer plans the model once on the full-resolution scene
//! ([`operator::plan`](crate::operator::plan): the adaptation of Sec. 4.4 is a property of
//! the whole scene, not of its preview) and applies the mapping to a smaller copy:
//!
//! * [`downsample_into`] averages the scene's luminances over boxes of source pixels
//!   (XYZ and scotopic luminance are additive, so a box average is the luminance of the
//!   area, as a coarser sensor would see it);
//! * [`mapping_at_width`] rescales the acuity Gaussian of Eq. 7 from full-resolution pixels to preview pixels
//!   (the same angle, fewer pixels per degree), with the operator's
//!   [`MIN_BLUR_SIGMA_PX`] rule;
//! * [`report_at_width`] takes the report's pixel measures (size, pixels per degree, the
//!   acuity Gaussian) to the preview's, for the stages that read them, such as the local
//!   adaptation map;
//! * [`exposure`] is a plain camera exposure (the highest visible luminance at the display
//!   maximum, colours kept, no rods, no blur): the reference an A/B split compares the
//!   model with, a project choice, not part of the paper;
//! * [`probe`] reads one pixel: its luminances, the smallest change an observer would see
//!   there (Eq. 4–6 through [`Sensitivity`]), and how many JNDs a given relative change is.

use crate::colour::{REC709, SrgbLut};
use crate::operator::{MIN_BLUR_SIGMA_PX, Mapping, Report};
use crate::visibility::{Sensitivity, VISIBLE_JND};
use crate::{DisplayImage, Error, HdrImage, Result, scotopic};

/// The size of a preview `width` pixels wide of a `full_width × full_height` image: the
/// aspect ratio kept, at least one pixel high.
pub fn preview_size(full_width: usize, full_height: usize, width: usize) -> (usize, usize) {
    let height = if full_width == 0 {
        0
    } else {
        ((full_height as f64 * width as f64 / full_width as f64).round() as usize).max(1)
    };
    (width, height)
}

/// `out` = `image` reduced to `width` pixels wide (see [`preview_size`]), each output pixel
/// the mean of the source pixels whose centres fall inside it; `out`'s planes are reused.
/// The view (angles) is kept: the preview shows the same scene with fewer pixels. A
/// non-finite source pixel makes its output pixel non-finite (shown black by the operator).
///
/// Errors if `width` is 0 or larger than the image.
pub fn downsample_into(image: &HdrImage, width: usize, out: &mut HdrImage) -> Result<()> {
    image.check_consistent()?;
    if width == 0 || width > image.width {
        return Err(Error::invalid(
            "width",
            width,
            format!("must be between 1 and the image width {}", image.width),
        ));
    }
    let (w, h) = preview_size(image.width, image.height, width);
    let spans = |full: usize, small: usize| -> Vec<(usize, usize)> {
        (0..small)
            .map(|i| {
                let a = i * full / small;
                let b = ((i + 1) * full / small).max(a + 1);
                (a, b)
            })
            .collect()
    };
    let (cols, rows) = (spans(image.width, w), spans(image.height, h));
    let reduce = |src: &[f32], dst: &mut Vec<f32>| {
        dst.clear();
        dst.reserve(w * h);
        let mut row_sum = vec![0f64; image.width];
        for &(y0, y1) in &rows {
            row_sum.iter_mut().for_each(|s| *s = 0.0);
            for y in y0..y1 {
                let line = &src[y * image.width..(y + 1) * image.width];
                for (s, v) in row_sum.iter_mut().zip(line) {
                    *s += f64::from(*v);
                }
            }
            for &(x0, x1) in &cols {
                let sum: f64 = row_sum[x0..x1].iter().sum();
                dst.push((sum / ((x1 - x0) * (y1 - y0)) as f64) as f32);
            }
        }
    };
    reduce(&image.x, &mut out.x);
    reduce(&image.y, &mut out.y);
    reduce(&image.z, &mut out.z);
    match &image.scotopic {
        Some(s) => reduce(s, out.scotopic.get_or_insert_with(Vec::new)),
        None => out.scotopic = None,
    }
    out.width = w;
    out.height = h;
    out.view = image.view;
    out.absolute_units = image.absolute_units;
    out.adopted_white = image.adopted_white;
    Ok(())
}

/// The mapping planned for an image `full_width` pixels wide, for a copy of it `width`
/// pixels wide: the acuity Gaussian keeps its angle (Eq. 7), so its standard deviation in
/// pixels scales with the width; below [`MIN_BLUR_SIGMA_PX`] it is skipped, as the
/// operator does.
pub fn mapping_at_width(mapping: &Mapping, full_width: usize, width: usize) -> Mapping {
    let sigma = if full_width == 0 {
        0.0
    } else {
        mapping.blur_sigma_px * width as f64 / full_width as f64
    };
    Mapping {
        blur_sigma_px: if sigma >= MIN_BLUR_SIGMA_PX {
            sigma
        } else {
            0.0
        },
        ..*mapping
    }
}

/// The [`operator::plan`](crate::operator::plan) report of an image, for a copy of it
/// `width` pixels wide ([`downsample_into`]): the same adaptation, thresholds, scales and
/// `k` (planned once at full resolution), with what is measured in pixels taken to the
/// preview's: its size ([`preview_size`]), the pixels per degree of the view at that
/// width, and the acuity Gaussian of [`mapping_at_width`]. The stages that work in pixels
/// from a report, such as the local adaptation map
/// ([`operator::local_map`](crate::operator::local_map), whose per-pixel Eq. 7 sigmas
/// come from the report's pixels per degree), then work at the preview's scale.
pub fn report_at_width(report: &Report, width: usize) -> Report {
    let (w, h) = preview_size(report.width, report.height, width);
    Report {
        width: w,
        height: h,
        pixels_per_degree: report
            .pixels_per_degree
            .and(report.view.pixels_per_degree(w)),
        mapping: mapping_at_width(&report.mapping, report.width, w),
        ..report.clone()
    }
}

/// A plain exposure of the scene of `report`: world luminance times
/// `L_dmax / highest visible luminance`, so that the highest visible luminance shows as the
/// display maximum, with the scene's colours (adapted to the display white as the model's
/// are), no rod contribution and no blur. What a
/// camera set to expose the scene would show; the reference of an A/B comparison.
pub fn exposure(report: &Report) -> Mapping {
    let display_max = report.mapping.display_max_cd_m2;
    let hv = report.highest_visible_cd_m2;
    Mapping {
        photopic_scale: if hv > 0.0 { display_max / hv } else { 0.0 },
        scotopic_scale: 0.0,
        rod_weight: 0.0,
        photopic_offset_cd_m2: 0.0,
        scotopic_offset_cd_m2: 0.0,
        display_max_cd_m2: display_max,
        blur_sigma_px: 0.0,
        // White-balanced as the model's image, so that an A/B split differs by the model.
        chromatic_adaptation: report.mapping.chromatic_adaptation,
    }
}

/// What the model says about one pixel of a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Probe {
    /// Photopic luminance (CIE Y), cd/m².
    pub luminance_cd_m2: f64,
    /// Scotopic luminance, scotopic cd/m² (the file's channel or [`scotopic::from_xyz`]).
    pub scotopic_cd_m2: f64,
    /// The smallest visible change of this pixel's colour, cd/m²
    /// ([`Sensitivity::threshold_cd_m2`] at its scotopic/photopic ratio).
    pub threshold_cd_m2: f64,
    /// The change asked about, as a fraction of the pixel's luminances.
    pub relative_change: f64,
    /// JNDs of that change ([`Sensitivity::jnd`] of the photopic and scotopic changes).
    pub change_jnd: f64,
    /// Whether that change is visible (at least [`VISIBLE_JND`]).
    pub change_visible: bool,
}

/// Read pixel (`x`, `y`) (column, row from the top left) of `image` for an observer of
/// `sensitivity`, and how visible a change of `relative_change` times its luminance (the
/// same colour brighter or darker, over an area large against the acuity Gaussian) is.
/// A non-finite or negative channel reads as 0, as in the operator.
pub fn probe(
    image: &HdrImage,
    x: usize,
    y: usize,
    sensitivity: &Sensitivity,
    relative_change: f64,
) -> Result<Probe> {
    image.check_consistent()?;
    sensitivity.validate()?;
    if x >= image.width || y >= image.height {
        return Err(Error::invalid(
            "pixel",
            format!("({x}, {y})"),
            format!("is outside the {}x{} image", image.width, image.height),
        ));
    }
    if !relative_change.is_finite() {
        return Err(Error::invalid(
            "change",
            relative_change,
            "must be a finite fraction",
        ));
    }
    let i = y * image.width + x;
    let clean = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
    let (px, py, pz) = (image.x[i], image.y[i], image.z[i]);
    let finite = px.is_finite() && py.is_finite() && pz.is_finite();
    let (px, py, pz) = if finite {
        (clean(px), clean(py), clean(pz))
    } else {
        (0.0, 0.0, 0.0)
    };
    let s = match &image.scotopic {
        Some(s) if finite => clean(s[i]),
        Some(_) => 0.0,
        None => scotopic::from_xyz(px, py, pz),
    };
    let (l, ls) = (f64::from(py), f64::from(s));
    let sp_ratio = if l > 0.0 {
        ls / l
    } else {
        scotopic::EQUAL_ENERGY_SP_RATIO
    };
    let jnd = sensitivity.jnd(relative_change * l, relative_change * ls);
    Ok(Probe {
        luminance_cd_m2: l,
        scotopic_cd_m2: ls,
        threshold_cd_m2: sensitivity.threshold_cd_m2(sp_ratio),
        relative_change,
        change_jnd: jnd,
        change_visible: jnd >= f64::from(VISIBLE_JND),
    })
}

/// One pixel of a display image as the display shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Displayed {
    /// Linear display RGB, 1.0 = the display maximum.
    pub linear_rgb: [f32; 3],
    /// The 8-bit sRGB code values the PNG output holds.
    pub srgb8: [u8; 3],
    /// The luminance the display emits, cd/m² (CIE Y of the Rec. 709 primaries times
    /// `L_dmax`).
    pub luminance_cd_m2: f64,
}

/// Pixel (`x`, `y`) of a display image.
pub fn displayed(image: &DisplayImage, x: usize, y: usize) -> Result<Displayed> {
    if x >= image.width || y >= image.height || image.r.len() < image.len() {
        return Err(Error::invalid(
            "pixel",
            format!("({x}, {y})"),
            format!("is outside the {}x{} image", image.width, image.height),
        ));
    }
    let i = y * image.width + x;
    let rgb = [image.r[i], image.g[i], image.b[i]];
    let lut = SrgbLut::new(8);
    let y_row = REC709.rgb_to_xyz().expect("Rec.709 primaries are valid")[1];
    let y_rel: f64 = y_row.iter().zip(rgb).map(|(m, c)| m * f64::from(c)).sum();
    Ok(Displayed {
        linear_rgb: rgb,
        srgb8: rgb.map(|c| lut.encode(c) as u8),
        luminance_cd_m2: y_rel * f64::from(image.display_max_cd_m2),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::operator::{self, ViewingConditions};
    use crate::tvi::cone_threshold_cd_m2;

    fn ramp(width: usize, height: usize) -> HdrImage {
        let mut img = HdrImage::zeros(width, height);
        for i in 0..img.len() {
            let l = 1.0 + (i % width) as f32 + 10.0 * (i / width) as f32;
            // D65 white (x, y) = (0.3127, 0.3290): display grey.
            (img.x[i], img.y[i], img.z[i]) = (0.950_456 * l, l, 1.089_058 * l);
        }
        img
    }

    #[test]
    fn box_average_of_exact_halves() {
        let img = ramp(4, 2);
        let mut out = HdrImage::zeros(0, 0);
        downsample_into(&img, 2, &mut out).unwrap();
        assert_eq!((out.width, out.height), (2, 1));
        // Row 0: 1 2 3 4, row 1: 11 12 13 14. Left box: (1+2+11+12)/4 = 6.5.
        assert_eq!(out.y, vec![6.5, 8.5]);
        assert!(out.scotopic.is_none());
    }

    #[test]
    fn uneven_boxes_cover_every_pixel_once() {
        // 7 columns into 3: spans [0,2) [2,4) [4,7); the total luminance is kept when the
        // means are weighted by their box sizes.
        let img = ramp(7, 3);
        let mut out = HdrImage::zeros(0, 0);
        downsample_into(&img, 3, &mut out).unwrap();
        assert_eq!((out.width, out.height), (3, 1));
        let total: f64 = img.y.iter().map(|v| f64::from(*v)).sum();
        let weighted =
            f64::from(out.y[0]) * 6.0 + f64::from(out.y[1]) * 6.0 + f64::from(out.y[2]) * 9.0;
        assert!((total - weighted).abs() < 1e-3, "{total} {weighted}");
    }

    #[test]
    fn full_width_is_a_copy_and_bad_widths_are_refused() {
        let mut img = ramp(5, 3);
        img.scotopic = Some(img.y.iter().map(|v| v * 2.0).collect());
        let mut out = HdrImage::zeros(0, 0);
        downsample_into(&img, 5, &mut out).unwrap();
        assert_eq!(out, img);
        assert!(downsample_into(&img, 0, &mut out).is_err());
        assert!(downsample_into(&img, 6, &mut out).is_err());
    }

    #[test]
    fn blur_keeps_its_angle() {
        let img = ramp(400, 200);
        let report = operator::plan(&img, &ViewingConditions::default()).unwrap();
        let m = Mapping {
            blur_sigma_px: 3.0,
            ..report.mapping
        };
        assert_eq!(mapping_at_width(&m, 400, 100).blur_sigma_px, 0.75);
        // 3 px at 1/100 of the width is 0.03 px, under MIN_BLUR_SIGMA_PX: no blur.
        assert_eq!(mapping_at_width(&m, 400, 4).blur_sigma_px, 0.0);
    }

    /// The local adaptation map of a preview, from the full-resolution report taken to the
    /// preview's width, has the acuity Gaussian of the preview's pixels: on a uniform scene
    /// (every offset 0) each pixel's sigma is the global one at that width, a quarter of
    /// the full image's here.
    #[test]
    fn report_at_width_puts_the_local_acuity_in_preview_pixels() {
        let mut img = HdrImage::zeros(400, 200);
        for i in 0..img.len() {
            (img.x[i], img.y[i], img.z[i]) = (0.950_456 * 0.04, 0.04, 1.089_058 * 0.04);
        }
        let conditions = ViewingConditions {
            view: Some(crate::View::perspective(4.0, 400, 200)),
            ..ViewingConditions::default()
        };
        let report = operator::plan(&img, &conditions).unwrap();
        let full_sigma = report.mapping.blur_sigma_px;
        assert!(full_sigma > 2.0, "{full_sigma}");
        let small = report_at_width(&report, 100);
        assert_eq!((small.width, small.height), (100, 50));
        assert!((small.mapping.blur_sigma_px - full_sigma / 4.0).abs() < 1e-12 * full_sigma);
        let ppd = report.pixels_per_degree.unwrap();
        assert!((small.pixels_per_degree.unwrap() - ppd / 4.0).abs() < 1e-12 * ppd);
        assert_eq!(small.world_adaptation_cd_m2, report.world_adaptation_cd_m2);
        let mut preview = HdrImage::zeros(0, 0);
        downsample_into(&img, 100, &mut preview).unwrap();
        let options = crate::local::LocalAdaptation::default();
        let map = operator::local_map(&preview, &small, &conditions, &options).unwrap();
        let sigmas = map.acuity_sigma_px.unwrap();
        for s in sigmas {
            let s = f64::from(s);
            assert!(
                (s - full_sigma / 4.0).abs() < 1e-5 * full_sigma,
                "{s} vs {full_sigma}"
            );
        }
    }

    #[test]
    fn exposure_puts_the_highest_visible_at_the_display_maximum() {
        let img = ramp(64, 64);
        let report = operator::plan(&img, &ViewingConditions::default()).unwrap();
        let m = exposure(&report);
        assert!(
            (m.photopic_scale * report.highest_visible_cd_m2 - m.display_max_cd_m2).abs() < 1e-9
        );
        let (out, _) = operator::apply(&img, &m);
        let hv = report.highest_visible_cd_m2 as f32;
        for (y, g) in img.y.iter().zip(&out.g) {
            let expected = (y / hv).min(1.0);
            assert!((g - expected).abs() < 2e-4, "{y}: {g} vs {expected}");
        }
    }

    #[test]
    fn probe_reads_luminances_and_jnds() {
        let img = ramp(8, 8);
        // Photopic adaptation at 1000 cd/m²: k = 0, cones alone, Eq. 4 threshold.
        let sens = Sensitivity::steady_state(1000.0, 2261.0);
        assert_eq!(sens.rod_weight, 0.0);
        let p = probe(&img, 3, 2, &sens, 0.5).unwrap();
        assert_eq!(p.luminance_cd_m2, 24.0);
        let expected_s = f64::from(scotopic::from_xyz(0.950_456 * 24.0, 24.0, 1.089_058 * 24.0));
        assert!((p.scotopic_cd_m2 - expected_s).abs() < 1e-9);
        let t = cone_threshold_cd_m2(1000.0);
        assert!((p.threshold_cd_m2 - t).abs() < 1e-9 * t);
        assert!((p.change_jnd - 12.0 / t).abs() < 1e-9 * p.change_jnd);
        assert_eq!(p.change_visible, 12.0 >= t);
        assert!(probe(&img, 8, 0, &sens, 0.1).is_err());
        assert!(probe(&img, 0, 0, &sens, f64::NAN).is_err());
    }

    #[test]
    fn displayed_white_is_the_display_maximum() {
        let img = DisplayImage {
            width: 2,
            height: 1,
            r: vec![1.0, 0.0],
            g: vec![1.0, 0.0],
            b: vec![1.0, 1.0],
            display_max_cd_m2: 80.0,
        };
        let w = displayed(&img, 0, 0).unwrap();
        assert_eq!(w.srgb8, [255, 255, 255]);
        assert!((w.luminance_cd_m2 - 80.0).abs() < 1e-9);
        // Pure blue: Y of the Rec. 709 blue primary, 0.0722 (BT.709-6 Table 1 derived).
        let b = displayed(&img, 1, 0).unwrap();
        assert!((b.luminance_cd_m2 / 80.0 - 0.0722).abs() < 1e-4, "{b:?}");
        assert!(displayed(&img, 2, 0).is_err());
    }

    #[test]
    fn probe_reads_bad_pixels_as_black() {
        let mut img = ramp(2, 1);
        img.y[0] = f32::NAN;
        let sens = Sensitivity::steady_state(1.0, 2.261);
        let p = probe(&img, 0, 0, &sens, 0.1).unwrap();
        assert_eq!(
            (p.luminance_cd_m2, p.scotopic_cd_m2, p.change_jnd),
            (0.0, 0.0, 0.0)
        );
        assert!(!p.change_visible);
    }
}
