//! The fuzz targets' checks (`fuzz/src/checks.rs`), on stable: every file kept under
//! `fuzz/seeds/<target>/` and `fuzz/regressions/<target>/` (inputs that once failed) is run
//! through its target's check, and this crate's own test images through every decoder's,
//! as the fuzz corpus is seeded with them.

#[path = "../../../fuzz/src/checks.rs"]
mod checks;

use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// The files in `dir` (none when it does not exist), sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .map(|e| e.unwrap().path())
            .filter(|p| p.is_file())
            .collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

/// Run `target`'s check on `path`, naming the file when it fails.
fn replay(target: &str, path: &Path) {
    let data = std::fs::read(path).unwrap();
    let result = std::panic::catch_unwind(|| checks::by_name(target, &data));
    assert!(
        result.is_ok(),
        "fuzz target {target} fails on {}",
        path.display()
    );
}

#[test]
fn every_file_kept_under_fuzz_passes_its_targets_check() {
    let mut kept = 0;
    for target in checks::TARGETS {
        for kind in ["seeds", "regressions"] {
            for path in files(&fuzz_dir().join(kind).join(target)) {
                replay(target, &path);
                kept += 1;
            }
        }
    }
    // Every folder under fuzz/seeds and fuzz/regressions is a target's.
    for kind in ["seeds", "regressions"] {
        for entry in std::fs::read_dir(fuzz_dir().join(kind)).unwrap() {
            let name = entry.unwrap().file_name().to_string_lossy().into_owned();
            assert!(
                checks::TARGETS.contains(&name.as_str()),
                "fuzz/{kind}/{name}"
            );
        }
    }
    assert!(kept >= 10, "only {kept} files under fuzz/");
}

#[test]
fn the_test_images_pass_every_decoders_check() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let images: Vec<PathBuf> = files(&data)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "hdr" || e == "exr"))
        .collect();
    assert!(images.len() >= 4, "{images:?}");
    for path in &images {
        for target in ["radiance", "exr", "pfm", "sniff"] {
            replay(target, path);
        }
    }
}
