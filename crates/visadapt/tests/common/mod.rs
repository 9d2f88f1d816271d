//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

pub mod paper;
#[allow(unused_imports)] // Not every test binary uses both.
pub use paper::{tp, ts};

/// A file committed under `crates/visadapt/tests/data/`.
pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// A file of the project's shared data set (`../shared/data/` beside the repository, or
/// `$VISADAPT_SHARED_DATA`). Too large to commit, so tests that need it skip with a note
/// when it is absent, unless `VISADAPT_REQUIRE_SHARED_DATA=1` (set by `.ci/run` whenever
/// the data exists), in which case its absence is a failure.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let root = std::env::var_os("VISADAPT_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    let p = root.join(rel);
    if p.exists() {
        return Some(p);
    }
    if std::env::var_os("VISADAPT_REQUIRE_SHARED_DATA").is_some_and(|v| v == "1") {
        panic!("shared test data {} is missing", p.display());
    }
    eprintln!("note: shared test data {} not found, skipping", p.display());
    None
}
