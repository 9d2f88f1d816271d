//! Per-frame cost of the time course on a 1920×1080 stream, reported by criterion as
//! pixels/s:
//!
//! * `stream_frame`: what `visadapt video` does per frame once the frame is decoded:
//!   `operator::plan` (the frame's world adaptation), `Adaptation::step_to`, the Eq. 8–9
//!   mapping, and `operator::apply_into` into a reused display image;
//! * `static_frame`: the same without the time course: `operator::plan` and
//!   `operator::apply_into` with the steady-state mapping (the difference to
//!   `stream_frame` is what the adaptation update costs);
//! * `static_map`: `operator::map` alone (plan + apply, allocating its output), the
//!   steady-state operator as a one-off call;
//! * `state_update`: the adaptation step and mapping alone, per frame (no pixels).
//!
//! The stream alternates between two frames a decade apart in luminance, so every frame
//! is a change of adaptation. Run with `cargo bench -p visadapt --bench timecourse`.

mod common;

use common::frame;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::operator::{self, ViewingConditions};
use visadapt::timecourse::Adaptation;

const WIDTH: usize = 1920;
const HEIGHT: usize = 1080;
const FPS: f64 = 30.0;

fn bench(c: &mut Criterion) {
    let frames = [frame(WIDTH, HEIGHT, 100.0), frame(WIDTH, HEIGHT, 1000.0)];
    let mut g = c.benchmark_group("timecourse");
    g.sample_size(20);
    g.throughput(Throughput::Elements((WIDTH * HEIGHT) as u64));
    for acuity in [false, true] {
        let cond = ViewingConditions {
            acuity,
            ..ViewingConditions::default()
        };
        let name = if acuity { "with_acuity" } else { "no_acuity" };
        let first = operator::plan(&frames[0], &cond).unwrap();
        let mut eye = Adaptation::adapted(
            first.world_adaptation_cd_m2,
            first.world_adaptation_scotopic_cd_m2,
        )
        .unwrap();
        let mut out = operator::apply(&frames[0], &first.mapping).0;
        let mut n = 0usize;
        g.bench_function(BenchmarkId::new("stream_frame", name), |b| {
            b.iter(|| {
                n += 1;
                let f = &frames[n % 2];
                let report = operator::plan(black_box(f), &cond).unwrap();
                eye.step_to(1.0 / FPS, &report).unwrap();
                let mapping = eye.mapping(&report);
                operator::apply_into(f, &mapping, &mut out);
                black_box(&out);
            })
        });
        g.bench_function(BenchmarkId::new("static_frame", name), |b| {
            b.iter(|| {
                n += 1;
                let f = &frames[n % 2];
                let report = operator::plan(black_box(f), &cond).unwrap();
                operator::apply_into(f, &report.mapping, &mut out);
                black_box(&out);
            })
        });
        g.bench_function(BenchmarkId::new("static_map", name), |b| {
            b.iter(|| {
                n += 1;
                black_box(operator::map(black_box(&frames[n % 2]), &cond).unwrap())
            })
        });
    }
    g.finish();

    // The state update alone, per frame.
    let reports = [
        operator::plan(&frames[0], &ViewingConditions::default()).unwrap(),
        operator::plan(&frames[1], &ViewingConditions::default()).unwrap(),
    ];
    let mut eye = Adaptation::adapted(
        reports[0].world_adaptation_cd_m2,
        reports[0].world_adaptation_scotopic_cd_m2,
    )
    .unwrap();
    let mut n = 0usize;
    let mut g = c.benchmark_group("timecourse");
    g.bench_function("state_update", |b| {
        b.iter(|| {
            n += 1;
            eye.step_to(1.0 / FPS, black_box(&reports[n % 2])).unwrap();
            black_box(eye.mapping(&reports[n % 2]))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
