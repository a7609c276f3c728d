//! The symframe pipeline as a library: what `symframe estimate`, `merge`, `fit`, `relight` and
//! `view` do, callable from any program.
//!
//! A job decodes the images of a capture once into an on-disk tile cache
//! ([`symframe_io::TileCache`]), runs a per-pixel method ([`symframe::PixelMethod`]: the
//! symmetry estimator, a baseline or the Ward fitter) tile by tile into result files (so memory
//! stays bounded, an interrupted run resumes, and a shard does a share of the tiles), then
//! writes the maps from the tiles a row of tiles at a time, with a JSON report, all at once
//! into the output folder. The caller owns interruption (a stop flag, polled between images and tiles)
//! and progress display (a callback).
//!
//! - [`estimate`] with an [`EstimateConfig`]: normals, tangents, confidence, anisotropy and the
//!   source map of a capture, or one shard's tiles; [`merge`] joins shards.
//! - [`fit`] with a [`FitConfig`]: per-pixel anisotropic Ward parameters in estimated frames.
//! - [`relight`] with a [`RelightConfig`]: the fitted maps rendered under new lights, edited.
//! - [`write_viewer`] with a [`ViewConfig`]: one self-contained HTML page relighting a fit (or
//!   showing an estimate) in the browser (WebGL2), with the same model and edits as
//!   [`relight`]; large maps as a tile pyramid beside it.
//! - [`calibrate()`] with a [`CalibrateConfig`]: light directions from a mirror sphere;
//!   [`calibrate_near()`] with a [`NearCalibrateConfig`]: light positions from two or more
//!   chrome spheres and a pinhole camera.
//! - [`integrate_job`] with an [`IntegrateConfig`]: an estimate's normals to a height map and a
//!   mesh.
//! - [`export_gltf`] with an [`ExportConfig`]: a fit or estimate as a glTF 2.0 asset.
//! - [`synth()`] with a [`SynthConfig`]: a rendered capture with ground truth;
//!   [`evaluate_job`] with an [`EvalConfig`]: an estimate against that truth.
//!
//! ```
//! use symframe::brdf::Ward;
//! use symframe::render::{Scene, TangentField};
//! use symframe::uniform_cone_lights;
//! use symframe_job::{estimate, Control, EstimateConfig, EstimateOutcome};
//!
//! # fn main() -> anyhow::Result<()> {
//! // A small synthetic capture: a brushed-metal sphere under 200 lights, written as an .lp
//! // dataset into a temporary folder.
//! let dir = tempfile::tempdir()?;
//! let scene = Scene::sphere(12, TangentField::Circular);
//! let lights = uniform_cone_lights(200, 65.0);
//! let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
//! let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
//! let lp = symframe_io::write_lp_dataset(
//!     &dir.path().join("capture"), &lights, &images, 12, 12,
//!     symframe_io::ImageFormat::Exr, None, None, Some(&scene.mask),
//! )?;
//!
//! // Estimate: the maps come back and are written to `out` with report.json.
//! let out = dir.path().join("out");
//! let config = EstimateConfig::new(&lp, &out);
//! let EstimateOutcome::Maps(done) = estimate(&config, &Control::default())? else {
//!     unreachable!("no shard was asked for");
//! };
//! assert!(done.report.pixels.estimated > 50);
//! assert!(done.maps.is_some(), "kept by default");
//! assert!(out.join("normals.npy").is_file() && out.join("source.npy").is_file());
//! # Ok(())
//! # }
//! ```

#![deny(unreachable_pub)]

pub mod calibrate;
pub mod calibrate_near;
pub mod colorbar;
mod estimate;
mod estimate_near;
pub mod eval;
pub mod export;
mod fit;
pub mod integrate;
mod maps_out;
mod merge;
mod outdir;
pub mod pictures;
mod relight;
pub mod synth;
pub mod synth_near;
mod tiles;
mod view;

use std::sync::atomic::AtomicBool;

pub use estimate::{
    estimate, BaselineParameters, CacheConfig, CacheReport, EstimateConfig, EstimateOutcome,
    FinishedEstimate, InputsRecord, LightCounts, MethodConfig, MethodParameters, Report, Shard,
    SymmetryParameters, TileReport, Timings, CACHE_DIR,
};
pub use fit::{fit, FitConfig, FitLights, FitOutcome, FitReport, FitTimings};
pub use maps_out::{SourceCount, Sources};
pub use merge::{merge, MergeOutcome, ShardManifest, MANIFEST};
pub use outdir::{check_output_set, OutputDir, OutputSet, Staging, LOCK_FILE};
pub use relight::{
    read_fit_maps, read_gltf_maps, read_ward_maps, relight, FittedMaps, RelightConfig,
    RelightOutcome,
};
pub use tiles::TILES_DIR;
pub use tiles::{peak_rss_bytes, shard_tiles, TileCounts};
pub use view::{
    write_viewer, PyramidOutcome, ViewConfig, ViewOutcome, DEFAULT_PYRAMID_ABOVE, DEFAULT_TILE_SIZE,
};
/// The parsers of files a hostile user can plant, for the fuzz targets (`fuzz/`).
#[cfg(any(test, feature = "fuzzing"))]
pub use {merge::check_shard_manifest, outdir::check_switch_plan};

pub use calibrate::{calibrate, CalibrateConfig, CalibrationReport};
pub use calibrate_near::{calibrate_near, NearCalibrateConfig, NearCalibrationReport};
pub use estimate_near::{LightModel, NearOptions, NearReport};
pub use eval::{evaluate_job, EvalConfig, EvalReport};
pub use export::{export_gltf, ExportConfig, ExportOutcome};
pub use integrate::{
    integrate_job, recorded_camera, CameraReport, IntegrateConfig, IntegrateReport,
};
pub use synth::{synth, RigSpec, SynthConfig, SynthOutcome, SynthShape};
pub use synth_near::{synth_near, NearSynthConfig};

/// The run stopped early on request; what was done (cache images, finished tiles) is kept,
/// and the same call again resumes.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted; run the same command again to resume")
    }
}

impl std::error::Error for Interrupted {}

/// A job error and its causes on one line, outermost first (each error's message leaves its
/// cause to the chain), a codec's multi-line message folded onto it: how the command line and
/// the Python package report an error.
pub fn one_line(e: &anyhow::Error) -> String {
    let parts: Vec<String> = e.chain().map(|c| c.to_string()).collect();
    parts
        .join(": ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// A stage of a job, as reported to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Decoding images into the tile cache (steps: images).
    Decoding,
    /// Running the per-pixel method (steps: tiles, counting those reused).
    Tiles,
    /// Reading the shards' tiles (steps: tiles).
    Merging,
    /// Rendering a synthetic capture (steps: images).
    Rendering,
}

impl Stage {
    /// A short name for display.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Decoding => "decoding",
            Stage::Tiles => "tiles",
            Stage::Merging => "merging",
            Stage::Rendering => "rendering",
        }
    }
}

/// Where a stage stands: `done` of `total` steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// The stage.
    pub stage: Stage,
    /// Steps finished (calls may arrive from several threads, not in order).
    pub done: u64,
    /// Steps of the stage.
    pub total: u64,
}

impl Progress {
    fn new(stage: Stage, done: u64, total: u64) -> Self {
        Self { stage, done, total }
    }
}

/// How the caller steers a job: a stop flag and a progress callback.
pub struct Control<'a> {
    /// Once set (e.g. by a Ctrl-C handler), no new image or tile is started; the job returns
    /// [`Interrupted`] and the same call later resumes.
    pub stop: &'a AtomicBool,
    /// Called as images are decoded and tiles finished (from worker threads).
    pub progress: &'a (dyn Fn(Progress) + Sync),
    /// Testing aid: behave as if stopped once this many tiles are finished.
    pub stop_after_tiles: Option<usize>,
    /// Called with one line for each thing the user should know that does not stop the job
    /// (mixed inputs, a corrupt tile result being recomputed).
    pub warning: &'a (dyn Fn(&str) + Sync),
    /// Testing aid: called at points where a killed or slow job must leave the output folder
    /// consistent (after the output lock is taken, after each file of the new output set is
    /// moved into place).
    pub checkpoint: &'a (dyn Fn(Checkpoint) + Sync),
}

/// A point of a job that [`Control::checkpoint`] is told about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Checkpoint {
    /// The output folder's lock is held (the job proper starts).
    OutputLocked,
    /// The n-th file (from 1) of the new output set is in place.
    Moved(usize),
}

/// A flag that nothing sets.
static NEVER: AtomicBool = AtomicBool::new(false);

impl Default for Control<'_> {
    /// Never stopped, no progress display.
    fn default() -> Self {
        Self {
            stop: &NEVER,
            progress: &|_| {},
            stop_after_tiles: None,
            warning: &|_| {},
            checkpoint: &|_| {},
        }
    }
}

impl Control<'_> {
    fn report(&self, p: Progress) {
        (self.progress)(p)
    }

    fn warn(&self, line: &str) {
        (self.warning)(line)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chain_is_joined_on_one_line() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such\nfile");
        let e = anyhow::Error::new(io).context("a.exr: cannot read");
        assert_eq!(one_line(&e), "a.exr: cannot read: no such file");
    }
}
