//! Fuzz target `radiance`: see `visadapt_fuzz::checks::radiance` for what it checks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| visadapt_fuzz::checks::radiance(data));
