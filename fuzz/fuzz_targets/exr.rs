//! Fuzz target `exr`: see `visadapt_fuzz::checks::exr` for what it checks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| visadapt_fuzz::checks::exr(data));
