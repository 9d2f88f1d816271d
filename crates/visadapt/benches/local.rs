//! Local adaptation against the global operator, in the same run (criterion, pixels/s):
//!
//! * `local_vs_global/global/WxH`: `plan` + `apply_into` with the acuity blur (the paper's
//!   operator as a video loop runs it, buffers reused);
//! * `local_vs_global/local/WxH`: `plan`, the adaptation map, the per-pixel tables and
//!   `local::apply_into` with the per-pixel acuity blur, buffers reused;
//! * `radius/R/1920x1080`: the local operator at radii of 0.25 to 16 degrees;
//! * `local_stages/S/1920x1080`: its stages one by one at 1°, buffers reused: `map` (the
//!   adaptation map), `tables` (the per-pixel coefficient tables), `mapping` (the mapping
//!   pass and clipping, the map's acuity sigmas left out) and `apply` (the mapping pass,
//!   the spatially varying acuity blur and clipping); `apply` − `mapping` is the blur.
//!
//! The frame spans four log units (0.01 to 100 cd/m², a dusk scene), so the local levels,
//! rod weights and blur sigmas vary over it, seen at 20 degrees as in the operator bench.
//!
//! `cargo bench -p visadapt --bench local -- --warm-up-time 1 --measurement-time 3`

mod common;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::local::{self, AdaptationMap, LocalAdaptation, LocalMapping};
use visadapt::operator::{
    AdaptationMode, ViewingConditions, apply_into, local_map, local_map_into, plan,
};
use visadapt::{DisplayImage, HdrImage, View};

/// Four log units left to right, a fine checker, a colour cast varying over the frame.
fn frame(w: usize, h: usize) -> HdrImage {
    common::textured(w, h, |u, v| 100.0 * 10f32.powf(-4.0 * u) * (0.5 + 0.5 * v))
}

fn conditions(w: usize, h: usize, adaptation: AdaptationMode) -> ViewingConditions {
    ViewingConditions {
        acuity: true,
        view: Some(View::perspective(20.0, w, h)),
        adaptation,
        ..ViewingConditions::default()
    }
}

/// The local operator on a frame in steady state: the map's planes and the display are
/// reused from the frame before (as a video's frames reuse them), as the global
/// operator's bench reuses its display.
fn run_local(
    im: &HdrImage,
    cond: &ViewingConditions,
    map: &mut AdaptationMap,
    out: &mut DisplayImage,
) {
    let AdaptationMode::Local(options) = cond.adaptation else {
        unreachable!("local conditions")
    };
    let report = plan(im, cond).expect("plan");
    local_map_into(im, &report, cond, &options, map).expect("map");
    let mapping = LocalMapping::steady_state(map, &report, options.rod_saturation);
    black_box(local::apply_into(im, map, &mapping, out));
}

fn bench(c: &mut Criterion) {
    let local_mode = AdaptationMode::Local(LocalAdaptation::default());
    let mut group = c.benchmark_group("local_vs_global");
    group.sample_size(10);
    for (w, h) in [(1920, 1080), (3840, 2160)] {
        let im = frame(w, h);
        let size = format!("{w}x{h}");
        group.throughput(Throughput::Elements((w * h) as u64));
        let global = conditions(w, h, AdaptationMode::Global);
        let mut out = DisplayImage::default();
        group.bench_function(BenchmarkId::new("global", &size), |b| {
            b.iter(|| {
                let r = plan(&im, &global).expect("plan");
                black_box(apply_into(&im, &r.mapping, &mut out));
            })
        });
        let local = conditions(w, h, local_mode);
        let mut map = AdaptationMap::default();
        group.bench_function(BenchmarkId::new("local", &size), |b| {
            b.iter(|| run_local(&im, &local, &mut map, &mut out))
        });
    }
    group.finish();

    let mut group = c.benchmark_group("radius");
    group.sample_size(10);
    let (w, h) = (1920, 1080);
    let im = frame(w, h);
    group.throughput(Throughput::Elements((w * h) as u64));
    let mut out = DisplayImage::default();
    let mut map = AdaptationMap::default();
    for radius in [0.25, 1.0, 4.0, 16.0] {
        let cond = conditions(
            w,
            h,
            AdaptationMode::Local(LocalAdaptation {
                radius_deg: radius,
                ..LocalAdaptation::default()
            }),
        );
        group.bench_function(BenchmarkId::new(format!("{radius}"), "1920x1080"), |b| {
            b.iter(|| run_local(&im, &cond, &mut map, &mut out))
        });
    }
    group.finish();
}

fn stages(c: &mut Criterion) {
    let mut group = c.benchmark_group("local_stages");
    group.sample_size(10);
    let (w, h) = (1920, 1080);
    let size = format!("{w}x{h}");
    let im = frame(w, h);
    group.throughput(Throughput::Elements((w * h) as u64));
    let cond = conditions(w, h, AdaptationMode::Local(LocalAdaptation::default()));
    let AdaptationMode::Local(options) = cond.adaptation else {
        unreachable!("local conditions")
    };
    let report = plan(&im, &cond).expect("plan");
    let mut kept = AdaptationMap::default();
    group.bench_function(BenchmarkId::new("map", &size), |b| {
        b.iter(|| {
            local_map_into(&im, &report, &cond, &options, &mut kept).expect("map");
            black_box(&kept);
        })
    });
    let map = local_map(&im, &report, &cond, &options).expect("map");
    group.bench_function(BenchmarkId::new("tables", &size), |b| {
        b.iter(|| {
            black_box(LocalMapping::steady_state(
                &map,
                &report,
                options.rod_saturation,
            ))
        })
    });
    let mapping = LocalMapping::steady_state(&map, &report, options.rod_saturation);
    let mut out = DisplayImage::default();
    let unblurred = local::AdaptationMap {
        acuity_sigma_px: None,
        ..map.clone()
    };
    group.bench_function(BenchmarkId::new("mapping", &size), |b| {
        b.iter(|| black_box(local::apply_into(&im, &unblurred, &mapping, &mut out)))
    });
    group.bench_function(BenchmarkId::new("apply", &size), |b| {
        b.iter(|| black_box(local::apply_into(&im, &map, &mapping, &mut out)))
    });
    group.finish();
}

criterion_group!(benches, bench, stages);
criterion_main!(benches);
