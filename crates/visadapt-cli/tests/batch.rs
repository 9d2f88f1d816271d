//! Batches, pipes and formats of `visadapt map`: several inputs into a folder, standard
//! input and output, the output formats.

mod common;
use common::*;

use std::path::{Path, PathBuf};
use visadapt::HdrImage;

/// The common grey field (equal-energy, with its scotopic channel), with a view.
fn grey(w: usize, h: usize, l: f32) -> HdrImage {
    let mut im = common::grey(w, h, l);
    im.view = Some(visadapt::View::perspective(40.0, w, h));
    im
}

#[test]
fn a_batch_writes_every_good_input_into_the_folder_and_fails_for_the_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let a = write_exr(dir.path().join("a.exr"), &grey(16, 8, 100.0));
    let bad = dir.path().join("b.exr");
    std::fs::write(&bad, b"v/1\x01 truncated").unwrap();
    let c = write_exr(dir.path().join("c.exr"), &grey(8, 8, 0.01));
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
            write_exr(dir.path().join(format!("{name}.exr")), &im)
        })
        .collect();
    for jobs in ["1", "2", "3"] {
        let out_dir = dir.path().join(format!("out{jobs}"));
        let out = succeed(
            visadapt()
                .arg("map")
                .args(&inputs)
                .args(["--json", "--jobs", jobs, "--format", "exr", "-o"])
                .arg(&out_dir),
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
    let a = write_exr(dir.path().join("a.exr"), &grey(4, 4, 10.0));
    let a2 = write_exr(sub.join("a.exr"), &grey(4, 4, 10.0));
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
    let a = write_exr(dir.path().join("scene.exr"), &grey(4, 4, 10.0));
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = succeed(
        visadapt()
            .arg("map")
            .arg(&a)
            .args(["--format", "jpg", "-o"])
            .arg(&out_dir),
    );
    assert_eq!(files_in(&out_dir), ["scene.jpg"]);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("world adaptation (Sec. 4.4)"), "{stdout}");
}

/// Width and height of a PNG.
fn image_size(path: &Path) -> (u32, u32) {
    let p = read_png(path);
    (p.width, p.height)
}

/// `map - --scale S` reads standard input with the factor in the decoder's conversion, as
/// `map FILE --scale S` does: the same file, byte for byte (it was scaled after decoding,
/// rounding each value twice; the OpenEXR output shows the last bits that differed).
#[test]
fn standard_input_is_scaled_as_a_file_is() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (256, 64);
    let n = w * h;
    let v = |k: usize, i: usize| ((i * 7919 + k * 104_729) % 1000) as f32 / 1000.0;
    let picture = visadapt::DisplayImage {
        width: w,
        height: h,
        r: (0..n).map(|i| v(0, i)).collect(),
        g: (0..n).map(|i| v(1, i)).collect(),
        b: (0..n).map(|i| v(2, i)).collect(),
        display_max_cd_m2: 1.0,
    };
    let hdr = dir.path().join("scene.hdr");
    let mut bytes = Vec::new();
    visadapt::io::radiance::write_display(&picture, &mut bytes).unwrap();
    std::fs::write(&hdr, &bytes).unwrap();
    let exr = dir.path().join("scene.exr");
    let file = std::fs::File::create(&exr).unwrap();
    visadapt::io::exr::write_display(&picture, std::io::BufWriter::new(file)).unwrap();
    for input in [hdr, exr] {
        let by_file = dir.path().join("by-file.exr");
        succeed(
            visadapt()
                .arg("map")
                .arg(&input)
                .args(["--scale", "179", "-o"])
                .arg(&by_file),
        );
        let out = succeed(
            visadapt()
                .args(["map", "-", "--scale", "179", "--format", "exr", "-o", "-"])
                .write_stdin(std::fs::read(&input).unwrap()),
        );
        assert!(
            out.stdout == std::fs::read(&by_file).unwrap(),
            "{}",
            input.display()
        );
    }
}

#[test]
fn a_pipe_reads_standard_input_and_writes_standard_output_with_the_report_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = grey(12, 6, 30.0);
    for (i, y) in scene.y.iter_mut().enumerate() {
        *y *= 1.0 + (i % 5) as f32;
    }
    let input = write_exr(dir.path().join("scene.exr"), &scene);
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
    succeed(
        visadapt()
            .args(["map", "-"])
            .arg(&input)
            .arg("-o")
            .arg(&out_dir)
            .write_stdin(bytes),
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

#[test]
fn float_tiff_and_radiance_outputs_hold_the_display_image_of_the_exr_output() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = grey(20, 10, 50.0);
    for (i, y) in scene.y.iter_mut().enumerate() {
        *y *= 0.2 + (i % 9) as f32;
    }
    let input = write_exr(dir.path().join("scene.exr"), &scene);
    let run = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        succeed(
            visadapt()
                .arg("map")
                .arg(&input)
                .args(["--display-max", "120"])
                .args(extra)
                .arg("-o")
                .arg(&path),
        );
        path
    };
    let limits = visadapt::Limits::default();
    // The EXR output read back: display XYZ in cd/m² (1.0 = 120 cd/m²).
    let exr = visadapt::io::read(&run("out.exr", &[]), &limits).unwrap();
    // TIFF: three 32-bit floats a pixel, linear Rec. 709; Y from the Rec. 709 weights.
    let tif = run("out.tif", &[]);
    let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(&tif).unwrap()).unwrap();
    assert_eq!(decoder.dimensions().unwrap(), (20, 10));
    assert_eq!(
        decoder.colortype().unwrap(),
        tiff::ColorType::RGB(32),
        "32-bit RGB"
    );
    let tiff::decoder::DecodingResult::F32(rgb) = decoder.read_image().unwrap() else {
        panic!("not float samples");
    };
    let mut bright = 0;
    for (i, px) in rgb.chunks(3).enumerate() {
        let y = 120.0 * (0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2]);
        assert!(
            // The weights are BT.709's, rounded to four digits.
            (y - exr.y[i]).abs() <= 5e-4 * exr.y[i].max(1.0),
            "pixel {i}: TIFF {y} cd/m², EXR {}",
            exr.y[i]
        );
        bright += (y > 1.0) as usize;
    }
    assert!(bright > 100, "the test image is not black");
    // The library reads its own float TIFF back in cd/m² (the ImageDescription's white).
    let back = visadapt::io::read(&tif, &limits).unwrap();
    assert!(back.absolute_units);
    for i in 0..back.y.len() {
        assert!(
            (back.y[i] - exr.y[i]).abs() <= 1e-4 * exr.y[i].max(1.0),
            "pixel {i}"
        );
    }
    // Radiance: read back by the library (EXPOSURE and PRIMARIES), RGBE precision (< 1 %).
    for name in ["out.hdr", "narrow.hdr"] {
        let extra: &[&str] = if name == "out.hdr" {
            &[]
        } else {
            &["--format", "hdr"]
        };
        let hdr = visadapt::io::read(&run(name, extra), &limits).unwrap();
        assert_eq!((hdr.width, hdr.height), (20, 10));
        for i in 0..hdr.y.len() {
            assert!(
                (hdr.y[i] - exr.y[i]).abs() <= 0.01 * exr.y[i] + 1e-3,
                "pixel {i}: Radiance {} cd/m², EXR {}",
                hdr.y[i],
                exr.y[i]
            );
        }
    }
    // A narrow image: flat RGBE pixels instead of run-length scanlines.
    let narrow = write_exr(dir.path().join("narrow.exr"), &grey(3, 5, 0.5));
    for ext in ["exr", "hdr"] {
        let out = visadapt()
            .arg("map")
            .arg(&narrow)
            .arg("-o")
            .arg(dir.path().join(format!("narrow-out.{ext}")))
            .output()
            .unwrap();
        assert!(out.status.success());
    }
    let a = visadapt::io::read(&dir.path().join("narrow-out.exr"), &limits).unwrap();
    let b = visadapt::io::read(&dir.path().join("narrow-out.hdr"), &limits).unwrap();
    assert_eq!((b.width, b.height), (3, 5));
    for i in 0..a.y.len() {
        assert!((a.y[i] - b.y[i]).abs() <= 0.01 * a.y[i] + 1e-4, "pixel {i}");
    }
    // Into a folder and to standard output by --format.
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    run("out", &["--format", "tiff"]);
    assert_eq!(files_in(&out_dir), ["scene.tif"]);
    let out = visadapt()
        .args(["map", "-", "-o", "-", "--format", "hdr"])
        .write_stdin(std::fs::read(&input).unwrap())
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(out.stdout.starts_with(b"#?RADIANCE\n"));
}

/// IEC 61966-2-1, written out independently of the library: encoded [0, 1] to linear.
fn srgb_to_linear(e: f64) -> f64 {
    if e <= 0.04045 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

#[test]
fn ldr_photographs_are_read_with_the_srgb_curve_undone_and_their_white_at_scale() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (6u32, 4u32);
    // 8-bit PNG, code value 128; 16-bit PNG, 40000; 8-bit grey TIFF, 200; a JPEG of a
    // uniform grey (its code values within 1 of 100).
    let png8 = dir.path().join("a.png");
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&png8).unwrap());
        let mut e = png::Encoder::new(f, w, h);
        e.set_color(png::ColorType::Rgb);
        e.set_depth(png::BitDepth::Eight);
        e.write_header()
            .unwrap()
            .write_image_data(&vec![128u8; (w * h * 3) as usize])
            .unwrap();
    }
    let png16 = dir.path().join("b.png");
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&png16).unwrap());
        let mut e = png::Encoder::new(f, w, h);
        e.set_color(png::ColorType::Rgb);
        e.set_depth(png::BitDepth::Sixteen);
        let v = 40000u16.to_be_bytes();
        let data: Vec<u8> = (0..w * h * 3).flat_map(|_| v).collect();
        e.write_header().unwrap().write_image_data(&data).unwrap();
    }
    let tif = dir.path().join("c.tif");
    {
        let f = std::fs::File::create(&tif).unwrap();
        let mut e = tiff::encoder::TiffEncoder::new(f).unwrap();
        e.write_image::<tiff::encoder::colortype::Gray8>(w, h, &vec![200u8; (w * h) as usize])
            .unwrap();
    }
    let jpg = dir.path().join("d.jpg");
    {
        let grey = visadapt::colour::srgb_decode(100.0 / 255.0);
        let n = (w * h) as usize;
        let image = visadapt::DisplayImage {
            width: w as usize,
            height: h as usize,
            r: vec![grey; n],
            g: vec![grey; n],
            b: vec![grey; n],
            display_max_cd_m2: 100.0,
        };
        visadapt::io::write_display(
            &image,
            &jpg,
            visadapt::io::OutputFormat::Jpeg { quality: 100 },
        )
        .unwrap();
    }
    for (path, code, tolerance) in [
        (&png8, 128.0 / 255.0, 1e-4),
        (&png16, 40000.0 / 65535.0, 1e-4),
        (&tif, 200.0 / 255.0, 1e-4),
        (&jpg, 100.0 / 255.0, 0.02),
    ] {
        let out = visadapt()
            .arg("map")
            .arg(path)
            .args(["--scale", "250", "--fov", "40", "--json", "-o"])
            .arg(dir.path().join("out.png"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let report = json(&out.stdout);
        // A uniform field: the highest visible luminance is the field's (250 × linear code
        // value: grey, so Y = each linear channel), the adaptation half of it (Sec. 4.4).
        let expected = 250.0 * srgb_to_linear(code);
        let got = report["highest_visible_cd_m2"].as_f64().unwrap();
        assert!(
            (got - expected).abs() <= tolerance * expected,
            "{}: {got} cd/m², expected {expected}",
            path.display()
        );
        assert_eq!(report["input_scale"], 250.0);
        assert_eq!(report["scene_white"], "D65");
    }
    // Without --scale the file's units are unknown: said on standard error.
    let out = visadapt()
        .arg("map")
        .arg(&png8)
        .args(["--fov", "40", "-o"])
        .arg(dir.path().join("out.png"))
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not say its units"));
    // A truncated PNG: one clear error naming the file.
    let bytes = std::fs::read(&png8).unwrap();
    let cut = dir.path().join("cut.png");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = visadapt()
        .arg("map")
        .arg(&cut)
        .args(["-o"])
        .arg(dir.path().join("cut-out.png"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let e = one_line_error(&out.stderr);
    assert!(e.contains("cut.png") && e.contains("PNG"), "{e}");
    assert!(!dir.path().join("cut-out.png").exists());
}
