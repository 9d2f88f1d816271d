//! Throughput of the steady-state operator on synthetic frames, reported by criterion as
//! pixels/s. The ids are fixed so that figures can be followed over time:
//!
//! * `full/1920x1080`, `full/3840x2160`: the whole operator with acuity as a video loop
//!   runs it: `plan` (adaptation quantiles, scale factors, blur size), then `apply_into`
//!   (mapping, acuity blur, clip) into reused buffers;
//! * `stages/plan/1920x1080`, `stages/apply/1920x1080`, `stages/blur/1920x1080`: the
//!   stages alone (`stages/blur` is the three-plane acuity Gaussian at the frame's sigma);
//!   the same at `3840x2160`, where the kernel is twice as wide;
//! * `memory_floor/1920x1080` (and `3840x2160`): one streaming pass that reads four f32
//!   planes and writes three (split over the same thread pool), the physical floor for
//!   one trip through memory, against which the others are read as ratios;
//! * `map_allocating/1920x1080`: `operator::map`, a one-off call that allocates its
//!   output (the difference to `full` is the first touch of fresh memory).
//!
//! `cargo bench -p visadapt --bench operator -- --warm-up-time 1 --measurement-time 3`

mod common;

use common::frame;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::blur::gaussian_blur_planes;
use visadapt::operator::{ViewingConditions, apply_into, map, plan};
use visadapt::{DisplayImage, HdrImage, View};

/// Moonlight: sigma is a few pixels at this field of view, so the blur does real work.
fn conditions(w: usize, h: usize) -> ViewingConditions {
    ViewingConditions {
        acuity: true,
        view: Some(View::perspective(20.0, w, h)),
        ..ViewingConditions::default()
    }
}

/// Samples per parallel work item of the floor pass (as the operator's passes).
const CHUNK: usize = 1 << 15;

/// Read four planes, write three: `out_c = in_c · a + in_s · b`, an affine map as cheap
/// as arithmetic gets, so that its time is the memory traffic.
fn memory_floor(im: &HdrImage, s: &[f32], out: &mut DisplayImage) {
    use rayon::prelude::*;
    let DisplayImage { r, g, b, .. } = out;
    r.par_chunks_mut(CHUNK)
        .zip(g.par_chunks_mut(CHUNK))
        .zip(b.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(i, ((r, g), b))| {
            let o = i * CHUNK;
            let n = r.len();
            let (x, y, z, s) = (
                &im.x[o..o + n],
                &im.y[o..o + n],
                &im.z[o..o + n],
                &s[o..o + n],
            );
            for k in 0..n {
                r[k] = x[k] * 0.5 + s[k] * 0.25;
                g[k] = y[k] * 0.5 + s[k] * 0.25;
                b[k] = z[k] * 0.5 + s[k] * 0.25;
            }
        });
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("operator");
    g.sample_size(20);
    for (w, h) in [(1920usize, 1080usize), (3840, 2160)] {
        let size = format!("{w}x{h}");
        let im = frame(w, h, 0.1);
        let cond = conditions(w, h);
        g.throughput(Throughput::Elements((w * h) as u64));
        let mut out = map(&im, &cond).unwrap().image;
        g.bench_with_input(BenchmarkId::new("full", &size), &im, |b, im| {
            b.iter(|| {
                let report = plan(black_box(im), &cond).unwrap();
                apply_into(im, &report.mapping, &mut out)
            })
        });
        g.bench_with_input(BenchmarkId::new("stages/plan", &size), &im, |b, im| {
            b.iter(|| plan(black_box(im), &cond).unwrap())
        });
        let report = plan(&im, &cond).unwrap();
        g.bench_with_input(BenchmarkId::new("stages/apply", &size), &im, |b, im| {
            b.iter(|| apply_into(black_box(im), &report.mapping, &mut out))
        });
        let sigma = report.mapping.blur_sigma_px as f32;
        g.bench_function(BenchmarkId::new("stages/blur", &size), |b| {
            b.iter(|| {
                let DisplayImage { r, g, b, .. } = &mut out;
                gaussian_blur_planes(&mut [r, g, b], w, h, black_box(sigma))
            })
        });
        let s: Vec<f32> = im.y.iter().map(|v| v * 2.0).collect();
        g.bench_with_input(BenchmarkId::new("memory_floor", &size), &im, |b, im| {
            b.iter(|| memory_floor(black_box(im), &s, &mut out))
        });
        if w == 1920 {
            g.bench_with_input(BenchmarkId::new("map_allocating", &size), &im, |b, im| {
                b.iter(|| map(black_box(im), &cond).unwrap())
            });
        }
        println!(
            "operator bench: blur sigma {sigma:.2} px at {size} (moonlight, 20° field of view)"
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
