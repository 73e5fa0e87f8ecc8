#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| panasonic::fuzzing::decode(data));
