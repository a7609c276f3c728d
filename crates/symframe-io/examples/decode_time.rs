//! Times decoding image files on one thread, the files read into memory first (so the disk is
//! not timed): `cargo run --release -p symframe-io --example decode_time -- [-r REPEATS] FILES...`.
//! Prints the best and median time per image over the repeats, and the throughput in MB/s of
//! decoded `f32` samples and of file bytes. `scripts/openexr-reference.sh` and
//! `scripts/exr-compression-bench.sh` run it next to the OpenEXR C++ library on the same files.
//!
//! `decode_time --sum FILES...` instead prints the FNV-1a 64 hash of every file's decoded
//! samples (their bytes, little-endian, in file order), which `scripts/exr-reference.cpp sum`
//! computes the same way from OpenEXR's decoding: equal hashes, values equal to the bit.

use std::path::PathBuf;
use std::time::Instant;

use symframe_io::{decode_image, DecodeOptions};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut repeats = 5;
    if args.first().is_some_and(|a| a == "-r") && args.len() >= 2 {
        repeats = args[1].parse().expect("-r takes a number");
        args.drain(..2);
    }
    let sum = args.first().is_some_and(|a| a == "--sum");
    if sum {
        args.remove(0);
    }
    if args.is_empty() {
        eprintln!("usage: decode_time [-r REPEATS] FILES... | --sum FILES...");
        std::process::exit(2);
    }
    let files: Vec<(PathBuf, Vec<u8>)> = args
        .iter()
        .map(|a| {
            (
                PathBuf::from(a),
                std::fs::read(a).expect("cannot read file"),
            )
        })
        .collect();
    let file_bytes: usize = files.iter().map(|f| f.1.len()).sum();
    let opts = DecodeOptions::default();
    if sum {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for (p, b) in &files {
            let img = decode_image(p, b, &opts).unwrap_or_else(|e| panic!("{e}"));
            for v in &img.data {
                for byte in v.to_le_bytes() {
                    h = (h ^ u64::from(byte)).wrapping_mul(0x100_0000_01b3);
                }
            }
        }
        println!("{h:016x}");
        return;
    }
    let mut sample_bytes = 0usize;
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        let mut samples = 0;
        for (p, b) in &files {
            let img = decode_image(p, b, &opts).unwrap_or_else(|e| panic!("{e}"));
            samples += img.data.len();
        }
        times.push(t.elapsed().as_secs_f64());
        sample_bytes = samples * 4;
    }
    times.sort_by(f64::total_cmp);
    let (best, median) = (times[0], times[times.len() / 2]);
    let n = files.len() as f64;
    println!(
        "{} files, {:.1} MB of file, {:.1} MB of f32 samples; per image: best {:.3} ms, median {:.3} ms; \
         {:.0} MB/s of samples, {:.0} MB/s of file (best)",
        files.len(),
        file_bytes as f64 / 1e6,
        sample_bytes as f64 / 1e6,
        best / n * 1e3,
        median / n * 1e3,
        sample_bytes as f64 / best / 1e6,
        file_bytes as f64 / best / 1e6
    );
}
