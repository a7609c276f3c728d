//! The view `samples`: the capture's own samples in the page, relit by the shader as
//! [`symframe::SampleRelighter`] does (`symframe relight --from-samples`).
//!
//! One texture array, four half floats per texel, layer by layer (rows top to bottom): layer
//! 0 the pixel's normal and 1 where it has a frame, layer 1 its tangent, then one layer per
//! light of the rig (its order) with the RGB slice (radiance over `n.l`) and 1 where the
//! sample is valid (0 and 0 where not). And the rig's triangulation: per triangle three rows of
//! four floats, each a row of its spherical inverse and the light (layer - 2) of that corner.

use std::path::Path;

use anyhow::{bail, Result};
use serde::Serialize;
use symframe_io::DecodeOptions;

use super::half_bits;
use super::page::encode_halves;
use super::{ViewConfig, MAX_SAMPLE_BYTES, MAX_SAMPLE_LIGHTS};

/// The samples as the page reads them.
#[derive(Serialize)]
pub(super) struct PageSamples {
    /// Lights (layers after the two of the frames).
    pub(super) lights: usize,
    /// The texture array, encoded as the other textures (`page.rs`), layer after layer.
    pub(super) layers: String,
    /// The triangulation: per triangle, three rows `[inverse row, corner light]`.
    pub(super) triangles: Vec<[[f32; 4]; 3]>,
}

/// The page's samples of `capture` (decoded with `decode`) in the frames of the maps in
/// `config.fit_dir` (`normals.npy`, `tangents.npy` of a fit or an estimate), of size
/// `(w, h)`.
pub(super) fn page_samples(
    config: &ViewConfig,
    (capture, decode): (&Path, &DecodeOptions),
    (w, h): (usize, usize),
    estimate: bool,
) -> Result<PageSamples> {
    let ds = symframe_io::open_dataset(capture)?;
    let lights = ds.lights.len();
    if lights > MAX_SAMPLE_LIGHTS {
        bail!(
            "{}: {lights} lights; the view `samples` takes at most {MAX_SAMPLE_LIGHTS} (a \
             browser's texture arrays hold 256 layers at least, two of them the frames): relight \
             more with symframe relight --from-samples",
            capture.display()
        );
    }
    let bytes = w * h * (lights + 2) * 8;
    if bytes > MAX_SAMPLE_BYTES {
        bail!(
            "{}: {w} x {h} pixels under {lights} lights make {} MiB of sample texels; the view \
             `samples` embeds at most {} MiB in the page: relight larger captures with symframe \
             relight --from-samples",
            capture.display(),
            bytes >> 20,
            MAX_SAMPLE_BYTES >> 20
        );
    }
    // The frames: an estimate folder's maps (no tangent map: every pixel isotropic), or a
    // fit's.
    let (estimated, fitted);
    let (normals, tangents): (&[f32], &[f32]) = if estimate {
        let read = |name| crate::relight::read_map(&config.fit_dir, name, &[h, w, 3]);
        let tangents = if config.fit_dir.join("tangents.npy").is_file() {
            read("tangents")?
        } else {
            vec![f32::NAN; w * h * 3]
        };
        estimated = (read("normals")?, tangents);
        (&estimated.0, &estimated.1)
    } else {
        fitted = crate::relight::read_fit_maps(&config.fit_dir)?;
        (fitted.normals(), fitted.tangents())
    };
    let relighter = crate::relight::sample_relighter(capture, decode, normals, tangents, (w, h))?;
    let lights = relighter.lights();
    let n = w * h;
    let mut halves = vec![0u16; n * (lights + 2) * 4];
    let (frames, slices) = halves.split_at_mut(n * 8);
    let (normal_layer, tangent_layer) = frames.split_at_mut(n * 4);
    for (p, frame) in relighter.frames().iter().enumerate() {
        if let Some((normal, tangent)) = frame {
            for c in 0..3 {
                normal_layer[4 * p + c] = half_bits(normal[c] as f32);
                tangent_layer[4 * p + c] = half_bits(tangent[c] as f32);
            }
            normal_layer[4 * p + 3] = half_bits(1.0);
        }
    }
    for (p, slice) in relighter
        .slices()
        .chunks_exact(lights.max(1) * 3)
        .enumerate()
    {
        for (k, rgb) in slice.chunks_exact(3).enumerate() {
            if rgb.iter().all(|v| v.is_finite()) {
                let o = 4 * (k * n + p);
                for c in 0..3 {
                    slices[o + c] = half_bits(rgb[c]);
                }
                slices[o + 3] = half_bits(1.0);
            }
        }
    }
    let triangles = relighter
        .triangles()
        .map(|(corners, inverse)| {
            let rows = inverse.transpose();
            [0, 1, 2].map(|r| {
                let row = rows.col(r);
                [row.x as f32, row.y as f32, row.z as f32, corners[r] as f32]
            })
        })
        .collect();
    Ok(PageSamples {
        lights,
        layers: encode_halves(&halves, 6)?,
        triangles,
    })
}

#[cfg(test)]
mod tests {
    use std::io::Read;

    use super::*;
    use symframe::brdf::Ward;
    use symframe::render::{Scene, TangentField};
    use symframe_io::{write_npy_f32, ImageFormat};

    /// An estimate folder of a 10 x 10 brushed sphere (its true frames) and its capture under
    /// `lights` lights in `dir`: (the folder, the capture's `.lp`).
    fn folders(dir: &Path, lights: usize) -> (std::path::PathBuf, std::path::PathBuf) {
        let scene = Scene::sphere(10, TangentField::Circular);
        let lights = symframe::uniform_cone_lights(lights, 65.0);
        let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
        let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
        let lp = symframe_io::write_lp_dataset(
            &dir.join("data"),
            &lights,
            &images,
            10,
            10,
            ImageFormat::Exr,
            None,
            None,
            Some(&scene.mask),
        )
        .unwrap();
        let est = dir.join("est");
        std::fs::create_dir_all(&est).unwrap();
        write_npy_f32(&est.join("normals.npy"), &[10, 10, 3], &scene.gt_normals()).unwrap();
        write_npy_f32(
            &est.join("tangents.npy"),
            &[10, 10, 3],
            &scene.gt_tangents(),
        )
        .unwrap();
        (est, lp)
    }

    /// The page's texture array holds the relighter's frames and slices as half floats (NaN:
    /// 0 with a zero flag), layer after layer; its triangles are the rig's, rows of the
    /// inverse and the corners' lights.
    #[test]
    fn the_page_holds_the_relighter_s_tables() {
        let dir = tempfile::tempdir().unwrap();
        let (est, lp) = folders(dir.path(), 30);
        let config = ViewConfig::new(&est);
        let decode = DecodeOptions::default();
        let page = page_samples(&config, (&lp, &decode), (10, 10), true).unwrap();
        let stack =
            symframe_io::load_stack(&symframe_io::open_dataset(&lp).unwrap(), &decode, &|| {})
                .unwrap();
        let rig = symframe::Rig::new(&stack_lights(&lp), symframe::RigOptions::default()).unwrap();
        let read = |name: &str| symframe_io::read_npy_f32(&est.join(name)).unwrap().1;
        let r = symframe::SampleRelighter::new(
            &stack,
            rig,
            &read("normals.npy"),
            &read("tangents.npy"),
            None,
        )
        .unwrap();
        let triangles: Vec<_> = r.triangles().collect();
        assert_eq!(page.lights, 30);
        assert_eq!(page.triangles.len(), triangles.len());
        for ((corners, inverse), rows) in triangles.iter().zip(&page.triangles) {
            for r in 0..3 {
                assert_eq!(rows[r][3], corners[r] as f32);
                assert_eq!(rows[r][0], inverse.col(0)[r] as f32);
            }
        }
        // Undo the page's encoding: base64, zlib, low bytes then high bytes.
        let bytes = base64_decode(&page.layers);
        let mut raw = Vec::new();
        flate2::read::ZlibDecoder::new(&bytes[..])
            .read_to_end(&mut raw)
            .unwrap();
        let n = raw.len() / 2;
        assert_eq!(n, 100 * 32 * 4);
        let half =
            |i: usize| half::f16::from_bits(u16::from_le_bytes([raw[i], raw[n + i]])).to_f32();
        let mut valid = 0;
        for p in 0..100 {
            match r.frames()[p] {
                Some((normal, _)) => {
                    assert_eq!(half(4 * p + 3), 1.0);
                    assert!((half(4 * p + 2) - normal.z as f32).abs() < 1e-3);
                }
                None => assert_eq!(half(4 * p + 3), 0.0),
            }
            for k in 0..30 {
                let o = 4 * ((k + 2) * 100 + p);
                let rgb = &r.slices()[(p * 30 + k) * 3..(p * 30 + k) * 3 + 3];
                if rgb[0].is_finite() {
                    valid += 1;
                    assert_eq!(half(o + 3), 1.0);
                    assert!(
                        (half(o) - rgb[0]).abs() <= 1e-3 * rgb[0].abs().max(1e-2),
                        "{p} {k}"
                    );
                } else {
                    assert_eq!((half(o), half(o + 3)), (0.0, 0.0));
                }
            }
        }
        assert!(valid > 500, "{valid}");
    }

    /// More lights than a texture array takes, more texels than a page holds, a pyramid: each
    /// refused with what to do instead.
    #[test]
    fn captures_the_page_cannot_hold_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let (est, lp) = folders(dir.path(), 260);
        let decode = DecodeOptions::default();
        let config = ViewConfig::new(&est);
        let e = page_samples(&config, (&lp, &decode), (10, 10), true)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("260 lights") && e.contains("at most 254"), "{e}");
        let (est, lp) = folders(&dir.path().join("small"), 30);
        let config = ViewConfig::new(&est);
        let e = page_samples(&config, (&lp, &decode), (8000, 8000), true)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("MiB") && e.contains("relight --from-samples"),
            "{e}"
        );
        let mut config = ViewConfig::new(&est);
        config.pyramid_above = 4;
        config.samples = Some((lp, decode));
        config.output = dir.path().join("v.html");
        let e = crate::write_viewer(&config).err().unwrap().to_string();
        assert!(e.contains("no pyramid"), "{e}");
        assert!(!config.output.exists());
    }

    fn stack_lights(lp: &Path) -> Vec<glam::DVec3> {
        symframe_io::open_dataset(lp).unwrap().lights
    }

    fn base64_decode(s: &str) -> Vec<u8> {
        const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let value = |c: u8| ABC.iter().position(|&a| a == c).unwrap() as u32;
        let mut out = Vec::new();
        for chunk in s.as_bytes().chunks(4) {
            let pad = chunk.iter().filter(|&&c| c == b'=').count();
            let v = chunk
                .iter()
                .map(|&c| if c == b'=' { 0 } else { value(c) })
                .fold(0u32, |a, d| (a << 6) | d);
            out.extend_from_slice(&v.to_be_bytes()[1..4 - pad]);
        }
        out
    }
}
