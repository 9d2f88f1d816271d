//! PNG encoding of a mapped 1920×1080 frame, the last stage of `visadapt map` and of each
//! `visadapt video` frame. Criterion reports the time per frame (and megapixels per
//! second: one element a pixel). The ids are fixed so that figures can be followed over
//! time:
//!
//! * `encode/png/1920x1080/{fast,fastest,rle,fdeflate}`: [`write_png_with`] at 8 bits per
//!   channel, into a reused buffer (sRGB encoding, filtering and deflate in parallel row
//!   bands; for `fdeflate`, the compressor on one thread while the next rows are filtered);
//! * `encode/png16/1920x1080/fast`: the same at 16 bits per channel (`visadapt map
//!   --bits 16`);
//! * `encode/srgb8/1920x1080`: the sRGB transfer alone ([`to_srgb8`], interleaved 8-bit
//!   codes), for the share of the transfer in the above.
//!
//! The frame is a display image as the operator leaves it: smooth gradients, a fine
//! texture and a little noise, values slightly below 0 and above 1 (clipped by the
//! encoder), so that it compresses about as a mapped photograph does.
//!
//! `cargo bench -p visadapt --bench encode -- --warm-up-time 1 --measurement-time 5`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use visadapt::DisplayImage;
use visadapt::io::display::{PngCompression, to_srgb8, write_png_with};

const WIDTH: usize = 1920;
const HEIGHT: usize = 1080;

/// The frame: per channel a diagonal gradient, a 4-pixel checker on a third of the image
/// (fine texture), and on the right quarter a hash noise of ±0.1 % (sensor noise after mapping): 1.65 MB
/// as a `fast` PNG (the 24 frames of a 1080p office video are 0.3-0.9 MB each).
fn frame() -> DisplayImage {
    let n = WIDTH * HEIGHT;
    let value = |p: usize, k: u32| {
        let (i, j) = (p % WIDTH, p / WIDTH);
        let (u, v) = (i as f32 / WIDTH as f32, j as f32 / HEIGHT as f32);
        let smooth = 0.5 + 0.45 * ((3.0 * u + 2.0 * v + k as f32).sin() * (1.0 - 0.5 * v));
        let texture = if i > WIDTH / 3 && i < 2 * WIDTH / 3 && (i / 4 + j / 4) % 2 == 0 {
            0.15
        } else {
            0.0
        };
        let hash = (p as u32).wrapping_mul(2_654_435_761).wrapping_add(k * 97) >> 24;
        let noise = if i > 3 * WIDTH / 4 {
            (hash as f32 / 255.0 - 0.5) * 0.002
        } else {
            0.0
        };
        (smooth * smooth + texture + noise) * 1.05 - 0.01
    };
    DisplayImage {
        width: WIDTH,
        height: HEIGHT,
        r: (0..n).map(|p| value(p, 0)).collect(),
        g: (0..n).map(|p| value(p, 1)).collect(),
        b: (0..n).map(|p| value(p, 2)).collect(),
        display_max_cd_m2: 100.0,
    }
}

fn bench(c: &mut Criterion) {
    let image = frame();
    let size = format!("{WIDTH}x{HEIGHT}");
    let mut group = c.benchmark_group("encode");
    group.sample_size(20);
    group.throughput(Throughput::Elements((WIDTH * HEIGHT) as u64));
    let mut bytes = Vec::new();
    for (name, compression) in [
        ("fast", PngCompression::Fast),
        ("fastest", PngCompression::Fastest),
        ("rle", PngCompression::Rle),
        ("fdeflate", PngCompression::Fdeflate),
    ] {
        bytes.clear();
        write_png_with(&image, 8, compression, &mut bytes).unwrap();
        eprintln!("encode/png/{size}/{name}: {} bytes", bytes.len());
        let id = BenchmarkId::new(format!("png/{size}"), name);
        group.bench_function(id, |b| {
            b.iter(|| {
                bytes.clear();
                write_png_with(&image, 8, compression, &mut bytes).unwrap();
                bytes.len()
            })
        });
    }
    bytes.clear();
    write_png_with(&image, 16, PngCompression::Fast, &mut bytes).unwrap();
    eprintln!("encode/png16/{size}/fast: {} bytes", bytes.len());
    group.bench_function(BenchmarkId::new(format!("png16/{size}"), "fast"), |b| {
        b.iter(|| {
            bytes.clear();
            write_png_with(&image, 16, PngCompression::Fast, &mut bytes).unwrap();
            bytes.len()
        })
    });
    group.bench_function(BenchmarkId::new("srgb8", &size), |b| {
        b.iter(|| to_srgb8(&image).len())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
