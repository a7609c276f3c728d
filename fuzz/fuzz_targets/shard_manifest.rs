//! Shard manifests (`shard.json`), read by `merge` from folders anyone may have written:
//! parsed and checked as `merge` does before it reads a tile or sizes anything.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = symframe_job::check_shard_manifest(text);
    }
});
