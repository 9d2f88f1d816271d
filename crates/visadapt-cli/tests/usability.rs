//! The command line as a new user meets it: help, usage errors, error wording, views,
//! outputs that cannot be written.

mod common;
use common::*;

use visadapt::Limits;

#[test]
fn bare_visadapt_prints_the_usage_and_the_commands() {
    let out = visadapt().output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("Usage: visadapt <COMMAND>"), "{text}");
    for command in [
        "map",
        "observer",
        "timecourse",
        "visible",
        "tolerance",
        "plot",
    ] {
        assert!(
            text.contains(&format!("\n  {command} ")),
            "{command}: {text}"
        );
    }
}

#[test]
fn usage_errors_keep_clap_tips_usage_and_pointer_to_help() {
    let out = visadapt().args(["mapp", "x.hdr"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let e = usage_error(&out.stderr);
    assert!(e.contains("tip: a similar subcommand exists: 'map'"), "{e}");
    assert!(e.contains("Usage: visadapt <COMMAND>"), "{e}");

    let out = visadapt()
        .args(["map", "x.hdr", "-o", "y.png", "--display-maxx", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let e = usage_error(&out.stderr);
    assert!(
        e.contains("tip: a similar argument exists: '--display-max'"),
        "{e}"
    );
    assert!(e.contains("Usage: visadapt map"), "{e}");
}

#[test]
fn bad_values_are_named_by_the_flag_as_typed_in_one_style() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_exr(dir.path().join("in.exr"), &grey(8, 8, 10.0));
    let input = input.to_str().unwrap();
    let cases: [(&[&str], &str); 9] = [
        (
            &["map", input, "-o", "x.png", "--peak", "-1"],
            "'--peak <L>'",
        ),
        (
            &["map", input, "-o", "x.png", "--display-max", "0"],
            "'--display-max <L>'",
        ),
        (
            &["map", input, "-o", "x.png", "--fov", "nan"],
            "'--fov <DEG>'",
        ),
        (
            &["map", input, "-o", "x.png", "--hot-pixel-fraction", "2"],
            "'--hot-pixel-fraction <F>'",
        ),
        (
            &["map", input, "-o", "x.png", "--world-adaptation", "-3"],
            "'--world-adaptation <L>'",
        ),
        (&["visible", input, input, "--scale", "0"], "'--scale <S>'"),
        (
            &[
                "tolerance",
                input,
                "-o",
                "t.exr",
                "--scotopic-adaptation",
                "inf",
            ],
            "'--scotopic-adaptation <LS>'",
        ),
        (
            &["observer", "1", "--display-max", "-80"],
            "'--display-max <L>'",
        ),
        (
            &["timecourse", "--from", "1", "--to", "-1", "--times", "1"],
            "'--to <L1>'",
        ),
    ];
    for (args, flag) in cases {
        let out = visadapt()
            .current_dir(dir.path())
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let e = usage_error(&out.stderr);
        assert!(e.starts_with("error: invalid value '"), "{args:?}: {e}");
        assert!(e.contains(&format!("for {flag}: ")), "{args:?}: {e}");
    }
    assert_eq!(files_in(dir.path()), ["in.exr"]);
}

#[test]
fn format_flags_for_another_format_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_exr(dir.path().join("in.exr"), &grey(8, 8, 10.0));
    for (flag, value, output) in [
        ("--bits", "16", "x.jpg"),
        ("--bits", "8", "x.exr"),
        ("--quality", "50", "x.png"),
        ("--png-compression", "rle", "x.tif"),
    ] {
        let out = visadapt()
            .current_dir(dir.path())
            .arg("map")
            .arg(&input)
            .args(["-o", output, flag, value])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{flag} {output}");
        let e = usage_error(&out.stderr);
        assert!(e.contains(flag) && e.contains(output), "{e}");
    }
    // Where they apply they are accepted.
    visadapt()
        .current_dir(dir.path())
        .arg("map")
        .arg(&input)
        .args(["-o", "x16.png", "--bits", "16"])
        .assert()
        .success();
    assert_eq!(files_in(dir.path()), ["in.exr", "x16.png"]);
}

#[test]
fn a_missing_output_folder_is_named_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_exr(dir.path().join("in.exr"), &grey(8, 8, 10.0));
    let missing = dir.path().join("no-such-folder");
    let commands: [Vec<String>; 4] = [
        vec!["map".into(), input.display().to_string(), "-o".into()],
        vec!["tolerance".into(), input.display().to_string(), "-o".into()],
        vec![
            "visible".into(),
            input.display().to_string(),
            input.display().to_string(),
            "-o".into(),
        ],
        vec!["chart".into(), "--white".into(), "1".into(), "-o".into()],
    ];
    for (args, name) in commands.iter().zip(["x.png", "t.exr", "j.png", "c.exr"]) {
        let out = visadapt()
            .args(args)
            .arg(missing.join(name))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        let e = one_line_error(&out.stderr);
        assert!(
            e.contains(&format!(
                "the output folder {} does not exist",
                missing.display()
            )),
            "{args:?}: {e}"
        );
        assert!(!e.contains(".visadapt-"), "{e}");
    }
    assert_eq!(files_in(dir.path()), ["in.exr"]);
}

#[test]
fn an_empty_file_is_called_empty() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.hdr");
    std::fs::write(&empty, b"").unwrap();
    let out = visadapt()
        .arg("map")
        .arg(&empty)
        .arg("-o")
        .arg(dir.path().join("x.png"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = one_line_error(&out.stderr);
    assert!(e.contains("empty.hdr") && e.contains("empty file"), "{e}");
    assert!(!e.contains("unrecognised"), "{e}");
}

#[test]
fn perspective_views_of_180_degrees_or_more_are_refused_fisheyes_kept() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_exr(dir.path().join("in.exr"), &grey(400, 200, 0.01));
    let out = visadapt()
        .current_dir(dir.path())
        .arg("map")
        .arg(&input)
        .args(["-o", "x.png", "--fov", "200"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let e = usage_error(&out.stderr);
    assert!(
        e.contains("'--fov <DEG>'") && e.contains("--projection fisheye"),
        "{e}"
    );
    assert_eq!(files_in(dir.path()), ["in.exr"]);

    // An angular fisheye spreads its 400 pixels evenly over 200 degrees: 2 pixels/degree,
    // and the blur is the acuity Gaussian's sigma in degrees times that.
    let out = succeed(
        visadapt()
            .current_dir(dir.path())
            .arg("map")
            .arg(&input)
            .args([
                "-o",
                "x.png",
                "--fov",
                "200",
                "--projection",
                "fisheye",
                "--json",
            ]),
    );
    let v = json(&out.stdout);
    assert!(
        (v["pixels_per_degree"].as_f64().unwrap() - 2.0).abs() < 1e-12,
        "{v}"
    );
    let sigma_deg = v["acuity_blur_sigma_deg"].as_f64().unwrap();
    assert!(sigma_deg > 0.0);
    let sigma_px = v["blur_sigma_px"].as_f64().unwrap();
    assert!((sigma_px - 2.0 * sigma_deg).abs() < 1e-9 * sigma_px, "{v}");
    // --projection alone says nothing: it needs the angle.
    let out = visadapt()
        .arg("map")
        .arg(&input)
        .args(["-o", "y.png", "--projection", "fisheye"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(usage_error(&out.stderr).contains("--fov <DEG>"));
}

#[test]
fn visible_writes_the_jnd_map_as_exr_and_names_both_formats() {
    let dir = tempfile::tempdir().unwrap();
    let reference = write_exr(dir.path().join("a.exr"), &grey(16, 8, 100.0));
    let mut brighter = grey(16, 8, 100.0);
    // The right half 20 % brighter: far above threshold there, nothing on the left.
    for y in 0..8 {
        for x in 8..16 {
            let i = y * 16 + x;
            brighter.x[i] *= 1.2;
            brighter.y[i] *= 1.2;
            brighter.z[i] *= 1.2;
            brighter.scotopic.as_mut().unwrap()[i] *= 1.2;
        }
    }
    let test = write_exr(dir.path().join("b.exr"), &brighter);
    let map = dir.path().join("jnd.exr");
    let out = succeed(
        visadapt()
            .arg("visible")
            .arg(&reference)
            .arg(&test)
            .args(["--no-acuity", "--json", "-o"])
            .arg(&map),
    );
    let v = json(&out.stdout);
    let jnd = visadapt::io::read(&map, &Limits::default()).unwrap();
    assert_eq!((jnd.width, jnd.height), (16, 8));
    let max = jnd.y.iter().cloned().fold(0.0f32, f32::max) as f64;
    let mean = jnd.y.iter().map(|&j| j as f64).sum::<f64>() / jnd.len() as f64;
    assert!(
        (max - v["max_jnd"].as_f64().unwrap()).abs() < 1e-4 * max,
        "{max} {v}"
    );
    assert!(
        (mean - v["mean_jnd"].as_f64().unwrap()).abs() < 1e-4 * mean,
        "{mean} {v}"
    );
    assert!(
        jnd.y[0] < 0.01 && jnd.y[15] > 1.0,
        "{} {}",
        jnd.y[0],
        jnd.y[15]
    );

    let out = visadapt()
        .arg("visible")
        .arg(&reference)
        .arg(&test)
        .arg("-o")
        .arg(dir.path().join("jnd.svg"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("use .png or .exr"));
}

#[test]
fn plots_take_the_papers_figure_numbers() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["fig8", "fig9", "fig10", "fig3"] {
        let out = dir.path().join(format!("{name}.svg"));
        visadapt()
            .args(["plot", name, "-o"])
            .arg(&out)
            .assert()
            .success();
        assert!(out.exists(), "{name}");
    }
}

#[test]
fn the_charts_view_travels_in_its_exr_and_a_default_view_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let chart = dir.path().join("chart.exr");
    visadapt()
        .args(["chart", "--white", "100", "-o"])
        .arg(&chart)
        .assert()
        .success();
    // The chart stands at the Snellen distance: 120 pixels per degree (its own report).
    let out = visadapt()
        .arg("map")
        .arg(&chart)
        .arg("-o")
        .arg(dir.path().join("c.png"))
        .arg("--json")
        .output()
        .unwrap();
    assert!(out.status.success());
    let v = json(&out.stdout);
    assert!(
        (v["pixels_per_degree"].as_f64().unwrap() - 120.0).abs() < 1e-6,
        "{v}"
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("view"));

    // A file without a view, acuity on: one warning naming the file and the guess.
    let plain = write_exr(dir.path().join("plain.exr"), &grey(32, 16, 10.0));
    let out = visadapt()
        .arg("map")
        .arg(&plain)
        .arg("-o")
        .arg(dir.path().join("p.png"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        stderr.matches("does not record its view").count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("plain.exr") && stderr.contains("60 degree"),
        "{stderr}"
    );
    // With --fov or without acuity there is nothing to warn about.
    for extra in [["--fov", "40"], ["--no-acuity", "--json"]] {
        let out = visadapt()
            .arg("map")
            .arg(&plain)
            .arg("-o")
            .arg(dir.path().join("q.png"))
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success());
        assert!(!String::from_utf8_lossy(&out.stderr).contains("view"));
    }
}
