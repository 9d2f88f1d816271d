//! What one frame of the interactive viewer (`visadapt serve`) costs on a 1080p source
//! at a 1280-pixel preview, stage by stage, as the server runs them: a new light level
//! needs the scene rescaled and planned at full resolution; every frame needs the preview
//! rescaled, mapped (with the acuity blur at preview size) and encoded as PNG.
//!
//! `cargo bench -p visadapt --bench preview -- --warm-up-time 1 --measurement-time 3`

mod common;

use common::frame;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use visadapt::operator::{ViewingConditions, apply_into, plan};
use visadapt::{DisplayImage, HdrImage, View, preview};

fn bench(c: &mut Criterion) {
    let (w, h, pw) = (1920usize, 1080usize, 1280usize);
    let base = frame(w, h, 1.0);
    // Moonlight, 20° wide: the acuity blur is a few pixels, real work.
    let cond = ViewingConditions {
        view: Some(View::perspective(20.0, w, h)),
        ..ViewingConditions::default()
    };
    let mut g = c.benchmark_group("preview_1080p_to_1280");
    g.sample_size(20);

    let mut small = HdrImage::zeros(0, 0);
    g.bench_function("downsample (once per preview width)", |b| {
        b.iter(|| preview::downsample_into(black_box(&base), pw, &mut small).unwrap())
    });

    let factor = base.peak_factor(0.05, cond.hot_pixel_fraction).unwrap();
    let mut scaled = base.clone();
    g.bench_function("new level: peak_factor + rescale + plan at 1080p", |b| {
        b.iter(|| {
            let f = base.peak_factor(0.05, cond.hot_pixel_fraction).unwrap();
            scaled.clone_from(&base);
            scaled.scale(f as f32);
            plan(black_box(&scaled), &cond).unwrap()
        })
    });

    let report = plan(&scaled, &cond).unwrap();
    let mapping = preview::mapping_at_width(&report.mapping, w, pw);
    let mut lit = small.clone();
    let mut out = DisplayImage::default();
    let mut png = Vec::new();
    g.bench_function("frame: rescale preview + apply with blur + PNG", |b| {
        b.iter(|| {
            lit.clone_from(&small);
            lit.scale(factor as f32);
            apply_into(black_box(&lit), &mapping, &mut out);
            png.clear();
            visadapt::io::display::write_png(&out, 8, &mut png).unwrap();
        })
    });
    g.bench_function("frame: apply with blur alone", |b| {
        b.iter(|| apply_into(black_box(&lit), &mapping, &mut out))
    });
    g.bench_function("frame: PNG encode alone", |b| {
        b.iter(|| {
            png.clear();
            visadapt::io::display::write_png(black_box(&out), 8, &mut png).unwrap();
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
