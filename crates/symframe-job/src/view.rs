//! The viewer: the folder of [`crate::fit`] (and the maps of the estimate it was fitted in) in,
//! one self-contained HTML file out that relights the fit in a browser in real time with WebGL2.
//!
//! The page needs nothing else (no network, works from a `file:` URL): the HTML, its script
//! and its shaders (`src/view/`, real files in the repository) are copied in, and the maps are
//! embedded as RGBA half-float textures, byte-shuffled, zlib-compressed and base64-encoded
//! (the browser inflates them with its own `DecompressionStream`). The shader is the model of
//! [`symframe::Relighter`] with the same edits, and it shades the pixels the relighter shades in
//! the frames the relighter uses (taken from it, not recomputed), so a screenshot under a light
//! matches `symframe relight --light` of the same fit (the browser test checks this).
//!
//! Textures, four half floats per pixel, rows top to bottom:
//! - `geom`: the normal, then a flag (0 no normal, 1 a normal but no model, 2 a model);
//! - `frame`: the shading tangent (the map's, or the relighter's own for isotropic pixels),
//!   then 1 where it came from the tangent map (only those are turned by a rotation);
//! - `kd`: diffuse albedo and `alpha_t`; `ks`: specular albedo and `alpha_b` (a glTF fit:
//!   `kd` base colour and metallic, `ks` roughness, anisotropy strength, 0, 0; the fitted
//!   light intensity is in the page's data);
//! - `est` (when the estimate's maps are found): confidence, anisotropy, source code, and a
//!   flag sum (1 confidence, 2 anisotropy, 4 source present).
//!
//! Values without a meaning (NaN) are stored as 0; the flags say where data is.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::{Edits, PixelSource};

use crate::relight::{read_fit_maps, FittedMaps};

/// The page template; `{{NAME}}` marks are filled in by [`render_page`].
const PAGE: &str = include_str!("view/viewer.html");
/// The page's script.
const SCRIPT: &str = include_str!("view/viewer.js");
/// The vertex shader (one triangle covering the canvas).
const VERTEX_SHADER: &str = include_str!("view/viewer.vert");
/// The fragment shader: relighting and the map views.
const FRAGMENT_SHADER: &str = include_str!("view/viewer.frag");

/// Everything the viewer needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewConfig {
    /// Output folder of [`crate::fit`].
    pub fit_dir: PathBuf,
    /// Output folder of the estimate the fit was made in (confidence, anisotropy and source
    /// maps); `None`: the `frames` folder recorded in `fit.json`, if it is still there.
    pub frames: Option<PathBuf>,
    /// The HTML file to write (its folder is created).
    pub output: PathBuf,
}

impl ViewConfig {
    /// The viewer of `fit_dir`, written as `fit_dir/viewer.html`, estimate maps from the
    /// folder `fit.json` names.
    pub fn new(fit_dir: impl Into<PathBuf>) -> Self {
        let fit_dir = fit_dir.into();
        Self {
            output: fit_dir.join("viewer.html"),
            fit_dir,
            frames: None,
        }
    }
}

/// What [`write_viewer`] wrote.
#[derive(Debug, Clone)]
pub struct ViewOutcome {
    /// The HTML file.
    pub path: PathBuf,
    /// Map size in pixels (the canvas is this size).
    pub width: usize,
    /// Map size in pixels.
    pub height: usize,
    /// Size of the file in bytes.
    pub bytes: u64,
    /// The views the page offers, `relit` first.
    pub views: Vec<&'static str>,
    /// The estimate folder whose maps were embedded, if any.
    pub frames: Option<PathBuf>,
    /// Things the user should know that did not stop the job (estimate maps not found).
    pub notes: Vec<String>,
}

/// The data block of the page (JSON in a `<script>` element).
#[derive(Serialize)]
struct PageData {
    /// Version of the data layout, checked by the script.
    format: u32,
    title: String,
    width: usize,
    height: usize,
    textures: Textures,
    views: Vec<&'static str>,
    /// Names of the source codes, by code.
    sources: Vec<&'static str>,
    /// The fitted model: `ward` or `gltf`.
    model: &'static str,
    /// A glTF fit's light intensity (1 for Ward).
    light_intensity: f64,
}

/// The encoded textures (see the module documentation).
#[derive(Serialize)]
struct Textures {
    geom: String,
    frame: String,
    kd: String,
    ks: String,
    est: Option<String>,
}

/// The estimate's maps that the viewer shows (each optional).
struct EstimateMaps {
    confidence: Option<Vec<f32>>,
    anisotropy: Option<Vec<f32>>,
    source: Option<Vec<u8>>,
}

/// Writes the viewer of a fit: see the module documentation. Errors name the file at fault
/// (a fit map missing or of the wrong size, an estimate map of the wrong size, the output).
pub fn write_viewer(config: &ViewConfig) -> Result<ViewOutcome> {
    check_replaceable(&config.output)?;
    let fitted = read_fit_maps(&config.fit_dir)?;
    let (w, h) = fitted.size();
    let relighter = fitted
        .relighter(&Edits::default())
        .with_context(|| config.fit_dir.display().to_string())?;
    let (normals, tangents) = match &fitted {
        FittedMaps::Ward(m) => (&m.normals, &m.tangents),
        FittedMaps::Gltf(m) => (&m.normals, &m.tangents),
    };
    let mut notes = Vec::new();
    let frames = frames_dir(config, &mut notes)?;
    let est = match &frames {
        Some(dir) => {
            let e = read_estimate_maps(dir, w, h)?;
            if e.confidence.is_none() && e.anisotropy.is_none() && e.source.is_none() {
                notes.push(format!(
                    "{}: no confidence.npy, anisotropy.npy or source.npy; those views are left \
                     out",
                    dir.display()
                ));
                None
            } else {
                Some(e)
            }
        }
        None => None,
    };

    let n = w * h;
    let geom = encode_texture(n, |p| match relighter.frame(p) {
        Some((_, nrm, _)) => [nrm.x as f32, nrm.y as f32, nrm.z as f32, 2.0],
        None => match finite3(normals, p) {
            Some([x, y, z]) => [x, y, z, 1.0],
            None => [0.0; 4],
        },
    })?;
    let frame = encode_texture(n, |p| match relighter.frame(p) {
        Some((t, _, aniso)) => [t.x as f32, t.y as f32, t.z as f32, f32::from(aniso)],
        None => match finite3(tangents, p) {
            Some([x, y, z]) => [x, y, z, 1.0],
            None => [0.0; 4],
        },
    })?;
    // Albedos and roughnesses matter only where there is a model (the flag of `geom`).
    let (kd, ks, mut views, model, light_intensity) = match &fitted {
        FittedMaps::Ward(maps) => (
            encode_texture(n, |p| {
                let c = &maps.kd[p * 3..p * 3 + 3];
                [c[0], c[1], c[2], maps.alpha_t[p]]
            })?,
            encode_texture(n, |p| {
                let c = &maps.ks[p * 3..p * 3 + 3];
                [c[0], c[1], c[2], maps.alpha_b[p]]
            })?,
            vec!["relit", "normal", "tangent", "kd", "ks"],
            "ward",
            1.0,
        ),
        FittedMaps::Gltf(maps) => (
            encode_texture(n, |p| {
                let c = &maps.base_color[p * 3..p * 3 + 3];
                [c[0], c[1], c[2], maps.metallic[p]]
            })?,
            encode_texture(n, |p| [maps.roughness[p], maps.anisotropy[p], 0.0, 0.0])?,
            vec!["relit", "normal", "tangent", "base_color"],
            "gltf",
            maps.exposure,
        ),
    };

    let est = match est {
        Some(e) => {
            let at = |m: &Option<Vec<f32>>, p: usize| m.as_ref().map_or(f32::NAN, |v| v[p]);
            let texture = encode_texture(n, |p| {
                let (c, a) = (at(&e.confidence, p), at(&e.anisotropy, p));
                let s = e.source.as_ref().map(|s| s[p]);
                let flags = u8::from(c.is_finite())
                    + 2 * u8::from(a.is_finite())
                    + 4 * u8::from(s.is_some());
                [c, a, f32::from(s.unwrap_or(0)), f32::from(flags)]
            })?;
            for (name, present) in [
                ("confidence", e.confidence.is_some()),
                ("anisotropy", e.anisotropy.is_some()),
                ("source", e.source.is_some()),
            ] {
                if present {
                    views.push(name);
                }
            }
            Some(texture)
        }
        None => None,
    };

    // The fit folder as given (a full path would show where it was made, not what it is).
    let title = config.fit_dir.display().to_string();
    let data = PageData {
        format: 1,
        title: title.clone(),
        width: w,
        height: h,
        textures: Textures {
            geom,
            frame,
            kd,
            ks,
            est,
        },
        views: views.clone(),
        sources: PixelSource::legend().iter().map(|l| l.1).collect(),
        model,
        light_intensity,
    };
    let page = render_page(&title, &data)?;
    write_file(&config.output, page.as_bytes())?;
    Ok(ViewOutcome {
        path: config.output.clone(),
        width: w,
        height: h,
        bytes: page.len() as u64,
        views,
        frames,
        notes,
    })
}

/// The estimate folder to take confidence, anisotropy and source from: the one asked for
/// (which must exist), else the `frames` folder of `fit.json` if it is still where it was
/// (as given to the fit, or relative to the fit folder's parent); `None` with a note otherwise.
fn frames_dir(config: &ViewConfig, notes: &mut Vec<String>) -> Result<Option<PathBuf>> {
    if let Some(dir) = &config.frames {
        if !dir.is_dir() {
            bail!(
                "{}: no such folder (the estimate's output folder)",
                dir.display()
            );
        }
        return Ok(Some(dir.clone()));
    }
    let report = config.fit_dir.join("fit.json");
    // Missing, it is a note; there but not a regular file (a FIFO, a device) or too large, an
    // error: never opened, never read past the cap.
    let text = match symframe_io::read_text_bounded(
        &report,
        "a report",
        symframe_io::limits::MAX_TEXT_FILE_BYTES,
    ) {
        Ok(t) => Some(t),
        Err(symframe_io::Error::Read { source, .. })
            if source.kind() == std::io::ErrorKind::NotFound =>
        {
            None
        }
        Err(e) => return Err(e.into()),
    };
    let recorded = text
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|r| r.get("frames")?.as_str().map(PathBuf::from));
    let Some(recorded) = recorded else {
        notes.push(format!(
            "{}: no estimate folder recorded; the confidence, anisotropy and source views are \
             left out (give the estimate's folder with --frames)",
            report.display()
        ));
        return Ok(None);
    };
    let mut candidates = vec![recorded.clone()];
    if recorded.is_relative() {
        if let Some(parent) = config.fit_dir.parent() {
            candidates.push(parent.join(&recorded));
        }
    }
    match candidates.into_iter().find(|c| c.is_dir()) {
        Some(dir) => Ok(Some(dir)),
        None => {
            notes.push(format!(
                "{}: the estimate folder {} is not there; the confidence, anisotropy and source \
                 views are left out (give it with --frames)",
                report.display(),
                recorded.display()
            ));
            Ok(None)
        }
    }
}

/// Reads the estimate maps of `dir` that exist, checking their size against the fit's.
fn read_estimate_maps(dir: &Path, w: usize, h: usize) -> Result<EstimateMaps> {
    let check = |path: &Path, shape: &[usize]| -> Result<()> {
        if shape != [h, w] {
            bail!(
                "{}: shape {shape:?} does not match the fit's maps ([{h}, {w}] expected)",
                path.display()
            );
        }
        Ok(())
    };
    let scalar = |name: &str| -> Result<Option<Vec<f32>>> {
        let path = dir.join(name);
        if !path.is_file() {
            return Ok(None);
        }
        let (shape, data) = symframe_io::read_npy_f32(&path)?;
        check(&path, &shape)?;
        Ok(Some(data))
    };
    let source_path = dir.join("source.npy");
    let source = if source_path.is_file() {
        let (shape, data) = symframe_io::read_npy_u8(&source_path)?;
        check(&source_path, &shape)?;
        Some(data)
    } else {
        None
    };
    Ok(EstimateMaps {
        confidence: scalar("confidence.npy")?,
        anisotropy: scalar("anisotropy.npy")?,
        source,
    })
}

/// The three values of pixel `p` of an `H x W x 3` map, if all are finite.
fn finite3(map: &[f32], p: usize) -> Option<[f32; 3]> {
    let v = [map[p * 3], map[p * 3 + 1], map[p * 3 + 2]];
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// One texture of `n` pixels, four values each from `texel`: half floats (NaN as 0, beyond the
/// half range clamped to it), the low bytes of all values then the high bytes (which deflate
/// far better than interleaved), zlib-compressed, base64-encoded.
fn encode_texture(n: usize, texel: impl Fn(usize) -> [f32; 4]) -> Result<String> {
    let mut bytes = vec![0u8; n * 8];
    let (lo, hi) = bytes.split_at_mut(n * 4);
    for p in 0..n {
        for (c, v) in texel(p).into_iter().enumerate() {
            let v = if v.is_nan() {
                0.0
            } else {
                v.clamp(-65504.0, 65504.0)
            };
            let [l, h] = half::f16::from_f32(v).to_bits().to_le_bytes();
            lo[p * 4 + c] = l;
            hi[p * 4 + c] = h;
        }
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
    z.write_all(&bytes)?;
    Ok(base64(&z.finish()?))
}

/// Standard base64 with padding.
fn base64(data: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ABC[(v >> (18 - 6 * i)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Escapes text for HTML element content.
fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The page: the template with its `{{NAME}}` marks replaced in one pass (so nothing inserted
/// is scanned again). The data is JSON with `<` escaped, so no string in it can end its
/// `<script>` element.
fn render_page(title: &str, data: &PageData) -> Result<String> {
    let json = serde_json::to_string(data)?.replace('<', "\\u003c");
    let fills = [
        ("TITLE", html_escape(title)),
        ("VERTEX_SHADER", VERTEX_SHADER.to_string()),
        ("FRAGMENT_SHADER", FRAGMENT_SHADER.to_string()),
        ("SCRIPT", SCRIPT.to_string()),
        ("DATA", json),
    ];
    let mut out =
        String::with_capacity(PAGE.len() + fills.iter().map(|f| f.1.len()).sum::<usize>());
    let mut rest = PAGE;
    while let Some(start) = rest.find("{{") {
        let Some(len) = rest[start..].find("}}") else {
            break;
        };
        let name = &rest[start + 2..start + len];
        let Some((_, value)) = fills.iter().find(|f| f.0 == name) else {
            bail!("viewer template: unknown mark {{{{{name}}}}}");
        };
        out.push_str(&rest[..start]);
        out.push_str(value);
        rest = &rest[start + len + 2..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The first line of the page after the doctype: how a page this tool wrote is told apart.
const PAGE_MARK: &str = "<!-- symframe viewer:";

/// Refuses `path` as the page's destination unless it is missing or a viewer page written
/// by this tool: `view -o` never replaces a fit's map or any other file it did not write.
fn check_replaceable(path: &Path) -> Result<()> {
    use std::io::Read;
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    let mut head = Vec::new();
    let ours = meta.is_file()
        && std::fs::File::open(path)
            .and_then(|f| f.take(256).read_to_end(&mut head))
            .is_ok()
        && String::from_utf8_lossy(&head)
            .lines()
            .take(2)
            .any(|l| l.starts_with(PAGE_MARK));
    if !ours {
        bail!(
            "{}: exists and is not a viewer page written by symframe view; refusing to replace \
             it (give another -o)",
            path.display()
        );
    }
    Ok(())
}

/// Writes `bytes` to `path` whole or not at all (a temporary file beside it, then renamed).
fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot create folder", parent.display()))?;
    }
    check_replaceable(path)?;
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file name", path.display()))?;
    let tmp = path.with_file_name(format!(
        ".{}.partial-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    // A file (or link) left at the temporary name goes; the new one is created, never opened
    // through a link.
    if std::fs::symlink_metadata(&tmp).is_ok_and(|m| !m.is_dir()) {
        let _ = std::fs::remove_file(&tmp);
    }
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| std::io::Write::write_all(&mut f, bytes))
        .with_context(|| format!("{}: cannot write", tmp.display()))
        .and_then(|()| {
            std::fs::rename(&tmp, path).with_context(|| format!("{}: cannot write", path.display()))
        });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_standard() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn the_template_has_every_mark_and_no_other() {
        let data = PageData {
            format: 1,
            title: "a</script>".into(),
            width: 1,
            height: 1,
            textures: Textures {
                geom: String::new(),
                frame: String::new(),
                kd: String::new(),
                ks: String::new(),
                est: None,
            },
            views: vec!["relit"],
            sources: vec![],
            model: "ward",
            light_intensity: 1.0,
        };
        let page = render_page("a</script>", &data).unwrap();
        assert!(!page.contains("{{"), "a mark was left");
        assert!(page.contains("a&lt;/script&gt;"));
        assert!(!page.contains("a</script>"));
        assert!(page.contains("#version 300 es"));
        assert!(page.contains("symframeReady"));
    }

    #[test]
    fn textures_are_shuffled_half_floats() {
        let s = encode_texture(2, |p| [p as f32, 0.5, f32::NAN, 1e9]).unwrap();
        // Back: base64 by hand, then zlib with flate2's decoder.
        let raw: Vec<u8> = {
            let table = |c: u8| -> u32 {
                match c {
                    b'A'..=b'Z' => (c - b'A') as u32,
                    b'a'..=b'z' => (c - b'a') as u32 + 26,
                    b'0'..=b'9' => (c - b'0') as u32 + 52,
                    b'+' => 62,
                    _ => 63,
                }
            };
            let b = s.trim_end_matches('=').as_bytes();
            let mut out = Vec::new();
            for ch in b.chunks(4) {
                let mut v = 0u32;
                for (i, &c) in ch.iter().enumerate() {
                    v |= table(c) << (18 - 6 * i);
                }
                for i in 0..ch.len() - 1 {
                    out.push((v >> (16 - 8 * i)) as u8);
                }
            }
            out
        };
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::ZlibDecoder::new(&raw[..]), &mut bytes)
            .unwrap();
        assert_eq!(bytes.len(), 16);
        let half = |i: usize| half::f16::from_bits(u16::from_le_bytes([bytes[i], bytes[8 + i]]));
        let got: Vec<f32> = (0..8).map(|i| half(i).to_f32()).collect();
        assert_eq!(got, vec![0.0, 0.5, 0.0, 65504.0, 1.0, 0.5, 0.0, 65504.0]);
    }
}
