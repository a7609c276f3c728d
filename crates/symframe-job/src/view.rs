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
mod pyramid;

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::{Edits, PixelSource, Relighter};

use crate::relight::{read_fit_maps, FittedMaps};
use npy::{Dtype, NpyBands};
use pyramid::{Builder, Layout};

/// The page template; `{{NAME}}` marks are filled in by [`render_page`].
const PAGE: &str = include_str!("view/viewer.html");
/// The page's script.
const SCRIPT: &str = include_str!("view/viewer.js");
/// The vertex shader (one tile's rectangle on the canvas).
const VERTEX_SHADER: &str = include_str!("view/viewer.vert");
/// The fragment shader: relighting and the map views.
const FRAGMENT_SHADER: &str = include_str!("view/viewer.frag");

/// The textures, in the order of [`Band::textures`].
const TEXTURE_NAMES: [&str; 5] = ["geom", "frame", "kd", "ks", "est"];

/// Default of [`ViewConfig::pyramid_above`]: WebGL2 browsers take textures of 4096 pixels a
/// side at least, and a page of larger maps would be hundreds of megabytes.
pub const DEFAULT_PYRAMID_ABOVE: usize = 4096;
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

/// The data block of the page (JSON in a `<script>` element).
#[derive(Serialize)]
struct PageData {
    /// Version of the data layout, checked by the script.
    format: u32,
    title: String,
    width: usize,
    height: usize,
    /// The coarsest level's textures (the whole maps without a pyramid).
    textures: Textures,
    /// The pyramid the page loads tiles of, if any.
    pyramid: Option<PagePyramid>,
    views: Vec<&'static str>,
    /// Names of the source codes, by code.
    sources: Vec<&'static str>,
    /// Their colours (as `source.png`).
    source_colors: Vec<[u8; 3]>,
    /// What the page shades: `ward`, `gltf` or `estimate`.
    model: &'static str,
    /// A glTF fit's light intensity (1 for Ward).
    light_intensity: f64,
}

/// The pyramid as the page sees it.
#[derive(Serialize)]
struct PagePyramid {
    /// The tile folder, relative to the page.
    dir: String,
    tile: usize,
    /// Levels below the page's: 0 (full resolution) to `levels - 1`, which is the page's.
    levels: usize,
}

/// The encoded textures (see the module documentation).
#[derive(Serialize, Default)]
struct Textures {
    geom: Option<String>,
    frame: Option<String>,
    kd: Option<String>,
    ks: Option<String>,
    est: Option<String>,
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

/// Where the texels come from, a band of rows at a time.
trait Rows {
    fn fill(&mut self, y0: usize, y1: usize, band: &mut Band) -> Result<()>;
}

/// A fit's maps (held whole: the relighter's frames are of the whole map) and its estimate's.
struct FitRows {
    width: usize,
    fitted: FittedMaps,
    relighter: Relighter,
    est: Option<EstimateMaps>,
}

impl Rows for FitRows {
    fn fill(&mut self, y0: usize, y1: usize, band: &mut Band) -> Result<()> {
        band.clear();
        let (normals, tangents) = (self.fitted.normals(), self.fitted.tangents());
        for p in y0 * self.width..y1 * self.width {
            // A mixed fit's glTF pixels are flagged 3 (its Ward pixels 2, as any model's).
            let gltf_here = match &self.fitted {
                FittedMaps::Mixed(_, g) => g.base_color[p * 3].is_finite(),
                _ => false,
            };
            let geom = match self.relighter.frame(p) {
                Some((_, nrm, _)) => [
                    nrm.x as f32,
                    nrm.y as f32,
                    nrm.z as f32,
                    if gltf_here { 3.0 } else { 2.0 },
                ],
                None => match finite3(normals, p) {
                    Some([x, y, z]) => [x, y, z, 1.0],
                    None => [0.0; 4],
                },
            };
            let frame = match self.relighter.frame(p) {
                Some((t, _, aniso)) => [t.x as f32, t.y as f32, t.z as f32, f32::from(aniso)],
                None => match finite3(tangents, p) {
                    Some([x, y, z]) => [x, y, z, 1.0],
                    None => [0.0; 4],
                },
            };
            // Albedos and roughnesses matter only where there is a model (the flag of `geom`).
            let (kd, ks) = match &self.fitted {
                FittedMaps::Gltf(m) | FittedMaps::Mixed(_, m)
                    if gltf_here || matches!(self.fitted, FittedMaps::Gltf(_)) =>
                {
                    let c = &m.base_color[p * 3..p * 3 + 3];
                    (
                        [c[0], c[1], c[2], m.metallic[p]],
                        [m.roughness[p], m.anisotropy[p], 0.0, 0.0],
                    )
                }
                FittedMaps::Ward(m) | FittedMaps::Mixed(m, _) => {
                    let (d, s) = (&m.kd[p * 3..p * 3 + 3], &m.ks[p * 3..p * 3 + 3]);
                    (
                        [d[0], d[1], d[2], m.alpha_t[p]],
                        [s[0], s[1], s[2], m.alpha_b[p]],
                    )
                }
                FittedMaps::Gltf(_) => unreachable!("matched above"),
            };
            let est = self.est.as_ref().map_or([0.0; 4], |e| e.texel(p));
            band.push([geom, frame, kd, ks, est]);
        }
        Ok(())
    }
}

/// An estimate folder read a band at a time.
struct EstimateRows {
    width: usize,
    normals: NpyBands,
    tangents: Option<NpyBands>,
    confidence: Option<NpyBands>,
    anisotropy: Option<NpyBands>,
    source: Option<NpyBands>,
}

impl Rows for EstimateRows {
    fn fill(&mut self, y0: usize, y1: usize, band: &mut Band) -> Result<()> {
        band.clear();
        let n = (y1 - y0) * self.width;
        let mut normals = Vec::new();
        self.normals.rows_f32(y0, y1, &mut normals)?;
        let mut tangents = vec![f32::NAN; n * 3];
        if let Some(t) = &mut self.tangents {
            t.rows_f32(y0, y1, &mut tangents)?;
        }
        let scalar = |m: &mut Option<NpyBands>| -> Result<Option<Vec<f32>>> {
            let Some(m) = m else { return Ok(None) };
            let mut v = Vec::new();
            m.rows_f32(y0, y1, &mut v)?;
            Ok(Some(v))
        };
        let confidence = scalar(&mut self.confidence)?;
        let anisotropy = scalar(&mut self.anisotropy)?;
        let source = match &mut self.source {
            Some(s) => {
                let mut v = Vec::new();
                s.rows_u8(y0, y1, &mut v)?;
                Some(v)
            }
            None => None,
        };
        let est = EstimateMaps {
            confidence,
            anisotropy,
            source,
        };
        for p in 0..n {
            let geom = match finite3(&normals, p) {
                Some([x, y, z]) => [x, y, z, 1.0],
                None => [0.0; 4],
            };
            let frame = match finite3(&tangents, p) {
                Some([x, y, z]) if geom[3] > 0.0 => [x, y, z, 1.0],
                _ => [0.0; 4],
            };
            band.push([geom, frame, [0.0; 4], [0.0; 4], est.texel(p)]);
        }
        Ok(())
    }
}

/// The estimate's maps that the viewer shows (each optional).
struct EstimateMaps {
    confidence: Option<Vec<f32>>,
    anisotropy: Option<Vec<f32>>,
    source: Option<Vec<u8>>,
}

impl EstimateMaps {
    fn is_empty(&self) -> bool {
        self.confidence.is_none() && self.anisotropy.is_none() && self.source.is_none()
    }

    /// The `est` texel of pixel `p`.
    fn texel(&self, p: usize) -> [f32; 4] {
        let at = |m: &Option<Vec<f32>>| m.as_ref().map_or(f32::NAN, |v| v[p]);
        let (c, a) = (at(&self.confidence), at(&self.anisotropy));
        let s = self.source.as_ref().map(|s| s[p]);
        let flags =
            u8::from(c.is_finite()) + 2 * u8::from(a.is_finite()) + 4 * u8::from(s.is_some());
        [c, a, f32::from(s.unwrap_or(0)), f32::from(flags)]
    }

    fn views(&self) -> impl Iterator<Item = &'static str> + '_ {
        [
            ("confidence", self.confidence.is_some()),
            ("anisotropy", self.anisotropy.is_some()),
            ("source", self.source.is_some()),
        ]
        .into_iter()
        .filter_map(|(v, p)| p.then_some(v))
    }
}

/// Whether `dir` holds an estimate's maps and no fitted ones.
fn is_estimate_folder(dir: &Path) -> bool {
    dir.join("normals.npy").is_file()
        && !dir.join("kd.npy").exists()
        && !dir.join("base_color.npy").exists()
}

/// What the page is made of: the maps' rows and what they hold.
struct Source {
    rows: Box<dyn Rows>,
    width: usize,
    height: usize,
    /// Which of [`TEXTURE_NAMES`] there are.
    present: [bool; 5],
    views: Vec<&'static str>,
    model: &'static str,
    light_intensity: f64,
    /// The estimate folder whose maps are shown.
    frames: Option<PathBuf>,
}

/// The maps of an estimate folder, read a band at a time.
fn estimate_source(config: &ViewConfig, notes: &mut Vec<String>) -> Result<Source> {
    if config.frames.is_some() {
        notes.push(format!(
            "{}: an estimate folder; --frames is not used",
            config.fit_dir.display()
        ));
    }
    let (r, width, height) = open_estimate(&config.fit_dir)?;
    let mut views = vec!["relit", "normal"];
    if r.tangents.is_some() {
        views.push("tangent");
    }
    let mut est = false;
    for (view, present) in [
        ("confidence", r.confidence.is_some()),
        ("anisotropy", r.anisotropy.is_some()),
        ("source", r.source.is_some()),
    ] {
        if present {
            views.push(view);
            est = true;
        }
    }
    Ok(Source {
        rows: Box::new(r),
        width,
        height,
        present: [true, true, false, false, est],
        views,
        model: "estimate",
        light_intensity: 1.0,
        frames: Some(config.fit_dir.clone()),
    })
}

/// The maps of a fit folder (held whole) and of its estimate.
fn fit_source(config: &ViewConfig, notes: &mut Vec<String>) -> Result<Source> {
    let fitted = read_fit_maps(&config.fit_dir)?;
    let (w, h) = fitted.size();
    let relighter = fitted
        .relighter(&Edits::default())
        .with_context(|| config.fit_dir.display().to_string())?;
    let frames = frames_dir(config, notes)?;
    let est = match &frames {
        Some(dir) => {
            let e = read_estimate_maps(dir, w, h)?;
            if e.is_empty() {
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
    let (mut views, model, light_intensity) = match &fitted {
        FittedMaps::Ward(_) => (vec!["relit", "normal", "tangent", "kd", "ks"], "ward", 1.0),
        FittedMaps::Gltf(m) => (
            vec!["relit", "normal", "tangent", "base_color"],
            "gltf",
            m.exposure,
        ),
        // Ward's and glTF's maps both: the page shows each pixel's own model.
        FittedMaps::Mixed(_, m) => (
            vec!["relit", "normal", "tangent", "kd", "ks", "base_color"],
            "auto",
            m.exposure,
        ),
    };
    if let Some(e) = &est {
        views.extend(e.views());
    }
    let present = [true, true, true, true, est.is_some()];
    Ok(Source {
        rows: Box::new(FitRows {
            width: w,
            fitted,
            relighter,
            est,
        }),
        width: w,
        height: h,
        present,
        views,
        model,
        light_intensity,
        frames,
    })
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

/// Opens the maps of an estimate folder: `normals.npy` (required), and `tangents.npy`,
/// `confidence.npy`, `anisotropy.npy`, `source.npy` where present, all of its size.
fn open_estimate(dir: &Path) -> Result<(EstimateRows, usize, usize)> {
    let path = dir.join("normals.npy");
    let normals = NpyBands::open_any(&path, Dtype::F32)?;
    let [h, w, c] = normals.shape();
    if c != 3 {
        bail!(
            "{}: shape [{h}, {w}, {c}] is not an H x W x 3 map",
            path.display()
        );
    }
    let open = |name: &str, dtype: Dtype, channels: usize| -> Result<Option<NpyBands>> {
        let path = dir.join(name);
        if !path.is_file() {
            return Ok(None);
        }
        NpyBands::open(&path, dtype, h, w, channels).map(Some)
    };
    Ok((
        EstimateRows {
            width: w,
            tangents: open("tangents.npy", Dtype::F32, 3)?,
            confidence: open("confidence.npy", Dtype::F32, 1)?,
            anisotropy: open("anisotropy.npy", Dtype::F32, 1)?,
            source: open("source.npy", Dtype::U8, 1)?,
            normals,
        },
        w,
        h,
    ))
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

/// Half floats, four a pixel, as the page takes them: the low bytes of all values then the
/// high bytes (which deflate far better than interleaved), zlib-compressed at `level`,
/// base64-encoded.
fn encode_halves(halves: &[u16], level: u32) -> Result<String> {
    let n = halves.len();
    let mut bytes = vec![0u8; n * 2];
    let (lo, hi) = bytes.split_at_mut(n);
    for (i, h) in halves.iter().enumerate() {
        let [l, b] = h.to_le_bytes();
        lo[i] = l;
        hi[i] = b;
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(level));
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
