//! `visadapt visible` and `visadapt tolerance`, end to end.

mod common;
use common::*;

use std::path::{Path, PathBuf};
use visadapt::{HdrImage, Limits};

/// `image` changed by `delta[i]` cd/m² at each pixel, in its own colour.
fn perturbed(image: &HdrImage, delta: impl Fn(usize, usize) -> f64) -> HdrImage {
    let mut out = image.clone();
    for y in 0..image.height {
        for x in 0..image.width {
            let i = y * image.width + x;
            let f = ((image.y[i] as f64 + delta(x, y)) / image.y[i] as f64) as f32;
            out.x[i] *= f;
            out.y[i] *= f;
            out.z[i] *= f;
            if let Some(s) = &mut out.scotopic {
                s[i] *= f;
            }
        }
    }
    out
}

/// A 64×32 grey field at 100 cd/m², and the same with ±3 thresholds of noise (random
/// sign) on its left half and ±0.5 threshold on its right half; the threshold is
/// t_p(50) = 3.0878 cd/m², the observer adapting to half the field's luminance.
fn noisy_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let reference = grey(64, 32, 100.0);
    let t = tp(50.0);
    let test = perturbed(&reference, |x, y| {
        let sign = if (x * 7 + y * 13) % 5 < 2 { -1.0 } else { 1.0 };
        sign * t * if x < 32 { 3.0 } else { 0.5 }
    });
    (
        write_exr(dir.join("ref.exr"), &reference),
        write_exr(dir.join("test.exr"), &test),
    )
}

#[test]
fn identical_images_show_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, _) = noisy_pair(dir.path());
    let out = succeed(
        visadapt()
            .arg("visible")
            .arg(&reference)
            .arg(&reference)
            .arg("--json"),
    );
    let v = json(&out.stdout);
    assert_eq!(v["visible_fraction"], 0.0);
    assert_eq!(v["mean_jnd"], 0.0);
    assert_eq!(v["max_jnd"], 0.0);
    assert!((v["adaptation_cd_m2"].as_f64().unwrap() - 50.0).abs() < 1e-4);
}

#[test]
fn noise_is_reported_in_jnds_with_a_heat_map() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, test) = noisy_pair(dir.path());
    let map = dir.path().join("map.png");
    let out = succeed(
        visadapt()
            .arg("visible")
            .arg(&reference)
            .arg(&test)
            .arg("-o")
            .arg(&map)
            .arg("--json"),
    );
    let v = json(&out.stdout);
    for key in [
        "visible_fraction",
        "mean_jnd",
        "max_jnd",
        "adaptation_cd_m2",
        "scotopic_adaptation_cd_m2",
        "cone_threshold_cd_m2",
        "rod_weight",
        "blur_sigma_px",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    // Left half 3 JND (visible), right half 0.5 JND: half the pixels, mean 1.75, max 3.
    assert_eq!(v["visible_fraction"], 0.5);
    assert!((v["mean_jnd"].as_f64().unwrap() - 1.75).abs() < 2e-3, "{v}");
    assert!((v["max_jnd"].as_f64().unwrap() - 3.0).abs() < 2e-3, "{v}");
    assert!((v["cone_threshold_cd_m2"].as_f64().unwrap() / tp(50.0) - 1.0).abs() < 1e-6);
    assert_eq!(v["rod_weight"], 0.0);
    // 60° over 64 px: the acuity Gaussian is far below a pixel.
    assert_eq!(v["blur_sigma_px"], 0.0);

    // The heat map: the image, then a colour bar panel; at least 240 px high. The 64×32
    // image is enlarged 7 times (224 rows, the most whole pixels within 240) and centred
    // vertically, 8 rows above and below (issue 13: it sat unenlarged in the top corner).
    let heat = read_png(&map);
    let (w, h, rgb) = (heat.width as usize, heat.height as usize, heat.samples);
    assert_eq!((w, h), (7 * 64 + 150, 240));
    let px = |x: usize, y: usize| {
        let i = (y * w + x) * 3;
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    };
    // 3 JND is red-magenta (inferno at 0.49), 0.5 JND dark purple (inferno at 0.23): image
    // pixel (x, y) covers the canvas from (7x, 8 + 7y) to (7x + 6, 8 + 7y + 6).
    let at = |x: usize, y: usize, dx: usize, dy: usize| px(7 * x + dx, 8 + 7 * y + dy);
    for (dx, dy) in [(0, 0), (6, 6), (3, 2)] {
        assert_eq!(at(10, 10, dx, dy), [185, 54, 85]);
        assert_eq!(at(50, 10, dx, dy), [81, 15, 103]);
        assert_eq!(at(10, 0, dx, dy), [185, 54, 85]);
        assert_eq!(at(50, 31, dx, dy), [81, 15, 103]);
    }
    // Above and below the image: white. The bar: pale yellow at its top (100 JND),
    // near-black at its bottom (0.1 JND); black label text beside it.
    for x in [0, 70, 447] {
        for y in [0, 7, 232, 239] {
            assert_eq!(px(x, y), [255, 255, 255], "({x}, {y})");
        }
    }
    let bar_x = 7 * 64 + 24;
    assert_eq!(px(bar_x, 34), [252, 255, 164]);
    assert_eq!(px(bar_x, 226), [0, 0, 4]);
    let dark_text = (7 * 64 + 40..w)
        .flat_map(|x| (0..h).map(move |y| (x, y)))
        .filter(|&(x, y)| px(x, y).iter().all(|&c| c < 80))
        .count();
    assert!(dark_text > 100, "{dark_text}");
    let mut names = files_in(dir.path());
    names.retain(|n| n != "ref.exr" && n != "test.exr");
    assert_eq!(names, ["map.png"]);
}

#[test]
fn text_report_names_the_results() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, test) = noisy_pair(dir.path());
    let out = visadapt()
        .arg("visible")
        .arg(&reference)
        .arg(&test)
        .output()
        .unwrap();
    assert!(out.status.success());
    let s = String::from_utf8(out.stdout).unwrap();
    assert!(s.contains("50.000 % of the pixels at 1 JND or more"), "{s}");
    assert!(s.contains("mean 1.75"), "{s}");
    assert!(
        s.contains("adapted to 50 cd/m² (from the reference)"),
        "{s}"
    );
}

/// The same noise, the scene lit at 0.01 cd/m²: the rods' Weber fraction is 40 %, and the
/// ±9.3 % noise becomes invisible (without the acuity Gaussian, which would lower it still).
#[test]
fn the_same_noise_is_invisible_at_night() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, test) = noisy_pair(dir.path());
    let out = succeed(visadapt().arg("visible").arg(&reference).arg(&test).args([
        "--peak",
        "0.01",
        "--no-acuity",
        "--json",
    ]));
    let v = json(&out.stdout);
    assert_eq!(v["visible_fraction"], 0.0);
    // Adapted to 0.005 cd/m² and 0.0113 scotopic cd/m² (k = 1); the left half changes by
    // 3·t_p(50)·1e-4 cd/m², seen by the rods: 2.261·9.263e-4 / t_s(0.011305) = 0.352 JND.
    assert!((v["adaptation_cd_m2"].as_f64().unwrap() - 0.005).abs() < 1e-8);
    let expected = 2.261 * 3.0 * tp(50.0) * 1e-4 / ts(0.011_305);
    assert!(
        (v["max_jnd"].as_f64().unwrap() / expected - 1.0).abs() < 2e-3,
        "{v}"
    );
    assert!((expected - 0.352).abs() < 1e-3, "{expected}");
}

#[test]
fn given_adaptation_and_field_of_view() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, test) = noisy_pair(dir.path());
    let run = |extra: &[&str]| {
        let out = succeed(
            visadapt()
                .arg("visible")
                .arg(&reference)
                .arg(&test)
                .arg("--json")
                .args(extra),
        );
        json(&out.stdout)
    };
    // Adapted to 5 cd/m² instead of 50: the cones' threshold falls to t_p(5) = 0.746.
    let v = run(&["--world-adaptation", "5"]);
    assert_eq!(v["adaptation_cd_m2"], 5.0);
    assert_eq!(v["adaptation_source"], "given");
    assert!((v["cone_threshold_cd_m2"].as_f64().unwrap() / tp(5.0) - 1.0).abs() < 1e-9);
    assert!((tp(5.0) - 0.746).abs() < 1e-3);
    assert_eq!(v["visible_fraction"], 1.0);
    // 1° over 64 px: 64.0 px/degree at the centre; Eq. 7 at 50 cd/m² (cutoff 46.76 c/deg,
    // c = 0.06176) gives sigma = sqrt(ln(1/c)/2)/(π·46.76) = 0.008034°, i.e. 0.514 px.
    let v = run(&["--fov", "1"]);
    assert!(
        (v["pixels_per_degree"].as_f64().unwrap() - 64.0).abs() < 0.01,
        "{v}"
    );
    assert!(
        (v["blur_sigma_px"].as_f64().unwrap() - 0.514).abs() < 0.003,
        "{v}"
    );
    // The blur averages the random-sign noise: fewer JNDs than without it.
    let sharp = run(&["--fov", "1", "--no-acuity"]);
    assert_eq!(sharp["blur_sigma_px"], 0.0);
    assert!(v["mean_jnd"].as_f64().unwrap() < 0.9 * sharp["mean_jnd"].as_f64().unwrap());
}

#[test]
fn images_of_different_sizes_give_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let a = write_exr(dir.path().join("a.exr"), &grey(64, 32, 1.0));
    let b = write_exr(dir.path().join("b.exr"), &grey(32, 64, 1.0));
    let map = dir.path().join("map.png");
    let out = visadapt()
        .arg("visible")
        .arg(&a)
        .arg(&b)
        .arg("-o")
        .arg(&map)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = one_line_error(&out.stderr);
    assert!(
        e.contains("b.exr") && e.contains("32x64") && e.contains("64x32"),
        "{e}"
    );
    assert!(e.contains("same size"), "{e}");
    assert_eq!(files_in(dir.path()), ["a.exr", "b.exr"]);
}

#[test]
fn unreadable_images_give_one_clear_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = write_exr(dir.path().join("good.exr"), &grey(16, 16, 1.0));
    let garbage = dir.path().join("garbage.hdr");
    std::fs::write(&garbage, b"this is not an image").unwrap();
    let missing = dir.path().join("missing.exr");
    let map = dir.path().join("map.png");
    for (a, b, name) in [
        (&good, &missing, "missing.exr"),
        (&missing, &good, "missing.exr"),
        (&good, &garbage, "garbage.hdr"),
        (&garbage, &good, "garbage.hdr"),
    ] {
        let out = visadapt()
            .arg("visible")
            .arg(a)
            .arg(b)
            .arg("-o")
            .arg(&map)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let e = one_line_error(&out.stderr);
        assert!(e.contains(name), "{e}");
    }
    assert_eq!(files_in(dir.path()), ["garbage.hdr", "good.exr"]);
}

#[test]
fn bad_arguments_are_refused_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    let good = write_exr(dir.path().join("good.exr"), &grey(16, 16, 1.0));
    for (extra, needle) in [
        (vec!["-o", "map.jpg"], "map.jpg"),
        (vec!["--fov", "0"], "--fov"),
        (vec!["--peak", "-1"], "--peak"),
        (vec!["--world-adaptation", "0"], "world-adaptation"),
    ] {
        let out = visadapt()
            .current_dir(dir.path())
            .arg("visible")
            .arg(&good)
            .arg(&good)
            .args(&extra)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{extra:?}");
        let e = cli_error(&out.stderr);
        assert!(e.contains(needle), "{e}");
    }
    // The map may not replace an input.
    let out = visadapt()
        .arg("visible")
        .arg(&good)
        .arg(&good)
        .arg("-o")
        .arg(&good)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert_eq!(files_in(dir.path()), ["good.exr"]);
}

#[test]
fn tolerance_map_is_written_in_cd_m2() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_exr(dir.path().join("in.exr"), &grey(40, 20, 100.0));
    let tol = dir.path().join("tol.exr");
    let out = succeed(
        visadapt()
            .arg("tolerance")
            .arg(&input)
            .arg("-o")
            .arg(&tol)
            .arg("--json"),
    );
    let v = json(&out.stdout);
    assert!((v["median_tolerance_cd_m2"].as_f64().unwrap() / tp(50.0) - 1.0).abs() < 1e-6);
    assert!((v["median_relative_tolerance"].as_f64().unwrap() - 0.030_878).abs() < 1e-5);
    // Read back: one grey channel, absolute units, t_p(50) = 3.0878 cd/m² everywhere.
    let map = visadapt::io::read(&tol, &Limits::default()).unwrap();
    assert_eq!((map.width, map.height), (40, 20));
    assert!(map.absolute_units);
    assert!(map.scotopic.is_none());
    assert!(
        map.y
            .iter()
            .all(|&t| (t as f64 / tp(50.0) - 1.0).abs() < 1e-6),
        "{}",
        map.y[0]
    );

    // Starlight: the same field at 0.002 cd/m²: the rods set the threshold,
    // t_s(0.002261)/2.261 = 1.0832e-3 cd/m², 54 % of the luminance.
    let out = succeed(
        visadapt()
            .arg("tolerance")
            .arg(&input)
            .arg("-o")
            .arg(&tol)
            .args(["--peak", "0.002", "--json"]),
    );
    let v = json(&out.stdout);
    let expected = ts(0.002_261) / 2.261;
    assert!((v["median_tolerance_cd_m2"].as_f64().unwrap() / expected - 1.0).abs() < 1e-4);
    assert!((expected - 1.083_2e-3).abs() < 1e-6);
    assert_eq!(files_in(dir.path()), ["in.exr", "tol.exr"]);
}

#[test]
fn tolerance_bad_input_gives_one_clear_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"v/1\x01 truncated").unwrap();
    let tol = dir.path().join("tol.exr");
    for (input, name) in [
        (dir.path().join("missing.hdr"), "missing.hdr"),
        (garbage.clone(), "garbage.exr"),
    ] {
        let out = visadapt()
            .arg("tolerance")
            .arg(&input)
            .arg("-o")
            .arg(&tol)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let e = one_line_error(&out.stderr);
        assert!(e.contains(name), "{e}");
    }
    let input = write_exr(dir.path().join("in.exr"), &grey(8, 8, 1.0));
    let out = visadapt()
        .arg("tolerance")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("tol.png"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains(".exr"));
    assert_eq!(files_in(dir.path()), ["garbage.exr", "in.exr"]);
}

/// `tolerance --fov` (the view flags `map` and `visible` have): the view sets how many
/// degrees a pixel spans for the stages that work in degrees. Acuity does not enter the
/// tolerance (it holds for errors of any extent), so with global adaptation and no glare
/// the view changes nothing; with local adaptation (a neighbourhood of 1 degree, `local`
/// module) it does. A 64×16 ramp, log luminance falling linearly from 1000 cd/m² on the
/// left to 1 cd/m² on the right (0.047 log units per pixel): at a 60-degree view a pixel
/// spans 0.94 degree and a pixel's neighbourhood is about itself, so the darkest column
/// adapts to about its own level; at a 2-degree view the 1-degree neighbourhood spans half
/// the ramp (less the edge-aware term: 2 degrees per log unit, 0.094 degree per pixel),
/// and at the ramp's dark end it reaches only brighter pixels: a higher adaptation, a
/// higher tolerance. Both against the library's map for the same view, exactly.
#[test]
fn tolerance_takes_the_view_flags() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (64, 16);
    let mut field = grey(w, h, 1.0);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let l = 10f32.powf(3.0 * (1.0 - x as f32 / (w - 1) as f32));
            (field.x[i], field.y[i], field.z[i]) = (l, l, l);
            field.scotopic.as_mut().unwrap()[i] = 2.261 * l;
        }
    }
    let input = write_exr(dir.path().join("ramp.exr"), &field);
    let run = |extra: &[&str]| -> Vec<f32> {
        let tol = dir.path().join("tol.exr");
        let out = visadapt()
            .arg("tolerance")
            .arg(&input)
            .arg("-o")
            .arg(&tol)
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        visadapt::io::read(&tol, &Limits::default()).unwrap().y
    };
    let mut local = Vec::new();
    for fov in [60.0, 2.0] {
        // The CLI's map is the library's for that view.
        let got = run(&["--adaptation", "local", "--fov", &fov.to_string()]);
        let conditions = visadapt::operator::ViewingConditions {
            acuity: false,
            adaptation: visadapt::operator::AdaptationMode::Local(Default::default()),
            view: Some(visadapt::View::perspective(fov, w, h)),
            ..Default::default()
        };
        let observation =
            visadapt::visibility::Observation::for_image(&field, &conditions).unwrap();
        let expected = visadapt::visibility::tolerance_map(&field, &observation.viewer()).unwrap();
        assert_eq!(got, expected, "--fov {fov}");
        local.push(got);
    }
    let dark = 8 * w + w - 1;
    // 60 degrees: adapted to at most its own 1 cd/m² (the brightest neighbourhoods keep
    // the global 500 cd/m², half the highest visible), so under t_p(1) = 0.391 cd/m²
    // (the rods, pooled, only lower it); measured 0.312.
    assert!((local[0][dark] as f64) < tp(1.0), "{}", local[0][dark]);
    // 2 degrees: the dark end sees brighter pixels; measured 0.425, 36 % higher.
    assert!(
        local[1][dark] > 1.2 * local[0][dark],
        "{} against {}",
        local[1][dark],
        local[0][dark]
    );
    // Without a view in the file or --fov, the stages in degrees say they guess it.
    for (extra, warned) in [
        (&["--adaptation", "local"][..], true),
        (&["--glare"][..], true),
        (&[][..], false),
    ] {
        let out = visadapt()
            .arg("tolerance")
            .arg(&input)
            .arg("-o")
            .arg(dir.path().join("tol.exr"))
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            stderr.matches("does not record its view").count(),
            usize::from(warned),
            "{extra:?}: {stderr}"
        );
    }
    // Global adaptation without glare: the view changes nothing.
    let global = run(&[]);
    assert_eq!(run(&["--fov", "5"]), global);
    // A perspective view under 180 degrees, as for map.
    let out = visadapt()
        .arg("tolerance")
        .arg(&input)
        .args(["-o", "t.exr", "--fov", "200"])
        .output()
        .unwrap();
    assert!(usage_error(&out.stderr).contains("--projection fisheye"));
}
