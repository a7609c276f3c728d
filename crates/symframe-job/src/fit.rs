//! The fit job: a capture and its estimated frames in, per-pixel anisotropic Ward (paper
//! Section 5.1) or glTF metallic-roughness parameters out, in a folder that [`crate::relight`] reads on its own. The samples
//! come from the tile cache tile by tile, as in [`crate::estimate`]: memory stays bounded, and
//! an interrupted fit resumes.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::{ExposureChoice, FitMaps, FitMethod, FitModel, FitParams, FitSummary, PixelOutcome};
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{CacheFormat, CacheOptions, Dataset, DecodeOptions, Fingerprints, StampKind};

use crate::estimate::{
    cache_dir, fingerprint_lights, fingerprint_mask, open_cache, read_mask, remove_cache,
    CacheConfig, CacheReport, InputsRecord, CACHE_DIR,
};
use crate::outdir::{in_locked_output, lock_warnings, OutputDir, OutputSet};
use crate::tiles::{read_tiles, run_tiles, tile_path, TileCounts};
use crate::tiles::{EVIDENCE_DIR, TILES_DIR};
use crate::{Checkpoint, Control};

mod records;

use records::FIT_TILE_VERSION;

/// Everything a fit job needs.
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// The capture, as for [`crate::estimate`].
    pub input: PathBuf,
    /// Output folder of an estimate of the same capture (`normals.npy`, `tangents.npy`).
    pub frames: PathBuf,
    /// Output folder (created; same-named files in it are replaced).
    pub output: PathBuf,
    /// Lights left out of the fit (evenly spaced in input order) to judge it on; they replace
    /// `params.holdout`.
    pub holdout: usize,
    /// The fit's parameters (`params.model` chooses the model; the default is the automatic
    /// choice per pixel, [`symframe::FitModel::DEFAULT`]).
    pub params: FitParams,
    /// glTF or automatic fit: the light intensity ([`FitParams::exposure`]); `None` chooses
    /// it by validation lights on up to `EXPOSURE_PIXELS` pixels spread over the image
    /// ([`symframe::ExposureChoice::select`]). Replaces `params.exposure`.
    pub exposure: Option<f64>,
    /// Mask image (`None`: the dataset's `mask.png`, if any).
    pub mask: Option<PathBuf>,
    /// How images are decoded.
    pub decode: DecodeOptions,
    /// The tile cache. Without a folder, the estimate's (`FRAMES/.symframe-cache`) is used
    /// when it exists, in the estimate's tile size (from its `report.json`), so a fit after an
    /// estimate decodes nothing; else `OUTPUT/.symframe-cache`.
    pub cache: CacheConfig,
}

impl FitConfig {
    /// Every default: no held-out lights, the default [`FitParams`] (the automatic model,
    /// its exposure chosen from the data) and cache.
    pub fn new(
        input: impl Into<PathBuf>,
        frames: impl Into<PathBuf>,
        output: impl Into<PathBuf>,
    ) -> Self {
        Self {
            input: input.into(),
            frames: frames.into(),
            output: output.into(),
            holdout: 0,
            params: FitParams::default(),
            exposure: None,
            mask: None,
            decode: DecodeOptions::default(),
            cache: CacheConfig::default(),
        }
    }

    /// The cache folder and options in force: an estimate's own cache is read with the tile
    /// size and sample format its report records.
    pub fn cache_in_force(&self) -> (PathBuf, CacheOptions) {
        let estimate_cache = self.frames.join(CACHE_DIR);
        if self.cache.dir.is_none() && estimate_cache.is_dir() {
            let report = symframe_io::read_text_bounded(
                &self.frames.join("report.json"),
                "a report",
                symframe_io::limits::MAX_TEXT_FILE_BYTES,
            )
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
            let tile = report
                .as_ref()
                .and_then(|r| r.pointer("/tiles/size")?.as_u64());
            // The estimate's cache format, so that its cache is reused rather than rebuilt.
            let format = match report
                .as_ref()
                .and_then(|r| r.pointer("/cache/format")?.as_str())
            {
                Some("f16") => CacheFormat::F16,
                Some("f32") => CacheFormat::F32,
                _ => self.cache.options.format,
            };
            let options = CacheOptions {
                tile: tile.map_or(self.cache.options.tile, |t| t as usize),
                format,
                ..self.cache.options
            };
            return (estimate_cache, options);
        }
        (cache_dir(&self.cache, &self.output), self.cache.options)
    }
}

/// What `fit.json` records about a run.
#[derive(Debug, Clone, Serialize)]
pub struct FitReport {
    /// symframe version.
    pub version: &'static str,
    /// The input as given.
    pub input: PathBuf,
    /// The frames folder as given.
    pub frames: PathBuf,
    /// The capture's fingerprint (the same as in the frames' `report.json`).
    pub inputs: InputsRecord,
    /// The mask used, if any.
    pub mask: Option<PathBuf>,
    /// The reflectance model fitted: `ward`, `gltf`, `auto`, `clearcoat` or `woven` (also in
    /// `parameters.model`); the model of each pixel of an automatic or two-lobe fit is in
    /// `model.npy` and the counts in `fit.ward_pixels`, `fit.gltf_pixels`,
    /// `fit.clearcoat_pixels` and `fit.woven_pixels`.
    pub model: &'static str,
    /// The model in words, and its frame.
    pub model_description: &'static str,
    /// The light intensity the glTF fit assumed (`parameters.exposure`), which relighting and
    /// export use; `None` for a Ward fit.
    pub exposure: Option<f64>,
    /// Whether that exposure was chosen from the data (`true`) or given (`false`).
    pub exposure_chosen: Option<bool>,
    /// How a chosen exposure was chosen: the intensities tried and the validation error of
    /// each ([`symframe::ExposureChoice::select`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exposure_choice: Option<ExposureChoice>,
    /// Fit parameters, including the held-out light indices.
    pub parameters: FitParams,
    /// Light counts.
    pub lights: FitLights,
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// Pixel counts and error figures (RMS of the radiance over channels; PSNR in dB).
    pub fit: FitSummary,
    /// Tiles computed by this run and reused from an interrupted one.
    pub tiles: TileCounts,
    /// An automatic fit's first pass, which gathers each pixel's evidence for the choice of
    /// its model: its tiles computed and reused, as for `tiles`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evidence_tiles: Option<TileCounts>,
    /// The on-disk tile cache of the decoded images.
    pub cache: CacheReport,
    /// Wall-clock seconds per stage.
    pub timings: FitTimings,
    /// Every warning of the run, as printed (taking the output folder's lock, the inputs,
    /// recomputed tiles), as `report.json` of an estimate records them.
    pub warnings: Vec<String>,
}

/// Light counts of a fit.
#[derive(Debug, Clone, Serialize)]
pub struct FitLights {
    /// Lights in the input.
    pub input: usize,
    /// Lights the fit used.
    pub fitted: usize,
    /// Lights held out to judge the fit.
    pub held_out: usize,
}

/// Seconds per stage.
#[derive(Debug, Clone, Serialize)]
pub struct FitTimings {
    /// Decoding the images into the tile cache, or opening it.
    pub load_s: f64,
    /// Fitting.
    pub fit_s: f64,
    /// Writing the outputs.
    pub write_s: f64,
    /// Everything.
    pub total_s: f64,
}

/// What a fit job produced: the maps and the report written.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// The fitted maps.
    pub maps: FitMaps,
    /// The report.
    pub report: FitReport,
}

/// Reads an `H x W x 3` map of the frames folder and checks it against the images' size.
fn read_frame_map(path: &Path, width: usize, height: usize) -> Result<Vec<f32>> {
    let (shape, data) = symframe_io::read_npy_f32(path)?;
    if shape != [height, width, 3] {
        bail!(
            "{}: shape {shape:?} does not match the images ({height} x {width} x 3 expected)",
            path.display()
        );
    }
    Ok(data)
}

/// Refuses frames estimated from another capture: the inputs fingerprint recorded in
/// `FRAMES/report.json` must be this capture's (`ours`, recomputed in the recorded way when
/// that differs). A report without one (older, or not from `estimate`) is a warning.
fn check_frames_inputs(
    config: &FitConfig,
    ds: &Dataset,
    ours: &Fingerprints,
    ctl: &Control,
) -> Result<()> {
    let rp = config.frames.join("report.json");
    let text = match symframe_io::read_text_bounded(
        &rp,
        "a report",
        symframe_io::limits::MAX_TEXT_FILE_BYTES,
    ) {
        Ok(t) => t,
        Err(symframe_io::Error::Read { source, .. })
            if source.kind() == std::io::ErrorKind::NotFound =>
        {
            ctl.warn(&format!(
                "{}: missing; the frames cannot be checked against {}",
                rp.display(),
                config.input.display()
            ));
            return Ok(());
        }
        Err(e) => return Err(e.into()),
    };
    let report: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", rp.display()))?;
    let Some(recorded) = report
        .get("inputs")
        .and_then(|v| serde_json::from_value::<InputsRecord>(v.clone()).ok())
    else {
        ctl.warn(&format!(
            "{}: records no input fingerprint (written by an older symframe?); the frames \
             cannot be checked against {}",
            rp.display(),
            config.input.display()
        ));
        return Ok(());
    };
    let here = if recorded.images_by == ours.kind {
        InputsRecord::of(ours)
    } else {
        let trust_mtime = recorded.images_by == StampKind::SizeAndMtime;
        // The inputs fingerprint does not depend on the cache format; any will do.
        InputsRecord::of(&symframe_io::dataset_fingerprints(
            ds,
            &config.decode,
            trust_mtime,
            CacheFormat::default(),
        )?)
    };
    if here.fingerprint != recorded.fingerprint {
        bail!(
            "{}: frames estimated from another capture than {} (input fingerprint {} in its \
             report.json, {} here); give the output folder of an estimate of this capture",
            config.frames.display(),
            config.input.display(),
            recorded.fingerprint,
            here.fingerprint
        );
    }
    Ok(())
}

/// Runs a fit job. The output folder is locked for the whole job; on an error the finished
/// tiles and the cache are kept (the same call resumes), and only what this job created and
/// holds nothing to resume from is removed again.
pub fn fit(config: &FitConfig, ctl: &Control) -> Result<FitOutcome> {
    for name in ["normals.npy", "tangents.npy"] {
        let p = config.frames.join(name);
        if !p.is_file() {
            bail!(
                "{}: missing (the frames folder must be an output folder of symframe estimate)",
                p.display()
            );
        }
    }
    in_locked_output(&config.output, ctl, |ctl, out, warnings| {
        run(config, ctl, out, warnings)
    })
}

fn run(
    config: &FitConfig,
    ctl: &Control,
    out: &OutputDir,
    warnings: &Mutex<Vec<String>>,
) -> Result<FitOutcome> {
    let t0 = Instant::now();
    let mut ds: Dataset = symframe_io::open_dataset(&config.input)?;
    for w in &ds.warnings {
        ctl.warn(&w.to_string());
    }
    // The mask in force is checked with the cache, before the images are decoded.
    ds.mask = config.mask.clone().or(ds.mask);
    let frames = ["normals.npy", "tangents.npy", "report.json"].map(|n| config.frames.join(n));
    out.guard_inputs(
        crate::estimate::dataset_files(&ds).chain(frames.iter().map(PathBuf::as_path)),
        "fit.json",
        &fit_writes,
        // The page of the old maps goes (`fit_owned`); nothing is written in its place.
        &|n| n == "viewer.html",
    )?;
    let params = FitParams {
        holdout: FitParams::holdout_lights(ds.lights.len(), config.holdout)
            .with_context(|| format!("holding out {} lights", config.holdout))?,
        ..config.params.clone()
    };
    let mut params = params;
    let (cache_dir, options) = config.cache_in_force();
    let (cache, cache_info, fps) =
        open_cache(&ds, &config.decode, &cache_dir, options, ctl, &|f| {
            check_frames_inputs(config, &ds, f, ctl)
        })?;
    let load_s = t0.elapsed().as_secs_f64();
    let grid = *cache.grid();
    let (w, h) = (grid.width, grid.height);
    let normals = read_frame_map(&config.frames.join("normals.npy"), w, h)?;
    let tangents = read_frame_map(&config.frames.join("tangents.npy"), w, h)?;
    let (mask_path, mask) = read_mask(&config.mask, &ds, &grid)?;
    symframe::Stack::check_inputs(w, h, cache.n_lights(), ds.lights.len(), mask.as_deref())
        .with_context(|| ds.source.display().to_string())?;
    let mut exposure_chosen = false;
    let mut exposure_choice = None;
    if params.model.uses_gltf() {
        params.exposure = match config.exposure {
            Some(e) => e,
            None => {
                exposure_chosen = true;
                let choice = choose_exposure(
                    &cache,
                    &ds.lights,
                    &params,
                    &normals,
                    &tangents,
                    mask.as_deref(),
                )
                .with_context(|| ds.source.display().to_string())?;
                let e = choice.exposure;
                exposure_choice = Some(choice);
                e
            }
        };
    }
    let method = FitMethod::new(&ds.lights, &params, &normals, &tangents, w * h)
        .with_context(|| ds.source.display().to_string())?;

    let mut f = Fingerprint::new();
    f.str("symframe fit")
        .str(env!("CARGO_PKG_VERSION"))
        .u64(FIT_TILE_VERSION as u64)
        .u64(cache.fingerprint())
        .u64(w as u64)
        .u64(h as u64)
        .u64(grid.tile as u64)
        .str(&serde_json::to_string(&params)?);
    fingerprint_lights(&mut f, &ds.lights);
    for v in normals.iter().chain(&tangents) {
        f.u64(v.to_bits() as u64);
    }
    fingerprint_mask(&mut f, mask.as_deref());
    let job = f.finish();

    let t_fit = Instant::now();
    let tiles_dir = config.output.join(TILES_DIR);
    let all: Vec<usize> = (0..grid.n_tiles()).collect();
    // An automatic fit chooses each pixel's model from its neighbourhood's evidence first: a
    // pass of its own, in tiles of its own (resumable like the fit's).
    let evidence_dir = config.output.join(EVIDENCE_DIR);
    let mut evidence_tiles = None;
    let choices = match method.evidence_pass() {
        Some(pass) => {
            let job = Fingerprint::new().u64(job).str("evidence").finish();
            let dir = &evidence_dir;
            evidence_tiles = Some(run_tiles(
                &cache,
                &pass,
                mask.as_deref(),
                job,
                &all,
                dir,
                ctl,
            )?);
            let mut evidence = vec![None; w * h];
            read_tiles(
                &grid,
                job,
                |t| tile_path(&evidence_dir, t),
                |p, r| evidence[p] = r,
            )?;
            Some(params.choose_models(&evidence, w, h)?)
        }
        None => None,
    };
    let method = match &choices {
        Some(c) => method.with_choices(c)?,
        None => method,
    };
    let counts = run_tiles(&cache, &method, mask.as_deref(), job, &all, &tiles_dir, ctl)?;
    let cache_path = cache.path().to_path_buf();
    drop(cache);
    let mut outcomes: Vec<Option<PixelOutcome>> = vec![None; w * h];
    read_tiles(
        &grid,
        job,
        |t| tile_path(&tiles_dir, t),
        |p, r: Option<PixelOutcome>| outcomes[p] = r,
    )?;
    let maps = FitMaps::from_outcomes(w, h, &normals, &tangents, &params, outcomes);
    let fit_s = t_fit.elapsed().as_secs_f64();

    let mut report = FitReport {
        version: env!("CARGO_PKG_VERSION"),
        input: config.input.clone(),
        frames: config.frames.clone(),
        inputs: InputsRecord::of(&fps),
        mask: mask_path,
        model: params.model.name(),
        model_description: params.model.description(),
        exposure: params.model.uses_gltf().then_some(params.exposure),
        exposure_chosen: params.model.uses_gltf().then_some(exposure_chosen),
        exposure_choice,
        lights: FitLights {
            input: ds.lights.len(),
            fitted: ds.lights.len() - params.holdout.len(),
            held_out: params.holdout.len(),
        },
        parameters: params,
        width: w,
        height: h,
        fit: maps.summary,
        tiles: counts,
        evidence_tiles,
        cache: CacheReport {
            info: cache_info,
            kept: !config.cache.remove_after,
        },
        timings: FitTimings {
            load_s,
            fit_s,
            write_s: 0.0,
            total_s: 0.0,
        },
        warnings: Vec::new(),
    };
    report.warnings = lock_warnings(warnings).clone();
    write_outputs(out, &maps, &mut report, t0, ctl)?;
    crate::tiles::remove_tile_folder(&tiles_dir)?;
    crate::tiles::remove_tile_folder(&evidence_dir)?;
    if config.cache.remove_after {
        remove_cache(&cache_path, &cache_dir)?;
    }
    Ok(FitOutcome { maps, report })
}

/// The parameter maps of each model (without extension; `.npy` and `.exr` are written).
const WARD_MAPS: [&str; 4] = ["kd", "ks", "alpha_t", "alpha_b"];
const GLTF_MAPS: [&str; 4] = ["base_color", "metallic", "roughness", "anisotropy_strength"];
use crate::relight::LOBE_MAPS;

/// Pixels the exposure of a glTF fit is chosen from, at most.
pub(crate) const EXPOSURE_PIXELS: usize = 2048;

/// The light intensity of a glTF fit chosen from up to [`EXPOSURE_PIXELS`] pixels (inside the
/// mask, with a frame) spread evenly over the image, read tile by tile from the cache
/// ([`symframe::ExposureChoice::select`]).
fn choose_exposure(
    cache: &symframe_io::TileCache,
    lights: &[glam::DVec3],
    params: &FitParams,
    normals: &[f32],
    tangents: &[f32],
    mask: Option<&[bool]>,
) -> Result<ExposureChoice> {
    use rayon::prelude::*;
    use symframe::{EstimateMaps, PixelData, PixelFitter};
    let grid = *cache.grid();
    let usable = |p: usize| mask.is_none_or(|m| m[p]) && EstimateMaps::vec_at(normals, p).is_some();
    let count = (0..grid.width * grid.height).filter(|&p| usable(p)).count();
    let stride = count.div_ceil(EXPOSURE_PIXELS).max(1);
    // The k-th usable pixel (row-major) is chosen when k is a multiple of the stride.
    let mut chosen = vec![false; grid.width * grid.height];
    for (k, p) in (0..chosen.len()).filter(|&p| usable(p)).enumerate() {
        chosen[p] = k % stride == 0;
    }
    // The held-out lights stay out of this choice too.
    PixelFitter::new(lights, params)?;
    let pixels: Vec<PixelData> = (0..grid.n_tiles())
        .into_par_iter()
        .flat_map_iter(|t| {
            let mut scratch = Vec::new();
            let view = cache.tile(t, &mut scratch);
            let mut out = Vec::new();
            for (k, p) in grid.pixels(t).enumerate() {
                if !chosen[p] {
                    continue;
                }
                let (Some(normal), tangent) = (
                    EstimateMaps::vec_at(normals, p),
                    EstimateMaps::vec_at(tangents, p),
                ) else {
                    continue;
                };
                let mut rgb = vec![0.0f32; lights.len() * 3];
                view.pixel(k, &mut rgb);
                out.push(PixelData {
                    normal,
                    tangent,
                    rgb,
                });
            }
            cache.release(t);
            out
        })
        .collect();
    ExposureChoice::select(lights, params, &pixels).with_context(|| {
        "no pixel to choose the exposure of the glTF fit from; give it with --exposure"
    })
}

/// Files an earlier fit into the same folder may have left that this one may not write: the
/// held-out residual maps of a fit with held-out lights, the other model's parameter maps and
/// pictures, and the viewer page of the old maps (`symframe view`'s default file), which would
/// no longer show this fit.
fn fit_owned(name: &str) -> bool {
    let stem = name.split('.').next().unwrap_or(name);
    name.starts_with("holdout_residual.")
        || name == "viewer.html"
        || WARD_MAPS.contains(&stem)
        || GLTF_MAPS.contains(&stem)
        || LOBE_MAPS.contains(&stem)
        || stem == "model"
}

/// Whether a fit writes (or removes) the file `name` of its output folder.
fn fit_writes(name: &str) -> bool {
    let stem = name.split('.').next().unwrap_or(name);
    fit_owned(name) || name == "fit.json" || ["normals", "tangents", "residual"].contains(&stem)
}

/// Writes every output file as one output set (staged, then switched in, `fit.json` last).
fn write_outputs(
    out: &OutputDir,
    maps: &FitMaps,
    report: &mut FitReport,
    t0: Instant,
    ctl: &Control,
) -> Result<()> {
    let t_write = Instant::now();
    let m = &maps.ward;
    let (w, h) = (m.width, m.height);
    let staging = OutputSet::new(out, fit_owned)?;
    // The model's (name, data) maps: per pixel three values, then one.
    type Named<'a> = Vec<(&'a str, &'a [f32])>;
    let ward: (Named, Named) = (
        vec![("kd", &m.kd), ("ks", &m.ks)],
        vec![("alpha_t", &m.alpha_t), ("alpha_b", &m.alpha_b)],
    );
    // An automatic fit writes each model's maps that it chose somewhere (NaN where another
    // model was chosen); a two-lobe fit only the two-lobe maps.
    let lobes_only = matches!(
        report.parameters.model,
        FitModel::Clearcoat | FitModel::Woven
    );
    let (mut maps3, mut maps1): (Named, Named) = match &maps.gltf {
        None if lobes_only => (Vec::new(), Vec::new()),
        None => ward,
        Some(g) => {
            let mut maps3: Named = vec![("base_color", &g.base_color)];
            let mut maps1: Named = vec![
                ("metallic", &g.metallic),
                ("roughness", &g.roughness),
                ("anisotropy_strength", &g.anisotropy),
            ];
            if maps.summary.ward_pixels > 0 {
                maps3.extend(ward.0);
                maps1.extend(ward.1);
            }
            (maps3, maps1)
        }
    };
    let s = &maps.summary;
    if let Some(l) = maps
        .lobes
        .as_ref()
        .filter(|_| lobes_only || s.clearcoat_pixels + s.woven_pixels > 0)
    {
        maps3.extend([
            (LOBE_MAPS[0], &l.kd[..]),
            (LOBE_MAPS[1], &l.ka),
            (LOBE_MAPS[2], &l.kb),
        ]);
        maps1.extend([
            (LOBE_MAPS[3], &l.alpha_t[..]),
            (LOBE_MAPS[4], &l.alpha_b),
            (LOBE_MAPS[5], &l.alpha_c),
        ]);
    }
    let frames: [(&str, &[f32]); 2] = [("normals", &m.normals), ("tangents", &m.tangents)];
    for (name, data) in maps3.iter().chain(&frames) {
        symframe_io::write_npy_f32(&staging.path(&format!("{name}.npy")), &[h, w, 3], data)?;
        symframe_io::write_exr_map(&staging.path(&format!("{name}.exr")), w, h, 3, data)?;
    }
    let residuals: [(&str, &[f32]); 2] = [
        ("residual", &maps.residual),
        ("holdout_residual", &maps.holdout_residual),
    ];
    for (name, data) in maps1.iter().chain(&residuals) {
        if *name == "holdout_residual" && report.parameters.holdout.is_empty() {
            continue;
        }
        symframe_io::write_npy_f32(&staging.path(&format!("{name}.npy")), &[h, w], data)?;
        symframe_io::write_exr_map(&staging.path(&format!("{name}.exr")), w, h, 1, data)?;
    }
    if report.parameters.model.uses_lobes() {
        // The model per pixel: 0 none, 1 Ward, 2 glTF, 3 clear coat, 4 woven; the picture
        // black, blue, orange, green, magenta.
        let codes: Vec<f32> = maps.model.iter().map(|&c| c as f32).collect();
        symframe_io::write_npy_f32(&staging.path("model.npy"), &[h, w], &codes)?;
        let colours: Vec<f32> = maps
            .model
            .iter()
            .flat_map(|&c| match c {
                FitMaps::MODEL_WARD => [0.2, 0.45, 1.0],
                FitMaps::MODEL_GLTF => [1.0, 0.55, 0.1],
                FitMaps::MODEL_CLEARCOAT => [0.2, 0.8, 0.3],
                FitMaps::MODEL_WOVEN => [0.85, 0.25, 0.8],
                _ => [0.0; 3],
            })
            .collect();
        symframe_io::write_png8_rgb(&staging.path("model.png"), w, h, &colours, false)?;
    }
    // Albedo pictures: clamped and sRGB-encoded, black where nothing was fitted.
    for (name, data) in &maps3 {
        symframe_io::write_png8_rgb(&staging.path(&format!("{name}.png")), w, h, data, true)?;
    }
    report.timings.write_s = t_write.elapsed().as_secs_f64();
    report.timings.total_s = t0.elapsed().as_secs_f64();
    let json = serde_json::to_value(&*report)?;
    staging.commit("fit.json", json, &|n| {
        (ctl.checkpoint)(Checkpoint::Moved(n))
    })
}
