//! Every image decoder path with symframe's limits: the first byte picks the format (EXR, PNG,
//! TIFF, HDR, PFM, JPEG), the rest is the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

const NAMES: [&str; 6] = ["f.exr", "f.png", "f.tif", "f.hdr", "f.pfm", "f.jpg"];

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let path = std::path::Path::new(NAMES[pick as usize % NAMES.len()]);
    let opts = symframe_io::DecodeOptions::default();
    let _ = symframe_io::decode_image(path, bytes, &opts);
});
