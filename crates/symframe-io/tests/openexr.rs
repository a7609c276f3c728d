//! Files written by the OpenEXR C++ library itself decode to OpenEXR's own values, to the bit.
//!
//! `tests/openexr/` holds 45 x 45 float RGB images (a lit sphere with 4% noise) written by
//! OpenEXR 3.1.5 with every compression it has: scan lines (blocks of 1 to 256 lines, the last
//! one partial) and tiles of 16 x 16 (partial at the edges), half floats, and float channels
//! for the lossy PXR24 and DWAA. `openexr-3.1.5.sums` gives, per file, the FNV-1a 64 hash of
//! the R, G, B floats OpenEXR decodes (interleaved, little-endian). Regenerate with
//! `scripts/exr-reference.cpp` (`exr-reference write DIR 45 1 16`, then `exr-reference sum`),
//! as `scripts/exr-compression-bench.sh` builds it.

use std::path::Path;

/// FNV-1a 64 of the samples' little-endian bytes, as `exr-reference sum` computes it.
fn fnv(data: &[f32]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in data {
        for b in v.to_le_bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
    h
}

#[test]
fn openexr_written_files_decode_to_openexrs_values() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr");
    let sums = std::fs::read_to_string(dir.join("openexr-3.1.5.sums")).unwrap();
    let mut seen = Vec::new();
    for line in sums.lines() {
        let (name, want) = line.split_once(' ').unwrap();
        let p = dir.join(name);
        let img = symframe_io::read_image(&p, &Default::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((img.width, img.height, img.channels), (45, 45, 3), "{name}");
        assert_eq!(format!("{:016x}", fnv(&img.data)), want, "{name}");
        seen.push(
            name.split('-')
                .next_back()
                .unwrap()
                .trim_end_matches(".exr"),
        );
    }
    for c in [
        "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab",
    ] {
        assert!(seen.contains(&c), "no {c} file");
    }
}

/// The PIZ files with bytes changed (4,000 changes of one byte each, at random) and cut
/// short: each gives an image or an error, never a panic (`decode_image` catches panics and
/// reports them as "decoder panicked", which this test counts as a failure).
#[test]
fn forged_piz_files_give_errors_not_panics() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr");
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for name in ["scan-half-piz.exr", "tile-half-piz.exr"] {
        let good = std::fs::read(dir.join(name)).unwrap();
        let p = Path::new("forged.exr");
        let check = |bytes: &[u8], what: &str| {
            if let Err(e) = symframe_io::decode_image(p, bytes, &Default::default()) {
                assert!(!e.to_string().contains("panicked"), "{name} {what}: {e}");
            }
        };
        let mut b = good.clone();
        for _ in 0..2000 {
            let i = rnd() as usize % b.len();
            let x = (rnd() % 255 + 1) as u8;
            b[i] ^= x;
            check(&b, &format!("byte {i} ^ {x:#x}"));
            b[i] ^= x;
        }
        for n in (0..good.len()).step_by(37) {
            check(&good[..n], &format!("cut at {n}"));
        }
    }
}

/// A compression this reader does not decode is refused with an error naming it: the HTJ2K
/// ones of OpenEXR 3.4 (codes 10 and 11, forged into a ZIP file's header) and a code no
/// OpenEXR has.
#[test]
fn unsupported_compressions_are_refused_by_name() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/openexr");
    let good = std::fs::read(dir.join("scan-half-zip.exr")).unwrap();
    let key = b"compression\0compression\0\x01\0\0\0";
    let at = good.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    assert_eq!(good[at], 3, "ZIP's code");
    for (code, want) in [(10u8, "HTJ2K256"), (11, "HTJ2K32"), (42, "compression")] {
        let mut b = good.clone();
        b[at] = code;
        let p = Path::new("forged.exr");
        let e = symframe_io::decode_image(p, &b, &Default::default()).unwrap_err();
        // The message with its causes, as the command line prints it.
        let mut msg = e.to_string();
        let mut cause = std::error::Error::source(&e);
        while let Some(c) = cause {
            msg = format!("{msg}: {c}");
            cause = c.source();
        }
        assert!(
            msg.contains(want) && !msg.contains("panicked"),
            "{code}: {msg}"
        );
    }
}
