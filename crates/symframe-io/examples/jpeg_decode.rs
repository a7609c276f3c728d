//! Times decoding 8-bit image files (JPEG) on one thread, the files read into memory first:
//! `cargo run --release -p symframe-io --example jpeg_decode -- [-r REPEATS] FILES...` prints,
//! per file, the best and median milliseconds over the repeats of decoding into the file's own
//! 8-bit samples (what an integer tile cache stores) and into linear `f32` samples
//! ([`symframe_io::decode_image`]). `scripts/jpeg-decode-bench.sh` runs it next to
//! libjpeg-turbo's `djpeg` on the same files.
//!
//! `jpeg_decode --ppm DIR FILES...` instead writes each file's decoded RGB samples as a binary
//! PPM `DIR/<stem>.ppm`, to compare them with another decoder's; `jpeg_decode --make W H OUT`
//! writes a W x H binary PPM of photograph-like content (shaded spheres on a textured
//! background, sensor noise) to encode as test JPEGs.

use std::path::{Path, PathBuf};
use std::time::Instant;

use symframe_io::codecs::decode_8bit;
use symframe_io::{decode_image, DecodeOptions};

/// Best and median of `repeats` timings of `f`, in milliseconds.
fn time(repeats: usize, mut f: impl FnMut()) -> (f64, f64) {
    let mut t: Vec<f64> = (0..repeats)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[0], t[t.len() / 2])
}

fn decode(p: &Path, b: &[u8]) -> (usize, usize, usize, Vec<u8>) {
    decode_8bit(p, b)
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_else(|| panic!("{}: not an 8-bit image", p.display()))
}

/// A `w x h` binary PPM of photograph-like content: smooth shading, a few glossy discs with
/// highlights, a fine texture and sensor noise (a fixed pseudo-random sequence).
fn make(w: usize, h: usize, out: &Path) {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    let discs = [(0.3, 0.4, 0.22), (0.7, 0.55, 0.18), (0.5, 0.8, 0.12)];
    let mut v = format!("P6\n{w} {h}\n255\n").into_bytes();
    v.reserve(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let (u, t) = (x as f32 / w as f32, y as f32 / h as f32);
            // Background: a gradient with a woven texture.
            let weave = ((x as f32 * 0.9).sin() * (y as f32 * 0.7).sin()) * 0.06;
            let mut rgb = [
                0.35 + 0.3 * u + weave,
                0.3 + 0.2 * t + weave,
                0.25 + 0.1 * u * t,
            ];
            for (k, &(cx, cy, r)) in discs.iter().enumerate() {
                let (dx, dy) = ((u - cx) * w as f32 / h as f32, t - cy);
                let d2 = (dx * dx + dy * dy) / (r * r);
                if d2 < 1.0 {
                    let nz = (1.0 - d2).sqrt();
                    let shade = 0.15 + 0.7 * (0.5 * nz - 0.4 * dx / r + 0.3 * dy / r).max(0.0);
                    let spec = (nz * 0.9 - 0.35 * dx / r + 0.2 * dy / r).max(0.0).powi(40);
                    let albedo = [[0.8, 0.3, 0.2], [0.2, 0.5, 0.8], [0.7, 0.7, 0.3]][k];
                    for c in 0..3 {
                        rgb[c] = albedo[c] * shade + spec;
                    }
                }
            }
            for c in rgb {
                let s = (c + 0.06 * noise()).clamp(0.0, 1.0).powf(1.0 / 2.2);
                v.push((s * 255.0).round() as u8);
            }
        }
    }
    std::fs::write(out, v).expect("cannot write");
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() == 4 && args[0] == "--make" {
        let size = |a: &str| a.parse::<usize>().expect("--make W H OUT");
        make(size(&args[1]), size(&args[2]), Path::new(&args[3]));
        return;
    }
    let mut repeats = 5;
    let mut ppm: Option<PathBuf> = None;
    while args.len() >= 2 && (args[0] == "-r" || args[0] == "--ppm") {
        if args[0] == "-r" {
            repeats = args[1].parse().expect("-r takes a number");
        } else {
            ppm = Some(PathBuf::from(&args[1]));
        }
        args.drain(..2);
    }
    if args.is_empty() || repeats == 0 {
        eprintln!("usage: jpeg_decode [-r REPEATS] FILES... | --ppm DIR FILES...");
        std::process::exit(2);
    }
    let opts = DecodeOptions::default();
    for a in &args {
        let p = PathBuf::from(a);
        let b = std::fs::read(&p).expect("cannot read file");
        if let Some(dir) = &ppm {
            let (w, h, ch, v) = decode(&p, &b);
            assert_eq!(ch, 3, "{a}: not RGB");
            let mut out = format!("P6\n{w} {h}\n255\n").into_bytes();
            out.extend_from_slice(&v);
            let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
            std::fs::write(dir.join(format!("{stem}.ppm")), out).expect("cannot write");
            continue;
        }
        let (w, h, _, _) = decode(&p, &b);
        let codes = time(repeats, || {
            std::hint::black_box(decode(&p, &b));
        });
        let linear = time(repeats, || {
            std::hint::black_box(decode_image(&p, &b, &opts).unwrap_or_else(|e| panic!("{e}")));
        });
        println!(
            "{a} {w}x{h} codes best {:.1} ms median {:.1} ms; linear f32 best {:.1} ms median {:.1} ms",
            codes.0, codes.1, linear.0, linear.1
        );
    }
}
