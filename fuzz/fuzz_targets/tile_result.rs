//! Tile result files (resume and merge).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = symframe_io::tile_results::parse_tile_result_bytes(data);
});
