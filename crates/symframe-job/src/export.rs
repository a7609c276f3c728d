//! The glTF export job (`symframe export gltf`): a fit's (or an estimate's) maps as a glTF 2.0 asset: a quad, or the
//! integrated mesh, with a metallic-roughness material, a tangent-space normal texture and
//! `KHR_materials_anisotropy`.
//!
//! Frames: the quad lies in the x-y plane facing +z (x right, y up: the camera frame), one image
//! width across; its vertex tangent is +x and bitangent +y, so a camera-frame normal *is* its
//! tangent-space normal (glTF's +Y-up normal-map convention). For `--mesh` the vertex normals and
//! tangents come from the maps at each pixel (one vertex per pixel), so the shading detail is in
//! the geometry and no normal texture is written.
//!
//! Material, from a `symframe fit --model gltf` folder: exactly the fitted base colour,
//! metallic, roughness and anisotropy strength (direction = the fit's tangent), quantised to
//! the 8-bit textures; the light intensity the fit assumed is recorded in the material's
//! `extras.symframe.lightIntensity` (a renderer lighting the asset with lights of that
//! intensity reproduces the photographs). From a Ward fit (a conversion, not a fit of the glTF
//! model): `metallic = ks / (kd + ks)` (luminances), `baseColor = kd + metallic (ks - kd)`; the
//! narrow roughness `alpha_narrow = min(alpha_t, alpha_b)` gives `roughness = sqrt(alpha_narrow)`
//! (glTF's `alpha = roughness^2`), and the anisotropy strength `s` solves
//! `alpha_wide = alpha_narrow + s^2 (1 - alpha_narrow)` (the extension's stretch), its direction
//! the axis of the wider highlight. From an automatic fit (`--model auto`, both models' maps):
//! the glTF parameters where the glTF model was chosen, the Ward pixels converted as above
//! after dividing their albedos by the fit's light intensity (one glTF material needs one
//! model; the conversion is approximate where Ward was chosen). From an estimate folder: grey base colour, roughness 0.5,
//! metallic 0, and anisotropy strength = the estimate's anisotropy where it has a tangent.
//!
//! Two-lobe pixels (`--model clearcoat`, `woven`, or chosen by `auto`) are converted the same
//! way, their GGX roughnesses taken as glTF's `alpha` directly. A clear-coat pixel's base
//! (`lobes_kd`, `lobes_ka`, `lobes_alpha_t`, `lobes_alpha_b`) becomes the metallic-roughness
//! material with its anisotropy, and its coat `KHR_materials_clearcoat`: factor
//! `kc / 0.04` (the coat's reflectance over that of glTF's index-1.5 coat, clamped to 1) and
//! roughness `sqrt(alpha_c)`, in one texture (R factor, G roughness) written only when some
//! pixel has a coat. glTF has no second anisotropic lobe: a woven pixel becomes one lobe with
//! both lobes' reflectance, stretched along the stronger lobe's wide axis (approximate).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};

/// Everything a glTF export needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportConfig {
    /// Output folder of [`crate::fit`] (kd, ks, alpha_t, alpha_b, normals, tangents `.npy`) or
    /// of [`crate::estimate`] (normals, tangents, anisotropy `.npy`).
    pub input: PathBuf,
    /// The file to write: `.gltf` (textures and `.bin` beside it) or `.glb` (all in one).
    pub output: PathBuf,
    /// Export the integrated mesh (one vertex per pixel) instead of a flat quad.
    pub mesh: bool,
    /// With `mesh`: the height map of [`crate::integrate`] (`None`: `INPUT/depth.npy`).
    pub depth: Option<PathBuf>,
    /// With `mesh`: leave out triangles across depth jumps (as the integrate job's `max_jump`).
    pub max_jump: f64,
    /// With `mesh`: the depth map is a perspective one through this camera (`K.txt`), the mesh
    /// metric in the camera frame. `None`: the camera recorded beside the depth map
    /// ([`crate::recorded_camera`]), else the depth map is a height map.
    pub camera: Option<PathBuf>,
}

impl ExportConfig {
    /// A quad, no mesh, the integrate job's default jump limit.
    pub fn new(input: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        Self {
            input: input.into(),
            output: output.into(),
            mesh: false,
            depth: None,
            max_jump: 2.0,
            camera: None,
        }
    }
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOutcome {
    /// The files written, the asset first.
    pub written: Vec<PathBuf>,
    /// Whether the material comes from a fit (else from an estimate's frames).
    pub fitted: bool,
    /// Vertices of the geometry.
    pub vertices: usize,
    /// Triangles of the geometry.
    pub triangles: usize,
}

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

fn byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The tangent-space frame at a vertex with normal `n`: tangent = +x projected onto the plane
/// of `n` (+y where `n` is along x), bitangent = `n x tangent`.
fn vertex_frame(n: [f32; 3]) -> ([f32; 3], [f32; 3]) {
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let norm = |a: [f32; 3]| {
        let l = dot(a, a).sqrt().max(1e-30);
        [a[0] / l, a[1] / l, a[2] / l]
    };
    let mut t = [1.0 - n[0] * n[0], -n[0] * n[1], -n[0] * n[2]];
    if dot(t, t) < 1e-6 {
        t = [-n[1] * n[0], 1.0 - n[1] * n[1], -n[1] * n[2]];
    }
    let t = norm(t);
    let b = [
        n[1] * t[2] - n[2] * t[1],
        n[2] * t[0] - n[0] * t[2],
        n[0] * t[1] - n[1] * t[0],
    ];
    (t, b)
}

/// The textures, as RGB bytes: base colour (sRGB), metallic-roughness (G roughness, B
/// metallic), normal (tangent space of the quad, `(n + 1) / 2`), anisotropy (RG direction in
/// the vertex tangent space, `(d + 1) / 2`, B strength).
pub fn textures(m: &Maps, quad: bool) -> [Vec<u8>; 4] {
    let n = m.w * m.h;
    let mut base = vec![0u8; 3 * n];
    let mut mr = vec![0u8; 3 * n];
    let mut normal = vec![0u8; 3 * n];
    let mut aniso = vec![0u8; 3 * n];
    for i in 0..n {
        for c in 0..3 {
            base[3 * i + c] = byte(symframe_io::linear_to_srgb(
                m.base[3 * i + c].clamp(0.0, 1.0),
            ));
        }
        mr[3 * i..3 * i + 3].copy_from_slice(&[0, byte(m.roughness[i]), byte(m.metallic[i])]);
        let nv = &m.normals[3 * i..3 * i + 3];
        let nv = if nv.iter().all(|v| v.is_finite()) {
            [nv[0], nv[1], nv[2]]
        } else {
            [0.0, 0.0, 1.0]
        };
        for c in 0..3 {
            normal[3 * i + c] = byte((nv[c] + 1.0) / 2.0);
        }
        // The vertex frame the direction is expressed in.
        let (tf, bf) = if quad {
            ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        } else {
            vertex_frame(nv)
        };
        let t = &m.tangents[3 * i..3 * i + 3];
        let (mut dx, mut dy, mut s) = (1.0f32, 0.0f32, 0.0f32);
        if t.iter().all(|v| v.is_finite()) {
            let (x, y) = (
                t[0] * tf[0] + t[1] * tf[1] + t[2] * tf[2],
                t[0] * bf[0] + t[1] * bf[1] + t[2] * bf[2],
            );
            let l = (x * x + y * y).sqrt();
            if l > 1e-6 {
                (dx, dy, s) = (x / l, y / l, m.strength[i]);
            }
        }
        aniso[3 * i..3 * i + 3].copy_from_slice(&[
            byte((dx + 1.0) / 2.0),
            byte((dy + 1.0) / 2.0),
            byte(s),
        ]);
    }
    [base, mr, normal, aniso]
}

/// The `KHR_materials_clearcoat` texture of `m`, as RGB bytes (R factor, G roughness, B 0),
/// where it has a coat.
pub fn clearcoat_texture(m: &Maps) -> Option<Vec<u8>> {
    let (factor, rough) = m.clearcoat.as_ref()?;
    Some(
        factor
            .iter()
            .zip(rough)
            .flat_map(|(&f, &r)| [byte(f), byte(r), 0])
            .collect(),
    )
}

/// The estimate's tangents as a glTF `KHR_materials_anisotropy` texture for a surface whose
/// tangent space is the image's (tangent +x right, bitangent +y up, as the exported quad's):
/// red/green the tangent's image-plane direction mapped `(d + 1) / 2`, blue the strength
/// (`strength`, clamped to [0, 1]); where there is no tangent, direction +x and strength 0.
/// Written by the estimate as `tangents_gltf.png`.
pub fn gltf_anisotropy_rgb8(tangents: &[f32], strength: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(3 * strength.len());
    for (t, &s) in tangents.chunks_exact(3).zip(strength) {
        let (mut dx, mut dy, mut st) = (1.0f32, 0.0f32, 0.0f32);
        let l = t[0].hypot(t[1]);
        if t.iter().all(|v| v.is_finite()) && s.is_finite() && l > 1e-6 {
            (dx, dy, st) = (t[0] / l, t[1] / l, s.clamp(0.0, 1.0));
        }
        out.extend([byte((dx + 1.0) / 2.0), byte((dy + 1.0) / 2.0), byte(st)]);
    }
    out
}

/// Geometry: positions, normals, tangents (xyzw), texture coordinates, triangle indices.
pub struct Geometry {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    tangents: Vec<[f32; 4]>,
    uvs: Vec<[f32; 2]>,
    indices: Vec<u32>,
}

/// A quad one unit wide, `h / w` tall, centred at the origin, facing +z.
pub fn quad(w: usize, h: usize) -> Geometry {
    let a = h as f32 / w as f32;
    Geometry {
        positions: vec![
            [-0.5, a / 2.0, 0.0],
            [0.5, a / 2.0, 0.0],
            [-0.5, -a / 2.0, 0.0],
            [0.5, -a / 2.0, 0.0],
        ],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        tangents: vec![[1.0, 0.0, 0.0, 1.0]; 4],
        uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        indices: vec![0, 2, 1, 1, 2, 3],
    }
}

/// The integrated mesh (`symframe integrate`), scaled like the quad (image width = 1).
pub fn from_mesh(m: &symframe::Mesh, w: usize, h: usize) -> Geometry {
    let s = 1.0 / w as f32;
    let (ox, oy) = (w as f32 / 2.0, h as f32 / 2.0);
    let mut g = Geometry {
        positions: Vec::with_capacity(m.positions.len()),
        normals: m.normals.clone(),
        tangents: Vec::with_capacity(m.positions.len()),
        uvs: Vec::with_capacity(m.positions.len()),
        indices: m.triangles.iter().flatten().copied().collect(),
    };
    for ((p, n), px) in m.positions.iter().zip(&m.normals).zip(&m.pixels) {
        g.positions
            .push([(p[0] - ox) * s, (p[1] - oy) * s, p[2] * s]);
        let (t, _) = vertex_frame(*n);
        g.tangents.push([t[0], t[1], t[2], 1.0]);
        g.uvs.push([
            (px[0] as f32 + 0.5) / w as f32,
            (px[1] as f32 + 0.5) / h as f32,
        ]);
    }
    g
}

/// A perspective mesh ([`symframe::Pinhole::mesh`]) as it is: camera-frame points in
/// the depths' unit (glTF's y up and -z forward are the camera frame's), uv at pixel centres.
pub fn from_camera_mesh(m: &symframe::Mesh, w: usize, h: usize) -> Geometry {
    let mut g = Geometry {
        positions: m.positions.clone(),
        normals: m.normals.clone(),
        tangents: Vec::with_capacity(m.positions.len()),
        uvs: Vec::with_capacity(m.positions.len()),
        indices: m.triangles.iter().flatten().copied().collect(),
    };
    for (n, px) in m.normals.iter().zip(&m.pixels) {
        let (t, _) = vertex_frame(*n);
        g.tangents.push([t[0], t[1], t[2], 1.0]);
        g.uvs.push([
            (px[0] as f32 + 0.5) / w as f32,
            (px[1] as f32 + 0.5) / h as f32,
        ]);
    }
    g
}

/// Whether `dir` holds the record of an orthographic integration (an `integrate.json` with no
/// camera), whose `depth.npy` is a height map in pixel units.
fn is_height_map(dir: &Path) -> Result<bool> {
    let path = dir.join("integrate.json");
    if !path.is_file() {
        return Ok(false);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let json: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    Ok(json.get("camera").is_none_or(Value::is_null))
}

fn pad4(v: &mut Vec<u8>, fill: u8) {
    while v.len() & 3 != 0 {
        v.push(fill);
    }
}

/// Builds the glTF document and its binary buffer; `images` are PNG files, embedded in the
/// buffer (`embed`, for .glb) or referenced by their file name: base colour,
/// metallic-roughness, normal, anisotropy and, when there is a fifth, the clear coat's (R
/// factor, G roughness), which adds `KHR_materials_clearcoat`.
pub fn document(
    g: &Geometry,
    images: &[(&str, &Path)],
    with_normal_texture: bool,
    embed: bool,
    bin_uri: Option<&str>,
    light_intensity: Option<f64>,
) -> Result<(Value, Vec<u8>)> {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut push_view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| -> usize {
        pad4(bin, 0);
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        let mut v = json!({ "buffer": 0, "byteOffset": offset, "byteLength": bytes.len() });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        views.push(v);
        views.len() - 1
    };
    let floats = |rows: &[f32]| -> Vec<u8> { rows.iter().flat_map(|v| v.to_le_bytes()).collect() };
    let mut attr = |bin: &mut Vec<u8>, data: Vec<f32>, comps: usize, kind: &str, minmax: bool| {
        let view = push_view(bin, &floats(&data), Some(34962));
        let count = data.len() / comps;
        let mut a = json!({
            "bufferView": view, "componentType": 5126, "count": count, "type": kind,
        });
        if minmax {
            let mut lo = vec![f32::INFINITY; comps];
            let mut hi = vec![f32::NEG_INFINITY; comps];
            for row in data.chunks_exact(comps) {
                for c in 0..comps {
                    lo[c] = lo[c].min(row[c]);
                    hi[c] = hi[c].max(row[c]);
                }
            }
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        accessors.push(a);
        accessors.len() - 1
    };
    let pos = attr(
        &mut bin,
        g.positions.iter().flatten().copied().collect(),
        3,
        "VEC3",
        true,
    );
    let nor = attr(
        &mut bin,
        g.normals.iter().flatten().copied().collect(),
        3,
        "VEC3",
        false,
    );
    let tan = attr(
        &mut bin,
        g.tangents.iter().flatten().copied().collect(),
        4,
        "VEC4",
        false,
    );
    let uv = attr(
        &mut bin,
        g.uvs.iter().flatten().copied().collect(),
        2,
        "VEC2",
        false,
    );
    let idx_bytes: Vec<u8> = g.indices.iter().flat_map(|v| v.to_le_bytes()).collect();
    let iv = push_view(&mut bin, &idx_bytes, Some(34963));
    accessors.push(json!({
        "bufferView": iv, "componentType": 5125, "count": g.indices.len(), "type": "SCALAR",
    }));
    let ind = accessors.len() - 1;
    let mut image_json = Vec::new();
    for (name, path) in images {
        if embed {
            let bytes = symframe_io::read_bounded(
                path,
                "an image file",
                symframe_io::limits::MAX_IMAGE_FILE_BYTES,
            )?;
            let v = push_view(&mut bin, &bytes, None);
            image_json.push(json!({ "bufferView": v, "mimeType": "image/png", "name": name }));
        } else {
            let file = path.file_name().unwrap_or_default().to_string_lossy();
            image_json.push(json!({ "uri": file, "name": name }));
        }
    }
    pad4(&mut bin, 0);
    let tex = |i: usize| json!({ "index": i });
    let mut pbr = json!({
        "baseColorTexture": tex(0),
        "metallicRoughnessTexture": tex(1),
        "metallicFactor": 1.0,
        "roughnessFactor": 1.0,
    });
    pbr["baseColorFactor"] = json!([1.0, 1.0, 1.0, 1.0]);
    let mut material = json!({
        "name": "symframe",
        "pbrMetallicRoughness": pbr,
        "extensions": {
            "KHR_materials_anisotropy": {
                "anisotropyStrength": 1.0,
                "anisotropyRotation": 0.0,
                "anisotropyTexture": tex(3),
            }
        },
    });
    let mut used = vec!["KHR_materials_anisotropy"];
    if images.len() > 4 {
        material["extensions"]["KHR_materials_clearcoat"] = json!({
            "clearcoatFactor": 1.0,
            "clearcoatTexture": tex(4),
            "clearcoatRoughnessFactor": 1.0,
            "clearcoatRoughnessTexture": tex(4),
        });
        used.push("KHR_materials_clearcoat");
    }
    if let Some(e) = light_intensity {
        material["extras"] = json!({ "symframe": { "lightIntensity": e } });
    }
    if with_normal_texture {
        material["normalTexture"] = json!({ "index": 2, "scale": 1.0 });
    }
    let textures: Vec<Value> = (0..images.len())
        .map(|i| json!({ "sampler": 0, "source": i }))
        .collect();
    let mut buffer = json!({ "byteLength": bin.len() });
    if let Some(uri) = bin_uri {
        buffer["uri"] = json!(uri);
    }
    let doc = json!({
        "asset": { "version": "2.0", "generator": format!("symframe {}", env!("CARGO_PKG_VERSION")) },
        "extensionsUsed": used,
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "symframe" }],
        "meshes": [{
            "primitives": [{
                "attributes": { "POSITION": pos, "NORMAL": nor, "TANGENT": tan, "TEXCOORD_0": uv },
                "indices": ind,
                "material": 0,
                "mode": 4,
            }]
        }],
        "materials": [material],
        "samplers": [{ "magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071 }],
        "textures": textures,
        "images": image_json,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [buffer],
    });
    Ok((doc, bin))
}

/// Packs a GLB: header, JSON chunk (space-padded), BIN chunk (zero-padded).
pub fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).unwrap_or_default();
    pad4(&mut json, b' ');
    let mut b = bin.to_vec();
    pad4(&mut b, 0);
    let total = 12 + 8 + json.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// Runs a glTF export; returns the files written and what they hold.
pub fn export_gltf(config: &ExportConfig) -> Result<ExportOutcome> {
    let ext = config
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let embed = match ext.as_deref() {
        Some("glb") => true,
        Some("gltf") => false,
        _ => bail!(
            "{}: the output must end in .gltf or .glb",
            config.output.display()
        ),
    };
    let maps = read_maps(&config.input)?;
    let (w, h) = (maps.w, maps.h);
    let geometry = if config.mesh {
        let depth_path = config
            .depth
            .clone()
            .unwrap_or_else(|| config.input.join("depth.npy"));
        let (shape, depth) = symframe_io::read_npy_f32(&depth_path).with_context(|| {
            format!(
                "a mesh needs a height map: the depth.npy of symframe integrate ({} missing or \
                 unreadable)",
                depth_path.display()
            )
        })?;
        if shape != [h, w] {
            bail!(
                "{}: shape {shape:?} does not match the maps ({h} x {w})",
                depth_path.display()
            );
        }
        let beside = depth_path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let camera = crate::integrate::camera_for(config.camera.as_deref(), beside)?;
        if camera.is_some() && is_height_map(beside)? {
            bail!(
                "{}: a height map of an orthographic integration (its integrate.json records no \
                 camera); integrate with --K for a perspective depth map",
                depth_path.display()
            );
        }
        if let Some((cam, _)) = camera {
            let mesh = cam.mesh(w, h, &depth, &maps.normals, config.max_jump);
            if mesh.triangles.is_empty() {
                bail!("{}: the mesh has no triangles", depth_path.display());
            }
            from_camera_mesh(&mesh, w, h)
        } else {
            let dm = symframe::DepthMap {
                width: w,
                height: h,
                depth,
                cg_iterations: 0,
                reweight_iterations: 0,
                energy: 0.0,
                regions: 0,
                pixels: 0,
            };
            let mesh = dm.mesh(&maps.normals, config.max_jump);
            if mesh.triangles.is_empty() {
                bail!("{}: the mesh has no triangles", depth_path.display());
            }
            from_mesh(&mesh, w, h)
        }
    } else {
        quad(w, h)
    };
    let out_dir = config
        .output
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let stem = config
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "asset".into());
    let coat = clearcoat_texture(&maps);
    let names: &[&str] = if coat.is_some() {
        &[
            "basecolor",
            "metallicroughness",
            "normal",
            "anisotropy",
            "clearcoat",
        ]
    } else {
        &["basecolor", "metallicroughness", "normal", "anisotropy"]
    };
    let bin_name = format!("{stem}.bin");
    // The asset's files, the .gltf or .glb last (the textures and buffer it names go in first).
    let mut targets: Vec<PathBuf> = Vec::new();
    if !embed {
        targets.extend(
            names
                .iter()
                .map(|n| out_dir.join(format!("{stem}_{n}.png"))),
        );
        targets.push(out_dir.join(&bin_name));
    }
    targets.push(config.output.clone());
    let mut inputs = input_files(&config.input)?;
    if config.mesh {
        inputs.push(
            config
                .depth
                .clone()
                .unwrap_or_else(|| config.input.join("depth.npy")),
        );
    }
    check_targets(&targets, &inputs)?;
    check_own_files(&targets, &config.output)?;
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("{}: cannot create folder", out_dir.display()))?;

    // Every file is written into a staging folder first, then moved in (see [`switch_in`]);
    // the folder goes in any case.
    let staging = Staging::new(&out_dir)?;
    let [base, mr, normal, aniso] = textures(&maps, !config.mesh);
    let mut images = Vec::new();
    for (name, bytes) in names
        .iter()
        .zip([&base, &mr, &normal, &aniso].into_iter().chain(&coat))
    {
        let p = staging.0.join(format!("{stem}_{name}.png"));
        symframe_io::write_png_rgb8(&p, w, h, bytes)?;
        images.push((*name, p));
    }
    let refs: Vec<(&str, &Path)> = images.iter().map(|(n, p)| (*n, p.as_path())).collect();
    let (doc, bin) = document(
        &geometry,
        &refs,
        !config.mesh,
        embed,
        (!embed).then_some(&bin_name),
        maps.light_intensity,
    )?;
    let asset = staging
        .0
        .join(config.output.file_name().unwrap_or_default());
    let mut staged: Vec<PathBuf> = Vec::new();
    if embed {
        std::fs::write(&asset, glb(&doc, &bin))
            .with_context(|| format!("{}: cannot write", asset.display()))?;
    } else {
        staged.extend(images.iter().map(|(_, p)| p.clone()));
        let bp = staging.0.join(&bin_name);
        std::fs::write(&bp, &bin).with_context(|| format!("{}: cannot write", bp.display()))?;
        staged.push(bp);
        std::fs::write(&asset, serde_json::to_string_pretty(&doc)? + "\n")
            .with_context(|| format!("{}: cannot write", asset.display()))?;
    }
    staged.push(asset);
    let moves: Vec<(PathBuf, PathBuf)> = staged.into_iter().zip(targets.iter().cloned()).collect();
    switch_in(&moves, &staging.0)?;
    drop(staging);
    // The asset first, then the buffer and the textures.
    let mut written = targets;
    written.rotate_right(1);
    if !embed {
        written[1..].rotate_right(1);
    }
    Ok(ExportOutcome {
        written,
        fitted: maps.fitted,
        vertices: geometry.positions.len(),
        triangles: geometry.indices.len() / 3,
    })
}

/// The files of the input folder an export may read (its `.npy` maps and `.json` records).
fn input_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("{}: cannot read", dir.display()))? {
        let p = e
            .with_context(|| format!("{}: cannot read", dir.display()))?
            .path();
        if p.extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("npy") || x.eq_ignore_ascii_case("json"))
        {
            v.push(p);
        }
    }
    Ok(v)
}

/// A path with its folder resolved (links included): the directory entry it names.
fn entry(p: &Path) -> Option<PathBuf> {
    let dir = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    Some(dir.canonicalize().ok()?.join(p.file_name()?))
}

/// The device and inode of the file `p` names (links followed), where the platform has them.
fn file_id(p: &Path) -> Option<(u64, u64)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = p;
        None
    }
}

/// Refuses, before anything is written, targets that are folders (the move would fail half-way)
/// and targets that would replace one of the export's inputs: the same directory entry, a
/// symbolic link to the input, or a hard link to it (the same file under another name).
fn check_targets(targets: &[PathBuf], inputs: &[PathBuf]) -> Result<()> {
    let inputs: Vec<_> = inputs
        .iter()
        .map(|p| (p.clone(), entry(p), p.canonicalize().ok(), file_id(p)))
        .collect();
    for t in targets {
        let meta = std::fs::symlink_metadata(t).ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            bail!(
                "{}: a folder is in the way of the exported file; move it or choose another \
                 output name",
                t.display()
            );
        }
        let (t_entry, t_file, t_id) = (entry(t), t.canonicalize().ok(), file_id(t));
        for (p, p_entry, p_file, p_id) in &inputs {
            let same_entry = t_entry.is_some() && t_entry == *p_entry;
            let same_file = t_file.is_some() && t_file == *p_file;
            let same_inode = t_id.is_some() && t_id == *p_id;
            if same_entry || same_file || same_inode {
                bail!(
                    "{}: is {}, one of the export's inputs: refusing to replace it; write the \
                     asset elsewhere or under another name",
                    t.display(),
                    p.display()
                );
            }
        }
    }
    Ok(())
}

/// The JSON of the glTF asset at `path` (a `.gltf`, or a `.glb`'s JSON chunk), read no
/// further than its first 64 MiB; `None` when it is not one (not a regular file, not JSON).
fn asset_json(path: &Path) -> Option<Value> {
    use std::io::Read;
    let meta = std::fs::symlink_metadata(path).ok()?;
    if !meta.is_file() {
        return None;
    }
    let cap = symframe_io::limits::MAX_TEXT_FILE_BYTES;
    let mut f = std::fs::File::open(path).ok()?;
    let mut head = [0u8; 20];
    let glb = f.read_exact(&mut head).is_ok() && &head[..4] == b"glTF" && &head[16..20] == b"JSON";
    let bytes = if glb {
        let len = u32::from_le_bytes([head[12], head[13], head[14], head[15]]) as u64;
        symframe_io::read_at_most(f, path, len.min(cap)).ok()?
    } else {
        symframe_io::read_bounded(path, "a glTF file", cap).ok()?
    };
    serde_json::from_slice(&bytes).ok()
}

/// Refuses, before anything is written, to replace a file that this tool did not write: the
/// asset at `output` must be absent or a glTF asset symframe wrote (its `asset.generator`), and
/// each of its companion files there (the `.bin` and textures) absent or named by that asset.
/// A user's `scene.gltf`, or a `scene.bin` beside a new asset, is never replaced without a word.
fn check_own_files(targets: &[PathBuf], output: &Path) -> Result<()> {
    let exists = |p: &Path| std::fs::symlink_metadata(p).is_ok();
    let ours = asset_json(output).filter(|doc| {
        doc["asset"]["generator"]
            .as_str()
            .is_some_and(|g| g.starts_with("symframe"))
    });
    if exists(output) && ours.is_none() {
        bail!(
            "{}: exists and is not a glTF asset written by symframe export (symframe replaces \
             only its own files); remove it or choose another output name",
            output.display()
        );
    }
    let named: Vec<String> = ours
        .iter()
        .flat_map(|doc| {
            ["buffers", "images"]
                .iter()
                .flat_map(|k| doc[*k].as_array().cloned().unwrap_or_default())
                .filter_map(|e| e["uri"].as_str().map(str::to_string))
                .collect::<Vec<_>>()
        })
        .collect();
    for t in targets
        .iter()
        .filter(|t| t.as_path() != output && exists(t))
    {
        let name = t.file_name().map(|n| n.to_string_lossy().into_owned());
        if !name.is_some_and(|n| named.contains(&n)) {
            bail!(
                "{}: exists and is not a file of a glTF asset symframe export wrote at {} \
                 (symframe replaces only its own files); remove it or choose another output \
                 name",
                t.display(),
                output.display()
            );
        }
    }
    Ok(())
}

/// The export's staging folder (`.symframe-export-PID-TOKEN` in the output's folder, a fresh
/// name: a folder already there is never touched), removed when dropped: on success and on
/// any error.
struct Staging(PathBuf);

impl Staging {
    fn new(dir: &Path) -> Result<Self> {
        let p = dir.join(format!(
            ".symframe-export-{}-{:016x}",
            std::process::id(),
            crate::outdir::new_token()
        ));
        std::fs::create_dir(&p).with_context(|| format!("{}: cannot create", p.display()))?;
        Ok(Self(p))
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// Moves each staged file onto its target, in order, keeping a link to (or, where links are not
/// supported, the moved) old file in `backup_dir`; if a move fails, the files moved so far are
/// taken out again and the old ones put back, so the targets hold either all the old files (an
/// error is returned) or all the new ones.
fn switch_in(moves: &[(PathBuf, PathBuf)], backup_dir: &Path) -> Result<()> {
    // (target, its old file's backup)
    let mut done: Vec<(&Path, Option<PathBuf>)> = Vec::new();
    let mut result = Ok(());
    for (i, (from, to)) in moves.iter().enumerate() {
        let backup = backup_dir.join(format!(".old-{i}"));
        let old = match std::fs::symlink_metadata(to) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => {
                result = Err(e).with_context(|| format!("{}: cannot read", to.display()));
                break;
            }
            Ok(m) if m.is_dir() => {
                result = Err(anyhow::anyhow!(
                    "{}: a folder is in the way of the exported file",
                    to.display()
                ));
                break;
            }
            Ok(_) => {
                match std::fs::hard_link(to, &backup).or_else(|_| std::fs::rename(to, &backup)) {
                    Ok(()) => Some(backup),
                    Err(e) => {
                        result = Err(e).with_context(|| format!("{}: cannot keep", to.display()));
                        break;
                    }
                }
            }
        };
        if let Err(e) = std::fs::rename(from, to) {
            result = Err(e).with_context(|| format!("{}: cannot replace", to.display()));
            if let Some(b) = &old {
                if std::fs::symlink_metadata(to).is_err() {
                    std::fs::rename(b, to).ok();
                }
            }
            break;
        }
        done.push((to, old));
    }
    if result.is_err() {
        for (to, old) in done.into_iter().rev() {
            match old {
                Some(b) => {
                    std::fs::rename(&b, to).ok();
                }
                None => {
                    std::fs::remove_file(to).ok();
                }
            }
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_switch_puts_every_old_file_back() {
        let d = tempfile::tempdir().unwrap();
        let (out, stage) = (d.path().join("out"), d.path().join("stage"));
        std::fs::create_dir_all(&out).unwrap();
        std::fs::create_dir_all(&stage).unwrap();
        let names = ["a.png", "b.bin", "c.gltf"];
        let moves: Vec<(PathBuf, PathBuf)> =
            names.iter().map(|n| (stage.join(n), out.join(n))).collect();
        let stage_new = || {
            for (from, _) in &moves {
                std::fs::write(from, "new").unwrap();
            }
        };
        // The old asset: a and b (c is new); a folder in the way of the last move.
        std::fs::write(out.join("a.png"), "old a").unwrap();
        std::fs::write(out.join("b.bin"), "old b").unwrap();
        std::fs::create_dir_all(out.join("c.gltf/x")).unwrap();
        stage_new();
        assert!(switch_in(&moves, &stage).is_err());
        assert_eq!(std::fs::read_to_string(out.join("a.png")).unwrap(), "old a");
        assert_eq!(std::fs::read_to_string(out.join("b.bin")).unwrap(), "old b");
        assert!(out.join("c.gltf/x").is_dir());
        // Cleared: every new file in.
        std::fs::remove_dir_all(out.join("c.gltf")).unwrap();
        stage_new();
        switch_in(&moves, &stage).unwrap();
        for n in names {
            assert_eq!(std::fs::read_to_string(out.join(n)).unwrap(), "new");
        }
    }

    #[test]
    fn quad_tangent_space_is_the_camera_frame_and_anisotropy_follows_the_tangent() {
        let s = 0.5f32.sqrt();
        let m = Maps {
            w: 2,
            h: 1,
            normals: vec![0.0, 0.0, 1.0, s, 0.0, s],
            tangents: vec![0.0, 1.0, 0.0, f32::NAN, f32::NAN, f32::NAN],
            base: vec![0.5; 6],
            metallic: vec![1.0, 0.0],
            roughness: vec![0.25, 1.0],
            strength: vec![0.8, 0.3],
            fitted: true,
            light_intensity: None,
            clearcoat: None,
        };
        let [base, mr, normal, aniso] = textures(&m, true);
        assert_eq!(&normal[..3], &[128, 128, 255]);
        assert_eq!(&normal[3..], &[218, 128, 218]);
        assert_eq!(&mr[..3], &[0, 64, 255]);
        // Tangent along +y: direction (0, 1), strength 0.8; no tangent: strength 0.
        assert_eq!(&aniso[..3], &[128, 255, 204]);
        assert_eq!(aniso[5], 0);
        assert_eq!(base[0], 188); // 0.5 linear, sRGB-encoded
    }

    #[test]
    fn gltf_anisotropy_texture_encodes_direction_and_strength() {
        let s = 0.5f32.sqrt();
        let t = [s, -s, 0.0, f32::NAN, f32::NAN, f32::NAN, 0.0, 0.6, 0.8];
        let rgb = gltf_anisotropy_rgb8(&t, &[0.5, 0.9, 1.5]);
        // (0.707, -0.707) -> (218, 37); strength 0.5 -> 128.
        assert_eq!(&rgb[..3], &[218, 37, 128]);
        // No tangent: +x, strength 0.
        assert_eq!(&rgb[3..6], &[255, 128, 0]);
        // A tilted tangent counts by its image-plane direction (+y); strength clamped.
        assert_eq!(&rgb[6..], &[128, 255, 255]);
        // The quad export's anisotropy texture of an estimate is the same picture.
        let m = Maps {
            w: 3,
            h: 1,
            normals: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, -0.8, 0.6],
            tangents: t.to_vec(),
            base: vec![0.5; 9],
            metallic: vec![0.0; 3],
            roughness: vec![0.5; 3],
            strength: vec![0.5, 0.0, 1.0],
            fitted: false,
            light_intensity: None,
            clearcoat: None,
        };
        assert_eq!(textures(&m, true)[3], rgb);
    }

    #[test]
    fn vertex_frames_are_orthonormal() {
        for n in [
            [0.0f32, 0.0, 1.0],
            [0.6, 0.0, 0.8],
            [1.0, 0.0, 0.0],
            [0.0, -0.6, 0.8],
        ] {
            let (t, b) = vertex_frame(n);
            let d = |a: [f32; 3], c: [f32; 3]| a[0] * c[0] + a[1] * c[1] + a[2] * c[2];
            assert!(d(t, n).abs() < 1e-6 && d(b, n).abs() < 1e-6 && d(t, b).abs() < 1e-6);
            assert!((d(t, t) - 1.0).abs() < 1e-5 && (d(b, b) - 1.0).abs() < 1e-5);
        }
        // Head-on: the quad's frame.
        assert_eq!(
            vertex_frame([0.0, 0.0, 1.0]),
            ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        );
    }

    #[test]
    fn glb_layout() {
        let doc = json!({ "asset": { "version": "2.0" } });
        let g = glb(&doc, &[1, 2, 3]);
        assert_eq!(&g[..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(g[8..12].try_into().unwrap()) as usize,
            g.len()
        );
        let jl = u32::from_le_bytes(g[12..16].try_into().unwrap()) as usize;
        assert_eq!(jl % 4, 0);
        assert_eq!(&g[16..20], b"JSON");
        assert_eq!(&g[20 + jl + 4..20 + jl + 8], b"BIN\0");
        assert_eq!(g.len() % 4, 0);
    }
}
