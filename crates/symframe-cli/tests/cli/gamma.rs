//! `--gamma` and colour tags: 16-bit images sRGB-decoded on request, the choice part of the
//! cache fingerprint (a changed gamma rebuilds the cache), and tags that disagree with the
//! decoding warned about in report.json.

use std::fs;
use std::path::Path;

use crate::common::{estimate, ok, report, s, symframe};

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

/// Inserts a chunk after the PNG header chunk of the file at `path`.
fn add_chunk(path: &Path, kind: &[u8; 4], data: &[u8]) {
    let png = fs::read(path).unwrap();
    let at = 8 + 8 + 13 + 4;
    let mut body = kind.to_vec();
    body.extend(data);
    let mut chunk = (data.len() as u32).to_be_bytes().to_vec();
    chunk.extend(&body);
    chunk.extend(crc32(&body).to_be_bytes());
    fs::write(path, [&png[..at], &chunk[..], &png[at..]].concat()).unwrap();
}

/// An `iCCP` chunk holding a minimal ICC profile named `name` (zlib with one stored block).
fn iccp(name: &str) -> Vec<u8> {
    let mut desc = b"desc\0\0\0\0".to_vec();
    desc.extend((name.len() as u32 + 1).to_be_bytes());
    desc.extend(name.as_bytes());
    desc.push(0);
    let mut icc = vec![0u8; 128];
    icc[36..40].copy_from_slice(b"acsp");
    icc.extend(1u32.to_be_bytes());
    icc.extend(b"desc");
    icc.extend(144u32.to_be_bytes());
    icc.extend((desc.len() as u32).to_be_bytes());
    icc.extend(desc);
    let mut d = b"icc\0\0\x78\x01\x01".to_vec();
    let n = icc.len() as u16;
    d.extend(n.to_le_bytes());
    d.extend((!n).to_le_bytes());
    d.extend(&icc);
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &icc {
        a = (a + x as u32) % 65_521;
        b = (b + a) % 65_521;
    }
    d.extend(((b << 16) | a).to_be_bytes());
    d
}

#[test]
fn gamma_flag_rebuilds_the_cache_and_colour_tags_are_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("d");
    ok(&symframe(&[
        "-q",
        "synth",
        "-o",
        s(&data),
        "--size",
        "16",
        "--rig",
        "cone:40",
        "--model",
        "lambertian",
        "--format",
        "png16",
    ]));
    let mut images: Vec<_> = fs::read_dir(data.join("images"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    images.sort();
    // Every image says gamma 1/2.2 (gAMA); the first also carries an Adobe RGB profile, which
    // takes precedence over its gAMA chunk (and gives no curve).
    for p in &images {
        add_chunk(p, b"gAMA", &45_455u32.to_be_bytes());
    }
    add_chunk(&images[0], b"iCCP", &iccp("Adobe RGB (1998)"));
    let out = tmp.path().join("out");
    ok(&estimate(&data, &out, &["-q"]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false);
    assert_eq!(r["parameters"]["gamma"], "auto");
    let w = crate::common::report_warnings(&out);
    assert!(
        w.iter()
            .any(|l| l.contains("ICC profile 'Adobe RGB (1998)' is not sRGB")
                && l.contains("img_0000.png")),
        "{w:?}"
    );
    assert!(
        w.iter().any(
            |l| l.contains("gamma-encoded, but they were taken as linear")
                && l.contains("(39 of the images")
        ),
        "{w:?}"
    );
    let linear = symframe_io::read_npy_f32(&out.join("normals.npy"))
        .unwrap()
        .1;

    // The same flags reuse the cache and report its warnings again.
    ok(&estimate(&data, &out, &["-q"]));
    assert_eq!(report(&out)["cache"]["hit"], true);
    assert_eq!(crate::common::report_warnings(&out).len(), w.len());

    // --gamma srgb rebuilds it; the curve now agrees with the tags, the profile still not.
    ok(&estimate(&data, &out, &["-q", "--gamma", "srgb"]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false);
    assert_eq!(r["parameters"]["gamma"], "srgb");
    let w = crate::common::report_warnings(&out);
    assert!(w.iter().any(|l| l.contains("is not sRGB")), "{w:?}");
    assert!(!w.iter().any(|l| l.contains("taken as linear")), "{w:?}");
    let srgb = symframe_io::read_npy_f32(&out.join("normals.npy"))
        .unwrap()
        .1;
    assert_ne!(linear, srgb);

    // --linear is --gamma linear; both at once is a usage error.
    let o = estimate(&data, &out, &["-q", "--gamma", "srgb", "--linear"]);
    assert_eq!(o.status.code(), Some(2));
}
