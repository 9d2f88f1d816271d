//! SIGINT and SIGTERM during long commands: the outputs in flight are removed, the files
//! already written are complete, and the exit status is 128 + the signal (130, 143).
#![cfg(unix)]

mod common;

use common::files_in;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running `visadapt` with `args`; `named` forces named temporary files (the path a
/// signal handler must clean up; by default Linux gives unnamed ones).
fn start(args: &[&str], named: bool) -> Child {
    let mut cmd = Command::new(assert_cmd::cargo::cargo_bin("visadapt"));
    cmd.args(args).stdout(Stdio::null()).stderr(Stdio::piped());
    if named {
        cmd.env("VISADAPT_NAMED_TEMPORARIES", "1");
    }
    cmd.spawn().unwrap()
}

fn temporaries(dir: &Path) -> Vec<String> {
    if !dir.is_dir() {
        return Vec::new();
    }
    files_in(dir)
        .into_iter()
        .filter(|f| f.starts_with(".visadapt-"))
        .collect()
}

/// Wait (polling) until `ready(dir)` holds while `child` still runs; panics if it ends
/// first or after a minute.
fn wait_for(child: &mut Child, dir: &Path, what: &str, ready: impl Fn(&Path) -> bool) {
    let start = Instant::now();
    while !ready(dir) {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the command ended ({status}) before {what}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no {what} within 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn send(child: &Child, signal: &str) {
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Interrupt `args` writing into `dir` with `signal` once a temporary file is in flight
/// (`named`) or once a first output is complete (unnamed temporaries); returns the exit
/// code and the files left.
fn interrupt(args: &[&str], dir: &Path, signal: &str, named: bool) -> (Option<i32>, Vec<String>) {
    let mut child = start(args, named);
    if named {
        wait_for(&mut child, dir, "a temporary file", |d| {
            !temporaries(d).is_empty()
        });
    } else {
        wait_for(&mut child, dir, "a first output", |d| {
            d.is_dir() && files_in(d).iter().any(|f| !f.starts_with('.'))
        });
    }
    send(&child, signal);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    (out.status.code(), files_in(dir))
}

/// Every PNG in `dir` decodes completely.
fn pngs_complete(dir: &Path, files: &[String]) {
    for f in files.iter().filter(|f| f.ends_with(".png")) {
        let bytes = std::fs::read(dir.join(f)).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader
            .next_frame(&mut buf)
            .unwrap_or_else(|e| panic!("{f}: {e}"));
    }
}

#[test]
fn demo_interrupted_removes_its_temporary_files_and_exits_130() {
    let tmp = tempfile::tempdir().unwrap();
    for (named, signal, code) in [
        (true, "-INT", 130),
        (true, "-TERM", 143),
        (false, "-INT", 130),
    ] {
        let dir = tmp.path().join(format!("demo{named}{signal}"));
        let (status, files) =
            interrupt(&["demo", "-o", dir.to_str().unwrap()], &dir, signal, named);
        assert_eq!(status, Some(code), "{signal} named={named}: {files:?}");
        assert!(temporaries(&dir).is_empty(), "{signal}: left {files:?}");
        // Interrupted before the end: not every file was written, those written are whole.
        assert!(files.len() < 21, "{files:?}");
        pngs_complete(&dir, &files);
    }
}

/// A PFM frame of `w × h` grey pixels of `v` cd/m² (with a ramp, so that it is not flat).
fn write_frame(path: &Path, w: usize, h: usize, v: f32) {
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for i in 0..w * h {
        let l = v * (1.0 + (i % w) as f32 / w as f32);
        for _ in 0..3 {
            bytes.extend_from_slice(&l.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn video_interrupted_removes_its_temporary_files_and_exits_130_or_143() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("in");
    std::fs::create_dir(&frames).unwrap();
    for i in 0..12 {
        write_frame(
            &frames.join(format!("f{i}.pfm")),
            1024,
            768,
            10f32.powi(i % 4),
        );
    }
    let pattern = frames.join("f%d.pfm");
    for (named, signal, code) in [
        (true, "-INT", 130),
        (true, "-TERM", 143),
        (false, "-TERM", 143),
    ] {
        let dir = tmp.path().join(format!("out{named}{signal}"));
        let (status, files) = interrupt(
            &[
                "video",
                pattern.to_str().unwrap(),
                "--fps",
                "10",
                "--format",
                "exr",
                "-o",
                dir.to_str().unwrap(),
            ],
            &dir,
            signal,
            named,
        );
        assert_eq!(status, Some(code), "{signal} named={named}: {files:?}");
        assert!(temporaries(&dir).is_empty(), "{signal}: left {files:?}");
        assert!(files.len() < 12, "{files:?}");
        // The frames written are whole.
        for f in &files {
            let img = visadapt::io::read(&dir.join(f), &visadapt::Limits::default())
                .unwrap_or_else(|e| panic!("{f}: {e}"));
            assert_eq!((img.width, img.height), (1024, 768), "{f}");
        }
    }
}
