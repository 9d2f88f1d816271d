//! Hostile input to the library (issue 9): bounded reads, the memory budget, and the
//! foreign EXR decoder run as users get it.

use visadapt::io::{self, InputFormat};
use visadapt::{Error, Limits, LimitsExceeded};

fn radiance(w: usize, h: usize) -> Vec<u8> {
    let mut f = format!("#?RADIANCE\n\n-Y {h} +X {w}\n").into_bytes();
    for _ in 0..w * h {
        f.extend([128, 128, 128, 129]);
    }
    f
}

#[test]
fn a_stream_is_refused_after_its_first_bytes() {
    let mut bytes = Vec::new();
    let e = io::read_bytes("/dev/zero".as_ref(), &Limits::default(), &mut bytes).unwrap_err();
    assert!(matches!(e, Error::Unsupported(_)), "{e}");
    assert_eq!(bytes.len(), io::HEAD_LEN);
}

#[test]
fn no_more_is_read_than_the_header_allows() {
    let dir = tempfile::tempdir().unwrap();
    // Radiance: 28 bytes per pixel and 4 per scanline at most, after the header.
    let picture = radiance(3, 2);
    let header_len = picture.len() - 3 * 2 * 4;
    let mut padded = picture.clone();
    padded.resize(4 << 20, 7);
    let p = dir.path().join("padded.hdr");
    std::fs::write(&p, &padded).unwrap();
    let mut bytes = Vec::new();
    let f = io::read_bytes(&p, &Limits::default(), &mut bytes).unwrap();
    assert_eq!(f, InputFormat::Radiance);
    assert_eq!(bytes.len(), header_len + 3 * 2 * 28 + 2 * 4);
    assert_eq!(io::decode(&bytes, &Limits::default()).unwrap().width, 3);

    // PFM: exactly the declared data.
    let mut pfm = b"Pf\n2 1\n-1.0\n".to_vec();
    pfm.extend(1f32.to_le_bytes());
    pfm.extend(2f32.to_le_bytes());
    let exact = pfm.len();
    pfm.resize(2 << 20, 0);
    let p = dir.path().join("padded.pfm");
    std::fs::write(&p, &pfm).unwrap();
    assert_eq!(
        io::read_bytes(&p, &Limits::default(), &mut bytes).unwrap(),
        InputFormat::Pfm
    );
    assert_eq!(bytes.len(), exact);
}

#[test]
fn a_file_larger_than_the_budget_is_a_limits_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("big.hdr");
    std::fs::write(&p, radiance(256, 256)).unwrap();
    let limits = Limits {
        max_memory_bytes: 100_000,
        ..Limits::default()
    };
    let e = io::read(&p, &limits).unwrap_err();
    assert!(
        matches!(
            &e,
            Error::Limits(LimitsExceeded::Memory {
                max_memory_bytes: 100_000,
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("--max-memory"), "{e}");
}

/// An OpenEXR header laid out by hand (OpenEXR file layout): scan lines, FLOAT channels
/// `names`, `compression` code, data window `w × h`.
fn exr_header(names: &[String], compression: u8, w: i32, h: i32) -> Vec<u8> {
    exr_header_typed(names, 2, compression, w, h)
}

/// [`exr_header`] with channels of pixel type `pixel_type` (1 HALF, 2 FLOAT).
fn exr_header_typed(names: &[String], pixel_type: i32, compression: u8, w: i32, h: i32) -> Vec<u8> {
    let mut f = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    let attr = |f: &mut Vec<u8>, name: &str, ty: &str, value: &[u8]| {
        f.extend_from_slice(name.as_bytes());
        f.push(0);
        f.extend_from_slice(ty.as_bytes());
        f.push(0);
        f.extend_from_slice(&(value.len() as i32).to_le_bytes());
        f.extend_from_slice(value);
    };
    let mut chlist = Vec::new();
    for name in names {
        chlist.extend_from_slice(name.as_bytes());
        chlist.push(0);
        chlist.extend_from_slice(&pixel_type.to_le_bytes());
        chlist.extend_from_slice(&[0, 0, 0, 0]);
        chlist.extend_from_slice(&1i32.to_le_bytes());
        chlist.extend_from_slice(&1i32.to_le_bytes());
    }
    chlist.push(0);
    let mut window = Vec::new();
    for v in [0i32, 0, w - 1, h - 1] {
        window.extend_from_slice(&v.to_le_bytes());
    }
    attr(&mut f, "channels", "chlist", &chlist);
    attr(&mut f, "compression", "compression", &[compression]);
    attr(&mut f, "dataWindow", "box2i", &window);
    attr(&mut f, "displayWindow", "box2i", &window);
    attr(&mut f, "lineOrder", "lineOrder", &[0]);
    attr(&mut f, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attr(&mut f, "screenWindowCenter", "v2f", &[0; 8]);
    attr(&mut f, "screenWindowWidth", "float", &1f32.to_le_bytes());
    f.push(0);
    f
}

/// Issue 9, item 1: a B44 file of under a kilobyte whose one block, at the pixel limit,
/// would decompress to 32 GiB. The exr crate reserves that before reading the 16 bytes of
/// data; the failed allocation aborted the process. Now the budget refuses it first.
#[test]
fn a_block_beyond_the_budget_is_refused_before_the_decoder_allocates() {
    let mut names: Vec<String> = (0..29).map(|i| format!("c{i:02}")).collect();
    names.extend(["B", "G", "R"].map(String::from));
    names.sort();
    // B44 (code 6) holds 32 lines per block: one block of 2^23 × 32 = 2^28 pixels.
    let mut f = exr_header(&names, 6, 1 << 23, 32);
    let table_end = f.len() as u64 + 8;
    f.extend_from_slice(&table_end.to_le_bytes());
    f.extend_from_slice(&0i32.to_le_bytes()); // y
    f.extend_from_slice(&16i32.to_le_bytes()); // size
    f.extend_from_slice(&[0x55; 16]);
    assert!(f.len() < 1100, "{}", f.len());
    let e = visadapt::io::decode(&f, &Limits::default()).unwrap_err();
    assert!(
        matches!(&e, Error::Limits(LimitsExceeded::Memory { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("--max-memory"), "{e}");
}

/// The planes of an image within the pixel limit but beyond the budget are refused before
/// they are allocated.
#[test]
fn planes_beyond_the_budget_are_refused() {
    let names = ["B", "G", "R"].map(String::from);
    let mut f = exr_header(&names, 0, 4096, 4096);
    let limits = Limits {
        max_memory_bytes: 64 << 20,
        ..Limits::default()
    };
    // Offsets need not be valid: the budget is checked first.
    f.extend(std::iter::repeat_n(0u8, 8 * 4096));
    let e = visadapt::io::decode(&f, &limits).unwrap_err();
    assert!(
        matches!(&e, Error::Limits(LimitsExceeded::Memory { .. })),
        "{e}"
    );
}

/// Issue 9, item 10: a B44 block whose `unpack14` arithmetic wraps (shift 12, zero base
/// value: `0 - bias`). Released builds of the exr crate wrap and decode an image; builds
/// with overflow checks panicked, and the guard turned that into "corrupt file", so the
/// tests saw another decoder than the users. The test profile now builds dependencies
/// without overflow checks or debug assertions, as a release build does.
#[test]
fn b44_wrapping_arithmetic_decodes_as_in_a_release_build() {
    let names = ["Y".to_string()];
    let mut f = exr_header_typed(&names, 1, 6, 4, 4); // HALF, B44, 4x4: one B44 block
    let table_end = f.len() as u64 + 8;
    f.extend_from_slice(&table_end.to_le_bytes());
    f.extend_from_slice(&0i32.to_le_bytes()); // y
    f.extend_from_slice(&14i32.to_le_bytes()); // size
    let mut block = [0u8; 14];
    block[2] = 12 << 2; // shift 12: bias 0x20 << 12 > the base value 0
    f.extend_from_slice(&block);
    let image = visadapt::io::decode(&f, &Limits::default());
    assert!(image.is_ok(), "{:?}", image.err());
    assert_eq!(image.unwrap().width, 4);
}

/// Issue 9, item 4: one finite pixel of 1e37 cd/m² in a dark scene overflowed the f32
/// mapping to +inf; clipping made NaN and the blur spread it: every pixel black, and the
/// report counted nothing. Every finite input must give display samples in [0, 1].
#[test]
fn a_huge_finite_pixel_stays_finite_and_is_counted() {
    use visadapt::HdrImage;
    use visadapt::operator::{ViewingConditions, map};
    let mut scene = HdrImage::zeros(64, 64);
    for (i, y) in scene.y.iter_mut().enumerate() {
        *y = 0.01 + 0.001 * (i % 7) as f32;
    }
    scene.x = scene.y.iter().map(|y| 0.9505 * y).collect();
    scene.z = scene.y.iter().map(|y| 1.089 * y).collect();
    let hot = 32 * 64 + 32;
    for (plane, v) in [
        (&mut scene.x, 0.9e37f32),
        (&mut scene.y, 1e37),
        (&mut scene.z, 1.1e37),
    ] {
        plane[hot] = v;
    }
    for extreme in [1e37f32, f32::MAX] {
        scene.x[hot] = extreme;
        let out = map(&scene, &ViewingConditions::default()).unwrap();
        let samples = out.image.r.iter().chain(&out.image.g).chain(&out.image.b);
        assert!(
            samples
                .clone()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        );
        // The dark scene is not black, and the hot pixel is white (clipped), counted.
        let lit = out.image.g.iter().filter(|v| **v > 0.0).count();
        assert!(lit > 4000, "{lit} of 4096 lit");
        assert!(out.stats.clipped >= 1, "{:?}", out.stats);
        assert!(out.stats.saturated >= 1, "{:?}", out.stats);
        assert_eq!(out.stats.non_finite, 0);
    }
}

/// Flags beyond what the f32 pipeline carries are refused with their own names.
#[test]
fn luminances_beyond_the_f32_range_are_refused_by_name() {
    use visadapt::operator::ViewingConditions;
    for (name, conditions) in [
        (
            "display-max",
            ViewingConditions {
                display_max_cd_m2: 1e39,
                ..ViewingConditions::default()
            },
        ),
        (
            "world-adaptation",
            ViewingConditions {
                world_adaptation_cd_m2: Some(1e300),
                ..ViewingConditions::default()
            },
        ),
        // Below the range: 1e-300 is 0 as f32, 1e-45 a subnormal.
        (
            "display-max",
            ViewingConditions {
                display_max_cd_m2: 1e-300,
                ..ViewingConditions::default()
            },
        ),
        (
            "world-adaptation",
            ViewingConditions {
                world_adaptation_cd_m2: Some(1e-45),
                ..ViewingConditions::default()
            },
        ),
    ] {
        let e = conditions.validate().unwrap_err();
        assert!(
            matches!(&e, Error::InvalidParameter { name: n, .. } if *n == name),
            "{e}"
        );
    }
    let mut scene = visadapt::HdrImage::zeros(2, 2);
    scene.y.fill(1.0);
    let e = scene.peak_factor(1e308, 0.0).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidParameter { name: "peak", .. }),
        "{e}"
    );
    // Scaling saturates instead of overflowing.
    scene.scale(1e30);
    scene.scale(1e30);
    assert!(scene.y.iter().all(|v| *v == f32::MAX));
}
