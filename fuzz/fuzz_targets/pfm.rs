//! Fuzz target `pfm`: see `visadapt_fuzz::checks::pfm` for what it checks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| visadapt_fuzz::checks::pfm(data));
