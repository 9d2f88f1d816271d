//! Batches, pipes and formats of `visadapt map`: several inputs into a folder, standard
//! input and output, the output formats.

mod common;
use common::*;

use std::path::{Path, PathBuf};
use visadapt::HdrImage;

/// A grey field at `l` cd/m² (equal-energy, with its scotopic channel), with a view.
fn grey(w: usize, h: usize, l: f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    im.x.fill(l);
    im.y.fill(l);
    im.z.fill(l);
    im.scotopic = Some(vec![2.261 * l; w * h]);
    im.absolute_units = true;
    im.view = Some(visadapt::View::perspective(40.0, w, h));
    im
}

fn write(dir: &Path, name: &str, image: &HdrImage) -> PathBuf {
    let path = dir.join(name);
    let file = std::fs::File::create(&path).unwrap();
    visadapt::io::exr::write_hdr(image, std::io::BufWriter::new(file)).unwrap();
    path
}

#[test]
fn a_batch_writes_every_good_input_into_the_folder_and_fails_for_the_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.exr", &grey(16, 8, 100.0));
    let bad = dir.path().join("b.exr");
    std::fs::write(&bad, b"v/1\x01 truncated").unwrap();
    let c = write(dir.path(), "c.exr", &grey(8, 8, 0.01));
    let out_dir = dir.path().join("out");
    let out = visadapt()
        .args(["map"])
        .args([&a, &bad, &c])
        .arg("-o")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert_eq!(out.status.code(), Some(1));
    // The others are still written, whole; nothing else is in the folder.
    assert_eq!(files_in(&out_dir), ["a.png", "c.png"]);
    let img = image_size(&out_dir.join("a.png"));
    assert_eq!(img, (16, 8));
    assert_eq!(image_size(&out_dir.join("c.png")), (8, 8));
    // One line per written file, in the inputs' order.
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(
        lines[0].contains("a.exr") && lines[0].contains("a.png"),
        "{stdout}"
    );
    assert!(
        lines[1].contains("c.exr") && lines[1].contains("c.png"),
        "{stdout}"
    );
    // Grey at 100 cd/m²: the world adaptation is half the highest visible (Sec. 4.4).
    assert!(lines[0].contains("adapted to 50 cd/m²"), "{stdout}");
    // The bad file is named with its problem, and a summary says how many failed.
    let stderr = String::from_utf8(out.stderr).unwrap();
    let errors: Vec<&str> = stderr.lines().collect();
    assert_eq!(errors.len(), 2, "{stderr}");
    assert!(errors[0].starts_with("visadapt: error: ") && errors[0].contains("b.exr"));
    assert!(errors[1].contains("1 of 3 inputs failed"), "{stderr}");
}

#[test]
fn a_batch_gives_the_same_report_and_pixels_as_single_runs_in_parallel_too() {
    let dir = tempfile::tempdir().unwrap();
    let inputs: Vec<PathBuf> = [(1000.0, "day"), (0.1, "dusk"), (1e-3, "night")]
        .iter()
        .map(|(l, name)| {
            let mut im = grey(24, 12, *l);
            // Some structure, so that the mapping is not a constant.
            for (i, y) in im.y.iter_mut().enumerate() {
                *y *= 1.0 + (i % 7) as f32;
            }
            write(dir.path(), &format!("{name}.exr"), &im)
        })
        .collect();
    for jobs in ["1", "2", "3"] {
        let out_dir = dir.path().join(format!("out{jobs}"));
        let out = visadapt()
            .arg("map")
            .args(&inputs)
            .args(["--json", "--jobs", jobs, "--format", "exr", "-o"])
            .arg(&out_dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8(out.stdout).unwrap();
        let lines: Vec<serde_json::Value> = stdout
            .lines()
            .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
            .collect();
        assert_eq!(lines.len(), 3);
        for (input, line) in inputs.iter().zip(&lines) {
            let single_out = dir.path().join("single.exr");
            let single = visadapt()
                .arg("map")
                .arg(input)
                .args(["--json", "-o"])
                .arg(&single_out)
                .output()
                .unwrap();
            assert!(single.status.success());
            let mut single = json(&single.stdout);
            let output = out_dir.join(input.with_extension("exr").file_name().unwrap());
            assert_eq!(line["input"], input.display().to_string());
            assert_eq!(line["output"], output.display().to_string());
            let obj = single.as_object_mut().unwrap();
            for (k, v) in obj.iter() {
                assert_eq!(&line[k], v, "{k} of {}", input.display());
            }
            // The same pixels as the single run's.
            assert_eq!(
                std::fs::read(&output).unwrap(),
                std::fs::read(&single_out).unwrap()
            );
        }
    }
}

#[test]
fn a_batch_refuses_two_inputs_for_one_output_and_a_contradicting_format_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    let a = write(dir.path(), "a.exr", &grey(4, 4, 10.0));
    let a2 = write(&sub, "a.exr", &grey(4, 4, 10.0));
    let out_dir = dir.path().join("out");
    let out = visadapt()
        .arg("map")
        .args([&a, &a2])
        .arg("-o")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = one_line_error(&out.stderr);
    assert!(
        e.contains("would both be written to") && e.contains("a.png"),
        "{e}"
    );
    assert!(!out_dir.exists());
    // An input would be replaced by its own output: refused, the input intact.
    let before = std::fs::read(&a2).unwrap();
    let out = visadapt()
        .arg("map")
        .args([&a2])
        .args(["--format", "exr", "-o"])
        .arg(&sub)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(one_line_error(&out.stderr).contains("would overwrite the input"));
    assert_eq!(std::fs::read(&a2).unwrap(), before);
    // --format against the file's own extension, --bits with a JPEG folder: usage errors.
    let out = visadapt()
        .arg("map")
        .arg(&a)
        .args(["--format", "exr", "-o"])
        .arg(dir.path().join("x.png"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(usage_error(&out.stderr).contains("contradicts the extension"));
    let out = visadapt()
        .arg("map")
        .args([&a, &a2])
        .args(["--format", "jpg", "--bits", "16", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(usage_error(&out.stderr).contains("--bits applies to PNG output only"));
}

#[test]
fn one_input_into_a_folder_takes_its_name_and_keeps_the_full_report() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "scene.exr", &grey(4, 4, 10.0));
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = visadapt()
        .arg("map")
        .arg(&a)
        .args(["--format", "jpg", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(files_in(&out_dir), ["scene.jpg"]);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("world adaptation (Sec. 4.4)"), "{stdout}");
}

/// Width and height of a PNG.
fn image_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    (info.width, info.height)
}

#[test]
fn a_pipe_reads_standard_input_and_writes_standard_output_with_the_report_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = grey(12, 6, 30.0);
    for (i, y) in scene.y.iter_mut().enumerate() {
        *y *= 1.0 + (i % 5) as f32;
    }
    let input = write(dir.path(), "scene.exr", &scene);
    let bytes = std::fs::read(&input).unwrap();
    for (format, file) in [(None, "by-file.png"), (Some("exr"), "by-file.exr")] {
        let by_file = dir.path().join(file);
        let out = visadapt()
            .arg("map")
            .arg(&input)
            .arg("-o")
            .arg(&by_file)
            .output()
            .unwrap();
        assert!(out.status.success());
        let mut cmd = visadapt();
        cmd.args(["map", "-", "-o", "-"]);
        if let Some(f) = format {
            cmd.args(["--format", f]);
        }
        let out = cmd.write_stdin(bytes.clone()).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        // The same file as from a file to a file, and nothing else on standard output.
        assert_eq!(out.stdout, std::fs::read(&by_file).unwrap(), "{file}");
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert!(stderr.contains("world adaptation (Sec. 4.4)"), "{stderr}");
        assert!(stderr.contains("wrote                         standard output"));
    }
    // --json with -o -: the report is the JSON object, on standard error.
    let out = visadapt()
        .args(["map", "-", "-o", "-", "--json"])
        .write_stdin(bytes.clone())
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(out.stdout.starts_with(b"\x89PNG"));
    let report = json(&out.stderr);
    assert_eq!(report["width"], 12);
    // A batch can read standard input once, named "stdin" in the folder.
    let out_dir = dir.path().join("out");
    let out = visadapt()
        .args(["map", "-"])
        .arg(&input)
        .arg("-o")
        .arg(&out_dir)
        .write_stdin(bytes)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(files_in(&out_dir), ["scene.png", "stdin.png"]);
}

#[test]
fn standard_input_that_is_no_image_is_one_clear_error_and_writes_nothing() {
    for (stdin, expected) in [
        (Vec::new(), "standard input: invalid image data: empty file"),
        (vec![0u8; 4096], "standard input: unsupported"),
        (b"v/1\x01 truncated".to_vec(), "standard input"),
    ] {
        let out = visadapt()
            .args(["map", "-", "-o", "-"])
            .write_stdin(stdin)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1));
        assert!(out.stdout.is_empty());
        let e = one_line_error(&out.stderr);
        assert!(e.contains(expected), "{e}");
    }
    // Usage errors: several inputs to standard output, standard input twice.
    let out = visadapt()
        .args(["map", "-", "x.exr", "-o", "-"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(usage_error(&out.stderr).contains("not to standard output"));
    let out = visadapt()
        .args(["map", "-", "-", "-o", "out/"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(usage_error(&out.stderr).contains("read only once"));
}
