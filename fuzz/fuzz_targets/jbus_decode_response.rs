#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| jbus::fuzzing::decode_response(data));
