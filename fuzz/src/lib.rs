//! The properties the fuzz targets check, one function per target. The same file
//! (`checks.rs`) is compiled into the library's stable test `tests/fuzz_replay.rs`, which
//! replays every file kept under `fuzz/` through these functions.

pub mod checks;
