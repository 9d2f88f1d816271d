//! Helpers shared by the command-line tests.
#![allow(dead_code)]

use assert_cmd::Command;
use std::path::{Path, PathBuf};
use visadapt::HdrImage;

/// Eq. 4 and Eq. 5, shared with the library's own tests.
#[path = "../../../visadapt/tests/common/paper.rs"]
mod paper;
#[allow(unused_imports)] // Not every test binary uses both.
pub use paper::{tp, ts};

pub fn visadapt() -> Command {
    Command::cargo_bin("visadapt").unwrap()
}

pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../visadapt/tests/data")
        .join(name)
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

/// An equal-energy grey field at `l` cd/m² with its scotopic channel (S/P 2.261), in
/// absolute units.
pub fn grey(w: usize, h: usize, l: f32) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    im.x.fill(l);
    im.y.fill(l);
    im.z.fill(l);
    im.scotopic = Some(vec![2.261 * l; w * h]);
    im.absolute_units = true;
    im
}

/// Write `image` as the OpenEXR `path` (its folders created); returns the path.
pub fn write_exr(path: impl AsRef<Path>, image: &HdrImage) -> PathBuf {
    let path = path.as_ref().to_path_buf();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let file = std::fs::File::create(&path).unwrap();
    visadapt::io::exr::write_hdr(image, std::io::BufWriter::new(file)).unwrap();
    path
}

/// A decoded PNG (its first frame).
pub struct Png {
    pub width: u32,
    pub height: u32,
    pub color_type: png::ColorType,
    /// The samples, interleaved, 8 or 16 bits as in the file.
    pub samples: Vec<u8>,
    /// The number of frames of an animated PNG.
    pub frames: Option<u32>,
}

pub fn read_png(path: &Path) -> Png {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let frames = reader.info().animation_control.map(|a| a.num_frames);
    let mut samples = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut samples).unwrap();
    samples.truncate(info.buffer_size());
    Png {
        width: info.width,
        height: info.height,
        color_type: info.color_type,
        samples,
        frames,
    }
}

/// Run a command that must succeed (its standard error in the failure); its output.
pub fn succeed(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Standard output of one JSON value per line.
pub fn json_lines(out: &[u8]) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(out)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}
