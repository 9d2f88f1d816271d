//! `visadapt timecourse`, `sequence` and `video`, end to end: outputs, values, bad input.

mod common;
use common::*;

use predicates::prelude::*;
use std::path::Path;
use visadapt::HdrImage;

fn f(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing or not a number in {v}"))
}

#[test]
fn timecourse_json_has_the_documented_keys_and_the_model_values() {
    let out = succeed(visadapt().args([
        "timecourse",
        "--from",
        "0.1",
        "--to",
        "5623",
        "--times",
        "0,1,10,75,100000",
        "--json",
    ]));
    let v = json(&out.stdout);
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 5);
    for row in rows {
        for key in [
            "t_seconds",
            "cone_threshold_cd_m2",
            "rod_threshold_scotopic_cd_m2",
            "photopic_scale",
            "scotopic_scale",
            "rod_weight",
            "offset_cd_m2",
            "acuity_cycles_per_degree",
        ] {
            assert!(f(row, key).is_finite(), "{key}");
        }
    }
    let (first, last) = (&rows[0], &rows[4]);
    assert_eq!(f(first, "t_seconds"), 0.0);
    // Adapted at the end: Eq. 4 at 5623 cd/m², Eq. 3 scale factor, no offset.
    assert!((f(last, "cone_threshold_cd_m2") / tp(5623.0) - 1.0).abs() < 1e-9);
    assert!((f(last, "photopic_scale") / (tp(40.0) / tp(5623.0)) - 1.0).abs() < 1e-9);
    assert_eq!(f(last, "offset_cd_m2"), 0.0);
    assert_eq!(f(last, "rod_weight"), 0.0);
    // At the switch: the threshold is raised (Baker's onset, ~0.44 log units), the display
    // is lifted by the Eq. 8 offset and acuity is reduced; both recover over the 75 s.
    assert!(f(first, "cone_threshold_cd_m2") > 2.5 * tp(5623.0));
    assert!(f(first, "offset_cd_m2") > 20.0);
    let b: Vec<f64> = rows.iter().map(|r| f(r, "offset_cd_m2")).collect();
    assert!(b[0] > b[1] && b[1] > b[2] && b[2] > b[3].abs(), "{b:?}");
    let ac: Vec<f64> = rows
        .iter()
        .map(|r| f(r, "acuity_cycles_per_degree"))
        .collect();
    assert!(ac[0] < ac[1] && ac[1] < ac[2] && ac[2] < ac[3], "{ac:?}");
    // Eq. 9: m_p·L_wa + b is the same at every time (rod weight is 0 here).
    let shown: Vec<f64> = rows
        .iter()
        .map(|r| f(r, "photopic_scale") * 5623.0 + f(r, "offset_cd_m2"))
        .collect();
    for s in &shown {
        assert!((s / shown[4] - 1.0).abs() < 1e-9, "{shown:?}");
    }
}

#[test]
fn timecourse_dark_adaptation_goes_down_monotonically_and_prints_a_table() {
    let out = visadapt()
        .args([
            "timecourse",
            "--from",
            "1412",
            "--to",
            "0.1",
            "--times",
            "0,30,60,210,600,1800",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v = json(&out.stdout);
    let rows = v.as_array().unwrap();
    let cone: Vec<f64> = rows.iter().map(|r| f(r, "cone_threshold_cd_m2")).collect();
    let rod: Vec<f64> = rows
        .iter()
        .map(|r| f(r, "rod_threshold_scotopic_cd_m2"))
        .collect();
    assert!(cone.windows(2).all(|w| w[1] < w[0]) && rod.windows(2).all(|w| w[1] < w[0]));
    // Starts at Eq. 4 of the old level (no jump on a dark step) and nothing is resolvable.
    assert!((cone[0] / tp(1412.0) - 1.0).abs() < 1e-9);
    assert_eq!(f(&rows[0], "acuity_cycles_per_degree"), 0.0);
    // Text: a header and one row per time.
    visadapt()
        .args([
            "timecourse",
            "--from",
            "1412",
            "--to",
            "0.1",
            "--times",
            "0,30,60",
        ])
        .assert()
        .success()
        .stdout(predicate::str::contains("cone thr").and(predicate::str::contains("    60.000")));
}

#[test]
fn timecourse_refuses_bad_input_in_one_line() {
    for (args, needle) in [
        (vec!["--from", "1", "--to", "2", "--times", "3,1"], "sorted"),
        (vec!["--from", "1", "--to", "2", "--times", "-3"], "--times"),
        (
            vec!["--from", "1", "--to", "2", "--times", "NaN"],
            "--times",
        ),
        (vec!["--from", "NaN", "--to", "2", "--times", "1"], "--from"),
        (vec!["--from", "1", "--to", "-0.5", "--times", "1"], "--to"),
        (vec!["--from", "-1", "--to", "2", "--times", "1"], "--from"),
        (
            vec![
                "--from",
                "1",
                "--to",
                "2",
                "--times",
                "1",
                "--display-max",
                "0",
            ],
            "--display-max",
        ),
    ] {
        let out = visadapt().arg("timecourse").args(&args).output().unwrap();
        assert!(!out.status.success(), "{args:?}");
        let e = cli_error(&out.stderr);
        assert!(e.contains(needle), "{args:?}: {e}");
        assert!(out.stdout.is_empty());
    }
}

#[test]
fn sequence_writes_numbered_frames_and_an_animation() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    let apng = dir.path().join("anim.png");
    let out = succeed(
        visadapt()
            .arg("sequence")
            .arg(data("mixtex.hdr"))
            .args([
                "--from", "0.1", "--to", "5623", "--times", "0,1,75", "--json", "-o",
            ])
            .arg(&frames)
            .arg("--apng")
            .arg(&apng),
    );
    assert_eq!(
        files_in(&frames),
        [
            "frame_000.png",
            "frame_001.png",
            "frame_002.png",
            "frame_003.png"
        ]
    );
    let v = json(&out.stdout);
    let list = v["frames"].as_array().unwrap();
    assert_eq!(list.len(), 4);
    assert!(list[0]["t_seconds"].is_null());
    assert_eq!(list[3]["t_seconds"].as_f64(), Some(75.0));
    // The washed-out frame right after the switch has a large offset, then it shrinks.
    let b: Vec<f64> = list.iter().map(|x| f(x, "offset_cd_m2")).collect();
    assert_eq!(b[0], 0.0);
    assert!(
        b[1] > 10.0 && b[2] < b[1] && b[3].abs() < 0.2 * b[1],
        "{b:?}"
    );
    // Frame 0 is exactly what `map --peak 0.1` shows.
    let mapped = dir.path().join("map.png");
    visadapt()
        .arg("map")
        .arg(data("mixtex.hdr"))
        .args(["--peak", "0.1", "-o"])
        .arg(&mapped)
        .assert()
        .success();
    assert_eq!(
        read_png(&frames.join("frame_000.png")).samples,
        read_png(&mapped).samples
    );
    // The animation holds the four frames, the first one being frame 0.
    let Png {
        samples: first,
        frames: n,
        ..
    } = read_png(&apng);
    assert_eq!(n, Some(4));
    assert_eq!(first, read_png(&frames.join("frame_000.png")).samples);
}

#[test]
fn sequence_refuses_bad_input_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let outdir = dir.path().join("o");
    for (args, needle) in [
        (
            vec!["--from", "0.1", "--to", "10", "--times", "5,1"],
            "sorted",
        ),
        (vec!["--from", "0", "--to", "10", "--times", "1"], "--from"),
        (vec!["--from", "0.1", "--to", "inf", "--times", "1"], "--to"),
        (
            vec!["--from", "0.1", "--to", "10", "--times", "-1,2"],
            "--times",
        ),
    ] {
        let out = visadapt()
            .arg("sequence")
            .arg(data("mixtex.hdr"))
            .args(&args)
            .arg("-o")
            .arg(&outdir)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let e = cli_error(&out.stderr);
        assert!(e.contains(needle), "{e}");
        assert!(!outdir.exists());
    }
    let out = visadapt()
        .args([
            "sequence",
            "no-such-file.hdr",
            "--from",
            "1",
            "--to",
            "2",
            "--times",
            "0",
            "-o",
        ])
        .arg(&outdir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("no-such-file.hdr"));
}

/// A small textured scene with highest visible luminance `peak` (cd/m²), `w`×`h`.
fn scene(w: usize, h: usize, peak: f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    for j in 0..h {
        for i in 0..w {
            let k = j * w + i;
            let l = peak
                * if (i + j) % 2 == 0 { 1.0 } else { 0.25 }
                * (0.5 + 0.5 * i as f32 / w as f32);
            (im.x[k], im.y[k], im.z[k]) = (0.950_47 * l, l, 1.088_83 * l);
        }
    }
    im.absolute_units = true;
    im
}

#[test]
fn video_carries_the_adaptation_from_frame_to_frame() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir(&input).unwrap();
    // Three dim frames, then the lights go up to 1000 cd/m² for three frames.
    for n in 0..6 {
        let peak = if n < 3 { 0.1 } else { 1000.0 };
        write_exr(input.join(format!("f_{n:04}.exr")), &scene(16, 8, peak));
    }
    std::fs::write(input.join("notes.txt"), "not a frame").unwrap();
    let outdir = dir.path().join("out");
    let pattern = input.join("f_%04d.exr");
    let out = succeed(
        visadapt()
            .arg("video")
            .arg(&pattern)
            .args(["--fps", "0.5", "--json", "--no-acuity", "-o"])
            .arg(&outdir),
    );
    let frames = json_lines(&out.stdout);
    assert_eq!(frames.len(), 6);
    assert_eq!(
        files_in(&outdir),
        [
            "f_0000.png",
            "f_0001.png",
            "f_0002.png",
            "f_0003.png",
            "f_0004.png",
            "f_0005.png"
        ]
    );
    let t: Vec<f64> = frames.iter().map(|v| f(v, "t_seconds")).collect();
    assert_eq!(t, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
    // World adaptation from each frame (half its highest luminance), the observer adapted
    // at first.
    let half_max = |peak| 0.5 * scene(16, 8, peak).y.iter().fold(0.0f32, |a, &b| a.max(b)) as f64;
    assert!((f(&frames[0], "world_adaptation_cd_m2") / half_max(0.1) - 1.0).abs() < 1e-6);
    assert!((f(&frames[5], "world_adaptation_cd_m2") / half_max(1000.0) - 1.0).abs() < 1e-6);
    let lwa = f(&frames[5], "world_adaptation_cd_m2");
    assert_eq!(f(&frames[0], "offset_cd_m2"), 0.0);
    assert_eq!(f(&frames[2], "offset_cd_m2"), 0.0);
    // The switch: raised threshold, a large offset, recovering over the next frames.
    let cone: Vec<f64> = frames[3..]
        .iter()
        .map(|v| f(v, "cone_threshold_cd_m2"))
        .collect();
    assert!(
        cone[0] > 1.5 * tp(lwa) && cone[0] > cone[1] && cone[1] > cone[2] && cone[2] > tp(lwa),
        "{cone:?}"
    );
    let b: Vec<f64> = frames[3..].iter().map(|v| f(v, "offset_cd_m2")).collect();
    assert!(b[0] > 10.0 && b[0] > b[1] && b[1] > b[2], "{b:?}");
    // The first frame is the static operator's output.
    let mapped = dir.path().join("map.png");
    visadapt()
        .arg("map")
        .arg(input.join("f_0000.exr"))
        .args(["--no-acuity", "-o"])
        .arg(&mapped)
        .assert()
        .success();
    assert_eq!(
        read_png(&outdir.join("f_0000.png")).samples,
        read_png(&mapped).samples
    );
}

#[test]
fn video_reads_pfm_and_radiance_frames_with_a_scale() {
    let dir = tempfile::tempdir().unwrap();
    for n in 1..=3 {
        std::fs::write(
            dir.path().join(format!("p{n}.pfm")),
            visadapt::io::pfm::encode(&scene(8, 4, 1.0)),
        )
        .unwrap();
        std::fs::copy(data("mixtex.hdr"), dir.path().join(format!("r{n}.hdr"))).unwrap();
    }
    let out = succeed(
        visadapt()
            .arg("video")
            .arg(dir.path().join("p%d.pfm"))
            .args([
                "--fps", "24", "--scale", "100", "--format", "exr", "--json", "-o",
            ])
            .arg(dir.path().join("o")),
    );
    let frames = json_lines(&out.stdout);
    let max = scene(8, 4, 1.0).y.iter().fold(0.0f32, |a, &b| a.max(b)) as f64;
    assert!((f(&frames[2], "world_adaptation_cd_m2") / (50.0 * max) - 1.0).abs() < 1e-4);
    assert_eq!(
        files_in(&dir.path().join("o")),
        ["p1.exr", "p2.exr", "p3.exr"]
    );
    visadapt()
        .arg("video")
        .arg(dir.path().join("r%d.hdr"))
        .args(["--fps", "24", "-o"])
        .arg(dir.path().join("r"))
        .assert()
        .success()
        .stdout(predicate::str::contains("wrote 3 frames"));
}

#[test]
fn video_refuses_bad_patterns_and_frame_rates_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    for n in [0, 1, 3] {
        write_exr(dir.path().join(format!("g{n}.exr")), &scene(4, 4, 1.0));
    }
    let outdir = dir.path().join("out");
    for (pattern, fps, needle) in [
        ("none_%03d.exr", "24", "matches no file"),
        ("g.exr", "24", "%d"),
        ("g%d.exr", "24", "frame 2 is missing"),
        ("g%d.exr", "0", "--fps"),
        ("g%d.exr", "nan", "--fps"),
    ] {
        let out = visadapt()
            .arg("video")
            .arg(dir.path().join(pattern))
            .args(["--fps", fps, "-o"])
            .arg(&outdir)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{pattern}");
        let e = cli_error(&out.stderr);
        assert!(e.contains(needle), "{pattern}: {e}");
        assert!(!outdir.exists(), "{pattern}");
    }
}

#[test]
fn video_stops_at_a_frame_of_another_size_and_keeps_what_it_wrote() {
    let dir = tempfile::tempdir().unwrap();
    write_exr(dir.path().join("v1.exr"), &scene(8, 4, 10.0));
    write_exr(dir.path().join("v2.exr"), &scene(8, 4, 20.0));
    write_exr(dir.path().join("v3.exr"), &scene(4, 4, 20.0));
    write_exr(dir.path().join("v4.exr"), &scene(8, 4, 20.0));
    let outdir = dir.path().join("out");
    let out = visadapt()
        .arg("video")
        .arg(dir.path().join("v%d.exr"))
        .args(["--fps", "30", "--fov", "60", "-o"])
        .arg(&outdir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = one_line_error(&out.stderr);
    assert!(
        e.contains("frame 3") && e.contains("4x4") && e.contains("8x4"),
        "{e}"
    );
    // The two good frames are there, whole, and nothing else (no temporary files).
    assert_eq!(files_in(&outdir), ["v1.png", "v2.png"]);
    for name in ["v1.png", "v2.png"] {
        assert_eq!(read_png(&outdir.join(name)).samples.len(), 8 * 4 * 3);
    }
    // A corrupt frame: the same, naming it.
    std::fs::write(dir.path().join("v3.exr"), b"v/1\x01 truncated").unwrap();
    std::fs::remove_dir_all(&outdir).unwrap();
    let out = visadapt()
        .arg("video")
        .arg(dir.path().join("v%d.exr"))
        .args(["--fps", "30", "--fov", "60", "-o"])
        .arg(&outdir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("v3.exr"));
    assert_eq!(files_in(&outdir), ["v1.png", "v2.png"]);
}

#[test]
fn video_never_overwrites_its_input() {
    let dir = tempfile::tempdir().unwrap();
    write_exr(dir.path().join("w1.exr"), &scene(4, 4, 1.0));
    let before = std::fs::read(dir.path().join("w1.exr")).unwrap();
    let out = visadapt()
        .arg("video")
        .arg(dir.path().join("w%d.exr"))
        .args(["--fps", "30", "--format", "exr", "-o"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("overwrite"));
    assert_eq!(std::fs::read(dir.path().join("w1.exr")).unwrap(), before);
}

#[test]
fn plot_draws_figures_8_to_10_as_svg_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("tc.svg");
    visadapt()
        .args(["plot", "timecourse", "-o"])
        .arg(&svg)
        .assert()
        .success();
    let text = std::fs::read_to_string(&svg).unwrap();
    for needle in [
        "Fig. 8",
        "Fig. 9",
        "Fig. 10",
        "threshold (envelope)",
        "<polyline",
    ] {
        assert!(text.contains(needle), "{needle}");
    }
    let png = dir.path().join("tc.png");
    visadapt()
        .args(["plot", "fig8-10", "-o"])
        .arg(&png)
        .assert()
        .success();
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let info = dec.read_info().unwrap();
    assert_eq!((info.info().width, info.info().height), (1500, 560));
}

/// Issue 8 §2: during Baker's dip (3 min after 0.1 → 5623 cd/m²) the default mapping keeps
/// the steady-state contrast (offset ≥ 0); `--undershoot in-mapping` is the paper's rule,
/// with its negative offset. The thresholds are the same either way.
#[test]
fn timecourse_undershoot_rule_changes_the_mapping_not_the_threshold() {
    let run = |extra: &[&str]| {
        let out = succeed(
            visadapt()
                .args([
                    "timecourse",
                    "--from",
                    "0.1",
                    "--to",
                    "5623",
                    "--times",
                    "180",
                    "--json",
                ])
                .args(extra),
        );
        json(&out.stdout)[0].clone()
    };
    let (clamped, paper) = (run(&[]), run(&["--undershoot", "in-mapping"]));
    assert!(f(&clamped, "cone_excess_log") < -0.05);
    assert_eq!(
        clamped["cone_threshold_cd_m2"],
        paper["cone_threshold_cd_m2"]
    );
    assert!(f(&clamped, "photopic_offset_cd_m2") >= 0.0, "{clamped}");
    assert!(f(&paper, "photopic_offset_cd_m2") < -1.0, "{paper}");
    assert!(f(&paper, "photopic_scale") > f(&clamped, "photopic_scale"));
}

/// Issue 8 §3: `--to 0` is darkness, so that Fig. 10 can be reproduced from the command
/// line (failed before: refused as not positive). Hecht's observer (200 cd/m²): the cones
/// reach their plateau within 5 min, the rods pass them at about 7 min (the Purkinje
/// break), and in darkness nothing is resolvable (acuity 0).
#[test]
fn timecourse_to_darkness_reproduces_figure_10() {
    let out = succeed(visadapt().args([
        "timecourse",
        "--from",
        "199.526",
        "--to",
        "0",
        "--times",
        "0,300,390,450,2400",
        "--json",
    ]));
    let v = json(&out.stdout);
    let rows = v.as_array().unwrap();
    let log = |i: usize, k: &str| f(&rows[i], k).log10();
    assert!(log(1, "cone_threshold_cd_m2") + 0.72 < 0.02);
    assert!(log(2, "rod_threshold_scotopic_cd_m2") > log(2, "cone_threshold_cd_m2"));
    assert!(log(3, "rod_threshold_scotopic_cd_m2") < log(3, "cone_threshold_cd_m2"));
    let depth = log(0, "cone_threshold_cd_m2") - log(4, "rod_threshold_scotopic_cd_m2");
    assert!((3.7..4.0).contains(&depth), "{depth}");
    for row in rows {
        assert_eq!(f(row, "acuity_cycles_per_degree"), 0.0);
        assert!(f(row, "photopic_scale").is_finite());
    }
}

#[test]
fn video_pipeline_writes_the_same_bytes_as_one_frame_after_another() {
    // Frames that move the adaptation (bright, dim, bright), with the acuity blur on: each
    // PNG must be byte for byte what the library gives frame by frame, in order.
    let dir = tempfile::tempdir().unwrap();
    let peaks = [500.0, 500.0, 0.05, 0.05, 0.05, 200.0, 200.0, 3.0];
    for (n, peak) in peaks.iter().enumerate() {
        write_exr(dir.path().join(format!("s{n}.exr")), &scene(40, 24, *peak));
    }
    let outdir = dir.path().join("out");
    visadapt()
        .arg("video")
        .arg(dir.path().join("s%d.exr"))
        // The library's PNG files are at `fast` (video's default is `fdeflate`).
        .args([
            "--fps",
            "2",
            "--fov",
            "30",
            "--png-compression",
            "fast",
            "-o",
        ])
        .arg(&outdir)
        .assert()
        .success();
    let mut eye: Option<visadapt::timecourse::Adaptation> = None;
    let mut display = visadapt::DisplayImage::default();
    for n in 0..peaks.len() {
        // The frame as the CLI reads it (the file's white and units included).
        let hdr = visadapt::io::read(
            &dir.path().join(format!("s{n}.exr")),
            &visadapt::Limits::default(),
        )
        .unwrap();
        let conditions = visadapt::operator::ViewingConditions {
            view: Some(visadapt::View::perspective(30.0, 40, 24)),
            ..Default::default()
        };
        let (scene, report) = visadapt::operator::prepare(&hdr, &conditions).unwrap();
        let state = match eye.as_mut() {
            None => eye.insert(
                visadapt::timecourse::Adaptation::adapted(
                    report.world_adaptation_cd_m2,
                    report.world_adaptation_scotopic_cd_m2,
                )
                .unwrap(),
            ),
            Some(s) => {
                s.step_to(0.5, &report).unwrap();
                s
            }
        };
        visadapt::operator::apply_state_into(&scene, &report, state, &conditions, &mut display)
            .unwrap();
        let expected = dir.path().join(format!("expected{n}.png"));
        visadapt::io::write_display(&display, &expected, visadapt::io::OutputFormat::png(8))
            .unwrap();
        // Compared as a boolean: a failure should name the frame, not print two PNGs.
        let same = std::fs::read(outdir.join(format!("s{n}.png"))).unwrap()
            == std::fs::read(&expected).unwrap();
        assert!(same, "frame {n} differs from the frame-by-frame PNG");
    }
}

/// The delays of an APNG, ms, frame by frame (the fcTL chunk of each frame).
fn apng_delays_ms(path: &Path) -> Vec<u16> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let mut delays = Vec::new();
    while reader.next_frame(&mut buf).is_ok() {
        let fc = reader.info().frame_control.unwrap();
        assert_eq!(fc.delay_den, 1000);
        delays.push(fc.delay_num);
    }
    delays
}

/// `sequence --apng` plays the real time steps sped up to --apng-seconds (6 s by
/// default), and says by how much; --apng-delay-ms keeps equal delays.
#[test]
fn sequence_animation_keeps_the_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let apng = dir.path().join("anim.png");
    let run = |extra: &[&str]| {
        let out = visadapt()
            .arg("sequence")
            .arg(data("mixtex.hdr"))
            .args([
                "--from",
                "0.1",
                "--to",
                "5623",
                "--times",
                "0,1,4,15,30,75",
                "-o",
            ])
            .arg(dir.path().join("frames"))
            .arg("--apng")
            .arg(&apng)
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    // 6 s: a 1 s hold of the first and last frames, 75 s of the sequence in 4 s.
    let text = run(&[]);
    assert_eq!(apng_delays_ms(&apng), [1000, 53, 160, 587, 800, 2400, 1000]);
    assert!(text.contains("18.75 times faster"), "{text}");
    // 12 s: every delay doubles, to the millisecond.
    let json = json(run(&["--apng-seconds", "12", "--json"]).as_bytes());
    assert_eq!(
        apng_delays_ms(&apng),
        [2000, 107, 320, 1173, 1600, 4800, 2000]
    );
    assert_eq!(json["apng_speedup"].as_f64(), Some(9.375));
    assert_eq!(json["apng_delays_ms"][5].as_u64(), Some(4800));
    // Equal delays on request.
    run(&["--apng-delay-ms", "250"]);
    assert_eq!(apng_delays_ms(&apng), [250; 7]);
    // Bad lengths, and both flags at once, are refused before any work.
    for (extra, needle) in [
        (&["--apng-seconds", "61"][..], "--apng-seconds"),
        (&["--apng-seconds", "0"][..], "--apng-seconds"),
        (
            &["--apng-seconds", "6", "--apng-delay-ms", "100"][..],
            "--apng-delay-ms",
        ),
    ] {
        let out = visadapt()
            .arg("sequence")
            .arg(data("mixtex.hdr"))
            .args(["--from", "0.1", "--to", "10", "--times", "1", "-o"])
            .arg(dir.path().join("bad"))
            .arg("--apng")
            .arg(dir.path().join("bad.png"))
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{extra:?}");
        assert!(cli_error(&out.stderr).contains(needle), "{extra:?}");
        assert!(!dir.path().join("bad").exists() && !dir.path().join("bad.png").exists());
    }
}

/// `sequence --label-time`: each frame carries its light level and time in a box in the
/// top-left corner, and only the box differs from the unlabelled frame; without the flag
/// the frames are, byte for byte, the library's own PNGs of the sequence.
#[test]
fn sequence_label_time_changes_only_the_box() {
    use visadapt::sequence::{self, Sequence};
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let frames = dir.path().join(name);
        visadapt()
            .arg("sequence")
            .arg(data("mixtex.hdr"))
            .args(["--from", "1412", "--to", "0.1", "--times", "0,20,210", "-o"])
            .arg(&frames)
            .arg("--apng")
            .arg(dir.path().join(format!("{name}.png")))
            .args(extra)
            .assert()
            .success();
        frames
    };
    let plain = run("plain", &[]);
    let labelled = run("labelled", &["--label-time"]);
    // The library's frames, written as PNG by the library.
    let scene = visadapt::io::read(&data("mixtex.hdr"), &visadapt::Limits::default()).unwrap();
    let seq = Sequence::new(1412.0, 0.1, vec![0.0, 20.0, 210.0]).unwrap();
    let mut expected = Vec::new();
    sequence::render(&scene, &seq, &Default::default(), |f| {
        let path = dir.path().join(format!("lib-{}.png", f.index));
        visadapt::io::write_display(f.image, &path, visadapt::io::OutputFormat::png(8))?;
        expected.push(std::fs::read(&path).unwrap());
        Ok(())
    })
    .unwrap();
    let (w, h) = (scene.width, scene.height);
    for (i, lib) in expected.iter().enumerate() {
        let name = format!("frame_{i:03}.png");
        assert_eq!(&std::fs::read(plain.join(&name)).unwrap(), lib, "{name}");
        let a = read_png(&plain.join(&name)).samples;
        let b = read_png(&labelled.join(&name)).samples;
        let text = seq.frame_label(i).unwrap();
        // The box as the label module draws it: 5x7 glyphs on 6-pixel advances with 2
        // pixels of padding, at one image pixel per font pixel below 300 rows.
        assert!(h < 300);
        let (bw, bh) = ((6 * text.chars().count() - 1 + 4).min(w), 11.min(h));
        let mut changed = 0;
        for y in 0..h {
            for x in 0..w {
                let k = 3 * (y * w + x);
                if x < bw && y < bh {
                    let px = &b[k..k + 3];
                    assert!(px == [255; 3] || px == [0; 3], "{name} ({x}, {y}): {px:?}");
                    changed += usize::from(px != &a[k..k + 3]);
                } else {
                    assert_eq!(a[k..k + 3], b[k..k + 3], "{name} ({x}, {y})");
                }
            }
        }
        assert!(changed > bw * bh / 2, "{name}: {changed}");
    }
    // The animation carries the labelled frames.
    assert_eq!(
        read_png(&dir.path().join("labelled.png")).samples,
        read_png(&labelled.join("frame_000.png")).samples
    );
}
