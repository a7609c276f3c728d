//! What a page is made of: a fit's maps (held whole, shaded by its relighter) or an estimate's
//! (read a band of rows at a time), and the estimate maps shown beside a fit, as rows of texels.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use symframe::{Edits, Relighter};

use super::npy::{Dtype, NpyBands};
use super::{Band, ViewConfig};
use crate::relight::{read_fit_maps, FittedMaps};

/// Where the texels come from, a band of rows at a time.
pub(super) trait Rows {
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
pub(super) fn is_estimate_folder(dir: &Path) -> bool {
    dir.join("normals.npy").is_file()
        && !dir.join("kd.npy").exists()
        && !dir.join("base_color.npy").exists()
}

/// What the page is made of: the maps' rows and what they hold.
pub(super) struct Source {
    pub(super) rows: Box<dyn Rows>,
    pub(super) width: usize,
    pub(super) height: usize,
    /// Which of [`super::TEXTURE_NAMES`] there are.
    pub(super) present: [bool; 5],
    pub(super) views: Vec<&'static str>,
    pub(super) model: &'static str,
    pub(super) light_intensity: f64,
    /// The estimate folder whose maps are shown.
    pub(super) frames: Option<PathBuf>,
}

/// The maps of an estimate folder, read a band at a time.
pub(super) fn estimate_source(config: &ViewConfig, notes: &mut Vec<String>) -> Result<Source> {
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
pub(super) fn fit_source(config: &ViewConfig, notes: &mut Vec<String>) -> Result<Source> {
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
