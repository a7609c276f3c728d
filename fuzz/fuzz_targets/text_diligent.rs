//! DiLiGenT folders: `filenames.txt`, `light_directions.txt` and `light_intensities.txt`, the
//! input split into the three at the first two 0xff bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("symframe-fuzz-dl-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join("a.png"), b"");
    let mut parts = data.splitn(3, |&b| b == 0xff);
    for name in ["filenames.txt", "light_directions.txt", "light_intensities.txt"] {
        let p = dir.join(name);
        match parts.next() {
            Some(b) => std::fs::write(&p, b).unwrap(),
            None => {
                let _ = std::fs::remove_file(&p);
            }
        }
    }
    let _ = symframe_io::open_dataset(&dir);
});
