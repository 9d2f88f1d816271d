//! Helpers shared by the command-line tests.
#![allow(dead_code)]

use assert_cmd::Command;
use std::path::{Path, PathBuf};

pub fn visadapt() -> Command {
    Command::cargo_bin("visadapt").unwrap()
}

pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../visadapt/tests/data")
        .join(name)
}

/// Eq. 4, written out independently of the library.
pub fn tp(l: f64) -> f64 {
    let x = l.log10();
    10f64.powf(if x <= -2.6 {
        -0.72
    } else if x >= 1.9 {
        x - 1.255
    } else {
        (0.249 * x + 0.65).powf(2.7) - 0.72
    })
}

pub fn json(out: &[u8]) -> serde_json::Value {
    serde_json::from_slice(out).expect("stdout is one JSON value")
}

pub fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

pub fn one_line_error(stderr: &[u8]) -> String {
    let s = String::from_utf8_lossy(stderr).into_owned();
    assert_eq!(s.trim_end().lines().count(), 1, "not one line: {s:?}");
    assert!(!s.contains("panicked"), "{s}");
    s
}

/// Eq. 5, written out independently of the library.
pub fn ts(l: f64) -> f64 {
    let x = l.log10();
    10f64.powf(if x <= -3.94 {
        -2.86
    } else if x >= -1.44 {
        x - 0.395
    } else {
        (0.405 * x + 1.6).powf(2.18) - 2.86
    })
}

/// A usage error in clap's own form: `error: ...`, then the pointer to `--help`.
pub fn usage_error(stderr: &[u8]) -> String {
    let s = String::from_utf8_lossy(stderr).into_owned();
    assert!(s.starts_with("error: "), "not a usage error: {s:?}");
    assert!(s.contains("For more information, try '--help'."), "{s}");
    assert!(!s.contains("panicked"), "{s}");
    s
}

/// Either kind of error the CLI reports: a usage error (clap's form) or a run-time error
/// (one line).
pub fn cli_error(stderr: &[u8]) -> String {
    if stderr.starts_with(b"error: ") {
        usage_error(stderr)
    } else {
        one_line_error(stderr)
    }
}
