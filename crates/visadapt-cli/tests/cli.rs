//! The command line, end to end: outputs, reports, and bad input.

mod common;
use common::*;

use predicates::prelude::*;

#[test]
fn observer_json_has_the_documented_keys_and_values() {
    let out = visadapt()
        .args(["observer", "0.001", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v = json(&out.stdout);
    for key in [
        "adaptation_cd_m2",
        "scotopic_adaptation_cd_m2",
        "display_adaptation_cd_m2",
        "cone_threshold_cd_m2",
        "rod_threshold_scotopic_cd_m2",
        "photopic_scale",
        "scotopic_scale",
        "rod_weight",
        "acuity_cycles_per_degree",
        "snellen",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["adaptation_cd_m2"], 0.001);
    assert!((v["scotopic_adaptation_cd_m2"].as_f64().unwrap() - 0.002261).abs() < 1e-9);
    assert_eq!(v["display_adaptation_cd_m2"], 40.0);
    let mp = tp(40.0) / tp(0.001);
    assert!((v["photopic_scale"].as_f64().unwrap() / mp - 1.0).abs() < 1e-9);
    assert_eq!(v["rod_weight"], 1.0);
    // Ward Larson 1997 Eq. 15 at 1e-3 cd/m²: 17.25·atan(1.4·(−3) + 0.35) + 25.72 = 3.01.
    assert!((v["acuity_cycles_per_degree"].as_f64().unwrap() - 3.01).abs() < 0.01);
    assert_eq!(v["snellen"], "20/200");
}

#[test]
fn observer_rejects_impossible_luminances() {
    for bad in ["0", "-1", "nan", "inf"] {
        let out = visadapt().args(["observer", bad]).output().unwrap();
        assert!(!out.status.success(), "{bad}");
        let e = usage_error(&out.stderr);
        assert!(e.contains("'<L>'") && e.contains("positive"), "{e}");
    }
    let out = visadapt().args(["observer", "abc"]).output().unwrap();
    assert!(!out.status.success());
}

#[test]
fn map_writes_png_and_reports() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("out.png");
    let out = succeed(
        visadapt()
            .arg("map")
            .arg(data("mixtex.hdr"))
            .arg("-o")
            .arg(&png)
            .arg("--json"),
    );
    let v = json(&out.stdout);
    let lwa = v["adaptation_cd_m2"].as_f64().unwrap();
    assert!((v["highest_visible_cd_m2"].as_f64().unwrap() / 2.0 - lwa).abs() < 1e-9 * lwa);
    assert!((v["photopic_scale"].as_f64().unwrap() / (tp(40.0) / tp(lwa)) - 1.0).abs() < 1e-9);
    for key in [
        "rod_weight",
        "acuity_cycles_per_degree",
        "blur_sigma_px",
        "scotopic_scale",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (128, 72));
    assert_eq!(reader.info().bit_depth, png::BitDepth::Eight);
    assert_eq!(files_in(dir.path()), ["out.png"]);
}

#[test]
fn map_other_outputs() {
    let dir = tempfile::tempdir().unwrap();
    for (name, extra) in [
        ("a.png", vec!["--bits", "16"]),
        ("b.jpg", vec![]),
        ("c.exr", vec![]),
    ] {
        let p = dir.path().join(name);
        visadapt()
            .arg("map")
            .arg(data("mixtex.hdr"))
            .arg("-o")
            .arg(&p)
            .args(extra)
            .assert()
            .success();
        assert!(std::fs::metadata(&p).unwrap().len() > 100);
    }
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(dir.path().join("a.png")).unwrap(),
    ));
    assert_eq!(
        decoder.read_info().unwrap().info().bit_depth,
        png::BitDepth::Sixteen
    );
}

#[test]
fn png_compression_changes_the_file_not_the_pixels() {
    // `map` at every level, a 16-bit one, and `sequence`'s frames: the same samples as
    // the default level in a file of that level (the library's encoder at that level,
    // byte for byte, is `io`'s test).
    let dir = tempfile::tempdir().unwrap();
    let map = |name: &str, extra: &[&str]| {
        let p = dir.path().join(name);
        succeed(
            visadapt()
                .arg("map")
                .arg(data("mixtex.hdr"))
                .arg("-o")
                .arg(&p)
                .args(extra),
        );
        (std::fs::read(&p).unwrap(), read_png(&p))
    };
    let (fast_bytes, fast) = map("default.png", &[]);
    for level in ["fast", "fastest", "rle", "fdeflate"] {
        let (bytes, png) = map(&format!("{level}.png"), &["--png-compression", level]);
        assert!(png.samples == fast.samples, "{level}: other pixels");
        assert_eq!(bytes == fast_bytes, level == "fast", "{level}");
    }
    let (_, wide) = map("wide.png", &["--bits", "16"]);
    let (wide_rle_bytes, wide_rle) = map(
        "wide-rle.png",
        &["--bits", "16", "--png-compression", "rle"],
    );
    assert!(wide_rle.samples == wide.samples);
    assert!(wide_rle_bytes != std::fs::read(dir.path().join("wide.png")).unwrap());

    let sequence = |out: &str, extra: &[&str]| {
        succeed(
            visadapt()
                .arg("sequence")
                .arg(data("mixtex.hdr"))
                .args(["--from", "100", "--to", "0.1", "--times", "0,30", "-o"])
                .arg(dir.path().join(out))
                .args(extra),
        );
    };
    sequence("seq", &[]);
    sequence("seq-rle", &["--png-compression", "rle"]);
    let frames = files_in(&dir.path().join("seq"));
    assert_eq!(frames, files_in(&dir.path().join("seq-rle")));
    assert!(frames.len() >= 2, "{frames:?}");
    for f in frames {
        let (a, b) = (
            dir.path().join("seq").join(&f),
            dir.path().join("seq-rle").join(&f),
        );
        assert!(read_png(&a).samples == read_png(&b).samples, "{f}");
        assert!(
            std::fs::read(&a).unwrap() != std::fs::read(&b).unwrap(),
            "{f}"
        );
    }

    // Not for other formats: refused before anything is written.
    let out = visadapt()
        .arg("video")
        .arg(dir.path().join("f_%d.exr"))
        .args([
            "--fps",
            "24",
            "--format",
            "exr",
            "--png-compression",
            "rle",
            "-o",
        ])
        .arg(dir.path().join("frames"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = one_line_error(&out.stderr);
    assert!(
        e.contains("--png-compression") && e.contains("--format exr"),
        "{e}"
    );
    assert!(!dir.path().join("frames").exists());
}

#[test]
fn map_text_report_names_what_it_used() {
    let dir = tempfile::tempdir().unwrap();
    visadapt()
        .arg("map")
        .arg(data("sunset-fisheye.hdr"))
        .arg("-o")
        .arg(dir.path().join("o.png"))
        .args(["--peak", "0.05"])
        .assert()
        .success()
        .stdout(predicate::str::contains("world adaptation"))
        .stdout(predicate::str::contains("0.025 cd/m²"))
        .stdout(predicate::str::contains(
            "angular fisheye 180.0 deg (from the file)",
        ))
        .stdout(predicate::str::contains("rod weight k"));
}

/// `--white-point`: the report says which white the colours were adapted from (issue 8 §1).
#[test]
fn map_reports_the_white_point_used() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        let out = succeed(
            visadapt()
                .arg("map")
                .arg(data("mixtex.hdr"))
                .arg("-o")
                .arg(dir.path().join("o.png"))
                .arg("--json")
                .args(extra),
        );
        json(&out.stdout)
    };
    let auto = run(&[]);
    assert_eq!(auto["scene_white"], "E");
    assert_eq!(auto["scene_white_source"], "from the file");
    let xy = auto["scene_white_xy"].as_array().unwrap();
    assert!((xy[0].as_f64().unwrap() - 1.0 / 3.0).abs() < 1e-12);
    let off = run(&["--white-point", "none"]);
    assert!(off["scene_white"].is_null());
    let d65 = run(&["--white-point", "D65"]);
    assert_eq!(d65["scene_white"], "D65");
    assert_eq!(d65["scene_white_source"], "given");
    let xy = run(&["--white-point", "0.4476,0.4074"]);
    assert_eq!(xy["scene_white"], "0.4476,0.4074");

    visadapt()
        .arg("map")
        .arg(data("mixtex.hdr"))
        .arg("-o")
        .arg(dir.path().join("t.png"))
        .assert()
        .success()
        .stdout(predicate::str::contains(
            "scene white E (from the file) adapted to the display's D65 (CAT16)",
        ));
    for bad in ["D50x", "0.7,0.5", "0,0.3", "nan,0.3"] {
        let out = visadapt()
            .arg("map")
            .arg(data("mixtex.hdr"))
            .arg("-o")
            .arg(dir.path().join("bad.png"))
            .args(["--white-point", bad])
            .output()
            .unwrap();
        assert!(!out.status.success(), "{bad}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("--white-point"),
            "{bad}"
        );
        assert!(!dir.path().join("bad.png").exists());
    }
}

/// Every failure: one line naming the file, non-zero exit, no output and no temporary
/// file left behind, and an existing output file untouched.
#[test]
fn bad_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let truncated = dir.path().join("truncated.hdr");
    let bytes = std::fs::read(data("mixtex.hdr")).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"this is not an image at all").unwrap();
    let huge = dir.path().join("huge.hdr");
    std::fs::write(
        &huge,
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2000000000 +X 2000000000\n",
    )
    .unwrap();
    let empty = dir.path().join("empty.pfm");
    std::fs::write(&empty, b"").unwrap();
    let keep = dir.path().join("keep.png");
    std::fs::write(&keep, b"precious").unwrap();

    for (input, what) in [
        (dir.path().join("missing.hdr"), "missing.hdr"),
        (truncated.clone(), "truncated.hdr"),
        (garbage.clone(), "garbage.exr"),
        (huge.clone(), "huge.hdr"),
        (empty.clone(), "empty.pfm"),
    ] {
        let before = files_in(dir.path());
        let out = visadapt()
            .arg("map")
            .arg(&input)
            .arg("-o")
            .arg(&keep)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{what}");
        let e = one_line_error(&out.stderr);
        assert!(e.contains(what), "{e}");
        // The cause is said once, not repeated by the error chain.
        assert!(e.matches("os error").count() <= 1, "{e}");
        assert_eq!(files_in(dir.path()), before, "{what}: files changed");
        assert_eq!(std::fs::read(&keep).unwrap(), b"precious");
    }
    // The limit is a flag: raising it lets a large (here: truncated) file be tried.
    let out = visadapt()
        .arg("map")
        .arg(&huge)
        .arg("-o")
        .arg(&keep)
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("--max-pixels"));
}

#[test]
fn bad_arguments_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.hdr");
    std::fs::copy(data("mixtex.hdr"), &input).unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["-o", "out.txt"], "output format"),
        (&["-o", "x.png", "--scale", "-2"], "--scale"),
        (&["-o", "x.png", "--peak", "nan"], "--peak"),
        (&["-o", "x.png", "--display-max", "0"], "display-max"),
        (&["-o", "x.png", "--fov", "0"], "--fov"),
        (
            &["-o", "x.png", "--world-adaptation", "-3"],
            "world-adaptation",
        ),
    ];
    for (args, what) in cases {
        let out = visadapt()
            .current_dir(dir.path())
            .arg("map")
            .arg(&input)
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        let e = cli_error(&out.stderr);
        assert!(e.contains(what), "{args:?}: {e}");
    }
    // Never overwrite the input, even spelled differently.
    let out = visadapt()
        .current_dir(dir.path())
        .args(["map", "in.hdr", "-o", "./in.hdr"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("overwrite the input"));
    assert_eq!(
        std::fs::read(&input).unwrap(),
        std::fs::read(data("mixtex.hdr")).unwrap()
    );
    assert_eq!(files_in(dir.path()), ["in.hdr"]);
}

#[test]
fn help_has_examples() {
    visadapt()
        .args(["map", "--help"])
        .assert()
        .success()
        .stdout(predicate::str::contains("Examples:"))
        .stdout(predicate::str::contains("--peak"));
    visadapt()
        .arg("--help")
        .assert()
        .success()
        .stdout(predicate::str::contains("observer"));
}

/// Outputs are ordinary files (0644), not the private mode of the temporary file they are
/// written through.
#[cfg(unix)]
#[test]
fn outputs_get_normal_permissions() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("out.png");
    visadapt()
        .arg("map")
        .arg(data("mixtex.hdr"))
        .arg("-o")
        .arg(&png)
        .assert()
        .success();
    let mode = std::fs::metadata(&png).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o644);
}
