//! Fuzz target `sniff`: see `visadapt_fuzz::checks::sniff` for what it checks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| visadapt_fuzz::checks::sniff(data));
