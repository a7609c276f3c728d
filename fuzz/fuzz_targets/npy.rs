//! The `.npy` reader (`fit`, `eval`, `relight`), limits included.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = symframe_io::output::decode_npy_f32(std::path::Path::new("fuzz.npy"), data);
});
