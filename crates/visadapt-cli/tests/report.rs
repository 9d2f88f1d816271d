//! The CLI prints the library's JSON reports (`visadapt::report`), so the CLI, the Python
//! package and the viewer agree key for key and value for value.

mod common;
use common::*;
use serde_json::Value;
use visadapt::observer::Observer;
use visadapt::operator::{self, ViewingConditions};
use visadapt::visibility::{self, ToleranceSummary, Viewer};
use visadapt::{Limits, View, io, report, timecourse};

/// The same keys, strings, booleans and integers, and numbers within 1e-12 relative: the
/// binary and this test may be built at different optimisation levels, which can move the
/// last bit of a libm result.
fn assert_same(got: &Value, want: &Value, at: &str) {
    match (got, want) {
        (Value::Object(g), Value::Object(w)) => {
            let keys = |m: &serde_json::Map<String, Value>| m.keys().cloned().collect::<Vec<_>>();
            assert_eq!(keys(g), keys(w), "keys of {at}");
            for (k, v) in w {
                assert_same(&g[k], v, &format!("{at}.{k}"));
            }
        }
        (Value::Array(g), Value::Array(w)) => {
            assert_eq!(g.len(), w.len(), "length of {at}");
            for (i, (g, w)) in g.iter().zip(w).enumerate() {
                assert_same(g, w, &format!("{at}[{i}]"));
            }
        }
        (Value::Number(g), Value::Number(w)) if w.is_f64() => {
            let (g, w) = (g.as_f64().unwrap(), w.as_f64().unwrap());
            let tol = 1e-12 * w.abs().max(f64::MIN_POSITIVE);
            assert!((g - w).abs() <= tol, "{at}: {g} vs {w}");
        }
        _ => assert_eq!(got, want, "{at}"),
    }
}

#[test]
fn map_json_is_the_library_report_of_the_same_run() {
    let input = data("WideFloatRange.exr");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.exr");
    let cli = visadapt()
        .args(["map", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args(["--json", "--fov", "40", "--display-max", "120"])
        .args(["--world-adaptation", "3"])
        .assert()
        .success();

    let image = io::read(&input, &Limits::default()).unwrap();
    let conditions = ViewingConditions {
        display_max_cd_m2: 120.0,
        world_adaptation_cd_m2: Some(3.0),
        view: Some(View::perspective(40.0, image.width, image.height)),
        ..ViewingConditions::default()
    };
    let lib = operator::map(&image, &conditions).unwrap();
    let expected = report::map_json(&lib.report, &lib.stats, 1.0);
    assert_same(&json(&cli.get_output().stdout), &expected, "report");
    // A few values checked against the model directly, so that equality is not vacuous.
    assert_eq!(expected["adaptation_cd_m2"], 3.0);
    assert_eq!(expected["adaptation_source"], "given");
    assert_eq!(expected["display_max_cd_m2"], 120.0);
    assert_eq!(expected["view"]["horizontal_fov_deg"], 40.0);
    let tp3 = tp(3.0);
    let got = expected["cone_threshold_cd_m2"].as_f64().unwrap();
    assert!((got / tp3 - 1.0).abs() < 1e-12, "{got} vs Eq. 4 {tp3}");
}

#[test]
fn observer_json_is_the_library_report() {
    for (l, scotopic) in [(0.01, None), (40.0, Some(90.0))] {
        let mut cmd = visadapt();
        cmd.args(["observer", &l.to_string(), "--json", "--display-max", "100"]);
        if let Some(s) = scotopic {
            cmd.args(["--scotopic", &s.to_string()]);
        }
        let cli = cmd.assert().success();
        let o = Observer::new(l, scotopic, Some(100.0)).unwrap();
        let expected = report::observer_json(&o);
        assert_same(&json(&cli.get_output().stdout), &expected, "report");
        assert_eq!(expected["adaptation_cd_m2"], l);
        let got = expected["rod_threshold_scotopic_cd_m2"].as_f64().unwrap();
        let want = ts(o.scotopic_adaptation_cd_m2);
        assert!((got / want - 1.0).abs() < 1e-12, "{got} vs Eq. 5 {want}");
    }
}

#[test]
fn timecourse_json_is_the_library_report() {
    let cli = visadapt()
        .args(["timecourse", "--from", "1412", "--to", "0.1"])
        .args(["--times", "0,60,210,1800", "--json"])
        .assert()
        .success();
    let sp = visadapt::scotopic::EQUAL_ENERGY_SP_RATIO;
    let moments = timecourse::course(
        (1412.0, 1412.0 * sp),
        (0.1, 0.1 * sp),
        &[0.0, 60.0, 210.0, 1800.0],
        80.0,
        Default::default(),
    )
    .unwrap();
    let expected = report::timecourse_json(&moments);
    assert_same(&json(&cli.get_output().stdout), &expected, "report");
    assert_eq!(expected.as_array().unwrap().len(), 4);
    assert_eq!(expected[3]["t_seconds"], 1800.0);
}

#[test]
fn visible_and_tolerance_json_are_the_library_reports() {
    let reference = data("GrayRampsHorizontal.exr");
    let dir = tempfile::tempdir().unwrap();
    let a = io::read(&reference, &Limits::default()).unwrap();
    let conditions = ViewingConditions::default();
    let (viewer, r) = Viewer::for_image(&a, &conditions).unwrap();

    // The same image twice: no visible difference, and the library agrees.
    let cli = visadapt()
        .args(["visible", reference.to_str().unwrap()])
        .args([reference.to_str().unwrap(), "--json"])
        .assert()
        .success();
    let d = visibility::difference(&a, &a, &viewer).unwrap();
    let expected = report::difference_json(&d, &r, 1.0, None);
    assert_same(&json(&cli.get_output().stdout), &expected, "report");
    assert_eq!(expected["max_jnd"], 0.0);

    let out = dir.path().join("tol.exr");
    let cli = visadapt()
        .args(["tolerance", reference.to_str().unwrap()])
        .args(["-o", out.to_str().unwrap(), "--json"])
        .assert()
        .success();
    let conditions = ViewingConditions {
        acuity: false,
        ..ViewingConditions::default()
    };
    let (viewer, r) = Viewer::for_image(&a, &conditions).unwrap();
    let tolerance = visibility::tolerance_map(&a, &viewer).unwrap();
    let summary = ToleranceSummary::of(&tolerance, &a.y).unwrap();
    let expected = report::tolerance_json(&summary, &r, 1.0, Some(out.to_str().unwrap()));
    assert_same(&json(&cli.get_output().stdout), &expected, "report");
    assert!(summary.min_cd_m2 <= summary.median_cd_m2);
    assert!(summary.median_cd_m2 <= summary.max_cd_m2);
}

#[test]
fn map_json_reports_local_adaptation() {
    let input = data("sunset-fisheye.hdr");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let cli = visadapt()
        .args(["map", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args([
            "--json",
            "--adaptation",
            "local",
            "--adaptation-radius",
            "2",
        ])
        .assert()
        .success();
    let v = json(&cli.get_output().stdout);
    assert_eq!(v["adaptation"], "local");
    let l = &v["local"];
    assert_eq!(l["radius_deg"], 2.0);
    let q = &l["adaptation_cd_m2"];
    let (lo, mid, hi) = (
        q["min"].as_f64().unwrap(),
        q["p50"].as_f64().unwrap(),
        q["max"].as_f64().unwrap(),
    );
    // The brightest neighbourhoods sit at (or just above) the global level; the median far
    // below it in this sunset (sky over dark ground).
    let global = v["adaptation_cd_m2"].as_f64().unwrap();
    assert!(
        lo < mid && mid < global && global <= hi * 1.0001,
        "{lo} {mid} {global} {hi}"
    );
    // The default stays global, with no local part.
    let cli = visadapt()
        .args([
            "map",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--json",
        ])
        .assert()
        .success();
    let v = json(&cli.get_output().stdout);
    assert_eq!(v["adaptation"], "global");
    assert!(v["local"].is_null());
    // A bad radius is one clear error.
    visadapt()
        .args(["map", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args(["--adaptation", "local", "--adaptation-radius", "0"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("adaptation-radius"));
}

/// Issue 8 §5 (failed before: `acuity_fallback` was true by rounding in the rod Weber range,
/// the text printed Eq. 7's contrast as if used, and nothing said Fig. 7 was extrapolated).
#[test]
fn observer_reports_the_contrast_used_and_extrapolation() {
    let run = |l: &str, json_out: bool| {
        let mut cmd = visadapt();
        cmd.args(["observer", l]);
        if json_out {
            cmd.arg("--json");
        }
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    };
    // Rod Weber range (0.05 .. 0.5 cd/m², rods more sensitive): no fallback, the contrast
    // used is Eq. 7's.
    for l in ["0.05", "0.1", "0.2", "0.3", "0.5"] {
        let v = json(&run(l, true));
        assert_eq!(v["acuity_fallback"], false, "{l}: {v}");
        assert_eq!(v["acuity_contrast_used"], v["threshold_contrast"]);
        assert_eq!(v["acuity_extrapolated"], false);
    }
    // 1e-3 cd/m²: Eq. 7 has no solution (t/L > 1); the text gives both contrasts.
    let v = json(&run("1e-3", true));
    assert_eq!(v["acuity_fallback"], true);
    let used = v["acuity_contrast_used"].as_f64().unwrap();
    // The rods' contrast held at the Weber fraction; the cones (t/L = 190) add ~1e-10 to
    // the pooled sensitivity (the default rule), nothing to the envelope.
    assert!((used - 10f64.powf(-0.395)).abs() < 1e-9);
    assert_eq!(v["acuity_threshold"], "pooled");
    assert!(v["threshold_contrast"].as_f64().unwrap() > 1.0);
    let text = String::from_utf8(run("1e-3", false)).unwrap();
    assert!(
        text.contains("contrast at the cutoff 0.4027 (Eq. 7 asks for"),
        "{text}"
    );
    // 1e-6 cd/m²: beyond Shaler's data.
    assert_eq!(json(&run("1e-6", true))["acuity_extrapolated"], true);
    let text = String::from_utf8(run("1e-6", false)).unwrap();
    assert!(text.contains("Fig. 7 extrapolated"), "{text}");
    let text = String::from_utf8(run("10", false)).unwrap();
    assert!(
        !text.contains("extrapolated") && !text.contains("asks for"),
        "{text}"
    );
}

/// Issue 8 §5 (failed before: only a count). A scene whose adaptation is in Eq. 4's Weber
/// range (half its pixels at 2000 cd/m², the rest at 200) on the default 80 cd/m² display:
/// the whites go to 2·L_wa → t_p(40)·10^1.255 = 94.1 cd/m² and clip. The report says how many,
/// why, and which display maximum shows them (2 × 10^1.9 = 158.9 cd/m²: the display
/// observer then is on the Weber branch too).
#[test]
fn map_says_how_many_pixels_clip_why_and_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bright.exr");
    let mut im = visadapt::HdrImage::zeros(64, 64);
    for k in 0..im.len() {
        let l = if k % 2 == 0 { 2000.0 } else { 200.0 };
        (im.x[k], im.y[k], im.z[k]) = (l, l, l); // grey of the file's equal-energy white
    }
    im.absolute_units = true;
    write_exr(&input, &im);
    let out = dir.path().join("out.png");
    let run = |extra: &[&str]| {
        let o = succeed(
            visadapt()
                .args([
                    "map",
                    input.to_str().unwrap(),
                    "-o",
                    out.to_str().unwrap(),
                    "--fov",
                    "40",
                ])
                .args(extra),
        );
        o.stdout
    };
    let v = json(&run(&["--json"]));
    assert!(v["pixels_clipped_fraction"].as_f64().unwrap() > 0.45, "{v}");
    let shown = v["highest_visible_display_cd_m2"].as_f64().unwrap();
    assert!((shown - 94.1).abs() < 0.2, "{shown}");
    let need = v["display_max_to_show_highest_visible_cd_m2"]
        .as_f64()
        .unwrap();
    assert!((need - 158.9).abs() < 0.5, "{need}");
    let text = String::from_utf8(run(&[])).unwrap();
    assert!(
        text.contains("pixels (50.0 %) above the display maximum"),
        "{text}"
    );
    assert!(
        text.contains("why:") && text.contains("--display-max 159"),
        "{text}"
    );
    // On that display nothing clips and the report says nothing more.
    let v = json(&run(&["--json", "--display-max", "170"]));
    assert_eq!(v["pixels_clipped"], 0, "{v}");
    assert!(v["display_max_to_show_highest_visible_cd_m2"].is_null());
}

/// Issue 8 §4: `--acuity-threshold` chooses Eq. 7's threshold contrast. A grey scene at
/// 0.2 cd/m² (adapted to 0.1): the default, the JND metric's pooled threshold, 0.5427
/// (hand computation in `acuity.rs`); `envelope`, the paper's rule, the rod Weber fraction
/// 0.4027, with a wider blur; the text report names the paper's rule.
#[test]
fn map_takes_the_acuity_threshold_rule() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("dim.exr");
    let mut im = visadapt::HdrImage::zeros(32, 32);
    im.x.fill(0.2);
    im.y.fill(0.2);
    im.z.fill(0.2);
    im.absolute_units = true;
    write_exr(&input, &im);
    let out = dir.path().join("out.png");
    let run = |extra: &[&str]| {
        let o = succeed(
            visadapt()
                .args(["map", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
                .args(["--fov", "2"])
                .args(extra),
        );
        String::from_utf8(o.stdout).unwrap()
    };
    let pooled = json(run(&["--json"]).as_bytes());
    let envelope = json(run(&["--json", "--acuity-threshold", "envelope"]).as_bytes());
    assert_eq!(pooled["acuity_threshold"], "pooled");
    assert_eq!(envelope["acuity_threshold"], "envelope");
    let c = |v: &Value| v["threshold_contrast"].as_f64().unwrap();
    assert!((c(&pooled) - 0.5427).abs() < 1e-3, "{pooled}");
    assert!((c(&envelope) - 0.4027).abs() < 1e-3, "{envelope}");
    let sigma = |v: &Value| v["acuity_blur_sigma_deg"].as_f64().unwrap();
    assert!(sigma(&envelope) > 1.2 * sigma(&pooled));
    assert!(run(&["--acuity-threshold", "envelope"]).contains("the paper's rule"));
    assert!(!run(&[]).contains("the paper's rule"));
}

/// A `w × h` grey EXR at `l` cd/m² (equal-energy, absolute units, no scotopic channel),
/// one pixel `odd` if given.
fn grey_exr(path: &std::path::Path, w: usize, h: usize, l: f32, odd: Option<f32>) {
    let mut im = grey(w, h, l);
    im.scotopic = None;
    if let Some(v) = odd {
        (im.x[0], im.y[0], im.z[0]) = (v, v, v);
    }
    write_exr(path, &im);
}

/// Issue 13: text reports wrote `1.8412e3 cd/m²`; they now write numbers for people (four
/// significant digits, no exponent from 0.001 to a million), while the JSON report keeps
/// every digit. A grey field at 3682.4 cd/m²: the observer adapts to half of it (Sec. 4.4),
/// 1841.2 cd/m², with the cone threshold of Eq. 4's Weber branch, L·10^-1.255 = 102.35.
#[test]
fn text_reports_write_numbers_for_people_and_json_keeps_every_digit() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bright.exr");
    grey_exr(&input, 16, 16, 3682.4, None);
    let out = dir.path().join("out.png");
    let run = |extra: &[&str]| {
        let o = succeed(
            visadapt()
                .args(["map", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
                .args(["--fov", "10"])
                .args(extra),
        );
        String::from_utf8(o.stdout).unwrap()
    };
    let l_wa = f64::from(3682.4f32) / 2.0;
    let text = run(&[]);
    assert!(
        text.contains("highest visible luminance     3682 cd/m²"),
        "{text}"
    );
    assert!(
        text.contains("world adaptation (Sec. 4.4)   1841 cd/m²"),
        "{text}"
    );
    let cones = format!("cones {:.1} cd/m²", tp(l_wa));
    assert_eq!(cones, "cones 102.4 cd/m²");
    assert!(text.contains(&cones), "{text}");
    assert!(!text.contains("e3") && !text.contains("e2"), "{text}");
    // JSON: the full value, not the four digits of the text.
    let v = json(run(&["--json"]).as_bytes());
    let got = v["adaptation_cd_m2"].as_f64().unwrap();
    assert!((got - l_wa).abs() < 1e-9 * l_wa, "{got} vs {l_wa}");
    assert!((got - 1841.0).abs() > 0.1, "{got}");
    let t = v["cone_threshold_cd_m2"].as_f64().unwrap();
    assert!((t / tp(l_wa) - 1.0).abs() < 1e-9, "{t}");
    assert!((t - 102.4).abs() > 1e-3, "{t}");

    // `observer 0.01`: the cone threshold of Eq. 4's middle branch, t_p(0.01) = 0.1933.
    let o = visadapt().args(["observer", "0.01"]).output().unwrap();
    let text = String::from_utf8(o.stdout).unwrap();
    let expected = format!("cone threshold (Eq. 4)        {:.4} cd/m²", tp(0.01));
    assert_eq!(&expected[30..], "0.1933 cd/m²");
    assert!(text.contains(&expected), "{text}");
    assert!(
        text.contains("observer adapted to 0.01 cd/m² (0.02261 scotopic cd/m²)"),
        "{text}"
    );
    let o = visadapt()
        .args(["observer", "0.01", "--json"])
        .output()
        .unwrap();
    let v = json(&o.stdout);
    let t = v["cone_threshold_cd_m2"].as_f64().unwrap();
    assert!((t / tp(0.01) - 1.0).abs() < 1e-12, "{t}");

    // `tolerance`: the same field's threshold, 102.35 cd/m² everywhere.
    let tol = dir.path().join("tol.exr");
    let o = succeed(visadapt().args([
        "tolerance",
        input.to_str().unwrap(),
        "-o",
        tol.to_str().unwrap(),
    ]));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.contains("adapted to 1841 cd/m² (from the image)")
            && text.contains("min 102.4, median 102.4, max 102.4 cd/m²"),
        "{text}"
    );
}

/// Issue 13: counts agree with their noun ("1 pixels with NaN ..." before).
#[test]
fn one_pixel_is_one_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("nan.exr");
    grey_exr(&input, 8, 8, 100.0, Some(f32::NAN));
    let o = succeed(
        visadapt()
            .args(["map", input.to_str().unwrap(), "-o"])
            .arg(dir.path().join("out.png"))
            .args(["--fov", "10"]),
    );
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(
        err.contains(": 1 pixel with NaN or infinite values shown black"),
        "{err}"
    );
}
