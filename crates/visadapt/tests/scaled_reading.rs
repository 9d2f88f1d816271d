//! `io::read_scaled` and `io::read_scaled_from` (the `--scale` of `map`, `tolerance` and
//! `video`, applied in the decoder's own pass) against reading and then
//! [`HdrImage::scale`], on every path of the decoders: Radiance RGBE (single- and
//! double-precision conversion), OpenEXR RGB half and float blocks with and without
//! `whiteLuminance`, luminance-only and lone-channel grey, luminance/chroma, XYZ parts
//! (scaled after decoding), PFM, and raw `gbrpf32le` frames (which give the same values as
//! a PFM file of the same samples).

mod common;

use common::{data, shared};
use std::path::{Path, PathBuf};
use visadapt::io::raw::FrameReader;
use visadapt::{DisplayImage, HdrImage, Limits, io};

/// Finite factors: unit conversions (179 lm/W, a display's 0.01), a sign change, zero, and
/// factors that push values into the subnormal range and beyond the `f32` range.
const FINITE: [f32; 7] = [179.0, 0.01, -3.0, 0.0, 1e-30, 3e30, 1.0];

/// Factors no matrix takes: applied after decoding, so bit for bit as `HdrImage::scale`.
const NOT_FINITE: [f32; 3] = [f32::INFINITY, f32::NEG_INFINITY, f32::NAN];

/// Both ways round a value's products to `f32` at most a few times (the scaled way once
/// in `f64`, or after a single-precision sum of three positive products; the other way
/// once more for the factor): each rounding is within 2^-24 of the value, so the two
/// agree within 2^-20 of the value, and within two of the smallest subnormal steps where
/// the values are subnormal.
fn agree(scaled: f32, after: f32) -> bool {
    if scaled.is_nan() || after.is_nan() {
        return scaled.is_nan() && after.is_nan();
    }
    if scaled == after {
        return true;
    }
    let (a, b) = (f64::from(scaled), f64::from(after));
    let tolerance = 2f64.powi(-20) * a.abs().max(b.abs()) + 2.0 * f64::from(f32::from_bits(1));
    (a - b).abs() <= tolerance
}

fn planes(image: &HdrImage) -> Vec<&[f32]> {
    let mut p = vec![&image.x[..], &image.y[..], &image.z[..]];
    p.extend(image.scotopic.as_deref());
    p
}

fn same_bits(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// `read_scaled(path, f)` against `read(path)` then `scale(f)`, for every factor; and
/// `read_scaled_into` and `read_scaled_from` (a stream of the file's bytes) against
/// `read_scaled`, bit for bit. Returns how many samples were not the same bit for bit
/// both ways (where the decoder's single rounding differs from rounding twice).
fn check(path: &Path) -> usize {
    let limits = Limits::default();
    let mut rounded_differently = 0;
    let plain = io::read(path, &limits).unwrap();
    for factor in FINITE.into_iter().chain(NOT_FINITE) {
        let scaled = io::read_scaled(path, &limits, factor).unwrap();
        let mut after = plain.clone();
        after.scale(factor);
        let what = format!("{} times {factor}", path.display());
        assert_eq!((scaled.width, scaled.height), (after.width, after.height));
        assert_eq!(scaled.absolute_units, after.absolute_units, "{what}");
        assert_eq!(scaled.adopted_white, after.adopted_white, "{what}");
        assert_eq!(scaled.view, after.view, "{what}");
        let exact = !factor.is_finite() || factor == 1.0;
        for (p, (s, a)) in planes(&scaled).into_iter().zip(planes(&after)).enumerate() {
            assert_eq!(s.len(), a.len(), "{what}");
            for (i, (&s, &a)) in s.iter().zip(a).enumerate() {
                let ok = if exact { same_bits(s, a) } else { agree(s, a) };
                rounded_differently += usize::from(!same_bits(s, a));
                assert!(
                    ok,
                    "{what}: plane {p} sample {i}: {s:e} read scaled, {a:e} after"
                );
            }
        }
        // The same through the reusing reader, into an image of another size.
        let (mut bytes, mut reused) = (Vec::new(), HdrImage::zeros(3, 5));
        io::read_scaled_into(path, &limits, factor, &mut bytes, &mut reused).unwrap();
        assert_eq!((reused.width, reused.height), (scaled.width, scaled.height));
        for (r, s) in planes(&reused).into_iter().zip(planes(&scaled)) {
            assert!(r.iter().zip(s).all(|(&r, &s)| same_bits(r, s)), "{what}");
        }
        // And from a stream (`map -` reads standard input so).
        let file = std::fs::File::open(path).unwrap();
        let streamed = io::read_scaled_from(file, &limits, factor).unwrap();
        assert_eq!(
            streamed.scotopic.is_some(),
            scaled.scotopic.is_some(),
            "{what}"
        );
        for (r, s) in planes(&streamed).into_iter().zip(planes(&scaled)) {
            assert!(r.iter().zip(s).all(|(&r, &s)| same_bits(r, s)), "{what}");
        }
    }
    rounded_differently
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("visadapt-scaled-{}-{name}", std::process::id()))
}

/// A display image of varied, positive and some negative linear values.
fn display(width: usize, height: usize, display_max_cd_m2: f32) -> DisplayImage {
    let n = width * height;
    let v = |k: usize, i: usize| ((i * 7919 + k * 104_729) % 1000) as f32 / 997.0 - 0.05;
    DisplayImage {
        width,
        height,
        r: (0..n).map(|i| v(0, i) * 1.3).collect(),
        g: (0..n).map(|i| v(1, i)).collect(),
        b: (0..n).map(|i| v(2, i) * 0.7).collect(),
        display_max_cd_m2,
    }
}

#[test]
fn radiance_files_read_scaled_agree_with_scaling_after() {
    check(&data("mixtex.hdr"));
    check(&data("sunset-fisheye.hdr"));
    // Written by the library: RGB (1, 1, 1) is 250 cd/m² through EXPOSURE.
    let path = temp("display.hdr");
    let mut bytes = Vec::new();
    io::radiance::write_display(&display(37, 11, 250.0), &mut bytes).unwrap();
    std::fs::write(&path, bytes).unwrap();
    check(&path);
    std::fs::remove_file(&path).unwrap();
}

/// A factor that the Radiance matrix cannot take (its entries, 179 / EXPOSURE × factor,
/// would pass the decoder's bound of 1e250) is applied after decoding: here EXPOSURE is
/// 1e-215 and the factor 1e36 (entries about 2e253). Every value saturates either way;
/// the read succeeds and gives `HdrImage::scale`'s values bit for bit.
#[test]
fn a_factor_beyond_the_radiance_matrix_bound_is_applied_after_decoding() {
    let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1e-215\n\n-Y 2 +X 3\n".to_vec();
    // Flat RGBE pixels: grey 0.5, red 1.0, black, a tiny blue, and two more greys.
    for rgbe in [[128, 128, 128, 128], [128, 0, 0, 129], [0, 0, 0, 0]] {
        bytes.extend_from_slice(&rgbe);
    }
    for rgbe in [[0, 0, 128, 1], [200, 200, 200, 120], [64, 64, 64, 140]] {
        bytes.extend_from_slice(&rgbe);
    }
    let path = temp("tiny-exposure.hdr");
    std::fs::write(&path, &bytes).unwrap();
    let limits = Limits::default();
    let factor = 1e36f32;
    let scaled = io::read_scaled(&path, &limits, factor).unwrap();
    let mut after = io::read(&path, &limits).unwrap();
    after.scale(factor);
    for (s, a) in planes(&scaled).into_iter().zip(planes(&after)) {
        assert!(
            s.iter().zip(a).all(|(&s, &a)| same_bits(s, a)),
            "{s:?} {a:?}"
        );
    }
    // Black stays black; the others saturate at the largest finite value.
    assert_eq!(scaled.y[2], 0.0);
    assert_eq!(scaled.y[0], f32::MAX, "{:?}", scaled.y);
    // Below the bound the factor goes into the matrix: the same saturated values.
    let below = io::read_scaled(&path, &limits, 1e30).unwrap();
    assert_eq!(below.y[0], f32::MAX);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn openexr_files_read_scaled_agree_with_scaling_after() {
    // Luminance only, and a lone G channel from about 6e-39 to 1.7e38 (products that
    // saturate, products in the subnormal range).
    check(&data("GrayRampsHorizontal.exr"));
    check(&data("WideFloatRange.exr"));
    // RGB half blocks with whiteLuminance (the display writer), converted block by block.
    let rgb = temp("display.exr");
    io::exr::write_display(
        &display(301, 67, 80.0),
        std::fs::File::create(&rgb).unwrap(),
    )
    .unwrap();
    // The two ways differ somewhere: the stream's comparison above could catch a
    // stream read that scaled after decoding.
    assert!(check(&rgb) > 0);
    std::fs::remove_file(&rgb).unwrap();
    // XYZ (with a scotopic plane): not converted, scaled after decoding.
    let mut scene = HdrImage::zeros(29, 13);
    for (i, v) in scene.y.iter_mut().enumerate() {
        *v = (i as f32 * 0.37).sin().abs() * 1e3;
    }
    scene.x.clone_from(&scene.y);
    scene.z.clone_from(&scene.y);
    scene.scotopic = Some(scene.y.iter().map(|v| v * 2.0).collect());
    let xyz = temp("xyz.exr");
    io::exr::write_hdr(&scene, std::fs::File::create(&xyz).unwrap()).unwrap();
    check(&xyz);
    std::fs::remove_file(&xyz).unwrap();
    // The shared samples: RGB half with chromaticities and whiteLuminance, luminance and
    // subsampled chroma, XYZ.
    for name in ["Tree.exr", "StarField.exr", "XYZ.exr", "Desk.exr"] {
        if let Some(path) = shared(&format!("openexr/{name}")) {
            check(&path);
        }
    }
}

#[test]
fn pfm_files_read_scaled_agree_with_scaling_after() {
    let mut scene = HdrImage::zeros(7, 3);
    for (i, v) in scene.y.iter_mut().enumerate() {
        *v = i as f32 * 0.25;
    }
    let path = temp("scene.pfm");
    std::fs::write(&path, io::pfm::encode(&scene)).unwrap();
    check(&path);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn raw_frames_read_scaled_agree_with_scaling_after() {
    let (width, height) = (5usize, 3usize);
    let mut stream = Vec::new();
    for frame in 0..2 {
        for i in 0..3 * width * height {
            let v = (i as f32 * 0.61 + frame as f32).cos() * 4.0;
            stream.extend_from_slice(&v.to_le_bytes());
        }
    }
    let limits = Limits::default();
    for factor in FINITE.into_iter().chain(NOT_FINITE) {
        let mut plain = FrameReader::new(stream.as_slice(), "s", 5, 3, &limits).unwrap();
        let mut scaled = FrameReader::new(stream.as_slice(), "s", 5, 3, &limits)
            .unwrap()
            .with_scale(factor);
        let (mut a, mut b) = (HdrImage::zeros(0, 0), HdrImage::zeros(0, 0));
        while plain.read_into(&mut a).unwrap() {
            assert!(scaled.read_into(&mut b).unwrap());
            a.scale(factor);
            let exact = !factor.is_finite() || factor == 1.0;
            for (pa, pb) in planes(&a).into_iter().zip(planes(&b)) {
                for (&after, &s) in pa.iter().zip(pb) {
                    let ok = if exact {
                        same_bits(s, after)
                    } else {
                        agree(s, after)
                    };
                    assert!(ok, "factor {factor}: {s:e} read scaled, {after:e} after");
                }
            }
        }
        assert!(!scaled.read_into(&mut b).unwrap());
    }
}

/// A PFM file and a raw frame of the same samples, read with the same factor, give the same
/// values bit for bit (the CLI's `map` of a PFM and `video` of a raw stream rely on it).
#[test]
fn pfm_and_raw_frames_of_the_same_samples_read_scaled_alike() {
    let (width, height) = (6usize, 4usize);
    let rgb = |x: usize, y: usize| {
        let t = (x * 31 + y * 17) as f32;
        [
            (t * 0.37).sin().abs() * 3.0,
            (t * 0.11).cos().abs(),
            t * 0.013,
        ]
    };
    // PFM: interleaved RGB, bottom row first, little-endian (negative scale).
    let mut pfm = format!("PF\n{width} {height}\n-1.0\n").into_bytes();
    for y in (0..height).rev() {
        for x in 0..width {
            for v in rgb(x, y) {
                pfm.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    // Raw gbrpf32le: the G, B and R planes, top row first.
    let mut raw = Vec::new();
    for channel in [1, 2, 0] {
        for y in 0..height {
            for x in 0..width {
                raw.extend_from_slice(&rgb(x, y)[channel].to_le_bytes());
            }
        }
    }
    let path = temp("same.pfm");
    std::fs::write(&path, &pfm).unwrap();
    let limits = Limits::default();
    for factor in [1.0, 179.0, 0.01] {
        let file = io::read_scaled(&path, &limits, factor).unwrap();
        let mut frames = FrameReader::new(raw.as_slice(), "s", 6, 4, &limits)
            .unwrap()
            .with_scale(factor);
        let mut frame = HdrImage::zeros(0, 0);
        assert!(frames.read_into(&mut frame).unwrap());
        for (a, b) in planes(&file).into_iter().zip(planes(&frame)) {
            let bits = |p: &[f32]| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a), bits(b), "factor {factor}");
        }
    }
    std::fs::remove_file(&path).unwrap();
}
