//! Frames per second of the video pipeline, as `visadapt video` runs it: a generated
//! 1920×1080 sequence written to a temporary folder, read back by the decoder threads
//! ([`video::FileFrames`]), stepped through the time course and mapped with acuity
//! ([`video::Observer`]), and encoded as 8-bit PNG files into another folder by the
//! encoder threads ([`video::FileSink`]). Criterion reports frames per second (one element
//! a frame). The ids are fixed so that figures can be followed over time:
//!
//! * `frames/hdr/1920x1080`: Radiance RGBE frames (run-length scanlines, as the library
//!   and Radiance write them);
//! * `frames/exr/1920x1080`: OpenEXR frames, RGB half floats, ZIP compression in blocks
//!   of 16 lines (a renderer's usual output);
//! * `frames_two_threads_each/{hdr,exr}/1920x1080`: the same with two decoder and two
//!   encoder threads (the default is one each per two cores), for the ratio.
//!
//! The sequence is 8 frames: a textured scene at 500 cd/m² that drops to 5 cd/m² at the
//! fourth frame, so that the adaptation state changes from frame to frame.
//!
//! The bench installs the allocator the `visadapt` binary installs
//! ([`visadapt::pages::HugePages`]), so that each iteration runs on the planes the one
//! before freed, as a long video runs on the planes of its earlier frames. Before it was
//! installed here, every iteration's planes were fresh pages that the kernel cleared,
//! about 160 MiB per 8 frames: the figures rose 1.28–1.38× when it was, with no change
//! to the pipeline (docs/performance-log.md).
//!
//! `cargo bench -p visadapt --bench video -- --warm-up-time 1 --measurement-time 8`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::path::{Path, PathBuf};
use visadapt::io::OutputFormat;
use visadapt::io::display::PngCompression;
use visadapt::operator::ViewingConditions;
use visadapt::video::{self, FileFrames, FileSink, Observer, Threads};
use visadapt::{DisplayImage, HdrImage, Limits, View};

/// The allocator `visadapt video` installs, so that the pipeline's planes are reused from
/// one iteration to the next as they are from frame to frame.
#[global_allocator]
static ALLOCATOR: visadapt::pages::HugePages = visadapt::pages::HugePages;

const WIDTH: usize = 1920;
const HEIGHT: usize = 1080;
const FRAMES: usize = 8;
const FPS: f64 = 24.0;

/// Linear Rec. 709 RGB of frame `k` at pixel (i, j), relative to the frame's peak: smooth
/// gradients times a fine checker with a colour cast, drifting a little from frame to frame
/// (so that no two frames compress alike).
fn rgb(k: usize, i: usize, j: usize) -> [f32; 3] {
    let u = (i + 7 * k) as f32 / WIDTH as f32;
    let v = j as f32 / HEIGHT as f32;
    let check = if (i / 4 + j / 4).is_multiple_of(2) {
        1.0
    } else {
        0.3
    };
    let l = (0.02 + 0.98 * (u.fract() * v)) * check;
    [l * (0.8 + 0.3 * v), l, l * (1.2 - 0.4 * u.fract())]
}

/// The peak luminance of frame `k`, cd/m²: a drop of two decades at the fourth frame.
fn peak(k: usize) -> f32 {
    if k < FRAMES / 2 { 500.0 } else { 5.0 }
}

/// Write the sequence into `dir` as `f_NNN.hdr` or `f_NNN.exr`; returns the paths.
fn write_sequence(dir: &Path, ext: &str) -> Vec<PathBuf> {
    (0..FRAMES)
        .map(|k| {
            let path = dir.join(format!("f_{k:03}.{ext}"));
            let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            if ext == "hdr" {
                // The display writer's RGBE with EXPOSURE: RGB 1 reads as `peak` cd/m².
                let mut im = DisplayImage {
                    width: WIDTH,
                    height: HEIGHT,
                    r: vec![0.0; WIDTH * HEIGHT],
                    g: vec![0.0; WIDTH * HEIGHT],
                    b: vec![0.0; WIDTH * HEIGHT],
                    display_max_cd_m2: peak(k),
                };
                for j in 0..HEIGHT {
                    for i in 0..WIDTH {
                        let [r, g, b] = rgb(k, i, j);
                        let p = j * WIDTH + i;
                        (im.r[p], im.g[p], im.b[p]) = (r, g, b);
                    }
                }
                visadapt::io::radiance::write_display(&im, file).unwrap();
            } else {
                use exr::prelude::*;
                let l = peak(k);
                let channels = SpecificChannels::rgb(|Vec2(i, j): Vec2<usize>| {
                    let [r, g, b] = rgb(k, i, j);
                    (
                        f16::from_f32(r * l),
                        f16::from_f32(g * l),
                        f16::from_f32(b * l),
                    )
                });
                let layer = Layer::new(
                    (WIDTH, HEIGHT),
                    LayerAttributes::default(),
                    Encoding::SMALL_LOSSLESS,
                    channels,
                );
                Image::from_layer(layer).write().to_buffered(file).unwrap();
            }
            path
        })
        .collect()
}

/// The whole sequence through the pipeline: decode, time course and mapping, PNG files.
fn run_sequence(frames: &FileFrames, sink: &FileSink, threads: Threads) -> video::Timings {
    let conditions = ViewingConditions {
        view: Some(View::perspective(60.0, WIDTH, HEIGHT)),
        ..ViewingConditions::default()
    };
    let mut eye = Observer::new(conditions, FPS).unwrap();
    video::run(
        frames,
        |_, hdr: &mut HdrImage, out: &mut DisplayImage| eye.frame(hdr, out).map(|_| ()),
        sink,
        threads,
    )
    .unwrap()
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut group = c.benchmark_group("video");
    group.sample_size(10);
    group.throughput(Throughput::Elements(FRAMES as u64));
    let size = format!("{WIDTH}x{HEIGHT}");
    for ext in ["hdr", "exr"] {
        let input = dir.path().join(ext);
        let output = dir.path().join(format!("{ext}-out"));
        std::fs::create_dir_all(&input).unwrap();
        std::fs::create_dir_all(&output).unwrap();
        let frames = FileFrames::new(write_sequence(&input, ext), Limits::default());
        let outputs = (0..FRAMES)
            .map(|k| output.join(format!("f_{k:03}.png")))
            .collect();
        let sink = FileSink::new(
            outputs,
            OutputFormat::png(8).with_png_compression(PngCompression::Fdeflate),
        );
        let id = BenchmarkId::new(format!("frames/{ext}"), &size);
        group.bench_function(id, |b| {
            b.iter(|| run_sequence(&frames, &sink, Threads::default()))
        });
        let two = Threads {
            decoders: 2,
            encoders: 2,
        };
        let id = BenchmarkId::new(format!("frames_two_threads_each/{ext}"), &size);
        group.bench_function(id, |b| b.iter(|| run_sequence(&frames, &sink, two)));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
