//! Visibility predictions against values computed independently from the paper's equations.

mod common;

use common::{tp, ts};
use visadapt::local::AdaptationMap;
use visadapt::operator::ViewingConditions;
use visadapt::visibility::{Adaptation, Sensitivity, Viewer, converged, difference, tolerance_map};
use visadapt::{HdrImage, Limits, Projection, View, io};

/// Scotopic/photopic ratio of equal-energy white (1700·∫V'/(683·∫V)).
const SP_WHITE: f32 = 2.261;

/// SplitMix64: a small deterministic generator for test noise.
struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1).
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn sign(&mut self) -> f64 {
        if self.next_u64() & 1 == 0 { 1.0 } else { -1.0 }
    }
    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// A uniform equal-energy grey field at `l` cd/m² with its scotopic channel.
fn grey(w: usize, h: usize, l: f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    im.x.fill(l);
    im.y.fill(l);
    im.z.fill(l);
    im.scotopic = Some(vec![SP_WHITE * l; w * h]);
    im.absolute_units = true;
    im
}

/// A textured scene whose brightest patches are at `peak` cd/m²: 8×8 blocks at 100 %, 85 %
/// and 70 % of the peak, in two colours: equal-energy white (S/P 2.261) and the ColorChecker
/// blue patch under illuminant E (S/P 5.66; XYZ and S/P as in `scotopic.rs`).
fn scene(w: usize, h: usize, peak: f32) -> HdrImage {
    let colours: [([f32; 3], f32); 2] = [
        ([1.0, 1.0, 1.0], SP_WHITE),
        ([0.082_13 / 0.060_03, 1.0, 0.271_97 / 0.060_03], 5.66),
    ];
    let levels = [1.0f32, 0.85, 0.7];
    let mut im = HdrImage::zeros(w, h);
    let mut s = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let (bx, by) = (x / 8, y / 8);
            let (xyz, sp) = colours[(bx + by) % 2];
            let l = peak * levels[(bx / 2 + by) % 3];
            let i = y * w + x;
            im.x[i] = xyz[0] * l;
            im.y[i] = l;
            im.z[i] = xyz[2] * l;
            s[i] = sp * l;
        }
    }
    im.scotopic = Some(s);
    im.absolute_units = true;
    im
}

/// Change pixel `i`'s luminance by `delta_y` cd/m² in its own colour.
fn perturb(im: &mut HdrImage, i: usize, delta_y: f64) {
    let f = ((im.y[i] as f64 + delta_y) / im.y[i] as f64) as f32;
    im.x[i] *= f;
    im.y[i] *= f;
    im.z[i] *= f;
    if let Some(s) = &mut im.scotopic {
        s[i] *= f;
    }
}

fn no_acuity() -> ViewingConditions {
    ViewingConditions {
        acuity: false,
        ..ViewingConditions::default()
    }
}

#[test]
fn identical_images_show_nothing() {
    let photo = io::read(&common::data("mixtex.hdr"), &Limits::default()).unwrap();
    for peak in [1e3f32, 1.0, 1e-3] {
        let mut scaled = photo.clone();
        scaled.scale(peak / visadapt::adaptation::highest_visible(&photo.y, 1e-3));
        for image in [scene(96, 64, peak), scaled] {
            let (viewer, _) = Viewer::for_image(&image, &ViewingConditions::default()).unwrap();
            let d = difference(&image, &image, &viewer).unwrap();
            assert_eq!(d.max_jnd, 0.0);
            assert_eq!(d.mean_jnd, 0.0);
            assert_eq!(d.visible_fraction, 0.0);
            assert!(d.jnd.iter().all(|&v| v == 0.0));
            assert!(d.is_invisible());
            assert!(converged(&image, &image, &viewer).unwrap());
        }
    }
}

/// The tolerance map against Eq. 4–6 computed by hand, for one pixel colour at a time.
#[test]
fn tolerance_map_matches_hand_computed_thresholds() {
    // Daylight: a uniform 100 cd/m² field adapts the observer to 50 cd/m² (Sec. 4.4), k = 0:
    // T = t_p(50) = 10^((0.249·log 50 + 0.65)^2.7 − 0.72) = 3.0878 cd/m².
    let day = grey(16, 16, 100.0);
    let (viewer, report) = Viewer::for_image(&day, &no_acuity()).unwrap();
    assert!((report.world_adaptation_cd_m2 - 50.0).abs() < 1e-3);
    let t = tolerance_map(&day, &viewer).unwrap();
    assert!((tp(50.0) - 3.087_8).abs() < 1e-3);
    assert!(
        t.iter().all(|&v| (v as f64 / tp(50.0) - 1.0).abs() < 1e-5),
        "{}",
        t[0]
    );

    // Starlight: 0.002 cd/m² field, adapted to 0.001 cd/m² and 0.002261 scotopic cd/m², k = 1.
    // White: rods, T = t_s(0.002261)/2.261 pooled with the cones' 1/t_p(0.001) (negligible).
    let night = grey(16, 16, 0.002);
    let (viewer, report) = Viewer::for_image(&night, &no_acuity()).unwrap();
    assert!((report.world_adaptation_scotopic_cd_m2 - 0.002_261).abs() < 1e-8);
    let t = tolerance_map(&night, &viewer).unwrap()[0] as f64;
    let (a, b) = (1.0 / tp(0.001), 2.261 / ts(0.002_261));
    let expected = 1.0 / (a.powf(3.5) + b.powf(3.5)).powf(1.0 / 3.5);
    assert!((t / expected - 1.0).abs() < 1e-4, "{t} vs {expected}");
    assert!((expected - 1.083_2e-3).abs() < 1e-6);
    // The same field made of a red with no scotopic signal: only the cones, 10^-0.72.
    let mut red = night.clone();
    red.scotopic = Some(vec![0.0; 256]);
    let t = tolerance_map(&red, &viewer).unwrap()[0] as f64;
    assert!((t - 10f64.powf(-0.72)).abs() < 1e-6, "{t}");
    // Starlight tolerance is 1.08e-3 cd/m² on a 2e-3 cd/m² field: 54 %, against 3.1 % by day.
}

/// Noise scaled to the tolerance map: at half the threshold almost nothing is visible, at
/// three times almost everything, at daylight, mesopic and starlight levels alike.
#[test]
fn noise_at_half_and_three_times_the_threshold() {
    let (w, h) = (256, 256);
    for peak in [100.0f32, 1.0, 0.01] {
        let reference = scene(w, h, peak);
        let (viewer, _) = Viewer::for_image(&reference, &no_acuity()).unwrap();
        let t = tolerance_map(&reference, &viewer).unwrap();
        let mut rng = Rng(7);

        // Noise of `a` thresholds with a random sign: `a` JND at every pixel. At night the
        // threshold is a large part of the luminance (54 % of the peak for white at 0.01
        // cd/m², the blue patches raising the rods' adaptation), so a darkening by three
        // thresholds can reach black: such a pixel changes by its whole luminance, `Y/T`
        // JND, still visible here as every patch is above one threshold.
        for (a, fraction) in [(0.5, 0.0), (3.0, 1.0)] {
            let mut test = reference.clone();
            let mut expected = 0.0;
            for (i, &t) in t.iter().enumerate() {
                let delta = a * rng.sign() * t as f64;
                let y = reference.y[i] as f64;
                perturb(&mut test, i, delta.max(-y));
                expected += delta.abs().min(if delta < 0.0 { y } else { f64::MAX }) / t as f64;
            }
            let expected = expected / (w * h) as f64;
            let d = difference(&reference, &test, &viewer).unwrap();
            assert_eq!(d.visible_fraction, fraction, "peak {peak}, a {a}");
            assert!(
                (d.mean_jnd / expected - 1.0).abs() < 1e-3,
                "peak {peak}: {}",
                d.mean_jnd
            );
            assert!(
                (d.max_jnd / a - 1.0).abs() < 1e-3,
                "peak {peak}: {}",
                d.max_jnd
            );
            if a < 1.0 {
                assert!(
                    (d.mean_jnd / a - 1.0).abs() < 1e-3,
                    "peak {peak}: {}",
                    d.mean_jnd
                );
            }
        }
    }

    // Gaussian noise of standard deviation a·T, in daylight (where it stays far from black):
    // visible where |z| ≥ 1/a, i.e. in P(|z| ≥ 2) = 4.55 % of the pixels at a = 1/2 and
    // P(|z| ≥ 1/3) = 73.89 % at a = 3; the mean is a·E|z| = a·√(2/π). Tolerances: 4
    // binomial standard deviations, 1.5 % on the mean.
    let reference = scene(w, h, 100.0);
    let (viewer, _) = Viewer::for_image(&reference, &no_acuity()).unwrap();
    let t = tolerance_map(&reference, &viewer).unwrap();
    let mut rng = Rng(9);
    for (a, fraction) in [(0.5, 0.045_50), (3.0, 0.738_88)] {
        let mut test = reference.clone();
        for (i, &t) in t.iter().enumerate() {
            perturb(&mut test, i, a * rng.normal() * t as f64);
        }
        let d = difference(&reference, &test, &viewer).unwrap();
        let sd = (fraction * (1.0 - fraction) / (w * h) as f64).sqrt();
        assert!(
            (d.visible_fraction - fraction).abs() < 4.0 * sd,
            "a {a}: {} vs {fraction}",
            d.visible_fraction
        );
        let mean = a * (2.0 / std::f64::consts::PI).sqrt();
        assert!(
            (d.mean_jnd / mean - 1.0).abs() < 0.015,
            "a {a}: {}",
            d.mean_jnd
        );
    }
}

/// The Weber fraction rises at night: ±10 % noise is plainly visible on a 100 cd/m² field
/// and invisible on a 0.01 cd/m² one.
#[test]
fn same_relative_noise_visible_by_day_invisible_at_night() {
    let (w, h) = (128, 128);
    let jnds = |l: f32, acuity: bool| {
        let reference = grey(w, h, l);
        let mut test = reference.clone();
        let mut rng = Rng(11);
        for i in 0..w * h {
            perturb(&mut test, i, 0.1 * rng.sign() * l as f64);
        }
        let conditions = ViewingConditions {
            acuity,
            view: Some(View::perspective(5.0, w, h)),
            ..ViewingConditions::default()
        };
        let (viewer, _) = Viewer::for_image(&reference, &conditions).unwrap();
        difference(&reference, &test, &viewer).unwrap()
    };
    // 100 cd/m²: adapted to 50, 10 cd/m² / t_p(50) = 3.2385 JND at every pixel.
    let day = jnds(100.0, false);
    let expected = 10.0 / tp(50.0);
    assert!((expected - 3.238_5).abs() < 1e-3);
    assert_eq!(day.visible_fraction, 1.0);
    assert!(
        (day.mean_jnd / expected - 1.0).abs() < 1e-4,
        "{}",
        day.mean_jnd
    );

    // 0.01 cd/m²: adapted to 0.005 cd/m², 0.011305 scotopic cd/m², k = 1. Rods:
    // 2.261e-3 / t_s(0.011305) = 2.261e-3 / 5.9488e-3 = 0.3801; cones 0.001 / t_p(0.005)
    // = 0.0052, pooled: 0.3801 JND at every pixel.
    let night = jnds(0.01, false);
    let rods = 0.1 * 0.02261 / ts(0.011_305);
    let cones = 0.001 / tp(0.005);
    let expected = (rods.powf(3.5) + cones.powf(3.5)).powf(1.0 / 3.5);
    assert!((expected - 0.380_1).abs() < 1e-3, "{expected}");
    assert_eq!(night.visible_fraction, 0.0);
    assert!(
        (night.max_jnd / expected - 1.0).abs() < 1e-3,
        "{}",
        night.max_jnd
    );

    // Through the acuity Gaussian (5° over 128 px, 25.6 px/degree) the per-pixel noise is
    // averaged as well. At night the blur is 1.25 px (cutoff 4.4 c/deg) and the mean falls
    // to well under half; by day it is 0.21 px and every pixel stays visible.
    let night_blurred = jnds(0.01, true);
    assert!(
        night_blurred.mean_jnd < 0.4 * night.mean_jnd,
        "{}",
        night_blurred.mean_jnd
    );
    let day_blurred = jnds(100.0, true);
    assert_eq!(day_blurred.visible_fraction, 1.0);
    assert!(
        day_blurred.mean_jnd > 0.85 * day.mean_jnd,
        "{}",
        day_blurred.mean_jnd
    );
}

/// Full-contrast sinusoidal gratings against the uniform field at their mean, seen through
/// the acuity Gaussian of Eq. 7 at 285 pixels per degree.
///
/// Tolerances follow the blur module's measured gain accuracy (absolute, against
/// `exp(−2π²σ²f²)`): 0.1 % for its exact kernel (σ < 5 px, daylight here), 0.5 % for its
/// recursive filter (σ ≥ 5 px, moonlight here), times the grating's unfiltered JNDs.
///
/// With the grating's peak at twice the mean `L`, the Sec. 4.4 rule adapts the observer to
/// `L`, and Eq. 7 makes the Gaussian's gain at the cutoff `ω_c(L)` equal to the threshold
/// contrast `c = t(L)/L` of the JND metric (the cones' at 100 cd/m², rods and cones pooled
/// at 0.04), so the grating at `ω_c` is displayed at exactly 1 JND; at frequency `f` its
/// amplitude is `c^((f/ω_c)²)·L`.
#[test]
fn gratings_above_the_acuity_cutoff_are_invisible_below_visible() {
    let (w, h) = (1200, 4);
    // Cutoff at 100 cd/m²: 17.25·atan(1.4·2 + 0.35) + 25.72 = 47.52 c/deg. 6 px per cycle
    // there: 285.1 px/degree, and the daylight Gaussian is 0.00805°, 2.30 px.
    let cutoff_day = 17.25 * (1.4f64 * 2.0 + 0.35).atan() + 25.72;
    assert!((cutoff_day - 47.52).abs() < 0.01);
    let ppd = 6.0 * cutoff_day;
    let run = |mean: f32, cycles_per_degree: f64| {
        let reference = grey(w, h, mean);
        let mut test = reference.clone();
        for y in 0..h {
            for x in 0..w {
                let phase = 2.0 * std::f64::consts::PI * cycles_per_degree * x as f64 / ppd;
                perturb(&mut test, y * w + x, mean as f64 * phase.cos());
            }
        }
        // Adapted to the grating's own level: half its highest visible luminance.
        let viewer = Viewer::steady_state(mean as f64, SP_WHITE as f64 * mean as f64, Some(ppd));
        let d = difference(&reference, &test, &viewer).unwrap();
        // The blur's replicated boundary bends the grating near the left and right edges;
        // measure the middle 600 columns of one row.
        d.jnd[w / 4..3 * w / 4].iter().fold(0f32, |m, &v| m.max(v)) as f64
    };

    // Daylight, 100 cd/m² (k = 0): c = t_p(100)/100 = 0.05559.
    let c = tp(100.0) / 100.0;
    assert!((c - 0.055_59).abs() < 1e-4);
    // Unfiltered, the grating is 100/t_p(100) = 1/c = 18.0 JND: tolerance 0.001·18 = 0.018.
    let at_cutoff = run(100.0, cutoff_day);
    assert!((at_cutoff - 1.0).abs() < 0.02, "{at_cutoff}");
    let below = run(100.0, 0.5 * cutoff_day); // c^-0.75 = 8.73 JND
    assert!((below - c.powf(-0.75)).abs() < 0.02, "{below}");
    let above = run(100.0, 1.5 * cutoff_day); // c^1.25 = 0.027 JND
    assert!((above - c.powf(1.25)).abs() < 0.02, "{above}");
    assert!(above < 0.05, "{above}");

    // Moonlight, 0.04 cd/m²: cutoff 17.25·atan(1.4·log 0.04 + 0.35) + 25.72 = 8.225 c/deg.
    // Threshold of a white change: rods (t_s(0.0904)/0.0904 = 10^-0.395 = 0.4027, the rod
    // Weber fraction) with k of Eq. 6 (smoothstep in log scotopic luminance over
    // 0.02261–22.61, 0.895 here) pooled with the cones: 0.01799 cd/m², so the unfiltered
    // grating is 0.04 / 0.01799 = 2.22 JND: tolerance 0.005·2.22 = 0.011. Eq. 7 uses the
    // same threshold, c = 0.01799/0.04 = 0.4498: the Gaussian is 0.02446°, 6.97 px.
    let cutoff_night = 17.25 * (1.4 * 0.04f64.log10() + 0.35).atan() + 25.72;
    assert!((cutoff_night - 8.225).abs() < 0.01);
    let ls: f64 = 2.261 * 0.04;
    let u = (ls.log10() - 0.02261f64.log10()) / 3.0;
    let k = 1.0 - u * u * (3.0 - 2.0 * u);
    let (a, b) = (1.0 / tp(0.04), k * 2.261 / ts(ls));
    let threshold = 1.0 / (a.powf(3.5) + b.powf(3.5)).powf(1.0 / 3.5);
    assert!(
        (k - 0.895).abs() < 1e-3 && (threshold - 0.017_99).abs() < 1e-4,
        "{k} {threshold}"
    );
    let c_night = threshold / 0.04;
    let expected = |f: f64| 0.04 / threshold * c_night.powf((f / cutoff_night).powi(2));
    let at_cutoff = run(0.04, cutoff_night); // 1 JND
    assert!((at_cutoff - 1.0).abs() < 0.011, "{at_cutoff}");
    let below = run(0.04, 0.5 * cutoff_night); // c^-0.75 = 1.82 JND
    assert!(
        (below - expected(0.5 * cutoff_night)).abs() < 0.015,
        "{below}"
    );
    assert!(below > 1.8);
    let above = run(0.04, 1.5 * cutoff_night); // c^1.25 = 0.368 JND
    assert!(
        (above - expected(1.5 * cutoff_night)).abs() < 0.015,
        "{above}"
    );
    assert!(above < 0.39);
    // The grating near-invisible in moonlight (12.3 c/deg) is 14.8 JND in daylight.
    let f = 1.5 * cutoff_night;
    let day = run(100.0, f);
    let expected_day = 100.0 / tp(100.0) * c.powf((f / cutoff_day).powi(2));
    assert!((expected_day - 14.81).abs() < 0.02, "{expected_day}");
    assert!((day - expected_day).abs() < 0.02, "{day}");
}

#[test]
fn images_of_different_sizes_are_refused() {
    let a = grey(16, 8, 1.0);
    let b = grey(8, 16, 1.0);
    let (viewer, _) = Viewer::for_image(&a, &ViewingConditions::default()).unwrap();
    let e = difference(&a, &b, &viewer).unwrap_err().to_string();
    assert!(e.contains("8x16") && e.contains("16x8"), "{e}");
    assert!(converged(&a, &b, &viewer).is_err());
    // Inconsistent planes are refused too.
    let mut broken = a.clone();
    broken.y.pop();
    assert!(difference(&a, &broken, &viewer).is_err());
    assert!(tolerance_map(&broken, &viewer).is_err());
}

/// Thresholds from any state, e.g. a time-varying one: ten times the steady thresholds
/// give a tenth of the JNDs.
#[test]
fn thresholds_can_come_from_a_time_varying_state() {
    let reference = scene(32, 32, 50.0);
    let mut test = reference.clone();
    for i in 0..test.len() {
        perturb(&mut test, i, 4.0);
    }
    let steady = Sensitivity::steady_state(25.0, 56.5);
    let raised = Sensitivity {
        cone_threshold_cd_m2: 10.0 * steady.cone_threshold_cd_m2,
        rod_threshold_scotopic_cd_m2: 10.0 * steady.rod_threshold_scotopic_cd_m2,
        ..steady
    };
    let view = |s| Viewer {
        adaptation: Adaptation::Global(s),
        acuity_sigma_px: 0.0,
    };
    let a = difference(&reference, &test, &view(steady)).unwrap();
    let b = difference(&reference, &test, &view(raised)).unwrap();
    assert!((a.max_jnd / b.max_jnd - 10.0).abs() < 1e-3);
    assert!(a.visible_fraction == 1.0 && b.visible_fraction == 0.0);
}

/// The time course of adaptation (Sec. 3.5, Eq. 8–9) feeds the same measure: just after the
/// lights go up the observer is dazzled and sees less; once adapted, exactly the steady state.
#[test]
fn a_time_course_state_feeds_the_thresholds() {
    let reference = scene(32, 32, 100.0);
    let mut test = reference.clone();
    for i in 0..test.len() {
        perturb(&mut test, i, 4.0);
    }
    let view = |s| Viewer {
        adaptation: Adaptation::Global(s),
        acuity_sigma_px: 0.0,
    };
    let steady = difference(
        &reference,
        &test,
        &view(Sensitivity::steady_state(50.0, 113.05)),
    )
    .unwrap();
    // Adapted to 0.1 cd/m², the world switches to 50 cd/m² (scotopic 113.05).
    let mut eye = visadapt::timecourse::Adaptation::equal_energy(0.1).unwrap();
    eye.step(0.0, 50.0, 113.05).unwrap();
    let dazzled = difference(
        &reference,
        &test,
        &view(Sensitivity::from_time_course(&eye)),
    )
    .unwrap();
    assert!(
        dazzled.max_jnd < 0.8 * steady.max_jnd,
        "{} vs {}",
        dazzled.max_jnd,
        steady.max_jnd
    );
    // An hour later adaptation is complete: the steady-state thresholds again.
    eye.step(3600.0, 50.0, 113.05).unwrap();
    let s = Sensitivity::from_time_course(&eye);
    let expected = Sensitivity::steady_state(50.0, 113.05);
    assert!((s.cone_threshold_cd_m2 / expected.cone_threshold_cd_m2 - 1.0).abs() < 1e-3);
    assert!(
        (s.rod_threshold_scotopic_cd_m2 / expected.rod_threshold_scotopic_cd_m2 - 1.0).abs() < 1e-3
    );
    assert_eq!(s.rod_weight, expected.rod_weight);
    let adapted = difference(&reference, &test, &view(s)).unwrap();
    assert!((adapted.max_jnd / steady.max_jnd - 1.0).abs() < 1e-3);
}

/// Per-pixel adaptation: a map equal to the global level changes nothing; a map equal to
/// each pixel's own luminance makes the cone threshold follow Weber's law pixel by pixel.
#[test]
fn per_pixel_adaptation_maps() {
    let image = scene(48, 48, 1000.0);
    let (viewer, report) = Viewer::for_image(&image, &no_acuity()).unwrap();
    let n = image.len();
    let flat = vec![report.world_adaptation_cd_m2 as f32; n];
    let flat_s = vec![report.world_adaptation_scotopic_cd_m2 as f32; n];
    let flat_map = AdaptationMap::from_levels(48, 48, &flat, &flat_s).unwrap();
    let local = Viewer::local(&flat_map);
    let g = tolerance_map(&image, &viewer).unwrap();
    let l = tolerance_map(&image, &local).unwrap();
    assert!(g.iter().zip(&l).all(|(a, b)| (a / b - 1.0).abs() < 1e-5));

    let own_s = image.scotopic.clone().unwrap();
    let own_map = AdaptationMap::from_levels(48, 48, &image.y, &own_s).unwrap();
    let own = Viewer::local(&own_map);
    let t = tolerance_map(&image, &own).unwrap();
    for (i, (t, y)) in t.iter().zip(&image.y).enumerate() {
        // Every pixel is at 700 cd/m² or more: cone Weber branch, 10^-1.255 = 5.559 %.
        let weber = t / y;
        assert!((weber - 0.055_59).abs() < 1e-4, "pixel {i}: {weber}");
    }
    // A map of the wrong size is refused.
    let short_map = AdaptationMap::from_levels(47, 48, &flat[48..], &flat_s[48..]).unwrap();
    assert!(tolerance_map(&image, &Viewer::local(&short_map)).is_err());
}

/// NaN and infinite pixels read as black, as the operator shows them, and are counted.
#[test]
fn non_finite_pixels_read_as_black() {
    let reference = grey(8, 8, 100.0);
    let mut test = reference.clone();
    test.y[3] = f32::NAN;
    test.x[5] = f32::INFINITY;
    let viewer = Viewer::steady_state(50.0, 113.05, None);
    let d = difference(&reference, &test, &viewer).unwrap();
    assert_eq!(d.non_finite_pixels, 2);
    // Black against 100 cd/m²: 100 / t_p(50) = 32.4 JND.
    assert!((d.max_jnd - 100.0 / tp(50.0)).abs() < 0.01, "{}", d.max_jnd);
    assert!((d.visible_fraction - 2.0 / 64.0).abs() < 1e-12);
    assert!(d.jnd.iter().all(|v| v.is_finite()));
}

/// The operator's view: an angular fisheye's pixels per degree give the blur size.
#[test]
fn viewer_from_an_image_uses_the_operators_acuity_blur() {
    let mut image = grey(400, 10, 0.08);
    image.view = Some(View {
        projection: Projection::AngularFisheye,
        horizontal_deg: 1.0,
        vertical_deg: 0.025,
    });
    let (viewer, report) = Viewer::for_image(&image, &ViewingConditions::default()).unwrap();
    // Adapted to 0.04 cd/m²: the pooled threshold contrast of Eq. 4-6 is 0.4498 (k = 0.895,
    // see the grating test), sigma = sqrt(ln(1/0.4498)/2)/(π·8.225) = 0.02446 deg, 400 px/deg.
    assert!(
        (report.acuity.sigma_deg - 0.024_46).abs() < 2e-5,
        "{}",
        report.acuity.sigma_deg
    );
    assert!((viewer.acuity_sigma_px - 400.0 * report.acuity.sigma_deg).abs() < 1e-9);
}

/// Issue 8 §4: one definition of the threshold for the acuity blur and the JND metric, so
/// that a full-contrast sinusoidal grating at the cutoff frequency `ω_c(L)`, on a field at
/// the adaptation luminance `L`, scores 1 JND at every level where Eq. 7 has a solution.
/// It failed before: the blur passed the envelope `min(c_p, c_s)` while the metric weights
/// the rods by `k`, and the grating scored 0.742 JND at 0.1 cd/m² and 0.578 at 0.3.
///
/// Expected values are recomputed here from Eq. 4-6 (k: the smoothstep of `mesopic.rs`):
/// the pooled threshold contrast `c = 1/((1/c_p)^3.5 + (k/c_s)^3.5)^(1/3.5)` makes the
/// grating exactly 1 JND; below the rod Weber range (L < 0.016 cd/m², only 0.01 here) the
/// blur holds the rods' contrast at the Weber fraction 0.4027 and the grating scores
/// `0.4027/c_s` = 0.909. Each level is seen at 6 pixels per cycle of its cutoff, where the
/// Gaussian (1.3-2.3 px) is the blur module's exact kernel, accurate to 0.1 % of the gain:
/// the tolerance is 0.01 JND against that value, and the criterion, ±20 % of 1 JND,
/// is asserted as well. The same through `visibility::compare`, globally and with local
/// adaptation (each pixel's own Gaussian from the adaptation map, blurred at sigmas
/// 2^(1/3) apart and interpolated: 3 %).
#[test]
fn full_contrast_grating_at_the_cutoff_is_one_jnd_from_001_to_1e4_cd_m2() {
    use visadapt::acuity::{AcuityFilter, AcuityThreshold};
    use visadapt::operator::AdaptationMode;
    let (w, h) = (1200, 16);
    let cutoff = |l: f64| 17.25 * (1.4 * l.log10() + 0.35).atan() + 25.72;
    let k = |ls: f64| {
        let u = ((ls.log10() - 0.02261f64.log10()) / 3.0).clamp(0.0, 1.0);
        1.0 - u * u * (3.0 - 2.0 * u)
    };
    let pool = |a: f64, b: f64| (a.powf(3.5) + b.powf(3.5)).powf(1.0 / 3.5);
    let weber = 10f64.powf(-0.395);
    // The grating: reference at `l`, test `l·(1 + cos)`, seen at `ppd`.
    let images = |l: f64, ppd: f64| {
        let reference = grey(w, h, l as f32);
        let mut test = reference.clone();
        for y in 0..h {
            for x in 0..w {
                let phase = 2.0 * std::f64::consts::PI * cutoff(l) * x as f64 / ppd;
                perturb(&mut test, y * w + x, l * phase.cos());
            }
        }
        (reference, test)
    };
    // The largest JND in the middle half of row 8 (the blur's replicated edges bend the
    // grating near the left and right ends).
    let peak = |jnd: &[f32]| {
        jnd[8 * w + w / 4..8 * w + 3 * w / 4]
            .iter()
            .fold(0f32, |m, &v| m.max(v)) as f64
    };
    let mut levels = 0;
    for i in 0..=24 {
        let l = 10f64.powf(-2.0 + i as f64 / 4.0); // 0.01 .. 1e4 cd/m²
        let ls = SP_WHITE as f64 * l;
        let (cp, cs, k) = (tp(l) / l, ts(ls) / ls, k(ls));
        let gain = 1.0 / pool(1.0 / cp, k / cs.min(weber));
        let expected = pool(gain / cp, k * gain / cs);
        let ppd = 6.0 * cutoff(l);
        let (reference, test) = images(l, ppd);
        let viewer = Viewer::steady_state(l, ls, Some(ppd));
        let got = peak(&difference(&reference, &test, &viewer).unwrap().jnd);
        println!("{l:.4} cd/m²: grating at the cutoff {got:.3} JND (expected {expected:.3})");
        assert!((got - 1.0).abs() <= 0.2, "{l} cd/m²: {got} JND");
        assert!(
            (got - expected).abs() < 0.01,
            "{l} cd/m²: {got} JND, expected {expected}"
        );
        if ls >= 10f64.powf(-1.44) {
            assert!((expected - 1.0).abs() < 1e-9);
        }

        // The operator's observer of the reference, global and local.
        for local in [false, true] {
            let conditions = ViewingConditions {
                world_adaptation_cd_m2: Some(l),
                world_adaptation_scotopic_cd_m2: Some(ls),
                view: Some(View::angular_fisheye(w as f64 / ppd, w, h)),
                adaptation: if local {
                    AdaptationMode::Local(Default::default())
                } else {
                    AdaptationMode::Global
                },
                ..Default::default()
            };
            let (d, _) = visadapt::visibility::compare(&reference, &test, &conditions).unwrap();
            let got = peak(&d.jnd);
            let tol = if local { 0.03 } else { 0.01 };
            assert!(
                (got - expected).abs() < tol,
                "{l} cd/m², local {local}: {got} JND, expected {expected}"
            );
        }

        // The paper's rule stays reachable, with its calibration of the metric.
        let paper = AcuityFilter::with_rule(l, ls, AcuityThreshold::Envelope);
        let envelope = Viewer {
            acuity_sigma_px: paper.sigma_deg * ppd,
            ..viewer
        };
        let got = peak(&difference(&reference, &test, &envelope).unwrap().jnd);
        let gain = cp.min(cs.min(weber));
        let expected = pool(gain / cp, k * gain / cs);
        assert!(
            (got - expected).abs() < 0.01,
            "{l} cd/m² (envelope): {got} JND, expected {expected}"
        );
        if (l - 0.1).abs() < 1e-9 {
            assert!((expected - 0.742).abs() < 1e-3, "{expected}");
        }
        levels += 1;
    }
    assert_eq!(levels, 25);
}

/// Issue 8: `visible` on WideFloatRange.exr (values from 6e-39 to 1.9e38, half negative)
/// against a black image gave NaN JNDs with local adaptation (the acuity blur overflowed on
/// differences of 1e38) and, globally or with glare, refused the observer ("invalid
/// cone-threshold 3.3e36"). Finite input must give finite JNDs in every mode.
#[test]
fn wide_float_range_gives_finite_jnds_in_every_mode() {
    use visadapt::operator::AdaptationMode;
    let Some(path) = common::shared("openexr/WideFloatRange.exr") else {
        return;
    };
    let reference = io::read(&path, &Limits::default()).unwrap();
    let mut black = reference.clone();
    for p in [&mut black.x, &mut black.y, &mut black.z] {
        p.fill(0.0);
    }
    black.scotopic = None;
    for local in [false, true] {
        for glare in [false, true] {
            let conditions = ViewingConditions {
                view: Some(View::perspective(60.0, reference.width, reference.height)),
                adaptation: if local {
                    AdaptationMode::Local(Default::default())
                } else {
                    AdaptationMode::Global
                },
                glare: glare.then(visadapt::glare::Glare::default),
                ..Default::default()
            };
            let (d, _) = visadapt::visibility::compare(&reference, &black, &conditions)
                .unwrap_or_else(|e| panic!("local {local}, glare {glare}: {e}"));
            let bad = d.jnd.iter().filter(|v| !v.is_finite()).count();
            assert_eq!(
                bad, 0,
                "local {local}, glare {glare}: {bad} non-finite JNDs"
            );
            assert!(d.mean_jnd.is_finite() && d.max_jnd.is_finite());
            // The brightest pixels (1.9e38 against black) are clearly visible.
            assert!(
                d.max_jnd > 1.0,
                "local {local}, glare {glare}: {}",
                d.max_jnd
            );
            println!(
                "local {local}, glare {glare}: max {:.3e} JND, mean {:.3e}, {:.1} % visible",
                d.max_jnd,
                d.mean_jnd,
                100.0 * d.visible_fraction
            );
        }
    }
}
