//! `visadapt demo`, `chart` and `plot`, end to end: the files they write, what they print,
//! and bad input.

mod common;
use common::*;

use predicates::prelude::*;
use std::path::Path;

/// Decode an 8-bit RGB PNG: (width, height, interleaved samples).
fn rgb_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let p = read_png(path);
    assert_eq!(p.color_type, png::ColorType::Rgb);
    (p.width, p.height, p.samples)
}

#[test]
fn demo_writes_four_panels_a_contact_sheet_and_a_table() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let run = visadapt().args(["demo", "-o"]).arg(&out).assert().success();
    let stdout = String::from_utf8_lossy(&run.get_output().stdout).into_owned();
    let mut expected = vec![
        "contact-sheet.png".to_string(),
        "panel-0.001.png".to_string(),
        "panel-0.04.png".to_string(),
        "panel-10.png".to_string(),
        "panel-1000.png".to_string(),
    ];
    // The paper's Fig. 12 sequences: 7 frames each (adapted + 6 times) and an animation.
    for seq in ["fig12a", "fig12b"] {
        expected.push(format!("{seq}.apng"));
        expected.extend((0..7).map(|i| format!("{seq}-{i}.png")));
    }
    expected.sort();
    assert_eq!(files_in(&out), expected);
    // The table: one row per level with its acuity and colour state, measured.
    for row in [
        "1000 ",
        "20/12",
        "vivid",
        "red 2.1x",
        "10 ",
        "0.04 ",
        "20/92",
        "20/100",
        "faint",
        "blue 2.8x",
        "0.001 ",
        "none, forms only",
    ] {
        assert!(stdout.contains(row), "{row:?} missing from\n{stdout}");
    }
    // The panels get darker with the level; the starlight panel is not black.
    let mean = |name: &str| {
        let (_, _, rgb) = rgb_png(&out.join(name));
        rgb.iter().map(|&v| v as f64).sum::<f64>() / rgb.len() as f64
    };
    let m: Vec<f64> = [
        "panel-1000.png",
        "panel-10.png",
        "panel-0.04.png",
        "panel-0.001.png",
    ]
    .iter()
    .map(|n| mean(n))
    .collect();
    assert!(m.windows(2).all(|w| w[1] < w[0]), "{m:?}");
    assert!(m[3] > 10.0, "{m:?}");
    // Light adaptation (Fig. 12a): the frame just after the switch to 5623 cd/m² is washed
    // out (brighter, less contrast) compared with the last frame, 75 s later.
    let (_, _, first) = rgb_png(&out.join("fig12a-1.png"));
    let (_, _, last) = rgb_png(&out.join("fig12a-6.png"));
    let spread = |rgb: &[u8]| {
        let (lo, hi) = rgb
            .iter()
            .fold((255u8, 0u8), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        hi as i32 - lo as i32
    };
    assert!(
        spread(&first) < spread(&last),
        "{} vs {}",
        spread(&first),
        spread(&last)
    );
    assert!(
        stdout.contains("fig12a.apng") && stdout.contains("fig12b.apng"),
        "{stdout}"
    );
    // The contact sheet holds the four panels (2 x 2) and their labels.
    let (pw, ph, _) = rgb_png(&out.join("panel-1000.png"));
    let (w, h, sheet) = rgb_png(&out.join("contact-sheet.png"));
    assert!(w > 2 * pw && h > 2 * ph, "{w}x{h} for panels {pw}x{ph}");
    // Labels are light text on the dark background above each panel.
    let light = sheet[..(w as usize * 60 * 3)]
        .iter()
        .filter(|&&v| v > 200)
        .count();
    assert!(light > 500, "{light}");
}

#[test]
fn demo_levels_can_be_chosen_and_bad_levels_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    visadapt()
        .args(["demo", "--levels", "50", "--no-sequences", "-o"])
        .arg(&out)
        .assert()
        .success()
        .stdout(predicate::str::contains("50 "))
        // One panel is one (issue 13: "wrote 1 panels").
        .stdout(predicate::str::contains(
            "wrote 1 panel and contact-sheet.png",
        ));
    assert_eq!(files_in(&out), ["contact-sheet.png", "panel-50.png"]);
    for bad in ["0", "-1", "nan", "inf", "1,0.0"] {
        let out = dir.path().join(format!("bad{bad}"));
        let run = visadapt()
            .args(["demo", "--levels", bad, "-o"])
            .arg(&out)
            .assert()
            .failure();
        let e = cli_error(&run.get_output().stderr);
        assert!(e.contains("level"), "{bad}: {e}");
        assert!(!out.exists(), "{bad}: the output directory was created");
    }
}

#[test]
fn demo_into_an_unwritable_directory_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let run = visadapt()
        .args(["demo", "-o"])
        .arg(file.join("sub"))
        .assert()
        .failure();
    let e = one_line_error(&run.get_output().stderr);
    assert!(e.contains("cannot create the output directory"), "{e}");
    assert_eq!(files_in(dir.path()), ["a-file"]);
}

#[test]
fn chart_writes_the_papers_exr_layout_in_absolute_units() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chart.exr");
    visadapt()
        .args(["chart", "--white", "0.04", "-o"])
        .arg(&path)
        .assert()
        .success()
        .stdout(predicate::str::contains("--fov 6.7"));
    let img = visadapt::io::read(&path, &visadapt::Limits::default()).unwrap();
    assert!(img.absolute_units);
    let max = img.y.iter().fold(0.0f32, |a, &b| a.max(b));
    assert!((max - 0.04).abs() < 1e-6, "{max}");
    let s = img.scotopic.as_ref().expect("scotopic channel");
    let smax = s.iter().fold(0.0f32, |a, &b| a.max(b));
    // White 9.5 under E: S/P 2.255.
    assert!((smax / max - 2.255).abs() < 0.01, "{}", smax / max);
    // Mapped with the printed field of view, it matches the demo's 0.04 panel.
    let png = dir.path().join("mapped.png");
    visadapt()
        .args(["map", "--fov", "6.7173", "-o"])
        .arg(&png)
        .arg(&path)
        .assert()
        .success()
        .stdout(predicate::str::contains("120.0"));
    // --fov moves the viewer, --no-gratings drops the gratings row.
    let near = dir.path().join("near.exr");
    visadapt()
        .args([
            "chart",
            "--white",
            "100",
            "--fov",
            "30",
            "--no-gratings",
            "-o",
        ])
        .arg(&near)
        .assert()
        .success()
        .stdout(predicate::str::contains("fov 30.0000"));
}

#[test]
fn chart_refuses_bad_input_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--white", "0"], "--white"),
        (vec!["--white", "nan"], "--white"),
        (vec!["--white", "-3"], "--white"),
        (vec!["--white", "1", "--fov", "0"], "fov"),
        (vec!["--white", "1", "--fov", "200"], "fov"),
    ] {
        let path = dir.path().join("c.exr");
        let run = visadapt()
            .arg("chart")
            .args(&args)
            .arg("-o")
            .arg(&path)
            .assert()
            .failure();
        let e = cli_error(&run.get_output().stderr);
        assert!(e.contains(needle), "{args:?}: {e}");
        assert!(!path.exists());
    }
    let run = visadapt()
        .args(["chart", "--white", "1", "-o"])
        .arg(dir.path().join("c.png"))
        .assert()
        .failure();
    assert!(one_line_error(&run.get_output().stderr).contains(".exr"));
    let run = visadapt()
        .args(["chart", "--white", "1", "-o"])
        .arg(dir.path().join("missing/c.exr"))
        .assert()
        .failure();
    one_line_error(&run.get_output().stderr);
    assert!(files_in(dir.path()).is_empty());
}

#[test]
fn plots_are_written_as_svg_and_png() {
    let dir = tempfile::tempdir().unwrap();
    for (name, alias) in [
        ("luminous-efficiency", "fig2"),
        ("tvi", "fig3"),
        ("spectral-sensitivity", "fig4"),
        ("acuity", "fig7"),
    ] {
        let svg = dir.path().join(format!("{name}.svg"));
        visadapt()
            .args(["plot", name, "-o"])
            .arg(&svg)
            .assert()
            .success();
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(
            text.starts_with("<svg") && text.contains("<polyline"),
            "{name}"
        );
        // Axes are labelled with their units.
        assert!(
            text.contains("nm)") || text.contains("cd/m²"),
            "{name}: axis units"
        );
        let png = dir.path().join(format!("{alias}.png"));
        visadapt()
            .args(["plot", alias, "-o"])
            .arg(&png)
            .assert()
            .success();
        let (w, h, rgb) = rgb_png(&png);
        assert!(w >= 900 && h >= 500);
        // Mostly white background, with dark text and coloured curves.
        let dark = rgb.chunks(3).filter(|p| p.iter().all(|&v| v < 80)).count();
        assert!(dark > 1000, "{name}: {dark} dark pixels");
    }
}

#[test]
fn plot_refuses_unknown_names_and_formats_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.svg");
    let run = visadapt()
        .args(["plot", "fig99", "-o"])
        .arg(&out)
        .assert()
        .code(2);
    let e = cli_error(&run.get_output().stderr);
    assert!(e.contains("fig99") && e.contains("tvi"), "{e}");
    // The list of accepted names has the figure numbers too (issue 13: they were accepted
    // but the error listed only the long names).
    let listed = e
        .split_once("[possible values: ")
        .and_then(|(_, rest)| rest.split_once(']'))
        .map(|(list, _)| list.split(", ").collect::<Vec<_>>())
        .unwrap_or_else(|| panic!("no list of names: {e}"));
    for name in [
        "tvi",
        "fig2",
        "fig3",
        "fig4",
        "fig7",
        "fig8",
        "fig9",
        "fig10",
        "timecourse",
    ] {
        assert!(listed.contains(&name), "{name} missing from {listed:?}");
    }
    let run = visadapt()
        .args(["plot", "tvi", "-o"])
        .arg(dir.path().join("x.pdf"))
        .assert()
        .failure();
    assert!(one_line_error(&run.get_output().stderr).contains(".svg or .png"));
    let run = visadapt()
        .args(["plot", "tvi", "-o"])
        .arg(dir.path().join("no/such/dir/x.svg"))
        .assert()
        .failure();
    one_line_error(&run.get_output().stderr);
    assert!(files_in(dir.path()).is_empty());
}
