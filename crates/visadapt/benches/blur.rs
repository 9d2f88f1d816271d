//! Throughput of `blur::gaussian_blur` (one plane) and `blur::gaussian_blur_planes`
//! (three planes) on a 1920×1080 HDR frame, for sigma 1 (exact kernel) and 4, 16, 64
//! (recursive filter). Throughput is in pixels, so criterion's Melem/s is Mpixel/s
//! (for three planes: pixels of the three-plane image).
//!
//! `cargo bench -p visadapt --bench blur -- --warm-up-time 1 --measurement-time 3`

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::blur::{gaussian_blur, gaussian_blur_planes};

const W: usize = 1920;
const H: usize = 1080;
const SIGMAS: [f32; 4] = [1.0, 4.0, 16.0, 64.0];

/// A frame with fine texture, gradients and a few 1e6 highlights on a dim background.
fn plane(seed: u32) -> Vec<f32> {
    (0..W * H)
        .map(|i| {
            let (x, y) = ((i % W) as f32, (i / W) as f32);
            let texture = if ((i % W) / 3 + (i / W) / 3 + seed as usize).is_multiple_of(2) {
                1.0
            } else {
                0.2
            };
            let highlight =
                if (x - 400.0 - 100.0 * seed as f32).abs() < 10.0 && (y - 300.0).abs() < 10.0 {
                    1e6
                } else {
                    0.0
                };
            1e-3 + 100.0 * (x / W as f32) * (y / H as f32) * texture + highlight
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("gaussian_blur_1080p");
    group.throughput(Throughput::Elements((W * H) as u64));
    let one = plane(0);
    let three = [plane(0), plane(1), plane(2)];
    for sigma in SIGMAS {
        group.bench_with_input(BenchmarkId::new("1 plane", sigma), &sigma, |b, &s| {
            b.iter_batched_ref(
                || one.clone(),
                |p| gaussian_blur(black_box(p), W, H, s),
                BatchSize::LargeInput,
            );
        });
        group.bench_with_input(BenchmarkId::new("3 planes", sigma), &sigma, |b, &s| {
            b.iter_batched_ref(
                || three.clone(),
                |[x, y, z]| gaussian_blur_planes(black_box(&mut [x, y, z]), W, H, s),
                BatchSize::LargeInput,
            );
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
