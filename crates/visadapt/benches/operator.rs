//! Throughput of the whole steady-state operator (`operator::map`) on synthetic frames,
//! with and without the acuity blur, reported by criterion as pixels/s.
//!
//! `cargo bench -p visadapt --bench operator`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::operator::{ViewingConditions, apply_into, map, plan};
use visadapt::{HdrImage, View};

/// A textured HDR frame: smooth gradients times a fine checker, peak about `peak` cd/m²,
/// with a D65-like colour cast that varies over the frame.
fn frame(w: usize, h: usize, peak: f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    for j in 0..h {
        for i in 0..w {
            let k = j * w + i;
            let u = i as f32 / w as f32;
            let v = j as f32 / h as f32;
            let check = if (i / 4 + j / 4) % 2 == 0 { 1.0 } else { 0.3 };
            let l = peak * (0.05 + 0.95 * u * v) * check;
            im.x[k] = l * (0.8 + 0.3 * v);
            im.y[k] = l;
            im.z[k] = l * (1.2 - 0.4 * u);
        }
    }
    im.absolute_units = true;
    im
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("operator");
    g.sample_size(20);
    for (w, h) in [(1920usize, 1080usize), (3840, 2160)] {
        // Moonlight: sigma is a few pixels at this field of view, so the blur does real work.
        let im = frame(w, h, 0.1);
        g.throughput(Throughput::Elements((w * h) as u64));
        for acuity in [false, true] {
            let cond = ViewingConditions {
                acuity,
                view: Some(View::perspective(20.0, w, h)),
                ..ViewingConditions::default()
            };
            let name = if acuity { "with_acuity" } else { "no_acuity" };
            g.bench_with_input(BenchmarkId::new(name, format!("{w}x{h}")), &im, |b, im| {
                b.iter(|| map(black_box(im), &cond).unwrap())
            });
            // The two stages alone, the second writing into reused buffers as a video
            // loop does (no allocation, no page faults per frame).
            let stage = format!("{name}_stages");
            g.bench_with_input(
                BenchmarkId::new(format!("{stage}/plan"), format!("{w}x{h}")),
                &im,
                |b, im| b.iter(|| plan(black_box(im), &cond).unwrap()),
            );
            let report = plan(&im, &cond).unwrap();
            let mut out = map(&im, &cond).unwrap().image;
            g.bench_with_input(
                BenchmarkId::new(format!("{stage}/apply_into"), format!("{w}x{h}")),
                &im,
                |b, im| b.iter(|| apply_into(black_box(im), &report.mapping, &mut out)),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
