//! Tile cache files: header (checksum, fields), block checksum table, kept warnings.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = symframe_io::tile_cache::check_cache_bytes(data);
});
