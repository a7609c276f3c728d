//! `normals.png` of `symframe estimate`: 16-bit, `(n + 1) / 2` in every channel, green up by
//! default (OpenGL, glTF) and down with `--normal-png directx`.

use crate::common::{s, symframe};
use symframe_io::{read_image, read_npy_f32, DecodeOptions};

#[test]
fn normals_png_holds_the_normals_in_either_y_convention() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let o = symframe(&["synth", "-o", s(&data), "--size", "24", "--rig", "cone:120"]);
    assert!(o.status.success());
    let opts = DecodeOptions {
        saturation: 2.0,
        ..DecodeOptions::default()
    };
    for (conv, sy) in [("opengl", 1.0f32), ("directx", -1.0)] {
        let out = tmp.path().join(conv);
        let o = symframe(&["estimate", s(&data), "-o", s(&out), "--normal-png", conv]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (_, n) = read_npy_f32(&out.join("normals.npy")).unwrap();
        let png = image_bit_depth(&out.join("normals.png"));
        assert_eq!(png, 16);
        let img = read_image(&out.join("normals.png"), &opts).unwrap();
        let mut checked = 0;
        for (v, p) in n.chunks_exact(3).zip(img.data.chunks_exact(3)) {
            if v[0].is_nan() {
                assert_eq!(p, &[0.0, 0.0, 0.0]);
                continue;
            }
            let want = [
                (v[0] + 1.0) / 2.0,
                (sy * v[1] + 1.0) / 2.0,
                (v[2] + 1.0) / 2.0,
            ];
            for (g, w) in p.iter().zip(want) {
                assert!((g - w).abs() < 1e-4, "{conv}: {p:?} for {v:?}");
            }
            checked += 1;
        }
        assert!(checked > 300);
    }
}

/// The bit depth in a PNG's header.
fn image_bit_depth(p: &std::path::Path) -> u8 {
    let b = std::fs::read(p).unwrap();
    assert_eq!(&b[12..16], b"IHDR");
    b[24]
}
