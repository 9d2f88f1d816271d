//! OpenEXR reader and writers: round trips, channel layouts, attributes, block layouts and
//! the sample images.
//!
//! Expected colours use the sRGB → XYZ matrix quoted (to 4 decimals) by IEC 61966-2-1,
//! Eq. (F.7), independently of the library's matrix code; tolerances are set by those 4
//! decimals (about 1e-4 relative), or by f16 precision where the data is half float.

mod common;

use exr::prelude::*;
use std::io::Cursor;
use visadapt::io::exr as vexr;
use visadapt::{DisplayImage, Error, HdrImage, Limits};

/// IEC 61966-2-1 Eq. (F.7): linear sRGB (Rec. 709 primaries, D65) → CIE XYZ.
const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];

fn srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    let m = SRGB_TO_XYZ;
    [0, 1, 2].map(|r| m[r][0] * rgb[0] + m[r][1] * rgb[1] + m[r][2] * rgb[2])
}

/// |a − b| ≤ tol · max(1, |b|).
fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

fn assert_xyz(img: &HdrImage, i: usize, expected: [f64; 3], tol: f64) {
    assert_xyz_scaled(img, i, expected, tol, 1.0);
}

/// Like [`assert_xyz`], with the tolerance relative to at least `scale` (e.g. the size of
/// the RGB input, since a 4-decimal matrix errs relative to its input, not its output).
fn assert_xyz_scaled(img: &HdrImage, i: usize, expected: [f64; 3], tol: f64, scale: f64) {
    let got = [img.x[i], img.y[i], img.z[i]].map(f64::from);
    for c in 0..3 {
        assert!(
            (got[c] - expected[c]).abs() <= tol * expected[c].abs().max(scale.max(1.0)),
            "pixel {i} channel {c}: got {got:?}, expected {expected:?}"
        );
    }
}

fn decode(bytes: &[u8]) -> HdrImage {
    let img = vexr::decode(bytes, &Limits::default()).expect("decodes");
    img.check_consistent().unwrap();
    img
}

/// Write a one-layer EXR in memory with the exr crate.
fn write_with_exr_crate(
    size: (usize, usize),
    channels: Vec<AnyChannel<FlatSamples>>,
    encoding: Encoding,
    attributes: LayerAttributes,
    chromaticities: Option<exr::meta::attribute::Chromaticities>,
) -> Vec<u8> {
    let layer = Layer::new(
        size,
        attributes,
        encoding,
        AnyChannels::sort(channels.into_iter().collect()),
    );
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = chromaticities;
    let mut out = Cursor::new(Vec::new());
    image.write().to_buffered(&mut out).unwrap();
    out.into_inner()
}

fn f32_channel(name: &str, v: Vec<f32>) -> AnyChannel<FlatSamples> {
    AnyChannel::new(name, FlatSamples::F32(v))
}

fn f16_channel(name: &str, v: &[f32]) -> AnyChannel<FlatSamples> {
    AnyChannel::new(
        name,
        FlatSamples::F16(v.iter().map(|&x| f16::from_f32(x)).collect()),
    )
}

fn scanlines(compression: Compression) -> Encoding {
    Encoding {
        compression,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    }
}

// ---------------------------------------------------------------------------------------
// Round trips through our writers
// ---------------------------------------------------------------------------------------

#[test]
fn hdr_writer_round_trips_exactly_with_scotopic() {
    let (w, h) = (5, 3);
    let n = w * h;
    let img = HdrImage {
        width: w,
        height: h,
        x: (0..n).map(|i| i as f32 * 0.5 + 0.001).collect(),
        y: (0..n).map(|i| (i as f32).powi(3) * 1e3 + 1e-4).collect(),
        z: (0..n).map(|i| 1e-6 * (i + 1) as f32).collect(),
        scotopic: Some((0..n).map(|i| 2.5e4 - i as f32).collect()),
        view: None,
        absolute_units: true,
        // The paper's layout reads back with its equal-energy white.
        adopted_white: Some(visadapt::colour::EQUAL_ENERGY),
    };
    let mut buf = Cursor::new(Vec::new());
    vexr::write_hdr(&img, &mut buf).unwrap();
    let back = decode(buf.get_ref());
    assert_eq!(back, img, "f32 X/Y/Z/scotopic must come back bit for bit");
}

#[test]
fn hdr_writer_without_scotopic_reads_back_absolute() {
    let mut img = HdrImage::zeros(2, 2);
    img.y = vec![1.0, 2.0, 3.0, 4.0];
    img.x = vec![0.5; 4];
    img.z = vec![0.25; 4];
    let mut buf = Cursor::new(Vec::new());
    vexr::write_hdr(&img, &mut buf).unwrap();
    let back = decode(buf.get_ref());
    assert!(back.absolute_units, "X/Y/Z layout is in cd/m²");
    assert_eq!(back.scotopic, None);
    assert_eq!((back.x, back.y, back.z), (img.x, img.y, img.z));
}

#[test]
fn display_writer_encodes_display_max_as_white_luminance() {
    let d = DisplayImage {
        width: 2,
        height: 2,
        r: vec![1.0, 0.0, 0.0, 0.25],
        g: vec![1.0, 1.0, 0.0, 0.5],
        b: vec![1.0, 0.0, 1.0, 0.75],
        display_max_cd_m2: 80.0,
    };
    let mut buf = Cursor::new(Vec::new());
    vexr::write_display(&d, &mut buf).unwrap();

    // The attributes, as any OpenEXR reader sees them.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(buf.get_ref()), false).unwrap();
    let header = &meta.headers[0];
    assert_eq!(header.own_attributes.white_luminance, Some(80.0));
    let c = header.shared_attributes.chromaticities.unwrap();
    assert_eq!(
        (c.red, c.green, c.blue),
        (Vec2(0.64, 0.33), Vec2(0.30, 0.60), Vec2(0.15, 0.06))
    );
    assert_eq!(c.white, Vec2(0.3127, 0.3290));
    assert!(
        header
            .channels
            .list
            .iter()
            .all(|c| c.sample_type == SampleType::F32)
    );
    assert_eq!(header.compression, Compression::RLE);

    // Read back: RGB (1,1,1) is 80 cd/m² of D65 white.
    let back = decode(buf.get_ref());
    assert!(back.absolute_units);
    for i in 0..4 {
        let rgb = [d.r[i], d.g[i], d.b[i]].map(|v| f64::from(v) * 80.0);
        assert_xyz(&back, i, srgb_to_xyz(rgb), 2e-4);
    }
    assert!(close(f64::from(back.y[0]), 80.0, 1e-6));
}

#[test]
fn writers_reject_inconsistent_images() {
    let mut img = HdrImage::zeros(2, 2);
    img.z.pop();
    assert!(matches!(
        vexr::write_hdr(&img, Cursor::new(Vec::new())),
        Err(Error::InvalidParameter { .. })
    ));
    let d = DisplayImage {
        width: 1,
        height: 1,
        r: vec![0.5],
        g: vec![0.5],
        b: vec![0.5],
        display_max_cd_m2: f32::NAN,
    };
    assert!(vexr::write_display(&d, Cursor::new(Vec::new())).is_err());
}

// ---------------------------------------------------------------------------------------
// Files written with the exr crate
// ---------------------------------------------------------------------------------------

/// A 3×2 RGB test pattern with a known pixel (1.0, 0.5, 0.25) at (1, 0).
fn pattern() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let r = vec![0.0, 1.0, 0.2, 4.0, 0.0, 100.0];
    let g = vec![0.0, 0.5, 0.2, 2.0, 1.0, 50.0];
    let b = vec![0.0, 0.25, 0.2, 1.0, 0.0, 25.0];
    (r, g, b)
}

#[test]
fn rgb_file_converts_with_rec709_matrix() {
    let (r, g, b) = pattern();
    let bytes = write_with_exr_crate(
        (3, 2),
        vec![
            f32_channel("R", r.clone()),
            f32_channel("G", g.clone()),
            f32_channel("B", b.clone()),
            f32_channel("A", vec![1.0; 6]),
        ],
        scanlines(Compression::ZIP16),
        LayerAttributes::default(),
        None,
    );
    let img = decode(&bytes);
    assert_eq!((img.width, img.height), (3, 2));
    assert!(!img.absolute_units, "no whiteLuminance: relative");
    // Y = 0.2126·1 + 0.7152·0.5 + 0.0722·0.25 = 0.58825
    assert!(close(f64::from(img.y[1]), 0.58825, 2e-4), "{}", img.y[1]);
    for i in 0..6 {
        let rgb = [r[i], g[i], b[i]].map(f64::from);
        assert_xyz(&img, i, srgb_to_xyz(rgb), 2e-4);
    }
}

#[test]
fn white_luminance_scales_to_cd_m2() {
    let (r, g, b) = pattern();
    let attributes = LayerAttributes {
        white_luminance: Some(100.0),
        ..LayerAttributes::default()
    };
    let bytes = write_with_exr_crate(
        (3, 2),
        vec![
            f16_channel("R", &r),
            f16_channel("G", &g),
            f16_channel("B", &b),
        ],
        scanlines(Compression::PIZ),
        attributes,
        None,
    );
    let img = decode(&bytes);
    assert!(img.absolute_units);
    assert!(close(f64::from(img.y[1]), 58.825, 2e-4), "{}", img.y[1]);
    // The grey pixel (0.2, 0.2, 0.2) (0.2 in f16 is 0.199951171875) → 100·0.19995 cd/m².
    let grey = f64::from(f16::from_f32(0.2).to_f32()) * 100.0;
    assert_xyz(&img, 2, [0.9505 * grey, grey, 1.089 * grey], 2e-4);
}

#[test]
fn chromaticities_of_cie_xyz_give_identity() {
    let xyz = exr::meta::attribute::Chromaticities {
        red: Vec2(1.0, 0.0),
        green: Vec2(0.0, 1.0),
        blue: Vec2(0.0, 0.0),
        white: Vec2(1.0 / 3.0, 1.0 / 3.0),
    };
    let (r, g, b) = pattern();
    let bytes = write_with_exr_crate(
        (3, 2),
        vec![
            f32_channel("R", r.clone()),
            f32_channel("G", g.clone()),
            f32_channel("B", b.clone()),
        ],
        scanlines(Compression::RLE),
        LayerAttributes::default(),
        Some(xyz),
    );
    let img = decode(&bytes);
    for i in 0..6 {
        assert_xyz(&img, i, [r[i], g[i], b[i]].map(f64::from), 1e-6);
    }
}

#[test]
fn other_chromaticities_are_applied() {
    // Primaries as in Tree.exr; white (1,1,1) must map to its white point with Y = 1.
    let c = exr::meta::attribute::Chromaticities {
        red: Vec2(0.62955, 0.341),
        green: Vec2(0.2867, 0.6108),
        blue: Vec2(0.1489, 0.07125),
        white: Vec2(0.3155, 0.33165),
    };
    let bytes = write_with_exr_crate(
        (1, 1),
        vec![
            f32_channel("R", vec![1.0]),
            f32_channel("G", vec![1.0]),
            f32_channel("B", vec![1.0]),
        ],
        scanlines(Compression::Uncompressed),
        LayerAttributes::default(),
        Some(c),
    );
    let img = decode(&bytes);
    let (xw, yw) = (0.3155f64, 0.33165f64);
    assert_xyz(&img, 0, [xw / yw, 1.0, (1.0 - xw - yw) / yw], 1e-5);
}

#[test]
fn luminance_only_and_lone_channels_are_grey() {
    for name in ["Y", "R", "G", "B"] {
        let bytes = write_with_exr_crate(
            (2, 1),
            vec![f32_channel(name, vec![2.0, 1e-3])],
            scanlines(Compression::ZIP1),
            LayerAttributes::default(),
            None,
        );
        let img = decode(&bytes);
        // Luminance kept as is; X, Z of D65 white: x/y = 0.3127/0.3290, z/y = 0.3583/0.3290.
        assert_xyz(&img, 0, [2.0 * 0.950_456, 2.0, 2.0 * 1.089_058], 1e-5);
        assert_xyz(&img, 1, [1e-3 * 0.950_456, 1e-3, 1e-3 * 1.089_058], 1e-5);
    }
}

#[test]
fn tiled_offset_window_any_line_order_every_compression() {
    // 37×21 data window at (5, −3): tiles 16×16 and scan lines, all compressions the exr
    // crate writes, increasing and decreasing order.
    let (w, h) = (37usize, 21usize);
    let value = |x: usize, y: usize| (x as f32 + 0.25) * 0.5 + y as f32 * 64.0;
    let g: Vec<f32> = (0..w * h).map(|i| value(i % w, i / w)).collect();
    for compression in [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
        Compression::PXR24,
        Compression::B44,
        Compression::B44A,
    ] {
        for blocks in [Blocks::ScanLines, Blocks::Tiles(Vec2(16, 16))] {
            for line_order in [LineOrder::Increasing, LineOrder::Decreasing] {
                let attributes = LayerAttributes {
                    layer_position: Vec2(5, -3),
                    ..LayerAttributes::default()
                };
                let bytes = write_with_exr_crate(
                    (w, h),
                    vec![f16_channel("Y", &g)],
                    Encoding {
                        compression,
                        blocks,
                        line_order,
                    },
                    attributes,
                    None,
                );
                let img = decode(&bytes);
                assert_eq!((img.width, img.height), (w, h), "{compression:?}");
                // Lossless: the f16 of the input. B44 is lossy (4×4 blocks quantised
                // relative to their range): the exr crate's own decoding of these bytes.
                let expected: Vec<f32> = if compression.is_lossless_for(SampleType::F16) {
                    g.iter().map(|&v| f16::from_f32(v).to_f32()).collect()
                } else {
                    let image = read()
                        .no_deep_data()
                        .largest_resolution_level()
                        .all_channels()
                        .first_valid_layer()
                        .all_attributes()
                        .from_buffered(Cursor::new(&bytes))
                        .unwrap();
                    image.layer_data.channel_data.list[0]
                        .sample_data
                        .values_as_f32()
                        .collect()
                };
                for (i, &v) in expected.iter().enumerate() {
                    assert!(
                        img.y[i] == v,
                        "{compression:?} {blocks:?} {line_order:?} pixel {i}: {} vs {v}",
                        img.y[i]
                    );
                }
            }
        }
    }
}

#[test]
fn mip_mapped_file_reads_full_resolution() {
    use exr::math::RoundingMode;
    let full = Vec2(20usize, 12usize);
    let levels: Vec<_> = exr::meta::mip_map_levels(RoundingMode::Down, full).collect();
    let channel = |name: &str, base: f32| {
        AnyChannel::new(
            name,
            Levels::Mip {
                level_data: levels
                    .iter()
                    .map(|(i, s)| FlatSamples::F32(vec![base + *i as f32; s.area()]))
                    .collect(),
                rounding_mode: RoundingMode::Down,
            },
        )
    };
    let layer = Layer::new(
        full,
        LayerAttributes::default(),
        Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::Tiles(Vec2(8, 8)),
            line_order: LineOrder::Increasing,
        },
        AnyChannels::sort(SmallVec::from_vec(vec![
            channel("R", 1.0),
            channel("G", 1.0),
            channel("B", 1.0),
        ])),
    );
    let mut out = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .unwrap();
    let img = decode(out.get_ref());
    assert_eq!((img.width, img.height), (20, 12));
    assert!(
        img.y.iter().all(|&v| close(f64::from(v), 1.0, 1e-6)),
        "level 0 has value 1"
    );
}

#[test]
fn first_layer_with_usable_channels_is_read() {
    let depth = Layer::new(
        (2, 2),
        LayerAttributes::named("depth"),
        scanlines(Compression::RLE),
        AnyChannels::sort(SmallVec::from_vec(vec![f32_channel("depth", vec![9.0; 4])])),
    );
    let colour = Layer::new(
        (2, 2),
        LayerAttributes::named("beauty"),
        scanlines(Compression::ZIP16),
        AnyChannels::sort(SmallVec::from_vec(vec![
            f32_channel("R", vec![1.0; 4]),
            f32_channel("G", vec![0.5; 4]),
            f32_channel("B", vec![0.25; 4]),
        ])),
    );
    let image = Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions((2, 2))),
        SmallVec::from_vec(vec![depth, colour]),
    );
    let mut out = Cursor::new(Vec::new());
    image.write().to_buffered(&mut out).unwrap();
    let img = decode(out.get_ref());
    assert_xyz(&img, 3, srgb_to_xyz([1.0, 0.5, 0.25]), 2e-4);
}

#[test]
fn prefixed_channels_and_unusable_files() {
    let bytes = write_with_exr_crate(
        (1, 1),
        vec![
            f32_channel("diffuse.R", vec![1.0]),
            f32_channel("diffuse.G", vec![0.5]),
            f32_channel("diffuse.B", vec![0.25]),
        ],
        scanlines(Compression::RLE),
        LayerAttributes::default(),
        None,
    );
    assert_xyz(&decode(&bytes), 0, srgb_to_xyz([1.0, 0.5, 0.25]), 2e-4);

    let bytes = write_with_exr_crate(
        (1, 1),
        vec![f32_channel("depth", vec![1.0])],
        scanlines(Compression::RLE),
        LayerAttributes::default(),
        None,
    );
    let e = vexr::decode(&bytes, &Limits::default()).unwrap_err();
    assert!(matches!(e, Error::Unsupported(_)), "{e}");
    assert!(e.to_string().contains("depth"), "{e}");
}

#[test]
fn limits_are_checked_and_truncation_is_an_error() {
    let bytes = write_with_exr_crate(
        (64, 64),
        vec![f32_channel("Y", vec![1.0; 64 * 64])],
        scanlines(Compression::ZIP16),
        LayerAttributes::default(),
        None,
    );
    let small = Limits {
        max_pixels: 4095,
        ..Limits::default()
    };
    assert!(matches!(
        vexr::decode(&bytes, &small),
        Err(Error::Limits(_))
    ));
    assert!(
        vexr::decode(
            &bytes,
            &Limits {
                max_pixels: 4096,
                ..Limits::default()
            }
        )
        .is_ok()
    );
    for cut in [10, 100, bytes.len() / 2, bytes.len() - 1] {
        let e = vexr::decode(&bytes[..cut], &Limits::default()).unwrap_err();
        assert!(matches!(e, Error::Decode { .. }), "cut at {cut}: {e}");
    }
}

// ---------------------------------------------------------------------------------------
// Luminance/chroma with subsampled chroma, in a file built byte by byte
// ---------------------------------------------------------------------------------------

/// A scan-line EXR with FLOAT channels BY, RY (subsampled 2×2) and Y, laid out by hand
/// after the OpenEXR file layout ("OpenEXR File Layout" document). The blocks are
/// compressed with the exr crate's own compressors, given a header whose bytes per pixel
/// matches the subsampled block size.
fn yca_file(
    w: usize,
    h: usize,
    y: &[f32],
    ry: &[f32],
    by: &[f32],
    compression: Compression,
) -> Vec<u8> {
    let code = match compression {
        Compression::Uncompressed => 0u8,
        Compression::RLE => 1,
        Compression::ZIP1 => 2,
        Compression::ZIP16 => 3,
        Compression::PIZ => 4,
        other => panic!("{other:?} not used here"),
    };
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
    for (name, s) in [("BY", 2i32), ("RY", 2), ("Y", 1)] {
        chlist.extend_from_slice(name.as_bytes());
        chlist.push(0);
        chlist.extend_from_slice(&2i32.to_le_bytes()); // FLOAT
        chlist.extend_from_slice(&[0, 0, 0, 0]); // pLinear, reserved
        chlist.extend_from_slice(&s.to_le_bytes());
        chlist.extend_from_slice(&s.to_le_bytes());
    }
    chlist.push(0);
    let mut window = Vec::new();
    for v in [0i32, 0, w as i32 - 1, h as i32 - 1] {
        window.extend_from_slice(&v.to_le_bytes());
    }
    attr(&mut f, "channels", "chlist", &chlist);
    attr(&mut f, "compression", "compression", &[code]);
    attr(&mut f, "dataWindow", "box2i", &window);
    attr(&mut f, "displayWindow", "box2i", &window);
    attr(&mut f, "lineOrder", "lineOrder", &[0]);
    attr(&mut f, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attr(&mut f, "screenWindowCenter", "v2f", &[0; 8]);
    attr(&mut f, "screenWindowWidth", "float", &1f32.to_le_bytes());
    f.push(0);
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&f), false).unwrap();
    let lines = compression.scan_lines_per_block();
    let blocks = h.div_ceil(lines);
    let mut chunks = Vec::new();
    let mut offsets = Vec::new();
    let table_end = f.len() + 8 * blocks;
    for block in 0..blocks {
        let (y0, y1) = (block * lines, ((block + 1) * lines).min(h));
        // Raw block: each line holds BY, RY (even lines only), then Y, native endian.
        let mut raw = Vec::new();
        for row in y0..y1 {
            if row % 2 == 0 {
                for plane in [by, ry] {
                    for v in &plane[(row / 2) * (w / 2)..(row / 2 + 1) * (w / 2)] {
                        raw.extend_from_slice(&v.to_ne_bytes());
                    }
                }
            }
            for v in &y[row * w..(row + 1) * w] {
                raw.extend_from_slice(&v.to_ne_bytes());
            }
        }
        let mut header = meta.headers[0].clone();
        header.channels.bytes_per_pixel = raw.len() / (w * (y1 - y0));
        let rect = IntegerBounds::new(Vec2(0, y0 as i32), Vec2(w, y1 - y0));
        let data = compression
            .compress_image_section_to_le(&header, raw, rect)
            .unwrap();
        offsets.push((table_end + chunks.len()) as u64);
        chunks.extend_from_slice(&(y0 as i32).to_le_bytes());
        chunks.extend_from_slice(&(data.len() as i32).to_le_bytes());
        chunks.extend_from_slice(&data);
    }
    for o in offsets {
        f.extend_from_slice(&o.to_le_bytes());
    }
    f.extend_from_slice(&chunks);
    f
}

#[test]
fn subsampled_luminance_chroma_is_reconstructed() {
    let (w, h) = (40, 36);
    let (cw, ch) = (w / 2, h / 2);
    let y: Vec<f32> = (0..w * h)
        .map(|i| 1.0 + 0.1 * (i % w + i / w) as f32)
        .collect();
    // Chroma samples (i, j) sit on pixel (2i, 2j).
    let ry: Vec<f32> = (0..cw * ch).map(|k| 0.01 * k as f32).collect();
    let by: Vec<f32> = vec![-0.25; cw * ch];
    for compression in [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
    ] {
        let img = decode(&yca_file(w, h, &y, &ry, &by, compression));
        assert_eq!((img.width, img.height), (w, h));
        // ImfRgbaYca: R = (RY+1)·Y, B = (BY+1)·Y, G = (Y − 0.2126 R − 0.0722 B)/0.7152.
        for j in 0..ch {
            for i in 0..cw {
                let p = (2 * j) * w + 2 * i;
                let yv = f64::from(y[p]);
                let r = (f64::from(ry[j * cw + i]) + 1.0) * yv;
                let b = 0.75 * yv;
                let g = (yv - 0.2126 * r - 0.0722 * b) / 0.7152;
                let scale = r + g + b;
                assert_xyz_scaled(&img, p, srgb_to_xyz([r, g, b]), 2e-4, scale);
            }
        }
        // Away from the edges (13 pixels), the interpolation filter reproduces the linear
        // chroma ramp at odd pixels: RY at pixel (x, y) is 0.01·(y/2·cw + x/2).
        for py in 14..h - 14 {
            for px in 14..w - 14 {
                let p = py * w + px;
                let chroma = 0.01 * ((py as f64 / 2.0) * cw as f64 + px as f64 / 2.0);
                let yv = f64::from(y[p]);
                let r = (chroma + 1.0) * yv;
                let b = 0.75 * yv;
                let g = (yv - 0.2126 * r - 0.0722 * b) / 0.7152;
                assert_xyz_scaled(&img, p, srgb_to_xyz([r, g, b]), 2e-4, r + g + b);
            }
        }
        // Y comes back unchanged everywhere.
        for (p, &v) in y.iter().enumerate() {
            assert!(
                close(f64::from(img.y[p]), f64::from(v), 1e-5),
                "{compression:?} {p}"
            );
        }
    }
    // Zero chroma is grey: R = G = B = Y, so XYZ is D65 white times Y.
    let grey = decode(&yca_file(
        w,
        h,
        &y,
        &vec![0.0; cw * ch],
        &vec![0.0; cw * ch],
        Compression::PIZ,
    ));
    for (p, &v) in y.iter().enumerate() {
        let v = f64::from(v);
        assert_xyz(&grey, p, [0.950_456 * v, v, 1.089_058 * v], 1e-5);
    }
}

// ---------------------------------------------------------------------------------------
// Sample images
// ---------------------------------------------------------------------------------------

/// Read the first layer's channels with the exr crate's own high-level reader.
fn reference_channels(path: &std::path::Path) -> (usize, usize, Vec<(String, Vec<f32>)>) {
    let image = read_first_flat_layer_from_file(path).unwrap();
    let layer = image.layer_data;
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let values = c.sample_data.values_as_f32().collect::<Vec<f32>>();
            (c.name.to_string(), values)
        })
        .collect();
    (layer.size.0, layer.size.1, channels)
}

fn channel<'a>(channels: &'a [(String, Vec<f32>)], name: &str) -> &'a [f32] {
    &channels.iter().find(|(n, _)| n == name).unwrap().1
}

/// Compare an RGB file against the exr crate's reading, through the Rec. 709 matrix,
/// times `white_luminance`.
fn check_rgb_file(path: &std::path::Path, white_luminance: f64) {
    let bytes = std::fs::read(path).unwrap();
    let img = decode(&bytes);
    let (w, h, ch) = reference_channels(path);
    assert_eq!((img.width, img.height), (w, h));
    let (r, g, b) = (channel(&ch, "R"), channel(&ch, "G"), channel(&ch, "B"));
    for i in (0..w * h).step_by(997) {
        let rgb = [r[i], g[i], b[i]].map(|v| f64::from(v) * white_luminance);
        let scale = rgb.iter().map(|v| v.abs()).sum();
        assert_xyz_scaled(&img, i, srgb_to_xyz(rgb), 2e-4, scale);
    }
    assert!(img.y.iter().all(|v| v.is_finite()));
}

#[test]
fn committed_gray_ramps_is_luminance_only() {
    let path = common::data("GrayRampsHorizontal.exr");
    let img = decode(&std::fs::read(&path).unwrap());
    let (w, h, ch) = reference_channels(&path);
    assert_eq!((img.width, img.height, w, h), (800, 800, 800, 800));
    assert!(!img.absolute_units);
    let y = channel(&ch, "Y");
    assert_eq!(img.y, y, "Y is passed through unchanged");
    for (i, &l) in y.iter().enumerate() {
        let l = f64::from(l);
        assert!(close(f64::from(img.x[i]), 0.950_456 * l, 1e-5));
        assert!(close(f64::from(img.z[i]), 1.089_058 * l, 1e-5));
    }
    let max = img.y.iter().cloned().fold(0.0f32, f32::max);
    assert!((17.9..=18.1).contains(&max), "{max}");
}

#[test]
fn committed_wide_float_range_stays_finite_scanline_and_tiled() {
    let path = common::data("WideFloatRange.exr");
    let bytes = std::fs::read(&path).unwrap();
    let img = decode(&bytes);
    let (w, h, ch) = reference_channels(&path);
    let g = channel(&ch, "G");
    assert_eq!((img.width, img.height), (w, h));
    let file_nonfinite = g.iter().filter(|v| !v.is_finite()).count();
    let ours_nonfinite = [&img.x, &img.y, &img.z]
        .iter()
        .map(|p| p.iter().filter(|v| !v.is_finite()).count())
        .max()
        .unwrap();
    assert_eq!(ours_nonfinite, file_nonfinite, "the reader adds no Inf/NaN");
    assert_eq!(img.y, g, "a lone G channel is read as luminance");
    let max = img.y.iter().cloned().fold(0.0f32, f32::max);
    assert!((1.69e38..=1.71e38).contains(&max), "{max}");
    // Z = 1.089·Y reaches 1.85e38: still finite in f32.
    assert!(img.z.iter().all(|v| v.is_finite()));
    let tiny = img
        .y
        .iter()
        .cloned()
        .filter(|v| *v > 0.0)
        .fold(f32::MAX, f32::min);
    assert!(tiny < 1e-37, "denormal-range values survive: {tiny}");

    // The same samples tiled and ZIP-compressed read back identically.
    let tiled = write_with_exr_crate(
        (w, h),
        vec![f32_channel("G", g.to_vec())],
        Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::Tiles(Vec2(64, 64)),
            line_order: LineOrder::Increasing,
        },
        LayerAttributes::default(),
        None,
    );
    let again = decode(&tiled);
    assert_eq!(again.y, img.y);
    assert_eq!(again.z, img.z);
}

#[test]
fn shared_tree_uses_white_luminance_and_chromaticities() {
    let Some(path) = common::shared("openexr/Tree.exr") else {
        return;
    };
    let img = decode(&std::fs::read(&path).unwrap());
    assert!(img.absolute_units, "whiteLuminance 621");
    let (w, h, ch) = reference_channels(&path);
    assert_eq!((img.width, img.height), (w, h));
    // RGB→XYZ of Tree's primaries (0.62955, 0.341), (0.2867, 0.6108), (0.1489, 0.07125),
    // white (0.3155, 0.33165), by the RP 177 construction.
    let m = visadapt::colour::Chromaticities {
        red: [0.62955, 0.341],
        green: [0.2867, 0.6108],
        blue: [0.1489, 0.07125],
        white: [0.3155, 0.33165],
    }
    .rgb_to_xyz()
    .unwrap();
    // White (1,1,1) has Y = 1, so the Y row sums to 1.
    assert!((m[1].iter().sum::<f64>() - 1.0).abs() < 1e-9);
    let (r, g, b) = (channel(&ch, "R"), channel(&ch, "G"), channel(&ch, "B"));
    for i in (0..w * h).step_by(1009) {
        let rgb = [r[i], g[i], b[i]].map(|v| f64::from(v) * 621.0);
        let xyz = visadapt::colour::mul_vec(&m, rgb);
        assert_xyz(&img, i, xyz, 1e-5);
    }
}

#[test]
fn shared_xyz_file_is_read_as_xyz() {
    let Some(path) = common::shared("openexr/XYZ.exr") else {
        return;
    };
    let img = decode(&std::fs::read(&path).unwrap());
    let (w, h, ch) = reference_channels(&path);
    assert_eq!((img.width, img.height), (w, h));
    let (r, g, b) = (channel(&ch, "R"), channel(&ch, "G"), channel(&ch, "B"));
    // The identity matrix, up to the f32 rounding of the white point 1/3 in the file.
    for i in 0..w * h {
        let expected = [r[i], g[i], b[i]].map(f64::from);
        assert_xyz(&img, i, expected, 1e-6);
    }
}

#[test]
fn shared_rgb_files_match_the_exr_crate() {
    for name in [
        "GoldenGate.exr",
        "CandleGlass.exr",
        "Cannon.exr",
        "Desk.exr",
    ] {
        let Some(path) = common::shared(&format!("openexr/{name}")) else {
            return;
        };
        check_rgb_file(&path, 1.0);
    }
}

#[test]
fn shared_star_field_luminance_chroma() {
    let Some(path) = common::shared("openexr/StarField.exr") else {
        return;
    };
    let img = decode(&std::fs::read(&path).unwrap());
    assert_eq!((img.width, img.height), (1000, 1000));
    assert!(!img.absolute_units);
    for p in [&img.x, &img.y, &img.z] {
        assert!(p.iter().all(|v| v.is_finite()));
    }
    // A night sky: dark on average, with bright stars; Y is never negative (it is the
    // file's own luminance channel).
    let mean = img.y.iter().map(|&v| f64::from(v)).sum::<f64>() / 1e6;
    let max = img.y.iter().cloned().fold(0.0f32, f32::max);
    assert!(img.y.iter().all(|&v| v >= 0.0));
    assert!(mean < 0.05 && max > 100.0, "mean {mean}, max {max}");
}

// ---------------------------------------------------------------------------------------
// Block layout of written files
// ---------------------------------------------------------------------------------------

/// The chunk count and block geometry a written file declares, as any reader sees them.
fn written_blocks(bytes: &[u8]) -> (usize, exr::meta::BlockDescription) {
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).unwrap();
    let h = &meta.headers[0];
    (h.chunk_count, h.blocks)
}

/// A display image of `width × height` with a ramp, to check every pixel comes back.
fn ramp_display(width: usize, height: usize) -> DisplayImage {
    let n = width * height;
    let ramp: Vec<f32> = (0..n).map(|i| i as f32 / n as f32).collect();
    DisplayImage {
        width,
        height,
        r: ramp.clone(),
        g: ramp.iter().map(|v| 1.0 - v).collect(),
        b: ramp,
        display_max_cd_m2: 1.0,
    }
}

#[test]
fn narrow_and_wide_images_are_written_in_blocks_sized_by_bytes() {
    use exr::meta::BlockDescription;
    // A 1-pixel-wide column took one RLE chunk per pixel (1 × 4194304: 4 M chunks, 47 s):
    // now tiles of at most BLOCK_BYTES, about n × 12 / 65536 chunks.
    for (w, h) in [
        (1usize, 1usize << 16),
        (3, 40_000),
        (1 << 20, 1),
        (200_000, 3),
    ] {
        let d = ramp_display(w, h);
        let mut buf = Cursor::new(Vec::new());
        vexr::write_display(&d, &mut buf).unwrap();
        let (chunks, blocks) = written_blocks(buf.get_ref());
        let bytes = w * h * 12;
        let most = bytes.div_ceil(vexr::BLOCK_BYTES) + h.max(w).div_ceil(5461);
        assert!(
            chunks <= most,
            "{w}x{h}: {chunks} chunks, expected ≤ {most}"
        );
        match blocks {
            BlockDescription::Tiles(t) => {
                assert!(
                    t.tile_size.0 * t.tile_size.1 * 12 <= vexr::BLOCK_BYTES,
                    "{w}x{h}"
                );
            }
            BlockDescription::ScanLines => panic!("{w}x{h} written in scan lines"),
        }
        assert_eq!(
            vexr::BlockLayout::for_image(w, h, 12).chunk_count(w, h),
            chunks
        );
        // Every pixel reads back (1.0 is 1 cd/m² of D65 white: compare Y).
        let back = decode(buf.get_ref());
        assert_eq!((back.width, back.height), (w, h));
        for i in [0, 1, w * h / 2, w * h - 1] {
            let rgb = [d.r[i], d.g[i], d.b[i]].map(f64::from);
            assert_xyz(&back, i, srgb_to_xyz(rgb), 2e-4);
        }
    }
    // The pathological sizes of the issue, by the layout alone (not written here).
    assert_eq!(
        vexr::BlockLayout::for_image(1, 4_194_304, 12).chunk_count(1, 4_194_304),
        769
    );
    assert!(vexr::BlockLayout::for_image(1, 1 << 27, 12).chunk_count(1, 1 << 27) < 25_000);
    // Ordinary images keep one scan line per chunk.
    for (w, h) in [(1920usize, 1080usize), (512, 512), (2, 2)] {
        let d = ramp_display(w, h);
        let mut buf = Cursor::new(Vec::new());
        vexr::write_display(&d, &mut buf).unwrap();
        assert_eq!(
            written_blocks(buf.get_ref()),
            (h, BlockDescription::ScanLines),
            "{w}x{h}"
        );
    }
}

#[test]
fn the_view_is_written_and_read_back() {
    use visadapt::{Projection, View};
    for view in [
        View::perspective(37.5, 40, 30),
        View::angular_fisheye(220.0, 40, 30),
    ] {
        let mut image = HdrImage::zeros(40, 30);
        image.y.fill(1.0);
        image.view = Some(view);
        let mut bytes = std::io::Cursor::new(Vec::new());
        visadapt::io::exr::write_hdr(&image, &mut bytes).unwrap();
        let back = visadapt::io::decode(bytes.get_ref(), &visadapt::Limits::default()).unwrap();
        let v = back.view.expect("the view is read back");
        assert_eq!(v.projection, view.projection);
        assert!((v.horizontal_deg - view.horizontal_deg).abs() < 1e-12);
        assert!((v.vertical_deg - view.vertical_deg).abs() < 1e-12);
    }
    assert_eq!(
        visadapt::io::radiance::view_options(&View {
            projection: Projection::Perspective,
            horizontal_deg: 60.0,
            vertical_deg: 35.5
        }),
        "-vtv -vh 60 -vv 35.5"
    );
    // Without a view, none is invented.
    let mut bytes = std::io::Cursor::new(Vec::new());
    let mut image = HdrImage::zeros(4, 4);
    image.y.fill(1.0);
    visadapt::io::exr::write_hdr(&image, &mut bytes).unwrap();
    let back = visadapt::io::decode(bytes.get_ref(), &visadapt::Limits::default()).unwrap();
    assert_eq!(back.view, None);
}

/// The block-parallel reader (each block's lines converted from f16 with the `half`
/// crate's slice conversion and to XYZ as they are copied out) against the exr crate's own
/// reading of the same file followed by the library's serial RGB → XYZ conversion, bit for
/// bit: every one of the 65536 f16 bit patterns (NaN, infinities, subnormals included) in
/// R, and shuffled in G and B, with a `whiteLuminance`, in scan-line blocks of 1, 16 and
/// 32 lines (both line orders, the data window offset) and in tiles.
#[test]
fn rgb_half_blocks_match_the_exr_crate_and_serial_conversion_bit_for_bit() {
    let (w, h) = (512usize, 128usize);
    let bits: Vec<u16> = (0..w * h).map(|i| i as u16).collect();
    let shuffled = |k: usize| -> Vec<f32> {
        (0..w * h)
            .map(|i| f16::from_bits(bits[(i * k + 12345) % (w * h)]).to_f32())
            .collect()
    };
    let r: Vec<f32> = bits.iter().map(|&b| f16::from_bits(b).to_f32()).collect();
    let (g, b) = (shuffled(40503), shuffled(257));
    for compression in [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
    ] {
        for (blocks, line_order) in [
            (Blocks::ScanLines, LineOrder::Increasing),
            (Blocks::ScanLines, LineOrder::Decreasing),
            (Blocks::Tiles(Vec2(64, 32)), LineOrder::Increasing),
        ] {
            let attributes = LayerAttributes {
                layer_position: Vec2(-7, 3),
                white_luminance: Some(179.0),
                ..LayerAttributes::default()
            };
            let bytes = write_with_exr_crate(
                (w, h),
                vec![
                    f16_channel("R", &r),
                    f16_channel("G", &g),
                    f16_channel("B", &b),
                ],
                Encoding {
                    compression,
                    blocks,
                    line_order,
                },
                attributes,
                None,
            );
            let img = decode(&bytes);
            let image = read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .first_valid_layer()
                .all_attributes()
                .from_buffered(Cursor::new(&bytes))
                .unwrap();
            let plane = |name: &str| -> Vec<f32> {
                let list = &image.layer_data.channel_data.list;
                let c = list.iter().find(|c| c.name == *name).unwrap();
                c.sample_data.values_as_f32().collect()
            };
            let (mut er, mut eg, mut eb) = (plane("R"), plane("G"), plane("B"));
            let m = visadapt::colour::REC709.rgb_to_xyz().unwrap();
            visadapt::colour::rgb_planes_to_xyz(&m, 179.0, &mut er, &mut eg, &mut eb);
            for (got, expected, name) in
                [(&img.x, &er, "X"), (&img.y, &eg, "Y"), (&img.z, &eb, "Z")]
            {
                // Bit for bit, except that any NaN matches any NaN: the vectorised
                // conversion may propagate the other operand's NaN payload (IEEE 754
                // leaves the choice open).
                for (i, (a, e)) in got.iter().zip(expected).enumerate() {
                    assert!(
                        a.to_bits() == e.to_bits() || (a.is_nan() && e.is_nan()),
                        "{compression:?} {blocks:?} {line_order:?} {name} pixel {i}: {a} vs {e}"
                    );
                }
            }
            assert!(img.absolute_units);
        }
    }
}
