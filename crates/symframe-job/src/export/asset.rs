//! The glTF asset itself: the 8-bit textures of the maps, the quad or mesh geometry with its
//! vertex frames, the JSON document with its binary buffer ([`document`]) and the GLB packing
//! ([`glb`]).

use std::path::Path;

use anyhow::Result;
use serde_json::{json, Value};

use super::Maps;

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
    pub(super) positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    tangents: Vec<[f32; 4]>,
    uvs: Vec<[f32; 2]>,
    pub(super) indices: Vec<u32>,
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

#[cfg(test)]
mod tests {
    use super::*;

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
