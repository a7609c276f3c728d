//! The viewer: the folder of [`crate::fit`] (and the maps of the estimate it was fitted in), or
//! the folder of [`crate::estimate`] alone, in; one HTML page out that relights the maps in a
//! browser in real time with WebGL2, zooms and pans.
//!
//! The page needs nothing else (no network, works from a `file:` URL): the HTML, its script
//! and its shaders (`src/view/`, real files in the repository) are copied in, and the maps are
//! embedded as RGBA half-float textures, byte-shuffled, zlib-compressed and base64-encoded
//! (the browser inflates them with its own `DecompressionStream`). Maps larger than
//! [`ViewConfig::pyramid_above`] go to a tile pyramid in a folder beside the page instead
//! (`view/pyramid.rs`), whose coarsest level is in the page; the page loads the tiles it shows.
//!
//! A fit is shaded with the model of [`symframe::Relighter`] with the same edits, in the frames
//! the relighter uses (taken from it, not recomputed), so a screenshot under a light matches
//! `symframe relight --light` of the same fit (the browser test checks this). An estimate has
//! no material: the page shades it with a fixed grey Lambert plus Ward lobe along its tangents.
//!
//! Textures, four half floats per pixel, rows top to bottom:
//! - `geom`: the normal, then a flag (0 no normal, 1 a normal but no model, 2 a model);
//! - `frame`: the shading tangent (the map's, or the relighter's own for isotropic pixels),
//!   then 1 where it came from the tangent map (only those are turned by a rotation);
//! - `kd`: diffuse albedo and `alpha_t`; `ks`: specular albedo and `alpha_b` (a glTF fit:
//!   `kd` base colour and metallic, `ks` roughness, anisotropy strength, 0, 0; the fitted
//!   light intensity is in the page's data); neither for an estimate;
//! - `est` (when the estimate's maps are found): confidence, anisotropy, source code, and a
//!   flag sum (1 confidence, 2 anisotropy, 4 source present).
//!
//! Values without a meaning (NaN) are stored as 0; the flags say where data is.

mod npy;
mod page;
mod pyramid;
mod samples;
mod sources;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use symframe::PixelSource;

use page::{
    check_replaceable, encode_halves, render_page, write_file, PageData, PagePyramid, Textures,
};
use pyramid::{Builder, Layout};
use sources::{estimate_source, fit_source, is_estimate_folder, Rows, Source};

/// The textures, in the order of [`Band::textures`].
const TEXTURE_NAMES: [&str; 5] = ["geom", "frame", "kd", "ks", "est"];

/// Default of [`ViewConfig::pyramid_above`]: WebGL2 browsers take textures of 4096 pixels a
/// side at least, and a page of larger maps would be hundreds of megabytes.
pub const DEFAULT_PYRAMID_ABOVE: usize = 4096;
/// The most lights the view `samples` takes: a WebGL2 browser takes texture arrays of 256
/// layers at least, two of which hold the frames.
pub(crate) const MAX_SAMPLE_LIGHTS: usize = 254;
/// The most bytes of sample texels the view `samples` embeds (four half floats per pixel,
/// light and frame layer): a page beyond that would not load in a browser tab.
pub(crate) const MAX_SAMPLE_BYTES: usize = 512 << 20;
/// Default of [`ViewConfig::tile_size`].
pub const DEFAULT_TILE_SIZE: usize = 256;

/// Everything the viewer needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewConfig {
    /// Output folder of [`crate::fit`], or of [`crate::estimate`] (a folder with
    /// `normals.npy` but no fitted maps).
    pub fit_dir: PathBuf,
    /// Output folder of the estimate the fit was made in (confidence, anisotropy and source
    /// maps); `None`: the `frames` folder recorded in `fit.json`, if it is still there.
    pub frames: Option<PathBuf>,
    /// The HTML file to write (its folder is created).
    pub output: PathBuf,
    /// Maps wider or taller than this many pixels are written as a tile pyramid in the folder
    /// `NAME_files` beside the page `NAME.html` (0: always).
    pub pyramid_above: usize,
    /// Side of the pyramid's square tiles, pixels.
    pub tile_size: usize,
    /// Also relight the capture's own samples in the fit's frames, with no model (the view
    /// `samples`, as `symframe relight --from-samples`): the capture, decoded with these
    /// options. The samples go into the page whole: at most 254 lights and 512 MiB of texels
    /// (four half floats per pixel and light), and no pyramid.
    pub samples: Option<(PathBuf, symframe_io::DecodeOptions)>,
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
            pyramid_above: DEFAULT_PYRAMID_ABOVE,
            tile_size: DEFAULT_TILE_SIZE,
            samples: None,
        }
    }
}

/// What [`write_viewer`] wrote.
#[derive(Debug, Clone)]
pub struct ViewOutcome {
    /// The HTML file.
    pub path: PathBuf,
    /// Map size in pixels.
    pub width: usize,
    /// Map size in pixels.
    pub height: usize,
    /// Size of the file in bytes.
    pub bytes: u64,
    /// The views the page offers, `relit` first.
    pub views: Vec<&'static str>,
    /// What the page shades: `ward`, `gltf` or `estimate` (an estimate folder, no fit).
    pub model: &'static str,
    /// The estimate folder whose maps were embedded, if any.
    pub frames: Option<PathBuf>,
    /// The tile pyramid, when the maps were too large for the page.
    pub pyramid: Option<PyramidOutcome>,
    /// Things the user should know that did not stop the job (estimate maps not found).
    pub notes: Vec<String>,
}

/// The tile pyramid [`write_viewer`] wrote beside the page.
#[derive(Debug, Clone)]
pub struct PyramidOutcome {
    /// Its folder.
    pub dir: PathBuf,
    /// Levels, the page's coarsest one included.
    pub levels: usize,
    /// Tile side, pixels.
    pub tile_size: usize,
    /// Tile files written.
    pub tiles: usize,
    /// Their bytes.
    pub bytes: u64,
}

/// Rows of the textures, four half floats a pixel (the `Some` ones of [`TEXTURE_NAMES`]).
struct Band {
    width: usize,
    textures: [Option<Vec<u16>>; 5],
}

impl Band {
    fn new(width: usize, present: [bool; 5]) -> Self {
        Self {
            width,
            textures: present.map(|p| p.then(Vec::new)),
        }
    }

    fn rows(&self) -> usize {
        match self.textures[0].as_ref() {
            Some(t) if self.width > 0 => t.len() / (4 * self.width),
            _ => 0,
        }
    }

    fn clear(&mut self) {
        for t in self.textures.iter_mut().flatten() {
            t.clear();
        }
    }

    /// Appends one pixel's texels (those of absent textures are dropped).
    fn push(&mut self, texels: [[f32; 4]; 5]) {
        for (t, v) in self.textures.iter_mut().zip(texels) {
            if let Some(t) = t {
                t.extend(v.map(half_bits));
            }
        }
    }

    /// Appends row `y` of `src` (full resolution), every `step`-th pixel.
    fn push_row_sampled(&mut self, src: &Band, y: usize, step: usize) {
        for (t, s) in self.textures.iter_mut().zip(&src.textures) {
            if let (Some(t), Some(s)) = (t, s) {
                let row = &s[y * src.width * 4..(y + 1) * src.width * 4];
                for px in row.chunks_exact(4).step_by(step) {
                    t.extend_from_slice(px);
                }
            }
        }
    }

    /// Columns `x0..x1` of every row.
    fn crop(&self, x0: usize, x1: usize) -> Band {
        let rows = self.rows();
        Band {
            width: x1 - x0,
            textures: std::array::from_fn(|i| {
                self.textures[i].as_ref().map(|t| {
                    (0..rows)
                        .flat_map(|y| &t[(y * self.width + x0) * 4..(y * self.width + x1) * 4])
                        .copied()
                        .collect()
                })
            }),
        }
    }
}

/// A value as half-float bits: NaN as 0, beyond the half range clamped to it.
fn half_bits(v: f32) -> u16 {
    let v = if v.is_nan() {
        0.0
    } else {
        v.clamp(-65504.0, 65504.0)
    };
    half::f16::from_f32(v).to_bits()
}

/// Writes the viewer of a fit or an estimate: see the module documentation. Errors name the
/// file at fault (a map missing or of the wrong size, an estimate map of the wrong size, the
/// output or its tile folder when they are not this tool's to replace).
pub fn write_viewer(config: &ViewConfig) -> Result<ViewOutcome> {
    check_replaceable(&config.output)?;
    if config.tile_size < 8 || config.tile_size > 4096 {
        bail!("tile size {}: must be 8 to 4096 pixels", config.tile_size);
    }
    let dir = &config.fit_dir;
    if !["normals.npy", "kd.npy", "base_color.npy"]
        .iter()
        .any(|f| dir.join(f).exists())
    {
        bail!(
            "{}: no maps to show (expected an output folder of symframe estimate, with \
             normals.npy, or of symframe fit, with base_color.npy or kd.npy)",
            dir.display()
        );
    }
    let mut notes = Vec::new();
    let source = if is_estimate_folder(&config.fit_dir) {
        estimate_source(config, &mut notes)?
    } else {
        fit_source(config, &mut notes)?
    };
    let Source {
        mut rows,
        width: w,
        height: h,
        present,
        mut views,
        model,
        light_intensity,
        frames,
    } = source;
    let tiled = w.max(h) > config.pyramid_above;
    let tiles_dir = pyramid::folder_of(&config.output);
    // The tile folder is replaced (a pyramid) or removed (none: it would be stale) only if
    // this tool wrote it.
    let old = match pyramid::our_folder(&tiles_dir) {
        Ok(old) => old,
        Err(e) if tiled => return Err(e),
        Err(_) => None,
    };
    let layout = if tiled {
        Layout::new(w, h, config.tile_size)
    } else {
        Layout {
            width: w,
            height: h,
            tile: w.max(h),
            top: 0,
        }
    };
    let building = tiled.then(|| partial_path(&tiles_dir));
    if let Some(b) = &building {
        if let Some(parent) = b.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("{}: cannot create folder", parent.display()))?;
        }
        // A leftover of an interrupted run of this tool goes; anything else stops the job.
        if let Some(files) = pyramid::our_folder(b)? {
            pyramid::remove_ours(b, &files)?;
        }
        std::fs::create_dir(b).with_context(|| format!("{}: cannot create", b.display()))?;
    }
    // Removed on any error from here on: this run created it, so all in it is its own.
    let _cleanup = building.as_ref().map(|b| RemoveOnDrop(b.clone()));
    let (top, tiles, tile_bytes) = build_levels(&mut *rows, layout, building.as_deref(), present)?;
    drop(rows);
    let encode = |i: usize| -> Result<Option<String>> {
        top.textures[i]
            .as_ref()
            .map(|t| encode_halves(t, 6))
            .transpose()
    };
    let textures = Textures {
        geom: encode(0)?,
        frame: encode(1)?,
        kd: encode(2)?,
        ks: encode(3)?,
        est: encode(4)?,
    };
    drop(top);
    if views.is_empty() {
        views.push("relit");
    }
    let samples = match &config.samples {
        Some(_) if tiled => bail!(
            "{}: the maps are {w} x {h}, above --pyramid-above {}: the view `samples` needs the \
             whole capture in the page (no pyramid)",
            config.fit_dir.display(),
            config.pyramid_above
        ),
        Some((capture, decode)) => {
            views.push("samples");
            let estimate = model == "estimate";
            Some(samples::page_samples(
                config,
                (capture, decode),
                (w, h),
                estimate,
            )?)
        }
        None => None,
    };

    // The folder as given (a full path would show where it was made, not what it is).
    let title = config.fit_dir.display().to_string();
    let data = PageData {
        format: 2,
        title: title.clone(),
        width: w,
        height: h,
        textures,
        pyramid: tiled.then(|| PagePyramid {
            dir: tiles_dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            tile: layout.tile,
            levels: layout.top + 1,
        }),
        views: views.clone(),
        sources: PixelSource::legend().iter().map(|l| l.1).collect(),
        source_colors: symframe_io::SOURCE_PALETTE.to_vec(),
        model,
        light_intensity,
        samples,
    };
    let page = render_page(&title, &data)?;
    // The tiles move into place, then the page that loads them is written, then the old tiles
    // go.
    let mut retired = None;
    if let Some(b) = &building {
        if let Some(files) = &old {
            let aside = aside_path(&tiles_dir);
            std::fs::rename(&tiles_dir, &aside)
                .with_context(|| format!("{}: cannot move aside", tiles_dir.display()))?;
            let files: Vec<PathBuf> = files
                .iter()
                .map(|f| aside.join(f.strip_prefix(&tiles_dir).unwrap_or(f)))
                .collect();
            retired = Some((aside, files));
        }
        std::fs::rename(b, &tiles_dir)
            .with_context(|| format!("{}: cannot write", tiles_dir.display()))?;
    } else if let Some(files) = &old {
        retired = Some((tiles_dir.clone(), files.clone()));
    }
    write_file(&config.output, page.as_bytes())?;
    if let Some((dir, files)) = retired {
        pyramid::remove_ours(&dir, &files)?;
    }
    Ok(ViewOutcome {
        path: config.output.clone(),
        width: w,
        height: h,
        bytes: page.len() as u64,
        views,
        model,
        frames,
        pyramid: tiled.then(|| PyramidOutcome {
            dir: tiles_dir.clone(),
            levels: layout.top + 1,
            tile_size: layout.tile,
            tiles,
            bytes: tile_bytes,
        }),
        notes,
    })
}

/// Removes the folder it names when dropped, if it is still there (a half-built pyramid).
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if std::fs::symlink_metadata(&self.0).is_ok_and(|m| m.is_dir()) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// A hidden name beside `path` for its old version while the new one moves in.
fn aside_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.old-{}", std::process::id()))
}

/// A hidden name beside `path` for a folder being built.
fn partial_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.partial-{}", std::process::id()))
}

/// Reads the maps a band of tile rows at a time into the pyramid (`dir`: its folder; `None`
/// without one, the page's level is then the whole map). Returns the page's level, the tile
/// files written and their bytes.
fn build_levels(
    rows: &mut dyn Rows,
    layout: Layout,
    dir: Option<&Path>,
    present: [bool; 5],
) -> Result<(Band, usize, u64)> {
    let mut builder = Builder::new(layout, dir, present)?;
    // The maps are read 256 rows at a time; each level keeps the rows of its next tile row
    // (without a pyramid: the whole map, which the page holds anyway).
    let step = 256;
    let mut band = Band::new(layout.width, present);
    let mut y0 = 0;
    while y0 < layout.height {
        let y1 = (y0 + step).min(layout.height);
        rows.fill(y0, y1, &mut band)?;
        builder.push(y0, &band)?;
        y0 = y1;
    }
    builder.finish()
}

#[cfg(test)]
mod tests {
    use super::page::base64;
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
            format: 2,
            title: "a</script>".into(),
            width: 1,
            height: 1,
            textures: Textures::default(),
            pyramid: None,
            views: vec!["relit"],
            sources: vec![],
            source_colors: vec![],
            model: "ward",
            light_intensity: 1.0,
            samples: None,
        };
        let page = render_page("a</script>", &data).unwrap();
        assert!(!page.contains("{{"), "a mark was left");
        assert!(page.contains("a&lt;/script&gt;"));
        assert!(!page.contains("a</script>"));
        assert!(page.contains("#version 300 es"));
        assert!(page.contains("symframeReady"));
    }

    /// The half floats of an encoded texture (base64 by hand, zlib with flate2, unshuffled).
    fn decode(s: &str) -> Vec<half::f16> {
        let table = |c: u8| -> u32 {
            match c {
                b'A'..=b'Z' => (c - b'A') as u32,
                b'a'..=b'z' => (c - b'a') as u32 + 26,
                b'0'..=b'9' => (c - b'0') as u32 + 52,
                b'+' => 62,
                _ => 63,
            }
        };
        let mut raw = Vec::new();
        for ch in s.trim_end_matches('=').as_bytes().chunks(4) {
            let mut v = 0u32;
            for (i, &c) in ch.iter().enumerate() {
                v |= table(c) << (18 - 6 * i);
            }
            for i in 0..ch.len() - 1 {
                raw.push((v >> (16 - 8 * i)) as u8);
            }
        }
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::ZlibDecoder::new(&raw[..]), &mut bytes)
            .unwrap();
        let n = bytes.len() / 2;
        (0..n)
            .map(|i| half::f16::from_bits(u16::from_le_bytes([bytes[i], bytes[n + i]])))
            .collect()
    }

    #[test]
    fn textures_are_shuffled_half_floats() {
        let mut band = Band::new(2, [true, false, false, false, false]);
        for p in 0..2 {
            band.push([[p as f32, 0.5, f32::NAN, 1e9]; 5]);
        }
        let s = encode_halves(band.textures[0].as_ref().unwrap(), 6).unwrap();
        let got: Vec<f32> = decode(&s).iter().map(|h| h.to_f32()).collect();
        assert_eq!(got, vec![0.0, 0.5, 0.0, 65504.0, 1.0, 0.5, 0.0, 65504.0]);
    }

    #[test]
    fn pyramid_tiles_hold_every_other_pixel_of_the_estimate() {
        let dir = tempfile::tempdir().unwrap();
        let est = dir.path().join("est");
        std::fs::create_dir(&est).unwrap();
        let (w, h) = (40usize, 36usize);
        // A different normal at every pixel; no normal in the first column.
        let normal = |x: usize, y: usize| -> [f32; 3] {
            if x == 0 {
                return [f32::NAN; 3];
            }
            let v = glam::Vec3::new(x as f32 - 20.0, y as f32 - 18.0, 40.0).normalize();
            v.to_array()
        };
        let normals: Vec<f32> = (0..h)
            .flat_map(|y| (0..w).flat_map(move |x| normal(x, y)))
            .collect();
        symframe_io::write_npy_f32(&est.join("normals.npy"), &[h, w, 3], &normals).unwrap();
        let mut config = ViewConfig::new(&est);
        config.pyramid_above = 32;
        config.tile_size = 8;
        let done = write_viewer(&config).unwrap();
        let p = done.pyramid.unwrap();
        // 40 x 36, 20 x 18, 10 x 9, 5 x 5 (the page's).
        assert_eq!((p.levels, p.tiles), (4, 5 * 5 + 3 * 3 + 2 * 2));
        let texel = |g: &[half::f16], tw: usize, i: usize, j: usize| -> [f32; 4] {
            std::array::from_fn(|c| g[(j * tw + i) * 4 + c].to_f32())
        };
        let expect = |x: usize, y: usize| -> [f32; 4] {
            let n = normal(x, y);
            if n[0].is_nan() {
                return [0.0; 4];
            }
            let q = |v: f32| half::f16::from_f32(v).to_f32();
            [q(n[0]), q(n[1]), q(n[2]), 1.0]
        };
        // Level 1, tile (2, 1): level-1 pixels x 16..20, y 8..16, full-resolution pixels twice
        // those.
        let script = std::fs::read_to_string(p.dir.join("1/2_1.js")).unwrap();
        assert!(
            script.starts_with("symframeTile(1,2,1,4,8,{"),
            "{script:.30}"
        );
        let geom = script.split('"').nth(3).unwrap();
        let g = decode(geom);
        assert_eq!(g.len(), 4 * 8 * 4);
        for j in 0..8 {
            for i in 0..4 {
                assert_eq!(
                    texel(&g, 4, i, j),
                    expect(2 * (16 + i), 2 * (8 + j)),
                    "{i} {j}"
                );
            }
        }
        // The page's level: every 8th pixel.
        let page = std::fs::read_to_string(&done.path).unwrap();
        let start = page.find("\"geom\":\"").unwrap() + 8;
        let g = decode(&page[start..start + page[start..].find('"').unwrap()]);
        assert_eq!(g.len(), 5 * 5 * 4);
        for j in 0..5 {
            for i in 0..5 {
                assert_eq!(texel(&g, 5, i, j), expect(8 * i, 8 * j));
            }
        }
    }
}
