//! `--glare` end to end: the report keys, the raised adaptation, and bad values.

mod common;
use common::*;

/// A 240 × 135 night scene as PFM (RGB, little-endian, bottom row first): grey 0.02 with
/// a 3 × 3 lamp of 1e5 at 5° right of the centre in a 40° view.
fn night_pfm(path: &std::path::Path) {
    let (w, h) = (240usize, 135usize);
    let ppd = (w as f64 / 2.0) / 20f64.to_radians().tan() * std::f64::consts::PI / 180.0;
    let (ci, cj) = (w / 2 + (5.0 * ppd).round() as usize, h / 2);
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for row in (0..h).rev() {
        for i in 0..w {
            let lamp = i.abs_diff(ci) <= 1 && row.abs_diff(cj) <= 1;
            let v: f32 = if lamp { 1e5 } else { 0.02 };
            for _ in 0..3 {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn map_glare_reports_the_veil_and_the_raised_adaptation() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("night.pfm");
    night_pfm(&input);
    let run = |extra: &[&str]| {
        let out = succeed(
            visadapt()
                .arg("map")
                .arg(&input)
                .args(["--scale", "1", "--fov", "40", "--json", "-o"])
                .arg(dir.path().join("out.png"))
                .args(extra),
        );
        json(&out.stdout)
    };
    let plain = run(&[]);
    assert!(plain["glare"].is_null());
    let glared = run(&["--glare", "--age", "60"]);
    let g = &glared["glare"];
    assert_eq!(g["age_years"], 60.0);
    assert_eq!(g["pigmentation"], 0.5);
    // Without glare the street sets the adaptation: half its 0.02 cd/m².
    let without = g["adaptation_without_glare_cd_m2"].as_f64().unwrap();
    assert!((without - 0.01).abs() < 1e-6, "{without}");
    assert_eq!(plain["adaptation_cd_m2"].as_f64().unwrap(), without);
    // With it the veil lifts the whole field: adaptation and thresholds rise.
    let with = glared["adaptation_cd_m2"].as_f64().unwrap();
    let raise = g["adaptation_ratio"].as_f64().unwrap();
    assert!(
        (raise - with / without).abs() < 1e-9 && raise > 1.5,
        "{raise}"
    );
    assert!(
        glared["cone_threshold_cd_m2"].as_f64().unwrap()
            > plain["cone_threshold_cd_m2"].as_f64().unwrap()
    );
    assert!(g["veil_at_fixation_cd_m2"].as_f64().unwrap() > 0.02);
    let s = g["scattered_fraction"].as_f64().unwrap();
    assert!(s > 0.0 && s < 1.0, "{s}");
}

#[test]
fn glare_options_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("night.pfm");
    night_pfm(&input);
    let out_png = dir.path().join("out.png");
    // --age only means something with --glare.
    let out = visadapt()
        .arg("map")
        .arg(&input)
        .args(["--scale", "1", "--age", "40", "-o"])
        .arg(&out_png)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--glare"));
    // An impossible age is one line naming it, and nothing is written.
    let out = visadapt()
        .arg("map")
        .arg(&input)
        .args(["--scale", "1", "--glare", "--age", "300", "-o"])
        .arg(&out_png)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = one_line_error(&out.stderr);
    assert!(err.contains("age"), "{err}");
    assert!(!out_png.exists());
}
