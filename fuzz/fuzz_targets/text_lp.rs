//! `.lp` light files: the dataset opener (with its image checks) and the light-direction reader.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("symframe-fuzz-lp-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join("a.png"), b"");
    let lp = dir.join("rig.lp");
    std::fs::write(&lp, data).unwrap();
    let _ = symframe_io::open_dataset(&lp);
    let _ = symframe_io::read_light_directions(&lp);
});
