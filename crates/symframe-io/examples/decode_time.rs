//! Times decoding image files on one thread, the files read into memory first (so the disk is
//! not timed): `cargo run --release -p symframe-io --example decode_time -- [-r REPEATS] FILES...`.
//! Prints the best and median time per image over the repeats, and the throughput in MB/s of
//! decoded `f32` samples and of file bytes. `scripts/openexr-reference.sh` runs it next to
//! the OpenEXR C++ library on the same files.

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
    if args.is_empty() {
        eprintln!("usage: decode_time [-r REPEATS] FILES...");
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
    let mut sample_bytes = 0usize;
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        let mut samples = 0;
        for (p, b) in &files {
            let img = decode_image(p, b, &opts).expect("decode failed");
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
