//! Local adaptation (`AdaptationMode::Local`): exactness against the paper's global model,
//! night lights that keep their hue, shadows that are not crushed, no halos, monotonicity.

mod common;

use visadapt::colour::srgb_encode;
use visadapt::local::LocalAdaptation;
use visadapt::operator::{AdaptationMode, Output, ViewingConditions, map};
use visadapt::{DisplayImage, HdrImage, Limits, io};

fn local(radius_deg: f64) -> ViewingConditions {
    ViewingConditions {
        adaptation: AdaptationMode::Local(LocalAdaptation {
            radius_deg,
            ..LocalAdaptation::default()
        }),
        ..ViewingConditions::default()
    }
}

fn run(image: &HdrImage, cond: &ViewingConditions) -> Output {
    map(image, cond).expect("maps")
}

/// Deterministic pseudo-random numbers in [0, 1).
fn noise(seed: &mut u32) -> f32 {
    *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    (*seed >> 8) as f32 / (1u32 << 24) as f32
}

/// A pixel of grey (D65 chromaticity) at luminance `l`.
fn grey(img: &mut HdrImage, i: usize, l: f32) {
    img.x[i] = 0.9505 * l;
    img.y[i] = l;
    img.z[i] = 1.089 * l;
}

/// Display luminance of pixel `i`, cd/m² (Rec. 709 luminance of the linear display RGB).
fn display_cd_m2(d: &DisplayImage, i: usize) -> f32 {
    (0.2126 * d.r[i] + 0.7152 * d.g[i] + 0.0722 * d.b[i]) * d.display_max_cd_m2
}

fn assert_same_pixels(a: &DisplayImage, b: &DisplayImage, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    for (name, p, q) in [("r", &a.r, &b.r), ("g", &a.g, &b.g), ("b", &a.b, &b.b)] {
        if let Some(i) = (0..p.len()).find(|&i| p[i].to_bits() != q[i].to_bits()) {
            panic!("{what}: {name}[{i}] = {} against {}", p[i], q[i]);
        }
    }
}

#[test]
fn uniform_image_is_the_global_model_bit_for_bit() {
    for level in [3000.0f32, 40.0, 1.0, 0.04, 0.001] {
        let mut img = HdrImage::zeros(96, 64);
        for i in 0..img.len() {
            grey(&mut img, i, level);
        }
        for scotopic in [false, true] {
            if scotopic {
                img.scotopic = Some(vec![level * 2.261; img.len()]);
            }
            for acuity in [true, false] {
                let cond = ViewingConditions {
                    acuity,
                    ..local(1.0)
                };
                let g = run(
                    &img,
                    &ViewingConditions {
                        adaptation: AdaptationMode::Global,
                        ..cond.clone()
                    },
                );
                let l = run(&img, &cond);
                assert_same_pixels(&l.image, &g.image, &format!("{level} cd/m²"));
                assert_eq!(l.stats, g.stats);
                let r = l.report.local.as_ref().expect("local report");
                assert_eq!(r.adaptation_cd_m2.min, g.report.world_adaptation_cd_m2);
                assert_eq!(r.adaptation_cd_m2.max, g.report.world_adaptation_cd_m2);
            }
        }
    }
}

fn sunset() -> HdrImage {
    io::read(&common::data("sunset-fisheye.hdr"), &Limits::default()).expect("sample image")
}

/// Mean absolute difference of the linear display planes.
fn mean_abs_diff(a: &DisplayImage, b: &DisplayImage) -> f64 {
    let n = a.r.len() as f64;
    [(&a.r, &b.r), (&a.g, &b.g), (&a.b, &b.b)]
        .iter()
        .map(|(p, q)| {
            p.iter()
                .zip(q.iter())
                .map(|(x, y)| f64::from((x - y).abs()))
                .sum::<f64>()
        })
        .sum::<f64>()
        / (3.0 * n)
}

#[test]
fn infinite_radius_is_the_global_model_and_large_radii_converge_to_it() {
    let mut img = sunset();
    for peak_scale in [1.0f32, 1e-4] {
        // Daylight as stored, and the same scene 10^4 times darker (mesopic to scotopic).
        img.scale(peak_scale);
        let global = run(&img, &ViewingConditions::default());
        let inf = run(&img, &local(f64::INFINITY));
        assert_same_pixels(&inf.image, &global.image, "infinite radius");
        let mut prev = f64::INFINITY;
        for radius in [1.0, 10.0, 1e3, 1e5] {
            let d = mean_abs_diff(&run(&img, &local(radius)).image, &global.image);
            assert!(d < prev, "radius {radius}: {d} not below {prev}");
            prev = d;
        }
        // 1e5 degrees: within float rounding of the global image.
        assert!(prev < 1e-5, "{prev}");
    }
}

/// The issue's night street: 0.01-0.03 cd/m² of textured grey, three 10 × 10 px lights of
/// Y = 10 cd/m² in the Rec. 709 red, green and blue primaries.
fn night_street() -> (HdrImage, [usize; 3]) {
    let (w, h) = (640, 480);
    let mut img = HdrImage::zeros(w, h);
    let mut seed = 7;
    for i in 0..img.len() {
        let l = 0.01 + 0.02 * noise(&mut seed);
        grey(&mut img, i, l);
    }
    // Rec. 709 primaries' XYZ at Y = 1 (IEC 61966-2-1 matrix columns).
    let primaries = [
        [0.4124 / 0.2126, 1.0, 0.0193 / 0.2126],
        [0.3576 / 0.7152, 1.0, 0.1192 / 0.7152],
        [0.1805 / 0.0722, 1.0, 0.9505 / 0.0722],
    ];
    let mut centres = [0; 3];
    for (k, p) in primaries.iter().enumerate() {
        let (x0, y0) = (150 + 170 * k, 200);
        for y in y0..y0 + 10 {
            for x in x0..x0 + 10 {
                let i = y * w + x;
                img.x[i] = 10.0 * p[0];
                img.y[i] = 10.0 * p[1];
                img.z[i] = 10.0 * p[2];
            }
        }
        centres[k] = (y0 + 5) * w + x0 + 5;
    }
    (img, centres)
}

/// HSV saturation and dominant channel of an encoded display pixel.
fn saturation(d: &DisplayImage, i: usize) -> (f32, usize) {
    let c = [d.r[i], d.g[i], d.b[i]].map(srgb_encode);
    let max = c.iter().copied().fold(0f32, f32::max);
    let min = c.iter().copied().fold(1f32, f32::min);
    let dominant = (0..3).max_by(|&a, &b| c[a].total_cmp(&c[b])).unwrap();
    ((max - min) / max, dominant)
}

#[test]
fn night_lights_keep_their_hue() {
    let (img, centres) = night_street();
    let global = run(&img, &ViewingConditions::default());
    let local = run(&img, &local(1.0));
    for (k, &i) in centres.iter().enumerate() {
        let (sg, _) = saturation(&global.image, i);
        let (sl, dominant) = saturation(&local.image, i);
        eprintln!("light {k}: saturation global {sg:.3}, local {sl:.3}");
        assert_eq!(dominant, k, "light {k} shows the wrong primary");
        assert!(sl > 0.5, "light {k}: saturation {sl}");
    }
    // The global model whitens green and blue (the issue's measurement).
    assert!(saturation(&global.image, centres[2]).0 < 0.1);
}

/// Fraction of pixels displayed under 0.5 cd/m².
fn black_fraction(d: &DisplayImage) -> f64 {
    (0..d.r.len())
        .filter(|&i| display_cd_m2(d, i) < 0.5)
        .count() as f64
        / d.r.len() as f64
}

fn daylight_blacks(name: &str, img: &HdrImage, at_most: f64) {
    let g = black_fraction(&run(img, &ViewingConditions::default()).image);
    let l = black_fraction(&run(img, &local(1.0)).image);
    eprintln!(
        "{name}: pixels displayed under 0.5 cd/m²: global {:.1} %, local {:.1} %",
        100.0 * g,
        100.0 * l
    );
    assert!(l < at_most * g, "{name}: {l} against {g}");
}

#[test]
fn daylight_shadows_are_not_black() {
    daylight_blacks("sunset-fisheye.hdr", &sunset(), 0.25);
    if let Some(p) = common::shared("openexr/Desk.exr") {
        let img = io::read(&p, &Limits::default()).expect("Desk.exr");
        daylight_blacks("Desk.exr", &img, 0.25);
    }
}

/// Local monotonicity: over pairs of pixels up to `reach` pixels apart (horizontally and
/// vertically), the fraction where the brighter world pixel (by more than 1 %, for the
/// cones and for the rods: where they disagree the rods may rightly show the photopically
/// darker pixel brighter, the Purkinje shift) is shown darker by more than `tolerance`
/// (relative), and the worst such reversal.
fn reversals(img: &HdrImage, d: &DisplayImage, reach: usize, tolerance: f32) -> (f64, f32) {
    let (w, h) = (img.width, img.height);
    let v: Vec<f32> = (0..img.len())
        .map(|i| {
            visadapt::scotopic::from_xyz(img.x[i].max(0.0), img.y[i].max(0.0), img.z[i].max(0.0))
        })
        .collect();
    let (mut pairs, mut bad, mut worst) = (0usize, 0usize, 0f32);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            for k in 1..=reach {
                for j in [(x + k < w).then(|| i + k), (y + k < h).then(|| i + k * w)]
                    .into_iter()
                    .flatten()
                {
                    let (a, b) = if img.y[i] > img.y[j] { (i, j) } else { (j, i) };
                    // Pixels the display clips (too bright, or out of its gamut) lose their
                    // luminance order by the clipping rule, whatever the adaptation.
                    let shown = |p: usize| {
                        [d.r[p], d.g[p], d.b[p]]
                            .iter()
                            .all(|&c| c > 0.0 && c < 0.999)
                    };
                    if !(img.y[a] > 1.01 * img.y[b]
                        && v[a] > 1.01 * v[b]
                        && img.y[b] > 0.0
                        && shown(a)
                        && shown(b))
                    {
                        continue;
                    }
                    pairs += 1;
                    let (da, db) = (display_cd_m2(d, a), display_cd_m2(d, b));
                    if db > 0.0 && da < db * (1.0 - tolerance) {
                        bad += 1;
                        worst = worst.max(1.0 - da / db);
                    }
                }
            }
        }
    }
    (bad as f64 / pairs as f64, worst)
}

#[test]
fn local_monotonicity() {
    let mut images = vec![("sunset-fisheye.hdr", sunset())];
    if let Some(p) = common::shared("openexr/Desk.exr") {
        images.push((
            "Desk.exr",
            io::read(&p, &Limits::default()).expect("Desk.exr"),
        ));
    }
    for (name, img) in images {
        let cond = ViewingConditions {
            acuity: false,
            ..local(1.0)
        };
        let d = run(&img, &cond).image;
        let g = run(
            &img,
            &ViewingConditions {
                adaptation: AdaptationMode::Global,
                ..cond.clone()
            },
        )
        .image;
        let (gf, gw) = reversals(&img, &g, 3, 0.05);
        eprintln!(
            "{name} global: {:.4} % of pairs reversed beyond 5 %, worst {:.1} %",
            100.0 * gf,
            100.0 * gw
        );
        let (fraction, worst) = reversals(&img, &d, 3, 0.05);
        eprintln!(
            "{name}: {:.4} % of pairs reversed beyond 5 %, worst {:.1} %",
            100.0 * fraction,
            100.0 * worst
        );
        // Measured: sunset 0.10 %, Desk 1.6 % (see the README): at soft edges the map
        // follows each side's level and the pixels of the ramp between them can trade
        // places. The global model has none.
        assert!(gf == 0.0, "{name}: global {gf}");
        assert!(fraction < 0.025, "{name}: {fraction}, worst {worst}");
    }
}

#[test]
fn no_halo_at_a_1000_to_1_edge() {
    // 1440 × 240 px over 60° (perspective): 24 px/deg at the centre. Left half 1 cd/m²,
    // right half 1000 cd/m², both textured ±30 %.
    let (w, h) = (1440, 240);
    let mut img = HdrImage::zeros(w, h);
    let mut seed = 99;
    for y in 0..h {
        for x in 0..w {
            let base = if x < w / 2 { 1.0 } else { 1000.0 };
            grey(&mut img, y * w + x, base * (0.7 + 0.6 * noise(&mut seed)));
        }
    }
    let out = run(&img, &local(1.0));
    let ppd = out.report.pixels_per_degree.unwrap();
    let column = |x: usize| -> f64 {
        (0..h)
            .map(|y| f64::from(display_cd_m2(&out.image, y * w + x)))
            .sum::<f64>()
            / h as f64
    };
    let edge = w / 2;
    let far = (edge as f64 - 10.0 * ppd) as usize;
    let reference: f64 = (far - 5..far + 5).map(column).sum::<f64>() / 10.0;
    let near = (edge as f64 - 2.0 * ppd) as usize;
    let worst = (near..edge).map(column).fold(f64::INFINITY, f64::min);
    eprintln!(
        "dark side within 2° of the edge: lowest column mean {:.1} % of its value 10° away",
        100.0 * worst / reference
    );
    assert!(worst >= 0.5 * reference, "{worst} against {reference}");
    // The global model shows the dark side at about 1/1000 of the bright side: black.
    let g = run(&img, &ViewingConditions::default());
    assert!(display_cd_m2(&g.image, h / 2 * w + far) < 0.5);
}

#[test]
fn visibility_uses_the_same_local_map() {
    use visadapt::visibility::{Observation, difference, tolerance_map};
    // A uniform image: the local observer is the global one, to the bit.
    let mut flat = HdrImage::zeros(64, 48);
    for i in 0..flat.len() {
        grey(&mut flat, i, 0.3);
    }
    let mut test = flat.clone();
    for i in (0..test.len()).filter(|i| i % 64 < 20) {
        grey(&mut test, i, 0.33);
    }
    let g = Observation::for_image(&flat, &ViewingConditions::default()).unwrap();
    let l = Observation::for_image(&flat, &local(1.0)).unwrap();
    assert!(g.map.is_none() && l.map.is_some());
    assert_eq!(
        tolerance_map(&flat, &g.viewer()).unwrap(),
        tolerance_map(&flat, &l.viewer()).unwrap()
    );
    let (dg, dl) = (
        difference(&flat, &test, &g.viewer()).unwrap(),
        difference(&flat, &test, &l.viewer()).unwrap(),
    );
    assert_eq!(dg.jnd, dl.jnd);

    // Daylight: the global tolerance is one constant (k = 0, one cone threshold) while the
    // local one follows each region's own threshold, far lower in the shadows.
    let img = sunset();
    let cond = ViewingConditions {
        acuity: false,
        ..local(1.0)
    };
    let g = Observation::for_image(
        &img,
        &ViewingConditions {
            adaptation: AdaptationMode::Global,
            ..cond.clone()
        },
    )
    .unwrap();
    let l = Observation::for_image(&img, &cond).unwrap();
    let tg = tolerance_map(&img, &g.viewer()).unwrap();
    let tl = tolerance_map(&img, &l.viewer()).unwrap();
    let lit: Vec<usize> = (0..img.len()).filter(|&i| img.y[i] > 0.0).collect();
    let (lo, hi) = lit.iter().fold((f32::INFINITY, 0f32), |(lo, hi), &i| {
        (lo.min(tg[i]), hi.max(tg[i]))
    });
    assert!(hi / lo < 1.001, "global tolerance varies: {lo}..{hi}");
    let map = l.map.as_ref().unwrap();
    let mut ratios: Vec<f32> = lit.iter().map(|&i| tl[i] / tg[i]).collect();
    ratios.sort_by(f32::total_cmp);
    let median = ratios[ratios.len() / 2];
    eprintln!(
        "sunset tolerance, local / global: median {median:.4}, range {:.4}..{:.4}",
        ratios[0],
        ratios[ratios.len() - 1]
    );
    assert!(median < 0.1, "{median}");
    // Each pixel's local tolerance is the Eq. 4 threshold of its own local adaptation
    // (daylight: k = 0 wherever the local level is photopic).
    for &i in lit.iter().step_by(997) {
        let la = map.adaptation_cd_m2(i);
        let las = map.adaptation_scotopic_cd_m2(i);
        if visadapt::mesopic::rod_weight(las) == 0.0 {
            let want = visadapt::tvi::cone_threshold_cd_m2(la);
            assert!(
                (f64::from(tl[i]) / want - 1.0).abs() < 1e-4,
                "pixel {i}: {} vs {want}",
                tl[i]
            );
        }
    }
}

/// A dark field of 0.01 cd/m² with one headlight of 2e6 cd/m² (the default view).
fn headlight() -> (HdrImage, usize) {
    let (w, h) = (320, 180);
    let mut img = HdrImage::zeros(w, h);
    for i in 0..w * h {
        grey(&mut img, i, 0.01);
    }
    let light = 90 * w + 200;
    grey(&mut img, light, 2e6);
    (img, light)
}

#[test]
fn glare_feeds_the_adaptation_map() {
    use visadapt::glare::Glare;
    use visadapt::operator::{local_map, prepare};
    let (img, light) = headlight();
    let options = LocalAdaptation::default();
    let without = local(options.radius_deg);
    let with = ViewingConditions {
        glare: Some(Glare::default()),
        ..without.clone()
    };
    let level = |c: &ViewingConditions, i: usize| {
        let (retina, report) = prepare(&img, c).unwrap();
        local_map(&retina, &report, c, &options)
            .unwrap()
            .adaptation_cd_m2(i)
    };
    // 20 px (about 3°) left of the light, and a far corner.
    let near = light - 20;
    let (a0, a1) = (level(&without, near), level(&with, near));
    let (c0, c1) = (level(&without, 0), level(&with, 0));
    println!("local adaptation near the light {a0:.4e} -> {a1:.4e}, corner {c0:.4e} -> {c1:.4e}");
    // Near the light the veil (tens of times the 0.01 cd/m² field, see the glare tests)
    // raises the local adaptation by far more than far from it.
    assert!(a1 > 3.0 * a0, "{a0} -> {a1}");
    assert!(
        a1 / a0 > 2.0 * (c1 / c0),
        "near ×{} corner ×{}",
        a1 / a0,
        c1 / c0
    );
    // And the map's report says so through map().
    let out = run(&img, &with);
    assert!(out.report.glare.is_some() && out.report.local.is_some());
}

#[test]
fn huge_finite_pixels_stay_finite() {
    // One pixel of 1e37 cd/m² in a dark scene: the global operator scales it down before
    // the mapping (issue 9 §4); the local tables are bounded the same way.
    let (mut img, light) = headlight();
    grey(&mut img, light, 1e37);
    let out = run(&img, &local(1.0));
    for p in [&out.image.r, &out.image.g, &out.image.b] {
        assert!(p.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    }
    assert_eq!(out.stats.saturated, 1);
    // The rest of the image is not black.
    assert!(display_cd_m2(&out.image, 0) > 0.01);
}

/// A textured frame of `w × h` pixels with a lit patch (four log units of range).
fn textured(w: usize, h: usize, seed: u32) -> HdrImage {
    let mut img = HdrImage::zeros(w, h);
    let mut s = seed;
    for y in 0..h {
        for x in 0..w {
            let lit = x > w / 2 && y < h / 3;
            let l = if lit { 500.0 } else { 0.05 } * (0.5 + noise(&mut s));
            grey(&mut img, y * w + x, l);
        }
    }
    img.absolute_units = true;
    img
}

#[test]
fn a_reused_map_is_a_fresh_one_bit_for_bit() {
    use visadapt::local::AdaptationMap;
    use visadapt::operator::{local_map, local_map_into, plan};
    let options = LocalAdaptation::default();
    let mut kept = AdaptationMap::default();
    // Larger, smaller, then the same size again; with and without acuity (the sigma
    // plane comes and goes).
    for (w, h, acuity, seed) in [
        (160, 90, true, 1),
        (64, 48, true, 2),
        (96, 64, false, 3),
        (96, 64, true, 4),
        (96, 64, true, 5),
    ] {
        let img = textured(w, h, seed);
        let cond = ViewingConditions {
            acuity,
            view: Some(visadapt::View::perspective(20.0, w, h)),
            ..local(options.radius_deg)
        };
        let report = plan(&img, &cond).expect("plan");
        let fresh = local_map(&img, &report, &cond, &options).expect("map");
        assert_eq!(fresh.acuity_sigma_px.is_some(), acuity, "{w}x{h}");
        local_map_into(&img, &report, &cond, &options, &mut kept).expect("map");
        assert_eq!(kept.offset_log.len(), w * h);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&kept.offset_log), bits(&fresh.offset_log), "{w}x{h}");
        assert_eq!(
            bits(&kept.offset_scotopic_log),
            bits(&fresh.offset_scotopic_log),
            "{w}x{h}"
        );
        assert_eq!(
            kept.acuity_sigma_px.as_deref().map(bits),
            fresh.acuity_sigma_px.as_deref().map(bits),
            "{w}x{h}"
        );
        assert_eq!(kept, fresh, "{w}x{h}");
    }
    // An invalid radius is refused and leaves the map as it was.
    let img = textured(32, 32, 6);
    let cond = local(1.0);
    let report = plan(&img, &cond).expect("plan");
    let before = kept.clone();
    let bad = LocalAdaptation {
        radius_deg: -1.0,
        ..options
    };
    assert!(local_map_into(&img, &report, &cond, &bad, &mut kept).is_err());
    assert_eq!(kept, before);
}

/// A sequence computes local adaptation's map once for all frames after the step
/// (`operator::apply_state_with_map`): each frame equals the frame stage computed on its
/// own with a fresh map (`operator::apply_state_into`), bit for bit; a map of another
/// size is refused.
#[test]
fn a_sequences_frames_share_one_map_bit_for_bit() {
    use visadapt::adaptation::highest_visible;
    use visadapt::local::AdaptationMap;
    use visadapt::operator::{apply_state_into, apply_state_with_map, prepare};
    use visadapt::sequence::{Sequence, render};
    let scene = textured(120, 80, 9);
    let cond = ViewingConditions {
        acuity: true,
        view: Some(visadapt::View::perspective(20.0, 120, 80)),
        ..local(1.0)
    };
    let seq = Sequence::new(300.0, 0.05, vec![1.0, 30.0, 300.0]).expect("sequence");
    // The retina of the frames after the step, as `render` rescales the scene in place.
    let mut after_scene = scene.clone();
    let hv = f64::from(highest_visible(&after_scene.y, cond.hot_pixel_fraction));
    after_scene.scale((seq.from_cd_m2 / hv) as f32);
    after_scene.absolute_units = true;
    after_scene.scale((seq.to_cd_m2 / seq.from_cd_m2) as f32);
    let (retina, after) = prepare(&after_scene, &cond).expect("prepare");
    let mut compared = 0;
    render(&scene, &seq, &cond, |f| {
        if f.index > 0 {
            assert_eq!(
                f.report.world_adaptation_cd_m2,
                after.world_adaptation_cd_m2
            );
            let mut want = DisplayImage::default();
            let (_, stats) =
                apply_state_into(&retina, &after, f.adaptation, &cond, &mut want).expect("frame");
            assert_same_pixels(f.image, &want, &format!("frame {}", f.index));
            assert_eq!(f.stats, stats);
            compared += 1;
        }
        Ok(())
    })
    .expect("render");
    assert_eq!(compared, 3);
    let other = AdaptationMap::default();
    let state = visadapt::timecourse::Adaptation::adapted(1.0, 2.0).expect("state");
    let err = apply_state_with_map(
        &retina,
        &after,
        &state,
        &cond,
        &other,
        &mut DisplayImage::default(),
    )
    .expect_err("a map of another size");
    assert!(err.to_string().contains("adaptation map"), "{err}");
}
