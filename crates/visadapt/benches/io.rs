//! Decoding cost of the HDR input formats (`visadapt::io::decode` on a file held in
//! memory), on generated 1920×1080 frames. The ids are fixed so that figures can be
//! followed over time:
//!
//! * `io/decode/exr_zip16_half/1920x1080`: OpenEXR, RGB half floats, ZIP in blocks of 16
//!   lines (a renderer's usual output, the `video` bench's frames);
//! * `io/decode/exr_piz_half/1920x1080`: the same with PIZ (wavelet) compression;
//! * `io/decode/exr_zip16_half_tiled/1920x1080`: ZIP16 in 64×64 tiles (the copy-out on
//!   the calling thread);
//! * `io/decode/exr_rle_float/1920x1080`: X, Y, Z 32-bit floats, RLE (what
//!   `visadapt::io::exr::write_hdr` writes);
//! * `io/decode/hdr/1920x1080`: Radiance RGBE, run-length scanlines;
//! * `io/decode_into/…`: the same five, decoded into one image whose planes are reused
//!   (`visadapt::io::exr::decode_into`, `visadapt::io::radiance::decode_into`), as
//!   `visadapt video` reads its frames.
//!
//! Criterion reports pixels per second (one element a pixel).
//!
//! `cargo bench -p visadapt --bench io -- --warm-up-time 1 --measurement-time 3`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use visadapt::{DisplayImage, Limits};

const WIDTH: usize = 1920;
const HEIGHT: usize = 1080;

/// Linear Rec. 709 RGB at pixel (i, j), relative to the peak: smooth gradients times a
/// fine checker with a colour cast (as the `video` bench's first frame).
fn rgb(i: usize, j: usize) -> [f32; 3] {
    let u = i as f32 / WIDTH as f32;
    let v = j as f32 / HEIGHT as f32;
    let check = if (i / 4 + j / 4).is_multiple_of(2) {
        1.0
    } else {
        0.3
    };
    let l = (0.02 + 0.98 * (u * v)) * check;
    [l * (0.8 + 0.3 * v), l, l * (1.2 - 0.4 * u)]
}

/// Peak luminance, cd/m² (our choice: a bright interior).
const PEAK: f32 = 500.0;

/// An RGB half-float OpenEXR file in memory.
fn exr_half(compression: exr::prelude::Compression, tiles: bool) -> Vec<u8> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|Vec2(i, j): Vec2<usize>| {
        let [r, g, b] = rgb(i, j);
        (
            f16::from_f32(r * PEAK),
            f16::from_f32(g * PEAK),
            f16::from_f32(b * PEAK),
        )
    });
    let encoding = Encoding {
        compression,
        blocks: if tiles {
            Blocks::Tiles(Vec2(64, 64))
        } else {
            Blocks::ScanLines
        },
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        (WIDTH, HEIGHT),
        LayerAttributes::default(),
        encoding,
        channels,
    );
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .unwrap();
    out.into_inner()
}

/// The frame as a display image (RGB 1 = `PEAK` cd/m²).
fn display() -> DisplayImage {
    let mut im = DisplayImage {
        width: WIDTH,
        height: HEIGHT,
        r: vec![0.0; WIDTH * HEIGHT],
        g: vec![0.0; WIDTH * HEIGHT],
        b: vec![0.0; WIDTH * HEIGHT],
        display_max_cd_m2: PEAK,
    };
    for j in 0..HEIGHT {
        for i in 0..WIDTH {
            let [r, g, b] = rgb(i, j);
            let p = j * WIDTH + i;
            (im.r[p], im.g[p], im.b[p]) = (r, g, b);
        }
    }
    im
}

fn bench(c: &mut Criterion) {
    use exr::prelude::Compression;
    let limits = Limits::default();
    let size = format!("{WIDTH}x{HEIGHT}");
    let mut files: Vec<(&str, Vec<u8>)> = vec![
        ("exr_zip16_half", exr_half(Compression::ZIP16, false)),
        ("exr_piz_half", exr_half(Compression::PIZ, false)),
        ("exr_zip16_half_tiled", exr_half(Compression::ZIP16, true)),
    ];
    let im = display();
    // The same frame in the paper's X, Y, Z layout, with the sRGB → XYZ matrix of
    // IEC 61966-2-1 Eq. (F.7).
    let mut hdr = visadapt::HdrImage::zeros(WIDTH, HEIGHT);
    for p in 0..WIDTH * HEIGHT {
        let (r, g, b) = (im.r[p] * PEAK, im.g[p] * PEAK, im.b[p] * PEAK);
        hdr.x[p] = 0.4124 * r + 0.3576 * g + 0.1805 * b;
        hdr.y[p] = 0.2126 * r + 0.7152 * g + 0.0722 * b;
        hdr.z[p] = 0.0193 * r + 0.1192 * g + 0.9505 * b;
    }
    let mut rle = std::io::Cursor::new(Vec::new());
    visadapt::io::exr::write_hdr(&hdr, &mut rle).unwrap();
    files.push(("exr_rle_float", rle.into_inner()));
    let mut rgbe = Vec::new();
    visadapt::io::radiance::write_display(&im, &mut rgbe).unwrap();
    files.push(("hdr", rgbe));

    let mut group = c.benchmark_group("io/decode");
    group.sample_size(20);
    group.throughput(Throughput::Elements((WIDTH * HEIGHT) as u64));
    for (name, bytes) in &files {
        group.bench_function(BenchmarkId::new(*name, &size), |b| {
            b.iter(|| visadapt::io::decode(bytes, &limits).unwrap())
        });
    }
    group.finish();

    // The same files decoded into one image whose planes are reused from frame to frame,
    // as `visadapt video` does (`visadapt::io::read_into`).
    let mut group = c.benchmark_group("io/decode_into");
    group.sample_size(20);
    group.throughput(Throughput::Elements((WIDTH * HEIGHT) as u64));
    for (name, bytes) in &files {
        let mut image = visadapt::io::decode(bytes, &limits).unwrap();
        let decode_into: fn(&[u8], &Limits, &mut visadapt::HdrImage) -> visadapt::Result<()> =
            if *name == "hdr" {
                visadapt::io::radiance::decode_into
            } else {
                visadapt::io::exr::decode_into
            };
        group.bench_function(BenchmarkId::new(*name, &size), |b| {
            b.iter(|| decode_into(bytes, &limits, &mut image).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
