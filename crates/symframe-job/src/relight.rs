//! The relight job: the folder of [`crate::fit`] in, images under new lights out (linear EXR
//! and a tone-mapped PNG per light), with optional appearance edits. The fitted maps are whole
//! images (about 100 bytes per pixel), so they are read at once.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use glam::DVec3;
use serde::Serialize;
use symframe::{Edits, GltfMaps, LobeMaps, Relighter, Rig, RigOptions, SampleRelighter, WardMaps};
use symframe_io::DecodeOptions;

use crate::outdir::{OutputDir, OutputSet};

/// Everything a relight job needs.
#[derive(Debug, Clone, PartialEq)]
pub struct RelightConfig {
    /// Output folder of [`crate::fit`].
    pub fit_dir: PathBuf,
    /// Output folder: `relit_NNN.exr` and `relit_NNN.png` per light.
    pub output: PathBuf,
    /// Light directions (camera frame, surface toward light; normalised here), one image each.
    pub lights: Vec<DVec3>,
    /// Factor on the diffuse albedo (>= 0).
    pub diffuse_scale: f64,
    /// Factor on the specular albedo (>= 0).
    pub specular_scale: f64,
    /// Factor on both roughnesses (> 0; below 1 = glossier).
    pub roughness_scale: f64,
    /// Rotation of the tangents about the normal, degrees (inside `region` if given); with
    /// one, the edited tangent map is written too (`tangents_edited.png`).
    pub rotate_tangents: Option<f64>,
    /// Mask image limiting the tangent rotation to its non-zero pixels.
    pub region: Option<PathBuf>,
    /// Exposure of the PNG pictures in stops (the EXR files are not affected).
    pub exposure: f64,
    /// A height map (`depth.npy` of [`crate::integrate`], H x W in pixel units, NaN where
    /// none) whose cast shadows darken the relit images: a pixel the relief hides from a
    /// light gets no light from it (ray-marched per pixel toward the light).
    pub shadows: Option<PathBuf>,
    /// Relight the capture's own samples in the fit's frames, with no model
    /// ([`symframe::SampleRelighter`]), instead of the fitted parameters: the capture, decoded
    /// with these options. No edits: there are no parameters to edit.
    pub from_samples: Option<(PathBuf, DecodeOptions)>,
}

/// What a relight job wrote.
#[derive(Debug, Clone)]
pub struct RelightOutcome {
    /// The PNG pictures, in light order.
    pub pictures: Vec<PathBuf>,
    /// What the user should hear of (what taking the output folder's lock left alone).
    pub warnings: Vec<String>,
}

/// What `relight.json` records about a run.
#[derive(Debug, Serialize)]
struct RelightReport<'a> {
    version: &'static str,
    fit_dir: &'a Path,
    /// Unit light directions, one per image, in file order.
    lights: Vec<[f64; 3]>,
    /// Image file names (without extension), one per light.
    images: Vec<String>,
    diffuse_scale: f64,
    specular_scale: f64,
    roughness_scale: f64,
    rotate_tangents_deg: Option<f64>,
    region: Option<&'a Path>,
    exposure_stops: f64,
    /// The height map whose cast shadows were applied.
    #[serde(skip_serializing_if = "Option::is_none")]
    shadows: Option<&'a Path>,
    /// The capture whose samples were relit, with no model (`--from-samples`).
    #[serde(skip_serializing_if = "Option::is_none")]
    from_samples: Option<&'a Path>,
    /// Every warning of the run, as printed (what taking the output folder's lock left alone).
    warnings: &'a [String],
}

/// The maps of a fit folder, of either model.
#[derive(Debug, Clone)]
pub enum FittedMaps {
    /// A Ward fit (`kd`, `ks`, `alpha_t`, `alpha_b`).
    Ward(WardMaps),
    /// A glTF fit (`base_color`, `metallic`, `roughness`, `anisotropy_strength`, and the
    /// exposure from `fit.json`).
    Gltf(GltfMaps),
    /// An automatic fit with both models: each pixel has either Ward or glTF parameters (the
    /// other model's are NaN there); the frames are the same.
    Mixed(WardMaps, GltfMaps),
}

impl FittedMaps {
    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        match self {
            FittedMaps::Ward(m) => (m.width, m.height),
            FittedMaps::Gltf(m) | FittedMaps::Mixed(_, m) => (m.width, m.height),
        }
    }

    /// The relighter of these maps with `edits`.
    pub fn relighter(&self, edits: &Edits) -> symframe::Result<Relighter> {
        match self {
            FittedMaps::Ward(m) => Relighter::new(m, edits),
            FittedMaps::Gltf(m) => Relighter::gltf(m, edits),
            FittedMaps::Mixed(w, g) => Relighter::of_fit(w, Some(g), edits),
        }
    }

    /// Unit normals, `H x W x 3`.
    pub fn normals(&self) -> &[f32] {
        match self {
            FittedMaps::Ward(m) => &m.normals,
            FittedMaps::Gltf(m) | FittedMaps::Mixed(_, m) => &m.normals,
        }
    }

    /// Unit tangents, `H x W x 3` (NaN where isotropic).
    pub fn tangents(&self) -> &[f32] {
        match self {
            FittedMaps::Ward(m) | FittedMaps::Mixed(m, _) => &m.tangents,
            FittedMaps::Gltf(m) => &m.tangents,
        }
    }
}

/// Reads the maps of a fit folder of any model: both models' where `base_color.npy` and
/// `kd.npy` are there (an automatic fit that chose each somewhere), a glTF fit where only
/// `base_color.npy` is, a Ward fit where only `kd.npy` is; a two-lobe fit's folder, which has
/// neither, reads as a Ward fit without parameters in its frames (its models are
/// `read_lobe_maps`'s).
pub fn read_fit_maps(dir: &Path) -> Result<FittedMaps> {
    if !dir.join("base_color.npy").is_file()
        && !dir.join("kd.npy").is_file()
        && dir.join(format!("{}.npy", LOBE_MAPS[0])).is_file()
    {
        let normals_path = dir.join("normals.npy");
        let (shape, normals) = symframe_io::read_npy_f32(&normals_path)?;
        let [h, w, 3] = shape[..] else {
            bail!(
                "{}: shape {shape:?} is not an H x W x 3 map",
                normals_path.display()
            );
        };
        let n = w * h;
        return Ok(FittedMaps::Ward(WardMaps {
            width: w,
            height: h,
            tangents: read_map(dir, "tangents", &[h, w, 3])?,
            normals,
            kd: vec![f32::NAN; 3 * n],
            ks: vec![f32::NAN; 3 * n],
            alpha_t: vec![f32::NAN; n],
            alpha_b: vec![f32::NAN; n],
        }));
    }
    if dir.join("base_color.npy").is_file() {
        let g = read_gltf_maps(dir)?;
        if dir.join("kd.npy").is_file() {
            let w = read_ward_maps(dir)?;
            if (w.width, w.height) != (g.width, g.height) {
                bail!("{}: the Ward and glTF maps disagree in size", dir.display());
            }
            return Ok(FittedMaps::Mixed(w, g));
        }
        Ok(FittedMaps::Gltf(g))
    } else {
        read_ward_maps(dir).map(FittedMaps::Ward)
    }
}

/// The two-lobe maps of a fit folder (without extension; `.npy` and `.exr` are written):
/// diffuse albedo, the two lobes' reflectances (`H x W x 3`), then the roughnesses along the
/// tangent and the binormal and the coat's (`H x W`). Which model each pixel has is in
/// `model.npy` ([`symframe::FitMaps::MODEL_CLEARCOAT`], [`symframe::FitMaps::MODEL_WOVEN`]).
pub(crate) const LOBE_MAPS: [&str; 6] = [
    "lobes_kd",
    "lobes_ka",
    "lobes_kb",
    "lobes_alpha_t",
    "lobes_alpha_b",
    "lobes_alpha_c",
];

/// Reads the two-lobe maps of a fit folder (a clear-coat, woven or automatic fit), `None`
/// where it has none.
pub(crate) fn read_lobe_maps(dir: &Path) -> Result<Option<LobeMaps>> {
    let first = dir.join(format!("{}.npy", LOBE_MAPS[0]));
    if !first.is_file() {
        return Ok(None);
    }
    let (shape, kd) = symframe_io::read_npy_f32(&first)?;
    let [h, w, 3] = shape[..] else {
        bail!(
            "{}: shape {shape:?} is not an H x W x 3 map",
            first.display()
        );
    };
    let kind = read_map(dir, "model", &[h, w])?
        .iter()
        .map(|&c| {
            if (0.0..=255.0).contains(&c) {
                c as u8
            } else {
                0
            }
        })
        .collect();
    let maps = LobeMaps {
        width: w,
        height: h,
        normals: read_map(dir, "normals", &[h, w, 3])?,
        tangents: read_map(dir, "tangents", &[h, w, 3])?,
        kind,
        kd,
        ka: read_map(dir, LOBE_MAPS[1], &[h, w, 3])?,
        kb: read_map(dir, LOBE_MAPS[2], &[h, w, 3])?,
        alpha_t: read_map(dir, LOBE_MAPS[3], &[h, w])?,
        alpha_b: read_map(dir, LOBE_MAPS[4], &[h, w])?,
        alpha_c: read_map(dir, LOBE_MAPS[5], &[h, w])?,
    };
    maps.check().with_context(|| format!("{}", dir.display()))?;
    Ok(Some(maps))
}

/// The relighter of a fit folder: [`FittedMaps::relighter`] with the two-lobe pixels of
/// [`read_lobe_maps`] rendered with their models.
pub(crate) fn fit_relighter(maps: &FittedMaps, dir: &Path, edits: &Edits) -> Result<Relighter> {
    let r = maps
        .relighter(edits)
        .with_context(|| dir.display().to_string())?;
    Ok(match read_lobe_maps(dir)? {
        Some(l) => r
            .with_lobes(&l, edits)
            .with_context(|| dir.display().to_string())?,
        None => r,
    })
}

/// Reads the fitted glTF maps of `dir` and the exposure its `fit.json` records.
pub fn read_gltf_maps(dir: &Path) -> Result<GltfMaps> {
    let path = dir.join("base_color.npy");
    let (shape, base_color) = symframe_io::read_npy_f32(&path)?;
    let [h, w, 3] = shape[..] else {
        bail!(
            "{}: shape {shape:?} is not an H x W x 3 map",
            path.display()
        );
    };
    let report = dir.join("fit.json");
    let text = symframe_io::read_text_bounded(
        &report,
        "a report",
        symframe_io::limits::MAX_TEXT_FILE_BYTES,
    )
    .with_context(|| {
        format!(
            "{}: cannot read (a glTF fit's exposure is recorded there)",
            report.display()
        )
    })?;
    let json: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", report.display()))?;
    let Some(exposure) = json.get("exposure").and_then(|v| v.as_f64()) else {
        bail!("{}: records no exposure of the glTF fit", report.display());
    };
    let maps = GltfMaps {
        width: w,
        height: h,
        metallic: read_map(dir, "metallic", &[h, w])?,
        roughness: read_map(dir, "roughness", &[h, w])?,
        anisotropy: read_map(dir, "anisotropy_strength", &[h, w])?,
        normals: read_map(dir, "normals", &[h, w, 3])?,
        tangents: read_map(dir, "tangents", &[h, w, 3])?,
        base_color,
        exposure,
    };
    maps.check().with_context(|| format!("{}", dir.display()))?;
    Ok(maps)
}

/// Reads one map of the fit folder, which must have the shape `expect`.
pub(crate) fn read_map(dir: &Path, name: &str, expect: &[usize]) -> Result<Vec<f32>> {
    let path = dir.join(format!("{name}.npy"));
    if !path.is_file() {
        bail!(
            "{}: missing (the folder must be an output folder of symframe fit)",
            path.display()
        );
    }
    let (shape, data) = symframe_io::read_npy_f32(&path)?;
    if shape != expect {
        bail!(
            "{}: shape {shape:?} does not match the folder's other maps ({expect:?} expected)",
            path.display()
        );
    }
    Ok(data)
}

/// Reads the fitted maps of `dir`, checking that every map has kd.npy's size.
pub fn read_ward_maps(dir: &Path) -> Result<WardMaps> {
    let kd_path = dir.join("kd.npy");
    if !kd_path.is_file() {
        bail!(
            "{}: missing (the folder must be an output folder of symframe fit)",
            kd_path.display()
        );
    }
    let (shape, kd) = symframe_io::read_npy_f32(&kd_path)?;
    let [h, w, 3] = shape[..] else {
        bail!(
            "{}: shape {shape:?} is not an H x W x 3 map",
            kd_path.display()
        );
    };
    Ok(WardMaps {
        width: w,
        height: h,
        ks: read_map(dir, "ks", &[h, w, 3])?,
        alpha_t: read_map(dir, "alpha_t", &[h, w])?,
        alpha_b: read_map(dir, "alpha_b", &[h, w])?,
        normals: read_map(dir, "normals", &[h, w, 3])?,
        tangents: read_map(dir, "tangents", &[h, w, 3])?,
        kd,
    })
}

impl RelightConfig {
    /// No edits, exposure 0, no lights yet, the fitted models.
    pub fn new(fit_dir: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        let e = Edits::default();
        Self {
            fit_dir: fit_dir.into(),
            output: output.into(),
            lights: Vec::new(),
            diffuse_scale: e.diffuse_scale,
            specular_scale: e.specular_scale,
            roughness_scale: e.roughness_scale,
            rotate_tangents: None,
            region: None,
            exposure: 0.0,
            shadows: None,
            from_samples: None,
        }
    }
}

/// Runs a relight job: renders the fitted maps under every light, edited, into `output`.
pub fn relight(config: &RelightConfig) -> Result<RelightOutcome> {
    let maps = read_fit_maps(&config.fit_dir)?;
    let (w, h) = maps.size();
    let lights: Vec<DVec3> = config.lights.iter().map(|l| l.normalize()).collect();
    let edits = Edits {
        diffuse_scale: config.diffuse_scale,
        specular_scale: config.specular_scale,
        roughness_scale: config.roughness_scale,
        tangent_rotation_deg: config.rotate_tangents.unwrap_or(0.0),
        region: match &config.region {
            Some(p) => Some(symframe_io::read_mask(p, w, h)?),
            None => None,
        },
    };
    // What renders a light: the capture's own samples (`--from-samples`), or the fitted
    // models with the edits; and the edited tangent map where the tangents are turned.
    type Render = Box<dyn Fn(DVec3) -> Vec<f32> + Sync>;
    let (render, edited_tangents): (Render, Option<Vec<f32>>) = match &config.from_samples {
        Some((capture, decode)) => {
            if edits != Edits::default() {
                bail!(
                    "--from-samples relights the photographs as they are: the edits \
                     (--diffuse-scale, --specular-scale, --roughness-scale, --rotate-tangents, \
                     --region) need a fitted model"
                );
            }
            let r = sample_relighter(capture, decode, maps.normals(), maps.tangents(), (w, h))?;
            (Box::new(move |l| r.render(l)), None)
        }
        None => {
            let r = fit_relighter(&maps, &config.fit_dir, &edits)?;
            let tangents = config.rotate_tangents.map(|_| r.tangents());
            (Box::new(move |l| r.render(l)), tangents)
        }
    };
    let heights = match &config.shadows {
        Some(p) => {
            let (shape, depth) = symframe_io::read_npy_f32(p)?;
            if shape != [h, w] {
                bail!(
                    "{}: shape {shape:?} does not match the fitted maps ({h} x {w})",
                    p.display()
                );
            }
            Some(depth.iter().map(|&v| v as f64).collect::<Vec<f64>>())
        }
        None => None,
    };

    let out = OutputDir::lock(&config.output)?;
    let inputs = config.region.iter().chain(&config.shadows);
    let result = out
        .guard_inputs(
            inputs,
            "relight.json",
            &|n| relight_owned(n) || n == "relight.json",
            &|_| false,
        )
        .and_then(|()| {
            write_relit(
                config,
                &out,
                (w, h),
                (&*render, edited_tangents.as_deref()),
                &lights,
                &edits,
                heights.as_deref(),
            )
        });
    if result.is_err() {
        out.discard_unfinished();
    }
    result
}

/// The relighter of `capture`'s own samples (decoded with `decode`, loaded whole) in the
/// frames `normals` and `tangents` of a fit of size `(w, h)`.
pub(crate) fn sample_relighter(
    capture: &Path,
    decode: &DecodeOptions,
    normals: &[f32],
    tangents: &[f32],
    (w, h): (usize, usize),
) -> Result<SampleRelighter> {
    let ds = symframe_io::open_dataset(capture)?;
    let stack = symframe_io::load_stack(&ds, decode, &|| {})?;
    if (stack.width, stack.height) != (w, h) {
        bail!(
            "{}: its images are {} x {}, the fit's maps {w} x {h}",
            capture.display(),
            stack.width,
            stack.height
        );
    }
    let rig = Rig::new(&ds.lights, RigOptions::default())
        .with_context(|| capture.display().to_string())?;
    // The fit's frames are NaN outside the mask it was made with: those pixels stay dark.
    SampleRelighter::new(&stack, rig, normals, tangents, None)
        .with_context(|| capture.display().to_string())
}

/// Files an earlier relight into the same folder may have left that this one may not write:
/// more pictures, the edited tangent map.
fn relight_owned(name: &str) -> bool {
    let numbered = name
        .strip_prefix("relit_")
        .and_then(|r| r.strip_suffix(".exr").or_else(|| r.strip_suffix(".png")))
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
    numbered || name == "tangents_edited.png"
}

/// Renders every light and writes the pictures as one output set (`relight.json` last).
fn write_relit(
    config: &RelightConfig,
    out: &OutputDir,
    (w, h): (usize, usize),
    (render, edited_tangents): (&(dyn Fn(DVec3) -> Vec<f32> + Sync), Option<&[f32]>),
    lights: &[DVec3],
    edits: &Edits,
    heights: Option<&[f64]>,
) -> Result<RelightOutcome> {
    let staging = OutputSet::new(out, relight_owned)?;
    let mut names = Vec::with_capacity(lights.len());
    for (i, &l) in lights.iter().enumerate() {
        let name = format!("relit_{i:03}");
        let mut img = render(l);
        if let Some(hf) = heights {
            let shadowed = symframe::render::Scene::cast_shadows(hf, w, h, l);
            for (px, _) in img.chunks_exact_mut(3).zip(&shadowed).filter(|(_, &s)| s) {
                px.fill(0.0);
            }
        }
        symframe_io::write_exr_rgb(&staging.path(&format!("{name}.exr")), w, h, &img)?;
        symframe_io::write_png8_rgb(
            &staging.path(&format!("{name}.png")),
            w,
            h,
            &Relighter::tone_map(&img, config.exposure),
            true,
        )?;
        names.push(name);
    }
    if let Some(tangents) = edited_tangents {
        symframe_io::write_png_rgb8(
            &staging.path("tangents_edited.png"),
            w,
            h,
            &symframe_io::tangent_map_rgb8(tangents),
        )?;
    }
    let report = RelightReport {
        version: env!("CARGO_PKG_VERSION"),
        fit_dir: &config.fit_dir,
        lights: lights.iter().map(|l| l.to_array()).collect(),
        images: names.clone(),
        diffuse_scale: edits.diffuse_scale,
        specular_scale: edits.specular_scale,
        roughness_scale: edits.roughness_scale,
        rotate_tangents_deg: config.rotate_tangents,
        region: config.region.as_deref(),
        exposure_stops: config.exposure,
        shadows: config.shadows.as_deref(),
        from_samples: config.from_samples.as_ref().map(|(p, _)| p.as_path()),
        warnings: out.warnings(),
    };
    staging.commit("relight.json", serde_json::to_value(&report)?, &|_| {})?;
    Ok(RelightOutcome {
        pictures: names
            .iter()
            .map(|n| config.output.join(format!("{n}.png")))
            .collect(),
        warnings: out.warnings().to_vec(),
    })
}
