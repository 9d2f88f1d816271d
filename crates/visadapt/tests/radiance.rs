//! Integration tests of the Radiance reader on real pictures: `mixtex.hdr` and
//! `sunset-fisheye.hdr` (committed), `office-fisheye.hdr` (shared data set, skipped when
//! absent). Decoded values are checked pixel by pixel against a small independent
//! decoder written here from the format's definition (Radiance `color.c`), plus
//! truncation, format detection and a 1080p decode-time check.

mod common;

use std::time::{Duration, Instant};
use visadapt::colour::{Chromaticities, RADIANCE_DEFAULT, mul_vec};
use visadapt::io::{self, InputFormat};
use visadapt::{Error, HdrImage, Limits, Projection, View};

/// Radiance's luminous efficacy of white light, lm/W (`color.h`, `WHTEFFICACY`).
const EFFICACY: f64 = 179.0;

/// A Radiance RGBE picture decoded the simple way: header key/values, standard
/// orientation only, every scanline new-style run-length encoded.
struct Raw {
    width: usize,
    height: usize,
    exposure: f64,
    primaries: Chromaticities,
    pixels: Vec<[u8; 4]>,
}

fn raw_decode(bytes: &[u8]) -> Raw {
    let end = bytes
        .windows(2)
        .position(|w| w == b"\n\n")
        .expect("header end")
        + 2;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let mut exposure = 1.0;
    let mut primaries = RADIANCE_DEFAULT;
    for line in header.lines() {
        if let Some(v) = line.strip_prefix("EXPOSURE=") {
            exposure *= v.trim().parse::<f64>().unwrap();
        } else if let Some(v) = line.strip_prefix("PRIMARIES=") {
            let p: Vec<f64> = v.split_whitespace().map(|t| t.parse().unwrap()).collect();
            primaries = Chromaticities {
                red: [p[0], p[1]],
                green: [p[2], p[3]],
                blue: [p[4], p[5]],
                white: [p[6], p[7]],
            };
        } else if let Some(v) = line.strip_prefix("FORMAT=") {
            assert_eq!(v.trim(), "32-bit_rle_rgbe");
        }
    }
    let nl = end + bytes[end..].iter().position(|&b| b == b'\n').unwrap();
    let res = std::str::from_utf8(&bytes[end..nl]).unwrap();
    let t: Vec<&str> = res.split_whitespace().collect();
    assert_eq!((t[0], t[2]), ("-Y", "+X"), "standard orientation");
    let (height, width): (usize, usize) = (t[1].parse().unwrap(), t[3].parse().unwrap());
    let mut p = nl + 1;
    let mut pixels = vec![[0u8; 4]; width * height];
    for row in pixels.chunks_mut(width) {
        assert_eq!(&bytes[p..p + 4], &[2, 2, (width >> 8) as u8, width as u8]);
        p += 4;
        for c in 0..4 {
            let mut j = 0;
            while j < width {
                let code = bytes[p] as usize;
                if code > 128 {
                    for px in &mut row[j..j + code - 128] {
                        px[c] = bytes[p + 1];
                    }
                    j += code - 128;
                    p += 2;
                } else {
                    for (k, px) in row[j..j + code].iter_mut().enumerate() {
                        px[c] = bytes[p + 1 + k];
                    }
                    j += code;
                    p += 1 + code;
                }
            }
        }
    }
    Raw {
        width,
        height,
        exposure,
        primaries,
        pixels,
    }
}

impl Raw {
    /// XYZ in cd/m² of pixel `i`: 179 × M·rgb / exposure, rgb = (m + 0.5)/256 · 2^(e−128).
    fn xyz(&self, i: usize) -> [f64; 3] {
        let p = self.pixels[i];
        if p[3] == 0 {
            return [0.0; 3];
        }
        let f = 2f64.powi(i32::from(p[3]) - 128) / 256.0;
        let rgb = [0, 1, 2].map(|c| (f64::from(p[c]) + 0.5) * f);
        let m = self.primaries.rgb_to_xyz().unwrap();
        mul_vec(&m, rgb).map(|v| v * EFFICACY / self.exposure)
    }
}

/// Every pixel of `img` equals the independent decode within `rel` (relative) or 1e-30
/// cd/m² absolute; returns the peak luminance.
fn assert_matches_raw(img: &HdrImage, raw: &Raw, rel: f64) -> f64 {
    assert_eq!((img.width, img.height), (raw.width, raw.height));
    let mut peak = 0.0f64;
    for i in 0..img.len() {
        let want = raw.xyz(i);
        for (got, want, name) in [
            (img.x[i], want[0], "X"),
            (img.y[i], want[1], "Y"),
            (img.z[i], want[2], "Z"),
        ] {
            let tol = rel * want.abs() + 1e-30;
            assert!(
                (f64::from(got) - want).abs() <= tol,
                "pixel {i} {name}: got {got}, want {want}"
            );
        }
        peak = peak.max(want[1]);
    }
    peak
}

fn read(bytes: &[u8]) -> HdrImage {
    io::decode(bytes, &Limits::default()).expect("decodes")
}

fn assert_truncations_fail(bytes: &[u8]) {
    let n = bytes.len();
    let cuts = [
        0,
        1,
        10,
        100,
        300,
        n / 100,
        n / 10,
        n / 3,
        n / 2,
        n - 1000,
        n - 5,
        n - 1,
    ];
    for cut in cuts.into_iter().filter(|&c| c < n) {
        match visadapt::io::radiance::decode(&bytes[..cut], &Limits::default()) {
            Err(Error::Decode { .. }) => {}
            other => panic!(
                "cut at {cut}/{n}: expected a decode error, got {:?}",
                other.map(|i| i.width)
            ),
        }
    }
}

#[test]
fn mixtex_decodes() {
    let bytes = std::fs::read(common::data("mixtex.hdr")).unwrap();
    assert_eq!(io::detect(&bytes), Some(InputFormat::Radiance));
    let img = io::read(&common::data("mixtex.hdr"), &Limits::default()).unwrap();
    assert_eq!((img.width, img.height), (128, 72));
    assert!(img.absolute_units);
    assert!(img.scotopic.is_none());
    img.check_consistent().unwrap();
    // VIEW= -vta ... -vh 66.6667 -vv 37.5 ...
    assert_eq!(
        img.view,
        Some(View {
            projection: Projection::AngularFisheye,
            horizontal_deg: 66.6667,
            vertical_deg: 37.5
        })
    );
    let raw = raw_decode(&bytes);
    assert_eq!(raw.exposure, 1.5, "pfilt -e 1.5");
    let peak = assert_matches_raw(&img, &raw, 1e-6);
    assert!(img.y.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(peak > 0.0);
}

#[test]
fn sunset_fisheye_has_view_and_exposures() {
    let bytes = std::fs::read(common::data("sunset-fisheye.hdr")).unwrap();
    let img = read(&bytes);
    assert_eq!((img.width, img.height), (544, 544));
    assert_eq!(
        img.view,
        Some(View {
            projection: Projection::AngularFisheye,
            horizontal_deg: 180.0,
            vertical_deg: 180.0
        })
    );
    let raw = raw_decode(&bytes);
    // The two EXPOSURE= lines of the header, multiplied.
    let exposure = 2.720623e-02 * 4.676974e+01;
    assert!((raw.exposure / exposure - 1.0).abs() < 1e-12);
    let peak = assert_matches_raw(&img, &raw, 1e-6);

    // One pixel by hand: the brightest, from its four bytes.
    let i = (0..img.len())
        .max_by(|&a, &b| img.y[a].total_cmp(&img.y[b]))
        .unwrap();
    let [r, g, b, e] = raw.pixels[i];
    let f = 2f64.powi(i32::from(e) - 128) / 256.0;
    let rgb = [r, g, b].map(|m| (f64::from(m) + 0.5) * f);
    let m = raw.primaries.rgb_to_xyz().unwrap();
    let lum = EFFICACY * (m[1][0] * rgb[0] + m[1][1] * rgb[1] + m[1][2] * rgb[2]) / exposure;
    assert!(
        (f64::from(img.y[i]) / lum - 1.0).abs() < 1e-6,
        "{} vs {lum}",
        img.y[i]
    );
    assert!((f64::from(img.y[i]) / peak - 1.0).abs() < 1e-6);
    // A sunset sky with the sun just set: of order 1e4–1e5 cd/m² at the peak.
    assert!((1e4..=3e5).contains(&peak), "peak luminance {peak} cd/m²");
    eprintln!("sunset-fisheye peak luminance {peak:.0} cd/m² at pixel {i}");
}

#[test]
fn office_fisheye_from_shared_data() {
    let Some(path) = common::shared("radiance/office-fisheye.hdr") else {
        return;
    };
    let bytes = std::fs::read(&path).unwrap();
    let img = io::read(&path, &Limits::default()).unwrap();
    assert_eq!((img.width, img.height), (786, 786));
    // VIEW= -vta -vv 182 -vh 182 -vp 0 0 0 -vd 0 0 1 -vu 0 1 0
    assert_eq!(
        img.view,
        Some(View {
            projection: Projection::AngularFisheye,
            horizontal_deg: 182.0,
            vertical_deg: 182.0
        })
    );
    let raw = raw_decode(&bytes);
    assert_eq!(raw.exposure, 1.0);
    let peak = assert_matches_raw(&img, &raw, 1e-6);
    eprintln!("office-fisheye peak luminance {peak:.0} cd/m²");
    assert_truncations_fail(&bytes);
}

#[test]
fn real_files_truncated_fail_cleanly() {
    for name in ["mixtex.hdr", "sunset-fisheye.hdr"] {
        let bytes = std::fs::read(common::data(name)).unwrap();
        assert_truncations_fail(&bytes);
    }
}

#[test]
fn header_lines_before_magic_in_a_real_file() {
    let bytes = std::fs::read(common::data("sunset-fisheye.hdr")).unwrap();
    let reference = read(&bytes);
    let mut moved = b"CAPDATE= 2018:11:06 17:03:12\nVIEW= -vth -vh 170 -vv 150\n".to_vec();
    moved.extend_from_slice(&bytes);
    assert_eq!(io::detect(&moved), Some(InputFormat::Radiance));
    assert!(io::radiance::looks_like_header(&moved));
    // The file's own later VIEW= line overrides the early one.
    assert_eq!(read(&moved), reference);
}

#[test]
fn absurd_header_sizes_are_refused_before_allocation() {
    let bytes =
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000000 +X 100000000\n\x02\x02\x00\x08";
    assert!(matches!(
        io::decode(bytes, &Limits::default()),
        Err(Error::Limits(_))
    ));
    let garbage: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let mut with_magic = b"#?RADIANCE\n".to_vec();
    with_magic.extend(&garbage);
    assert!(matches!(
        io::decode(&with_magic, &Limits::default()),
        Err(Error::Decode { .. })
    ));
}

/// New-style RLE encoding of one scanline (runs of ≥ 4 equal bytes, literals ≤ 128).
fn rle_scanline(px: &[[u8; 4]], out: &mut Vec<u8>) {
    let n = px.len();
    out.extend([2, 2, (n >> 8) as u8, n as u8]);
    for c in 0..4 {
        let mut lit_start = 0;
        let mut i = 0;
        let flush = |out: &mut Vec<u8>, from: usize, to: usize| {
            let mut s = from;
            while s < to {
                let k = (to - s).min(128);
                out.push(k as u8);
                out.extend(px[s..s + k].iter().map(|p| p[c]));
                s += k;
            }
        };
        while i < n {
            let mut run = 1;
            while i + run < n && run < 127 && px[i + run][c] == px[i][c] {
                run += 1;
            }
            if run >= 4 {
                flush(out, lit_start, i);
                out.extend([128 + run as u8, px[i][c]]);
                i += run;
                lit_start = i;
            } else {
                i += 1;
            }
        }
        flush(out, lit_start, n);
    }
}

/// Decode a synthetic 1920×1080 picture (sky-like gradient with flat regions and noise),
/// RLE and flat, and report the best of several runs. The bound asserted is loose (the
/// test profile is not the release profile and CI machines vary); the target is ~10 ms.
#[test]
fn decode_1080p_is_fast() {
    let (w, h) = (1920usize, 1080usize);
    let mut seed = 7u32;
    let mut px = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let p = if y < h / 3 {
                [200, 180, 250, 130] // flat sky
            } else if x % 64 < 32 {
                [(x / 8) as u8, (y / 5) as u8, 90, 125 + (y % 3) as u8]
            } else {
                [
                    (seed >> 24) as u8,
                    (seed >> 16) as u8,
                    (seed >> 8) as u8,
                    128,
                ]
            };
            px.push(p);
        }
    }
    let header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=0.5\n\n-Y 1080 +X 1920\n";
    let mut rle = header.to_vec();
    for row in px.chunks(w) {
        rle_scanline(row, &mut rle);
    }
    let mut flat = header.to_vec();
    flat.extend(px.iter().flatten());

    let best = |bytes: &[u8]| {
        let mut best = Duration::MAX;
        for _ in 0..5 {
            let t = Instant::now();
            let img = io::decode(bytes, &Limits::default()).unwrap();
            best = best.min(t.elapsed());
            assert_eq!((img.width, img.height), (w, h));
        }
        best
    };
    // Decoding into the previous frame's planes (no fresh pages to fault in).
    let best_reused = |bytes: &[u8]| {
        let mut img = io::decode(bytes, &Limits::default()).unwrap();
        let mut best = Duration::MAX;
        for _ in 0..5 {
            let t = Instant::now();
            io::radiance::decode_into(bytes, &Limits::default(), &mut img).unwrap();
            best = best.min(t.elapsed());
        }
        best
    };
    let (t_rle, t_flat) = (best(&rle), best(&flat));
    let (r_rle, r_flat) = (best_reused(&rle), best_reused(&flat));
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    eprintln!(
        "1920x1080 decode: RLE ({} bytes) {:.2} ms, reusing planes {:.2} ms; flat {:.2} ms, reusing planes {:.2} ms",
        rle.len(),
        ms(t_rle),
        ms(r_rle),
        ms(t_flat),
        ms(r_flat)
    );
    // Same pixels both ways.
    assert_eq!(read(&rle), read(&flat));
    assert!(t_rle < Duration::from_millis(200) && t_flat < Duration::from_millis(200));
}
