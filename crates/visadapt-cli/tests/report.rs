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
