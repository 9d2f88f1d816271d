//! Fuzz target `operator`: see `visadapt_fuzz::checks::operator` for what it checks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| visadapt_fuzz::checks::operator(data));
