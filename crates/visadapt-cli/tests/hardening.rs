//! Hostile and careless use, end to end (issue 9): outputs that are inputs, streams, absurd
//! patterns, permissions, and the flags' ranges.

mod common;
use common::*;

use std::path::{Path, PathBuf};

/// A small valid Radiance picture, `w × h` flat grey pixels of about 1 (× 179 cd/m²).
fn radiance(w: usize, h: usize) -> Vec<u8> {
    let mut f = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n").into_bytes();
    for _ in 0..w * h {
        f.extend([128, 128, 128, 129]);
    }
    f
}

fn write_scene(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, radiance(8, 8)).unwrap();
    p
}

/// No `.visadapt-*` temporary file left in `dir`.
fn assert_no_temporaries(dir: &Path) {
    let stray: Vec<String> = files_in(dir)
        .into_iter()
        .filter(|n| n.starts_with(".visadapt-"))
        .collect();
    assert!(stray.is_empty(), "{stray:?}");
}

/// Run `args` and expect an error that mentions `needle` (one line at run time, clap's
/// form for a usage error); returns it.
fn fails_with(dir: &Path, args: &[&str], needle: &str) -> String {
    let out = visadapt().current_dir(dir).args(args).output().unwrap();
    assert!(!out.status.success(), "{args:?} succeeded");
    let e = cli_error(&out.stderr);
    assert!(e.contains(needle), "{args:?}: {e}");
    e
}

#[test]
fn sequence_never_overwrites_its_input_under_any_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d, "scene.hdr");
    let original = std::fs::read(&scene).unwrap();
    std::os::unix::fs::symlink("scene.hdr", d.join("link.png")).unwrap();
    std::fs::hard_link(&scene, d.join("hard.png")).unwrap();
    let base = [
        "sequence",
        "scene.hdr",
        "--from",
        "1",
        "--to",
        "100",
        "--times",
        "0,1",
    ];
    for apng in ["scene.hdr", "./scene.hdr", "link.png", "hard.png"] {
        let mut args = base.to_vec();
        args.extend(["-o", "frames", "--apng", apng]);
        fails_with(d, &args, "overwrite the input");
        assert_eq!(std::fs::read(&scene).unwrap(), original, "{apng}");
    }
    // A frame name that is the input: the input lives in the output directory under the
    // name of frame 0.
    std::fs::create_dir(d.join("out")).unwrap();
    std::fs::copy(&scene, d.join("out/frame_000.png")).unwrap();
    let mut args = base.to_vec();
    args[1] = "out/frame_000.png";
    args.extend(["-o", "out"]);
    fails_with(d, &args, "overwrite the input");
    assert_eq!(
        std::fs::read(d.join("out/frame_000.png")).unwrap(),
        original
    );
    assert_eq!(files_in(&d.join("out")), ["frame_000.png"]);
    assert_no_temporaries(d);
}

#[test]
fn no_command_writes_over_an_input_through_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d, "scene.hdr");
    let original = std::fs::read(&scene).unwrap();
    std::os::unix::fs::symlink("scene.hdr", d.join("sym.exr")).unwrap();
    std::os::unix::fs::symlink("scene.hdr", d.join("sym.png")).unwrap();
    std::fs::hard_link(&scene, d.join("hard.png")).unwrap();
    std::fs::hard_link(&scene, d.join("hard.exr")).unwrap();
    for out in ["sym.png", "hard.png", "sym.exr", "hard.exr"] {
        fails_with(d, &["map", "scene.hdr", "-o", out], "overwrite the input");
    }
    for out in ["sym.exr", "hard.exr"] {
        fails_with(
            d,
            &["tolerance", "scene.hdr", "-o", out],
            "overwrite the input",
        );
    }
    for out in ["sym.png", "hard.png"] {
        fails_with(
            d,
            &["visible", "scene.hdr", "scene.hdr", "-o", out],
            "overwrite the input",
        );
    }
    assert_eq!(std::fs::read(&scene).unwrap(), original);
    assert_no_temporaries(d);
}

#[test]
fn video_never_overwrites_an_input_frame_through_a_hard_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("in")).unwrap();
    std::fs::create_dir(d.join("out")).unwrap();
    let f1 = write_scene(&d.join("in"), "f1.hdr");
    write_scene(&d.join("in"), "f2.hdr");
    // out/f2.png is frame 1 under another name.
    std::fs::hard_link(&f1, d.join("out/f2.png")).unwrap();
    let original = std::fs::read(&f1).unwrap();
    fails_with(
        d,
        &["video", "in/f%d.hdr", "--fps", "10", "-o", "out"],
        "overwrite the input",
    );
    assert_eq!(std::fs::read(&f1).unwrap(), original);
    assert_eq!(files_in(&d.join("out")), ["f2.png"]);
}

#[test]
fn streams_are_refused_after_their_first_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Before the fix the whole stream was read before the format check: 10 GB in 11 s.
    fails_with(
        d,
        &["map", "/dev/zero", "-o", "out.png"],
        "unrecognised first bytes",
    );
    std::fs::create_dir(d.join("in")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", d.join("in/f1.hdr")).unwrap();
    fails_with(
        d,
        &["video", "in/f%d.hdr", "--fps", "10", "-o", "out"],
        "unrecognised first bytes",
    );
    // A valid header followed by an endless stream of zeros: only what the header allows
    // is read, within a small budget, and the picture decodes.
    let mut f = radiance(4, 4);
    f.resize(f.len() + (64 << 20), 0);
    std::fs::write(d.join("padded.hdr"), &f).unwrap();
    succeed(visadapt().current_dir(d).args([
        "map",
        "padded.hdr",
        "-o",
        "p.png",
        "--max-memory",
        "4M",
    ]));
}

#[test]
fn the_memory_budget_names_itself() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(d, "scene.hdr");
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--max-memory", "100"],
        "--max-memory",
    );
    for bad in ["0", "abc", "12Q", "99999999999T"] {
        fails_with(
            d,
            &["map", "scene.hdr", "-o", "o.png", "--max-memory", bad],
            "max-memory",
        );
    }
}

#[test]
fn absurd_frame_padding_is_refused_without_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Before the fix: a panic in formatting (width > 65535).
    fails_with(
        d,
        &["video", "f_%065536d.hdr", "--fps", "24", "-o", "out"],
        "%065536d",
    );
    fails_with(
        d,
        &["video", "f_%0256d.hdr", "--fps", "24", "-o", "out"],
        "file name",
    );
}

/// `visadapt args...` under `sh` with `umask`.
fn with_umask(dir: &Path, umask: &str, args: &str) -> std::process::Output {
    let bin = assert_cmd::cargo::cargo_bin("visadapt");
    std::process::Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(format!("umask {umask} && exec '{}' {args}", bin.display()))
        .output()
        .unwrap()
}

fn mode(p: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).unwrap().permissions().mode() & 0o7777
}

#[test]
fn outputs_honour_the_umask_and_never_copy_setuid() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Before the fix: 0644 whatever the umask.
    let out = with_umask(d, "077", "plot tvi -o private.svg");
    assert!(out.status.success());
    assert_eq!(mode(&d.join("private.svg")), 0o600);
    let out = with_umask(d, "022", "plot tvi -o public.svg");
    assert!(out.status.success());
    assert_eq!(mode(&d.join("public.svg")), 0o644);
    // Replacing a file keeps its permission bits but not setuid/setgid.
    std::fs::write(d.join("old.svg"), "x").unwrap();
    std::fs::set_permissions(d.join("old.svg"), std::fs::Permissions::from_mode(0o6750)).unwrap();
    let out = with_umask(d, "022", "plot tvi -o old.svg");
    assert!(out.status.success());
    assert_eq!(mode(&d.join("old.svg")), 0o750);
    assert_no_temporaries(d);
}

#[test]
fn flags_beyond_the_f32_range_are_refused_by_their_own_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(d, "scene.hdr");
    // Before the fix: Inf pixels written, or "invalid scotopic inf" for `observer 1e308`.
    fails_with(d, &["observer", "1e308"], "<L>");
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--peak", "1e308"],
        "peak",
    );
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--scale", "1e38"],
        "scale",
    );
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--display-max", "1e39"],
        "display-max",
    );
    fails_with(d, &["chart", "-o", "c.exr", "--white", "1e308"], "--white");
    fails_with(
        d,
        &["timecourse", "--from", "1e300", "--to", "1", "--times", "0"],
        "--from",
    );
    // Below the range too: a 1e-300 cd/m² display became 0 in f32 and the map was written.
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--display-max", "1e-300"],
        "display-max",
    );
    fails_with(
        d,
        &["map", "scene.hdr", "-o", "o.png", "--scale", "1e-40"],
        "scale",
    );
    assert!(files_in(d).iter().all(|f| f == "scene.hdr"));
}

#[test]
fn one_huge_finite_pixel_does_not_blacken_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 64×64 grey PFM in a dark scene, one pixel at 1e37.
    let (w, h) = (64usize, 64usize);
    let mut f = format!("Pf\n{w} {h}\n-1.0\n").into_bytes();
    for i in 0..w * h {
        let v: f32 = if i == 2080 { 1e37 } else { 0.01 };
        f.extend(v.to_le_bytes());
    }
    std::fs::write(d.join("hot.pfm"), &f).unwrap();
    let out = succeed(visadapt().current_dir(d).args([
        "map",
        "hot.pfm",
        "-o",
        "hot.png",
        "--json",
        "--world-adaptation",
        "0.01",
    ]));
    let v = json(&out.stdout);
    assert!(v["pixels_clipped"].as_u64().unwrap() >= 1, "{v}");
    let dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(d.join("hot.png")).unwrap(),
    ));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buf).unwrap();
    let black = buf.chunks(3).filter(|p| p.iter().all(|c| *c == 0)).count();
    // Before the fix: 4096 of 4096 black.
    assert!(black < 100, "{black} of 4096 pixels black");
}
