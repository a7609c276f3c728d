//! Every input that crashed a fuzz target (`fuzz/`, see the README's "Fuzzing") is kept in
//! `tests/fuzz-crashes/<target>/` and replayed here through the same entry point: each must
//! give a result or an error, never a panic.

use std::path::{Path, PathBuf};

fn inputs(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz-crashes")
        .join(target);
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// `'shape': (` followed by a `)` only before the `(`: the header check must not slice
/// backwards.
#[test]
fn npy() {
    let files = inputs("npy");
    assert!(!files.is_empty());
    for f in files {
        let b = std::fs::read(&f).unwrap();
        let r = symframe_io::output::decode_npy_f32(Path::new("fuzz.npy"), &b);
        assert!(r.is_err(), "{f:?}");
    }
}

#[test]
fn image() {
    const NAMES: [&str; 6] = ["f.exr", "f.png", "f.tif", "f.hdr", "f.pfm", "f.jpg"];
    for f in inputs("image") {
        let b = std::fs::read(&f).unwrap();
        if let Some((&pick, bytes)) = b.split_first() {
            let path = Path::new(NAMES[pick as usize % NAMES.len()]);
            let _ = symframe_io::decode_image(path, bytes, &Default::default());
        }
    }
}

#[test]
fn tile_result_and_cache_file() {
    for f in inputs("tile_result") {
        let _ = symframe_io::tile_results::parse_tile_result_bytes(&std::fs::read(&f).unwrap());
    }
    for f in inputs("cache_file") {
        let _ = symframe_io::tile_cache::check_cache_bytes(&std::fs::read(&f).unwrap());
    }
}
