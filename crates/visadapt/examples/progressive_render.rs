//! A progressive Monte Carlo renderer that stops when its remaining noise is invisible.
//!
//! Ferwerda et al. 1996 (abstract, Sec. 6) propose their model "as the basis of
//! perceptually-based error metrics for limiting the precision of global illumination
//! computations". This example renders a scene whose exact radiance is known, at daylight,
//! dusk, moonlight and starlight levels, and compares two stopping rules:
//!
//! * **perceptual**: double the samples per pixel until the estimate after `2N` samples is
//!   indistinguishable from the one after `N` for an observer adapted to the scene
//!   ([`visibility::converged`]: every pixel under 1 JND, Eq. 4–7). The difference of the
//!   two estimates has the standard deviation of the error of the `2N` one, so this asks
//!   whether the remaining noise is visible;
//! * **fixed precision**: double until every pixel's relative standard error (estimated
//!   from its samples) is at most 1 %.
//!
//! The scene: a floor 4 m × 2.67 m, a checkerboard of 0.25 m squares of albedo 0.7 and
//! 0.15, lit by a 1 m × 0.5 m diffuse area light 0.8 m above its centre, seen from above;
//! the picture (240 × 160 pixels) spans 30° of the observer's view. Light and floor are
//! equal-energy white (X = Y = Z, scotopic = 2.261·Y). The estimator samples the light's
//! area uniformly; the exact irradiance comes from Lambert's formula for a polygonal
//! source. The four levels use the same random numbers, so their noise is the same
//! relative to the signal: only the observer changes.
//!
//! Run with `cargo run --release --example progressive_render [-- OUT_DIR]`. With a
//! directory, it also writes, per level, the exact picture and the estimate after
//! [`SNAPSHOT_SPP`] samples per pixel as OpenEXR (X, Y, Z, scotopic in cd/m²), for
//! `visadapt visible exact-daylight.exr estimate-daylight.exr --fov 30 -o jnd.png`.

use std::f64::consts::PI;
use visadapt::adaptation::highest_visible;
use visadapt::operator::ViewingConditions;
use visadapt::scotopic::EQUAL_ENERGY_SP_RATIO;
use visadapt::visibility::{self, Viewer};
use visadapt::{HdrImage, View, io};

/// Picture size, pixels.
const WIDTH: usize = 240;
const HEIGHT: usize = 160;
/// Horizontal field of view of the picture at the observer's eye, degrees.
const FOV_DEG: f64 = 30.0;
/// Floor half-extent along x, metres (y follows from the aspect ratio).
const FLOOR_HALF_X: f64 = 2.0;
/// Checkerboard square, metres, and the two albedos.
const SQUARE: f64 = 0.25;
const ALBEDO: [f64; 2] = [0.7, 0.15];
/// The light: a rectangle centred above the origin, facing down.
const LIGHT_HALF: [f64; 2] = [0.5, 0.25];
const LIGHT_HEIGHT: f64 = 0.8;
/// Samples per pixel of the first pass, and the most the loop will take.
const FIRST_PASS: u32 = 4;
const MAX_SAMPLES: u32 = 1 << 16;
/// Samples per pixel of the estimate written with `OUT_DIR`.
const SNAPSHOT_SPP: u32 = 16;
/// The fixed-precision rule: relative standard error of every pixel.
const FIXED_RELATIVE_ERROR: f64 = 0.01;

/// The light levels: highest visible luminance of the picture, cd/m² (the paper's Fig. 11
/// uses 1000, 10, 0.04 and 0.001).
const LEVELS: [(&str, f64); 4] = [
    ("daylight", 1000.0),
    ("dusk", 1.0),
    ("moonlight", 0.04),
    ("starlight", 0.001),
];

fn main() -> std::process::ExitCode {
    // Errors in a sentence (Display), not a Debug dump.
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("progressive_render: error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), visadapt::Error> {
    let scene = Scene::new();
    // Exact radiance for a light of unit radiance; each level scales the light so that the
    // picture's highest visible luminance (Sec. 4.4's quantile) is the level.
    let exact_unit = scene.exact();
    let hv_unit = highest_visible(
        &exact_unit,
        visadapt::adaptation::DEFAULT_HOT_PIXEL_FRACTION,
    ) as f64;
    let conditions = ViewingConditions {
        view: Some(View::perspective(FOV_DEG, WIDTH, HEIGHT)),
        ..ViewingConditions::default()
    };
    let out_dir = std::env::args_os().nth(1).map(std::path::PathBuf::from);
    // The folder is made before minutes of work, not found missing after them.
    if let Some(dir) = &out_dir {
        std::fs::create_dir_all(dir).map_err(|e| {
            visadapt::Error::Io(std::io::Error::new(
                e.kind(),
                format!("{}: cannot create the output folder: {e}", dir.display()),
            ))
        })?;
    }

    println!(
        "{:<10} {:>10} {:>10} | {:>10} {:>9} | {:>9} {:>7} | true error at the perceptual stop",
        "level", "peak cd/m²", "adapted to", "perceptual", "rel. err.", "1 % rule", "ratio",
    );
    for (name, peak) in LEVELS {
        let light = peak / hv_unit;
        let exact = image(
            &exact_unit
                .iter()
                .map(|l| l * light as f32)
                .collect::<Vec<_>>(),
        );
        let run = scene.progressive(light, &conditions)?;
        let (viewer, report) = Viewer::for_image(&exact, &conditions)?;
        let true_error = visibility::difference(&exact, &run.perceptual_image, &viewer)?;
        if let Some(dir) = &out_dir {
            for (file, picture) in [("exact", &exact), ("estimate", &run.snapshot)] {
                let path = dir.join(format!("{file}-{name}.exr"));
                io::display::write_atomically(&path, |w| io::exr::write_hdr(picture, w))?;
            }
        }
        println!(
            "{:<10} {:>10} {:>10} | {:>6} spp {:>8.1} % | {:>5} spp {:>6.0}x | max {:.2} JND, {:.2} % of pixels visible",
            name,
            peak,
            four_significant(report.world_adaptation_cd_m2),
            run.perceptual_spp,
            100.0 * run.perceptual_max_relative_error,
            run.fixed_spp,
            run.fixed_spp as f64 / run.perceptual_spp as f64,
            true_error.max_jnd,
            100.0 * true_error.visible_fraction,
        );
    }
    println!(
        "\nperceptual: stop when the estimates after N and 2N samples differ by under 1 JND everywhere;\n\
         rel. err.: the largest relative standard error of any pixel when it stops;\n\
         1 % rule: stop when every pixel's relative standard error is at most 1 %;\n\
         true error: the perceptual estimate against the exact image, for the same observer."
    );
    Ok(())
}

/// `x` with four significant digits.
fn four_significant(x: f64) -> String {
    let decimals = (3 - x.log10().floor() as i32).max(0) as usize;
    format!("{x:.decimals$}")
}

/// An equal-energy white image from a luminance plane.
fn image(y: &[f32]) -> HdrImage {
    let mut im = HdrImage::zeros(WIDTH, HEIGHT);
    im.x.copy_from_slice(y);
    im.y.copy_from_slice(y);
    im.z.copy_from_slice(y);
    im.scotopic = Some(y.iter().map(|v| v * EQUAL_ENERGY_SP_RATIO as f32).collect());
    im.absolute_units = true;
    im
}

/// What one progressive run found.
struct Run {
    /// Samples per pixel when the perceptual rule stopped.
    perceptual_spp: u32,
    /// The estimate it stopped with.
    perceptual_image: HdrImage,
    /// Largest relative standard error of any pixel at that point.
    perceptual_max_relative_error: f64,
    /// Samples per pixel when the 1 % rule stopped.
    fixed_spp: u32,
    /// The estimate after [`SNAPSHOT_SPP`] samples per pixel.
    snapshot: HdrImage,
}

/// The floor and the light.
struct Scene {
    /// Floor point of each pixel centre, metres.
    points: Vec<[f64; 2]>,
    /// Albedo of each pixel.
    albedo: Vec<f64>,
}

impl Scene {
    fn new() -> Self {
        let half_y = FLOOR_HALF_X * HEIGHT as f64 / WIDTH as f64;
        let mut points = Vec::with_capacity(WIDTH * HEIGHT);
        let mut albedo = Vec::with_capacity(WIDTH * HEIGHT);
        for j in 0..HEIGHT {
            for i in 0..WIDTH {
                let x = -FLOOR_HALF_X + (i as f64 + 0.5) / WIDTH as f64 * 2.0 * FLOOR_HALF_X;
                let y = half_y - (j as f64 + 0.5) / HEIGHT as f64 * 2.0 * half_y;
                let parity = ((x / SQUARE).floor() + (y / SQUARE).floor()) as i64;
                points.push([x, y]);
                albedo.push(ALBEDO[parity.rem_euclid(2) as usize]);
            }
        }
        Scene { points, albedo }
    }

    /// Exact luminance (cd/m²) for a light of radiance 1: `ρ/π · E`, with the irradiance
    /// `E` of a uniform polygonal source by Lambert's formula,
    /// `E = L/2 · Σ Θ_i (n · Γ_i)` over the polygon's edges as seen from the point.
    fn exact(&self) -> Vec<f32> {
        let [hx, hy] = LIGHT_HALF;
        let corners = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]];
        self.points
            .iter()
            .zip(&self.albedo)
            .map(|(p, rho)| {
                let v: Vec<[f64; 3]> = corners
                    .iter()
                    .map(|c| normalize([c[0] - p[0], c[1] - p[1], LIGHT_HEIGHT]))
                    .collect();
                let mut sum = 0.0;
                for k in 0..4 {
                    let (a, b) = (v[k], v[(k + 1) % 4]);
                    let theta = dot(a, b).clamp(-1.0, 1.0).acos();
                    let g = normalize(cross(a, b));
                    sum += theta * g[2]; // n = +z, the floor's normal
                }
                (rho / PI * 0.5 * sum.abs()) as f32
            })
            .collect()
    }

    /// Render progressively with a light of radiance `light` (cd/m²), doubling the samples
    /// until both stopping rules have fired.
    fn progressive(
        &self,
        light: f64,
        conditions: &ViewingConditions,
    ) -> Result<Run, visadapt::Error> {
        let n = self.points.len();
        let area = 4.0 * LIGHT_HALF[0] * LIGHT_HALF[1];
        // Per pixel: sum and sum of squares of the luminance samples, and a random stream.
        let mut sum = vec![0f64; n];
        let mut sum_sq = vec![0f64; n];
        let mut rng: Vec<Rng> = (0..n as u64).map(Rng::new).collect();
        let mut samples = 0u32;
        let mut previous: Option<HdrImage> = None;
        let mut perceptual = None;
        let mut fixed_spp = None;
        let mut snapshot = None;
        while samples < MAX_SAMPLES && (perceptual.is_none() || fixed_spp.is_none()) {
            let pass = if samples == 0 { FIRST_PASS } else { samples };
            for (k, (p, rho)) in self.points.iter().zip(&self.albedo).enumerate() {
                let r = &mut rng[k];
                let scale = rho / PI * light * area * LIGHT_HEIGHT * LIGHT_HEIGHT;
                for _ in 0..pass {
                    // A uniform point on the light; cos θ at both ends is h/r.
                    let qx = (2.0 * r.uniform() - 1.0) * LIGHT_HALF[0];
                    let qy = (2.0 * r.uniform() - 1.0) * LIGHT_HALF[1];
                    let r2 =
                        (qx - p[0]).powi(2) + (qy - p[1]).powi(2) + LIGHT_HEIGHT * LIGHT_HEIGHT;
                    let l = scale / (r2 * r2);
                    sum[k] += l;
                    sum_sq[k] += l * l;
                }
            }
            samples += pass;
            let m = samples as f64;
            let mean: Vec<f32> = sum.iter().map(|s| (s / m) as f32).collect();
            let current = image(&mean);
            let max_relative = sum
                .iter()
                .zip(&sum_sq)
                .map(|(s, q)| {
                    let mu = s / m;
                    let var = ((q / m - mu * mu) * m / (m - 1.0)).max(0.0);
                    (var / m).sqrt() / mu
                })
                .fold(0f64, f64::max);

            if perceptual.is_none()
                && let Some(prev) = &previous
            {
                let (viewer, _) = Viewer::for_image(&current, conditions)?;
                if visibility::converged(prev, &current, &viewer)? {
                    perceptual = Some((samples, current.clone(), max_relative));
                }
            }
            if fixed_spp.is_none() && max_relative <= FIXED_RELATIVE_ERROR {
                fixed_spp = Some(samples);
            }
            if samples == SNAPSHOT_SPP {
                snapshot = Some(current.clone());
            }
            previous = Some(current);
        }
        let (perceptual_spp, perceptual_image, max_rel) = perceptual.unwrap_or_else(|| {
            (
                samples,
                previous.clone().expect("at least one pass"),
                f64::NAN,
            )
        });
        Ok(Run {
            perceptual_spp,
            perceptual_image,
            perceptual_max_relative_error: max_rel,
            fixed_spp: fixed_spp.unwrap_or(samples),
            snapshot: snapshot.expect("the loop passes the snapshot's sample count"),
        })
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

/// xorshift64* (Vigna 2016), seeded per pixel through SplitMix64 so the streams differ.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        Rng((z ^ (z >> 31)) | 1)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}
