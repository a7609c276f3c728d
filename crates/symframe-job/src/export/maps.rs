//! The maps an export is made from ([`read_maps`]): a glTF fit's as they are, a Ward or two-lobe
//! fit's converted to the metallic-roughness model, an estimate's as a grey material.

use std::path::Path;

use anyhow::{bail, Result};

/// The per-pixel material and frame maps an export is made from.
pub struct Maps {
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
    /// Unit normals, `H x W x 3`, NaN where none.
    pub normals: Vec<f32>,
    /// Unit tangents (wide-highlight axis), NaN where isotropic.
    pub tangents: Vec<f32>,
    /// Linear base colour, `H x W x 3`.
    pub base: Vec<f32>,
    /// Metallic, `H x W`.
    pub metallic: Vec<f32>,
    /// Roughness, `H x W`.
    pub roughness: Vec<f32>,
    /// Anisotropy strength, `H x W`.
    pub strength: Vec<f32>,
    /// Whether the maps come from a fit (else an estimate).
    pub fitted: bool,
    /// For a glTF fit: the light intensity it was fitted under (`fit.json`'s `exposure`);
    /// `None` for a Ward fit (converted) or an estimate.
    pub light_intensity: Option<f64>,
    /// `KHR_materials_clearcoat` factor and roughness per pixel (`H x W` each), where some
    /// pixel has a clear-coat model; 0 elsewhere.
    pub clearcoat: Option<(Vec<f32>, Vec<f32>)>,
}

fn read_map(dir: &Path, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
    let p = dir.join(name);
    if !p.is_file() {
        bail!("{}: missing", p.display());
    }
    let (s, v) = symframe_io::read_npy_f32(&p)?;
    if s != shape {
        bail!("{}: shape {s:?}, expected {shape:?}", p.display());
    }
    Ok(v)
}

fn lum(c: &[f32]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// Converts the Ward parameters of `dir` (`kd`, `ks`, `alpha_t`, `alpha_b` `.npy`) into the
/// glTF maps of `m` at every pixel that has them (the conversion of the module
/// documentation), the albedos divided by `intensity` first (the light intensity of the glTF
/// maps they join: a Ward fit's albedos carry the photographs' scale). Where the wider
/// highlight is along the binormal, `m.tangents` is turned to it.
fn convert_ward(dir: &Path, m: &mut Maps, intensity: f32) -> Result<()> {
    let (w, h) = (m.w, m.h);
    let kd = read_map(dir, "kd.npy", &[h, w, 3])?;
    let ks = read_map(dir, "ks.npy", &[h, w, 3])?;
    let at = read_map(dir, "alpha_t.npy", &[h, w])?;
    let ab = read_map(dir, "alpha_b.npy", &[h, w])?;
    for i in 0..w * h {
        let d: [f32; 3] = std::array::from_fn(|c| kd[3 * i + c] / intensity);
        let s: [f32; 3] = std::array::from_fn(|c| ks[3 * i + c] / intensity);
        put_lobe(m, i, d, s, at[i] as f64, ab[i] as f64);
    }
    Ok(())
}

/// Pixel `i` of `m` as a metallic-roughness material of diffuse albedo `d` and specular
/// reflectance `s` (the module documentation's conversion), roughness `a_t` along the tangent
/// and `a_b` along the binormal (glTF's `alpha`); where the wider one is along the binormal,
/// `m.tangents` is turned to it. Nothing where a value is not finite.
fn put_lobe(m: &mut Maps, i: usize, d: [f32; 3], s: [f32; 3], a_t: f64, a_b: f64) {
    if !d.iter().chain(&s).all(|v| v.is_finite()) {
        return;
    }
    let (ld, ls) = (lum(&d).max(0.0), lum(&s).max(0.0));
    let metal = if ld + ls > 0.0 { ls / (ld + ls) } else { 0.0 };
    m.metallic[i] = metal;
    for c in 0..3 {
        m.base[3 * i + c] = (d[c] + metal * (s[c] - d[c])).clamp(0.0, 1.0);
    }
    if !(a_t.is_finite() && a_b.is_finite()) {
        return;
    }
    let (narrow, wide) = (a_t.min(a_b).clamp(1e-4, 1.0), a_t.max(a_b).clamp(1e-4, 1.0));
    m.roughness[i] = narrow.sqrt() as f32;
    m.strength[i] = ((wide - narrow) / (1.0 - narrow).max(1e-9))
        .sqrt()
        .clamp(0.0, 1.0) as f32;
    if a_b > a_t {
        // The wider highlight is along the binormal n x t.
        let nv = &m.normals[3 * i..3 * i + 3];
        let t = &m.tangents[3 * i..3 * i + 3];
        let b = [
            nv[1] * t[2] - nv[2] * t[1],
            nv[2] * t[0] - nv[0] * t[2],
            nv[0] * t[1] - nv[1] * t[0],
        ];
        m.tangents[3 * i..3 * i + 3].copy_from_slice(&b);
    }
}

/// glTF's clear coat reflects 4% at normal incidence (index 1.5): a coat factor of 1.
const GLTF_COAT_F0: f32 = 0.04;

/// Converts the two-lobe pixels of `dir` ([`crate::relight::read_lobe_maps`]) into the glTF
/// maps of `m` (the module documentation's conversion), the reflectances divided by
/// `intensity` first (as [`convert_ward`]'s); sets `m.clearcoat` where some pixel has a coat.
fn convert_lobes(dir: &Path, m: &mut Maps, intensity: f32) -> Result<()> {
    let Some(l) = crate::relight::read_lobe_maps(dir)? else {
        return Ok(());
    };
    if (l.width, l.height) != (m.w, m.h) {
        bail!("{}: the maps disagree in size", dir.display());
    }
    let n = m.w * m.h;
    let (mut factor, mut rough) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut coated = false;
    for i in 0..n {
        let Some(p) = l.model(i) else {
            continue;
        };
        let k = |v: [f64; 3]| -> [f32; 3] { v.map(|x| x as f32 / intensity) };
        let (d, ka, kb) = (k(p.kd), k(p.ka), k(p.kb));
        match p.kind {
            symframe::LobeKind::Clearcoat => {
                put_lobe(m, i, d, ka, p.alpha_t, p.alpha_b);
                factor[i] = (lum(&kb) / GLTF_COAT_F0).clamp(0.0, 1.0);
                rough[i] = (p.alpha_c.clamp(0.0, 1.0) as f32).sqrt();
                coated = true;
            }
            symframe::LobeKind::Woven => {
                let s: [f32; 3] = std::array::from_fn(|c| ka[c] + kb[c]);
                // The weft lobe has the roughnesses swapped.
                let (a_t, a_b) = if lum(&kb) > lum(&ka) {
                    (p.alpha_b, p.alpha_t)
                } else {
                    (p.alpha_t, p.alpha_b)
                };
                put_lobe(m, i, d, s, a_t, a_b);
            }
        }
    }
    if coated {
        m.clearcoat = Some((factor, rough));
    }
    Ok(())
}

/// Reads a fit folder (kd.npy present) or an estimate folder.
pub fn read_maps(dir: &Path) -> Result<Maps> {
    let np = dir.join("normals.npy");
    if !np.is_file() {
        bail!(
            "{}: missing (the input must be an output folder of symframe fit or estimate)",
            np.display()
        );
    }
    let (shape, normals) = symframe_io::read_npy_f32(&np)?;
    if shape.len() != 3 || shape[2] != 3 || shape[0] == 0 || shape[1] == 0 {
        bail!(
            "{}: expected an H x W x 3 array, got {shape:?}",
            np.display()
        );
    }
    let (h, w) = (shape[0], shape[1]);
    let tangents = read_map(dir, "tangents.npy", &[h, w, 3])?;
    let n = w * h;
    if dir.join("base_color.npy").is_file() {
        let g = crate::relight::read_gltf_maps(dir)?;
        if (g.width, g.height) != (w, h) {
            bail!("{}: the maps disagree in size", dir.display());
        }
        // The fitted values; where nothing was fitted, black, rough, isotropic.
        let fill = |v: &[f32], default: f32| -> Vec<f32> {
            v.iter()
                .map(|&x| if x.is_finite() { x } else { default })
                .collect()
        };
        let strength = (0..n)
            .map(|i| {
                let s = g.anisotropy[i];
                if tangents[3 * i].is_finite() && s.is_finite() {
                    s
                } else {
                    0.0
                }
            })
            .collect();
        let mut m = Maps {
            w,
            h,
            base: fill(&g.base_color, 0.0),
            metallic: fill(&g.metallic, 0.0),
            roughness: fill(&g.roughness, 1.0),
            strength,
            normals,
            tangents,
            fitted: true,
            light_intensity: Some(g.exposure),
            clearcoat: None,
        };
        if dir.join("kd.npy").is_file() {
            // An automatic fit: its Ward pixels converted, in the glTF maps' light intensity.
            convert_ward(dir, &mut m, g.exposure as f32)?;
        }
        convert_lobes(dir, &mut m, g.exposure as f32)?;
        return Ok(m);
    }
    let lobes = dir
        .join(format!("{}.npy", crate::relight::LOBE_MAPS[0]))
        .is_file();
    if dir.join("kd.npy").is_file() || lobes {
        let mut m = Maps {
            w,
            h,
            base: vec![0.0; 3 * n],
            metallic: vec![0.0; n],
            roughness: vec![1.0; n],
            strength: vec![0.0; n],
            normals,
            tangents,
            fitted: true,
            light_intensity: None,
            clearcoat: None,
        };
        if dir.join("kd.npy").is_file() {
            convert_ward(dir, &mut m, 1.0)?;
        }
        convert_lobes(dir, &mut m, 1.0)?;
        Ok(m)
    } else {
        let aniso = if dir.join("anisotropy.npy").is_file() {
            read_map(dir, "anisotropy.npy", &[h, w])?
        } else {
            vec![0.0; n]
        };
        let strength = (0..n)
            .map(|i| {
                if tangents[3 * i].is_finite() && aniso[i].is_finite() {
                    aniso[i].clamp(0.0, 1.0)
                } else {
                    0.0
                }
            })
            .collect();
        Ok(Maps {
            w,
            h,
            base: vec![0.5; 3 * n],
            metallic: vec![0.0; n],
            roughness: vec![0.5; n],
            strength,
            normals,
            tangents,
            fitted: false,
            light_intensity: None,
            clearcoat: None,
        })
    }
}
