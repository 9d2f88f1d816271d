//! The glare stage against the acuity blur it sits beside, at 1920×1080 and 3840×2160:
//! `glare::apply` (four planes: X, Y, Z and scotopic, splat, FFT convolution, read-back;
//! with a fresh workspace, as one `map` runs it, and with one kept from call to call, as
//! `video` runs it) and `blur::gaussian_blur_planes` (the operator's acuity stage on its
//! three display planes) at sigma 2 px, a night scene's acuity blur at 60° (Eq. 7 at
//! 0.01 cd/m²: ~0.06°, ~1.9 px at 1080p; the recursive blur's cost does not depend on
//! sigma). Both in the same run, so their ratio holds on a shared machine. Throughput is
//! in pixels.
//!
//! `cargo bench -p visadapt --bench glare -- --warm-up-time 1 --measurement-time 3`

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::blur::gaussian_blur_planes;
use visadapt::glare::{self, Glare};
use visadapt::{HdrImage, View};

/// A night street: a dim textured field with a pair of headlights of 1e5 cd/m².
fn night(w: usize, h: usize) -> HdrImage {
    let mut s = HdrImage::zeros(w, h);
    for k in 0..w * h {
        let (x, y) = (k % w, k / w);
        let texture = if (x / 4 + y / 4).is_multiple_of(2) {
            1.0
        } else {
            0.3
        };
        let lamp = [(w * 2 / 5, h / 2), (w * 3 / 5, h / 2)]
            .iter()
            .any(|(cx, cy)| x.abs_diff(*cx) < w / 400 + 1 && y.abs_diff(*cy) < w / 400 + 1);
        let l = if lamp { 1e5 } else { 0.02 * texture };
        s.x[k] = 0.9505 * l;
        s.y[k] = l;
        s.z[k] = 1.089 * l;
    }
    s
}

fn bench(c: &mut Criterion) {
    for (name, w, h) in [("1080p", 1920, 1080), ("4k", 3840, 2160)] {
        let mut group = c.benchmark_group(format!("glare_vs_acuity_{name}"));
        group.throughput(Throughput::Elements((w * h) as u64));
        group.sample_size(10);
        let scene = night(w, h);
        let view = View::perspective(60.0, w, h);
        group.bench_function(BenchmarkId::new("glare", "4 planes"), |b| {
            b.iter(|| glare::apply(black_box(&scene), &view, &Glare::default()).unwrap());
        });
        // As a video's frames run it: a workspace kept from call to call.
        let mut workspace = glare::Workspace::new();
        group.bench_function(BenchmarkId::new("glare, workspace kept", "4 planes"), |b| {
            b.iter(|| {
                let (retina, report) = workspace
                    .apply(black_box(&scene), &view, &Glare::default())
                    .unwrap();
                black_box((retina.y[0], report))
            });
        });
        let planes = [scene.x.clone(), scene.y.clone(), scene.z.clone()];
        group.bench_function(BenchmarkId::new("acuity blur", "3 planes"), |b| {
            b.iter_batched_ref(
                || planes.clone(),
                |[x, y, z]| gaussian_blur_planes(black_box(&mut [x, y, z]), w, h, 2.0),
                BatchSize::LargeInput,
            );
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
