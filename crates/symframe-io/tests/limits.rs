//! Forged headers: every decoder refuses a declared size beyond the limits, or beyond what the
//! file can hold, with a one-line error naming the file, before allocating it (never an abort
//! such as "memory allocation of 40000000000 bytes failed").

use std::fs::{self, File};
use std::path::{Path, PathBuf};

use symframe_io::{read_image, read_npy_f32, write_exr_rgb, write_npy_f32, DecodeOptions, Error};

fn opts() -> DecodeOptions {
    DecodeOptions::default()
}

/// The error of decoding `p`: one line, naming the file.
/// The error and its causes on one line, as the command line prints them.
fn chain(e: &Error) -> String {
    let mut s = e.to_string();
    let mut cause = std::error::Error::source(e);
    while let Some(c) = cause {
        s = format!("{s}: {c}");
        cause = c.source();
    }
    s
}

fn refusal(p: &Path) -> (Error, String) {
    let e = read_image(p, &opts()).unwrap_err();
    let s = chain(&e);
    assert!(s.starts_with(p.to_str().unwrap()), "{s}");
    assert_eq!(s.lines().count(), 1, "{s}");
    (e, s)
}

fn assert_limits(p: &Path, needle: &str) {
    let (e, s) = refusal(p);
    assert!(matches!(e, Error::Limits { .. }), "{s}");
    assert!(
        s.contains(": exceeds limits: ") && s.contains(needle),
        "{s}"
    );
}

/// Finds `pat` in `b`.
fn find(b: &[u8], pat: &[u8]) -> usize {
    b.windows(pat.len())
        .position(|w| w == pat)
        .expect("pattern")
}

/// A small EXR whose data window is patched to `w x h`.
fn forged_exr(dir: &Path, name: &str, w: i32, h: i32) -> PathBuf {
    let p = dir.join(name);
    write_exr_rgb(&p, 4, 4, &[0.5; 48]).unwrap();
    let mut b = fs::read(&p).unwrap();
    let at = find(&b, b"dataWindow\0box2i\0") + 17 + 4;
    for (k, v) in [0i32, 0, w - 1, h - 1].iter().enumerate() {
        b[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    fs::write(&p, &b).unwrap();
    p
}

#[test]
fn exr_header_claiming_100000_squared_in_1_kb() {
    let d = tempfile::tempdir().unwrap();
    let p = forged_exr(d.path(), "huge.exr", 100_000, 100_000);
    assert!(fs::metadata(&p).unwrap().len() < 2048);
    assert_limits(
        &p,
        "EXR header declares 100000x100000 pixels, more than 65536 per side",
    );
    // Within the per-side limit but not what a 1 KB file can hold.
    let p = forged_exr(d.path(), "big.exr", 16_000, 8_000);
    assert_limits(&p, "declares 16000x8000 pixels in a file of");
    let p = forged_exr(d.path(), "many.exr", 60_000, 60_000);
    assert_limits(&p, "more than 134217728 in all");
}

/// CRC-32 (ISO-HDLC), as PNG chunks use.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xedb8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

#[test]
fn png_jpeg_hdr_tiff_and_pfm_headers() {
    let d = tempfile::tempdir().unwrap();
    // PNG: IHDR patched (with a valid CRC).
    let p = d.path().join("a.png");
    symframe_io::write_png8_rgb(&p, 4, 4, &[0.5; 48], false).unwrap();
    let mut b = fs::read(&p).unwrap();
    let at = find(&b, b"IHDR");
    b[at + 4..at + 8].copy_from_slice(&50_000u32.to_be_bytes());
    b[at + 8..at + 12].copy_from_slice(&50_000u32.to_be_bytes());
    let crc = crc32(&b[at..at + 17]);
    b[at + 17..at + 21].copy_from_slice(&crc.to_be_bytes());
    fs::write(&p, &b).unwrap();
    assert_limits(&p, "PNG header declares 50000x50000 pixels");

    // JPEG: the frame header (SOF0) patched to 65535 x 65535.
    let p = d.path().join("a.jpg");
    ::image::ImageEncoder::write_image(
        ::image::codecs::jpeg::JpegEncoder::new_with_quality(File::create(&p).unwrap(), 90),
        &[100u8; 8 * 8 * 3],
        8,
        8,
        ::image::ExtendedColorType::Rgb8,
    )
    .unwrap();
    let mut b = fs::read(&p).unwrap();
    let at = find(&b, &[0xff, 0xc0]);
    b[at + 5..at + 9].copy_from_slice(&[0xff, 0xff, 0xff, 0xff]);
    fs::write(&p, &b).unwrap();
    assert_limits(&p, "JPEG header declares 65535x65535 pixels");

    // Radiance HDR: the resolution line.
    let p = d.path().join("a.hdr");
    fs::write(
        &p,
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n\x80\x80\x80\x80",
    )
    .unwrap();
    let (_, s) = refusal(&p);
    assert!(s.contains("100000"), "{s}");
    let p = d.path().join("b.hdr");
    fs::write(
        &p,
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 10000 +X 10000\n\x80\x80\x80\x80",
    )
    .unwrap();
    assert_limits(&p, "HDR header declares 10000x10000 pixels in a file of");

    // TIFF: ImageWidth and ImageLength (SHORT or LONG) patched.
    let p = d.path().join("a.tif");
    tiff::encoder::TiffEncoder::new(File::create(&p).unwrap())
        .unwrap()
        .write_image::<tiff::encoder::colortype::RGB16>(2, 2, &[7u16; 12])
        .unwrap();
    let mut b = fs::read(&p).unwrap();
    assert_eq!(&b[..2], b"II");
    let ifd = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes([b[ifd], b[ifd + 1]]) as usize;
    for k in 0..n {
        let e = ifd + 2 + 12 * k;
        let tag = u16::from_le_bytes([b[e], b[e + 1]]);
        let ty = u16::from_le_bytes([b[e + 2], b[e + 3]]);
        if tag == 256 || tag == 257 {
            if ty == 3 {
                b[e + 8..e + 10].copy_from_slice(&60_000u16.to_le_bytes());
            } else {
                b[e + 8..e + 12].copy_from_slice(&60_000u32.to_le_bytes());
            }
        }
    }
    fs::write(&p, &b).unwrap();
    let (e, s) = refusal(&p);
    assert!(
        matches!(e, Error::Limits { .. } | Error::Decode { .. }),
        "{s}"
    );

    // PFM: beyond the limits, and more than the file holds.
    let p = d.path().join("a.pfm");
    fs::write(&p, b"PF\n100000 100000\n-1.0\n\0\0\0\0").unwrap();
    assert_limits(&p, "PFM header declares 100000x100000 pixels");
    fs::write(&p, b"PF\n1000 1000\n-1.0\n\0\0\0\0").unwrap();
    let (_, s) = refusal(&p);
    assert!(s.contains("truncated"), "{s}");
}

#[test]
fn npy_header_claiming_100000_squared_by_3() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("n.npy");
    write_npy_f32(&p, &[2, 2, 3], &[0.25; 12]).unwrap();
    let good = fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&good).into_owned();
    assert!(text.contains("(2, 2, 3)"), "{text}");
    // A version 1.0 header declaring `shape`, then the original 48 bytes of data.
    let forge = |shape: &str| {
        let mut h = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(&good[good.len() - 48..]);
        fs::write(&p, &b).unwrap();
        let e = read_npy_f32(&p).unwrap_err();
        let s = chain(&e);
        assert!(s.starts_with(p.to_str().unwrap()), "{s}");
        (e, s)
    };
    let (e, s) = forge("(100000, 100000, 3)");
    assert!(matches!(e, Error::Limits { .. }), "{s}");
    assert!(s.contains("shape (100000, 100000, 3), more than"), "{s}");
    let (e, s) = forge("(1000, 1000, 3)");
    assert!(matches!(e, Error::Decode { .. }), "{s}");
    assert!(
        s.contains("truncated: shape (1000, 1000, 3) needs 12000000 bytes"),
        "{s}"
    );
    let (_, s) = forge("(99999999999999999999999, 3)");
    assert!(s.contains("exceeds limits"), "{s}");
    // The untouched file still reads.
    fs::write(&p, &good).unwrap();
    assert_eq!(read_npy_f32(&p).unwrap().0, vec![2, 2, 3]);
}
