//! Chromatic adaptation from the scene's adopted white to the display's D65 (issue 8 §1):
//! grey files come out neutral whatever their format declares as white, the white each
//! reader reports, and `WhitePoint::Off` keeping the paper's (unadapted) colours.
//!
//! Neutral means CIELAB chroma C*ab < 1.5 against the display white D65 (a ΔE*ab of about
//! 2.3 is one just-noticeable difference: Sharma 2003, *Digital Color Imaging Handbook*,
//! §1.7), measured on the linear display planes of unclipped pixels.

use exr::prelude::*;
use std::io::Cursor;
use visadapt::colour::{self, D65, EQUAL_ENERGY, WhitePoint};
use visadapt::io::{exr as vexr, radiance};
use visadapt::operator::{Source, ViewingConditions, map};
use visadapt::{DisplayImage, HdrImage, Limits};

/// Rec. 709 / sRGB linear RGB to CIE XYZ (IEC 61966-2-1, Eq. F.7).
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];

/// CIELAB (a*, b*) of display pixel `p` against D65 at the display maximum.
fn ab(d: &DisplayImage, p: usize) -> [f64; 2] {
    let rgb = [d.r[p], d.g[p], d.b[p]].map(f64::from);
    let xyz = RGB_TO_XYZ.map(|row| row[0] * rgb[0] + row[1] * rgb[1] + row[2] * rgb[2]);
    let n = RGB_TO_XYZ.map(|row| row.iter().sum::<f64>());
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let [fx, fy, fz] = [0, 1, 2].map(|i| f(xyz[i] / n[i]));
    [500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// The largest C*ab over the unclipped, non-black pixels, and how many there were.
fn max_chroma(d: &DisplayImage) -> (f64, usize) {
    let mut worst = 0.0f64;
    let mut n = 0;
    for p in 0..d.len() {
        let m = d.r[p].max(d.g[p]).max(d.b[p]);
        if m > 0.01 && m < 0.999 {
            let [a, b] = ab(d, p);
            worst = worst.max(a.hypot(b));
            n += 1;
        }
    }
    (worst, n)
}

/// One RGBE pixel of the value `v` in every channel (Ward, "Real Pixels", 1991).
fn rgbe_grey(v: f64) -> [u8; 4] {
    let e = v.log2().floor() as i32 + 1;
    let m = (v / 2f64.powi(e) * 256.0) as u8;
    [m, m, m, (e + 128) as u8]
}

/// A flat (uncompressed) Radiance RGBE file, `w × h`, a grey ramp over 2.5 decades in
/// radiance (× 179 lm/W for cd/m²), with an extra header line (or none).
fn grey_rgbe(w: usize, h: usize, header: &str) -> Vec<u8> {
    let mut out = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n{header}\n");
    if !header.is_empty() {
        out.push('\n');
    }
    let mut out = (out + &format!("-Y {h} +X {w}\n")).into_bytes();
    for _ in 0..h {
        for i in 0..w {
            let v = 10f64.powf(-2.5 + 2.5 * i as f64 / (w - 1) as f64);
            out.extend_from_slice(&rgbe_grey(v));
        }
    }
    out
}

fn conditions(white_point: WhitePoint) -> ViewingConditions {
    ViewingConditions {
        white_point,
        ..ViewingConditions::default()
    }
}

#[test]
fn grey_rgbe_file_is_neutral() {
    let img = radiance::decode(&grey_rgbe(64, 4, ""), &Limits::default()).unwrap();
    assert_eq!(img.adopted_white, Some(EQUAL_ENERGY));
    let out = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    assert_eq!(out.report.scene_white, Some(EQUAL_ENERGY));
    assert_eq!(out.report.scene_white_source, Source::File);
    let (c, n) = max_chroma(&out.image);
    println!("grey RGBE: max C* {c:.3} over {n} pixels");
    assert!(n > 100, "{n} unclipped pixels");
    assert!(c < 1.5, "C* {c}");

    // Without chromatic adaptation (the paper) the same grey is pink: E on a D65 display
    // is a* ≈ +8.5, b* ≈ +5.6 at full luminance.
    let paper = map(&img, &conditions(WhitePoint::Off)).unwrap();
    assert_eq!(paper.report.scene_white, None);
    let (c0, _) = max_chroma(&paper.image);
    println!("grey RGBE without adaptation: max C* {c0:.3}");
    assert!(c0 > 5.0, "C* {c0}");
}

#[test]
fn radiance_primaries_white_is_the_adopted_white() {
    // A grey file whose PRIMARIES= declare D65 is shown as it is.
    let d65 = "PRIMARIES= 0.64 0.33 0.30 0.60 0.15 0.06 0.3127 0.3290";
    let img = radiance::decode(&grey_rgbe(64, 4, d65), &Limits::default()).unwrap();
    assert_eq!(img.adopted_white, Some(D65));
    let out = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    let (c, _) = max_chroma(&out.image);
    assert!(c < 1.5, "C* {c}");
    // Forcing E on it shifts the colours (the caller's choice wins over the file's).
    let forced = map(&img, &conditions(WhitePoint::Chromaticity(EQUAL_ENERGY))).unwrap();
    assert_eq!(forced.report.scene_white_source, Source::Caller);
    let (cf, _) = max_chroma(&forced.image);
    assert!(cf > 5.0, "C* {cf}");
}

/// A `w × 1` RGB EXR ramp with equal R, G, B, Rec. 709 primaries and the given white.
fn grey_exr(w: usize, white: (f32, f32), adopted_neutral: Option<(f32, f32)>) -> Vec<u8> {
    let ramp: Vec<f32> = (0..w)
        .map(|i| 10f32.powf(-1.0 + 3.0 * i as f32 / (w - 1) as f32))
        .collect();
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = ["R", "G", "B"]
        .into_iter()
        .map(|c| AnyChannel::new(c, FlatSamples::F32(ramp.clone())))
        .collect();
    let attributes = LayerAttributes {
        adopted_neutral: adopted_neutral.map(|(x, y)| Vec2(x, y)),
        ..LayerAttributes::default()
    };
    let encoding = Encoding {
        compression: Compression::Uncompressed,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new((w, 1), attributes, encoding, AnyChannels::sort(channels));
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = Some(exr::meta::attribute::Chromaticities {
        red: Vec2(0.64, 0.33),
        green: Vec2(0.30, 0.60),
        blue: Vec2(0.15, 0.06),
        white: Vec2(white.0, white.1),
    });
    let mut out = Cursor::new(Vec::new());
    image.write().to_buffered(&mut out).unwrap();
    out.into_inner()
}

#[test]
fn rgb_exr_with_an_equal_energy_white_is_neutral() {
    let third = 1.0 / 3.0;
    let bytes = grey_exr(256, (third, third), None);
    let img = vexr::decode(&bytes, &Limits::default()).unwrap();
    let w = img.adopted_white.unwrap();
    assert!((w[0] - 1.0 / 3.0).abs() < 1e-7 && (w[1] - 1.0 / 3.0).abs() < 1e-7);
    let out = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    let (c, n) = max_chroma(&out.image);
    println!("EXR with white E: max C* {c:.3} over {n} pixels");
    assert!(n > 50 && c < 1.5, "C* {c} over {n}");
    let (c0, _) = max_chroma(&map(&img, &conditions(WhitePoint::Off)).unwrap().image);
    assert!(c0 > 5.0, "without adaptation C* {c0}");
}

#[test]
fn exr_adopted_neutral_overrides_the_chromaticities_white() {
    // RGB (1, 1, 1) is D65 by the chromaticities, but the file says E is neutral: the
    // pixels are then shown as D65 adapted from E, a bluish grey.
    let bytes = grey_exr(256, (0.3127, 0.3290), Some((1.0 / 3.0, 1.0 / 3.0)));
    let img = vexr::decode(&bytes, &Limits::default()).unwrap();
    let w = img.adopted_white.unwrap();
    assert!((w[0] - 1.0 / 3.0).abs() < 1e-7, "{w:?}");
    let out = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    let (c, _) = max_chroma(&out.image);
    let [a, b] = ab(&out.image, 200);
    println!("D65 grey under an adopted E: max C* {c:.2}; a* {a:.2}, b* {b:.2} at pixel 200");
    assert!(c > 5.0 && b < 0.0, "C* {c}, b* {b}");
    // Without the attribute the same file is neutral.
    let plain = vexr::decode(&grey_exr(256, (0.3127, 0.3290), None), &Limits::default()).unwrap();
    assert_eq!(
        plain.adopted_white,
        Some([0.3127f32 as f64, 0.3290f32 as f64])
    );
    let (c, _) = max_chroma(&map(&plain, &conditions(WhitePoint::Auto)).unwrap().image);
    assert!(c < 1.5, "C* {c}");
}

#[test]
fn paper_layout_is_equal_energy_and_round_trips_its_white() {
    let mut img = HdrImage::zeros(8, 2);
    for i in 0..img.len() {
        let l = 1.0 + i as f32;
        (img.x[i], img.y[i], img.z[i]) = (l, l, l);
    }
    img.absolute_units = true;
    // Written without an adopted white: read back as the paper's E.
    let mut buf = Cursor::new(Vec::new());
    vexr::write_hdr(&img, &mut buf).unwrap();
    let back = vexr::decode(buf.get_ref(), &Limits::default()).unwrap();
    assert_eq!(back.adopted_white, Some(EQUAL_ENERGY));
    // Written with one: it is kept as `adoptedNeutral`.
    img.adopted_white = Some([0.3457, 0.3585]);
    let mut buf = Cursor::new(Vec::new());
    vexr::write_hdr(&img, &mut buf).unwrap();
    let back = vexr::decode(buf.get_ref(), &Limits::default()).unwrap();
    let w = back.adopted_white.unwrap();
    assert!((w[0] - 0.3457).abs() < 1e-6 && (w[1] - 0.3585).abs() < 1e-6);
}

#[test]
fn an_image_without_a_declared_white_is_left_as_it_is() {
    let mut img = HdrImage::zeros(16, 1);
    for i in 0..img.len() {
        let l = 1.0 + i as f32;
        (img.x[i], img.y[i], img.z[i]) = (0.9505 * l, l, 1.089 * l);
    }
    let auto = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    assert_eq!(auto.report.scene_white, Some(D65));
    assert_eq!(auto.report.scene_white_source, Source::Default);
    let off = map(&img, &conditions(WhitePoint::Off)).unwrap();
    for (a, b) in auto.image.r.iter().zip(&off.image.r) {
        assert!((a - b).abs() < 1e-6);
    }
}

/// The transform acts on chromaticity, not luminance: the report (adaptation, thresholds,
/// scale factors, k, acuity) is the same with and without it; neutrals keep Y exactly
/// (the white maps to the white); the ColorChecker's colours under E keep Y within 1 %.
#[test]
fn luminance_and_every_threshold_are_unchanged() {
    let img = radiance::decode(&grey_rgbe(64, 4, ""), &Limits::default()).unwrap();
    let on = map(&img, &conditions(WhitePoint::Auto)).unwrap();
    let off = map(&img, &conditions(WhitePoint::Off)).unwrap();
    let (mut a, mut b) = (on.report.clone(), off.report.clone());
    a.mapping.chromatic_adaptation = colour::IDENTITY;
    (a.scene_white, a.scene_white_source) = (None, Source::Caller);
    (b.scene_white, b.scene_white_source) = (None, Source::Caller);
    assert_eq!(a, b);
    // Display luminance of the grey ramp: identical to float precision.
    let y = |d: &DisplayImage, p: usize| {
        RGB_TO_XYZ[1][0] * d.r[p] as f64
            + RGB_TO_XYZ[1][1] * d.g[p] as f64
            + RGB_TO_XYZ[1][2] * d.b[p] as f64
    };
    let unclipped = |d: &DisplayImage, p: usize| d.r[p].max(d.g[p]).max(d.b[p]) < 0.999;
    for p in 0..64 {
        let (ya, yb) = (y(&on.image, p), y(&off.image, p));
        if unclipped(&on.image, p) && unclipped(&off.image, p) {
            assert!(
                (ya - yb).abs() <= 2e-4 * yb.max(1e-3),
                "pixel {p}: {ya} vs {yb}"
            );
        }
    }
    let cat = colour::cat16(EQUAL_ENERGY, D65).unwrap();
    let mut worst = 0.0f64;
    for i in 0..24 {
        let ph = visadapt::spectral::integrate(&visadapt::spectral::reflected(
            &visadapt::spectral::EQUAL_ENERGY,
            visadapt::spectral::colorchecker(i),
        ));
        let after = colour::mul_vec(&cat, [ph.x, ph.y, ph.z]);
        worst = worst.max((after[1] / ph.y - 1.0).abs());
    }
    println!("ColorChecker under E: largest change of Y by CAT16 E -> D65 {worst:.4}");
    assert!(worst < 0.01, "{worst}");
}

#[test]
fn grey_rgbe_file_is_neutral_with_local_adaptation() {
    // The per-pixel tables of local adaptation are built from the same chromatically
    // adapted cone matrix as the global operator.
    use visadapt::local::LocalAdaptation;
    use visadapt::operator::AdaptationMode;
    let img = radiance::decode(&grey_rgbe(64, 4, ""), &Limits::default()).unwrap();
    let local = |white_point| ViewingConditions {
        adaptation: AdaptationMode::Local(LocalAdaptation::default()),
        ..conditions(white_point)
    };
    let out = map(&img, &local(WhitePoint::Auto)).unwrap();
    let (c, n) = max_chroma(&out.image);
    println!("grey RGBE, local adaptation: max C* {c:.3} over {n} pixels");
    assert!(n > 100, "{n} unclipped pixels");
    assert!(c < 1.5, "C* {c}");
    let paper = map(&img, &local(WhitePoint::Off)).unwrap();
    let (c0, _) = max_chroma(&paper.image);
    assert!(c0 > 5.0, "C* {c0}");
}
