//! What an estimation job records (`report.json`) and returns.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use symframe::{BaselineParams, EstimateMaps, EstimatorParams, PixelCounts};
use symframe_io::{CacheInfo, Fingerprints, Gamma, StampKind};

use super::{NearReport, Sources};

/// What `report.json` records about a run.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// symframe version.
    pub version: &'static str,
    /// The input as given.
    pub input: PathBuf,
    /// The capture's fingerprint, which `fit` checks its own input against.
    pub inputs: InputsRecord,
    /// The mask used, if any.
    pub mask: Option<PathBuf>,
    /// The estimation method: `symmetry`, `woodham`, `woodham-robust` or `max-reflectance`.
    pub method: &'static str,
    /// Parameters in force (the method's own).
    pub parameters: MethodParameters,
    /// Light counts.
    pub lights: LightCounts,
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// What happened to the pixels.
    pub pixels: PixelCounts,
    /// Which measure each pixel's normal comes from (`source.npy`): the legend and counts.
    pub sources: Sources,
    /// Mean symmetry-objective evaluations per estimated pixel.
    pub evals_per_pixel: f64,
    /// How the image was split into tiles and what this run did with them.
    pub tiles: TileReport,
    /// The on-disk tile cache of the decoded images.
    pub cache: CacheReport,
    /// Wall-clock seconds per stage, and peak memory.
    pub timings: Timings,
    /// Every warning of the run, as printed (inputs, recomputed tiles, suspicious results).
    pub warnings: Vec<String>,
    /// The camera and light model of a near-light run (absent for distant lights).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub near: Option<NearReport>,
}

/// The capture a job read, as its report records it: the path-free inputs fingerprint (see
/// [`Fingerprints::inputs`]), so that a later job on the maps can tell whether it reads the
/// same capture (a copy of it included).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputsRecord {
    /// The fingerprint (hex).
    pub fingerprint: String,
    /// How the images entered it: by `content` or by `size_and_mtime` (`--trust-mtime`).
    pub images_by: StampKind,
}

impl InputsRecord {
    /// The record of `f`.
    pub fn of(f: &Fingerprints) -> Self {
        Self {
            fingerprint: format!("{:016x}", f.inputs),
            images_by: f.kind,
        }
    }
}

/// Tiles as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct TileReport {
    /// Tile side in pixels.
    pub size: usize,
    /// Tiles of the whole image.
    pub count: usize,
    /// `K/N` for a shard, else absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
    /// Tiles this run was asked for (all, or the shard's).
    pub this_run: usize,
    /// Tiles estimated by this run.
    pub computed: usize,
    /// Tiles found finished by an interrupted earlier run of the same job and reused.
    pub reused: usize,
}

/// The tile cache as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct CacheReport {
    /// Where it is, its size, whether it was reused (`hit`), what was decoded.
    #[serde(flatten)]
    pub info: CacheInfo,
    /// Whether it is kept after the run.
    pub kept: bool,
}

/// The parameters of whichever method ran, as recorded in the report.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum MethodParameters {
    /// The symmetry method's.
    Symmetry(SymmetryParameters),
    /// A baseline's.
    Baseline(BaselineParameters),
}

/// Baseline parameters as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineParameters {
    /// Shadow threshold, outlier rule.
    #[serde(flatten)]
    pub baseline: BaselineParams,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// The transfer curve of integer inputs (`auto`: 8-bit sRGB, 16-bit linear).
    pub gamma: Gamma,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
    /// The EXR layer read (absent: the default layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exr_layer: Option<String>,
}

/// Symmetry-method parameters as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct SymmetryParameters {
    /// Light cone half-angle in halfway space, degrees.
    pub theta_d_max_deg: f64,
    /// Estimator parameters.
    #[serde(flatten)]
    pub estimator: EstimatorParams,
    /// The domain threshold actually used.
    pub min_domain_used: u32,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// The transfer curve of integer inputs (`auto`: 8-bit sRGB, 16-bit linear).
    pub gamma: Gamma,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
    /// The EXR layer read (absent: the default layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exr_layer: Option<String>,
}

/// Light counts.
#[derive(Debug, Clone, Serialize)]
pub struct LightCounts {
    /// Lights in the input.
    pub input: usize,
    /// Lights used: inside the cone for the symmetry method, all of them for a baseline.
    pub used: usize,
    /// Lights outside the cone, dropped (0 for a baseline).
    pub dropped: usize,
}

/// Seconds per stage.
#[derive(Debug, Clone, Serialize)]
pub struct Timings {
    /// Decoding the images into the tile cache, or opening it.
    pub load_s: f64,
    /// Building the rig (0 for a baseline: it has none).
    pub rig_s: f64,
    /// Estimating.
    pub estimate_s: f64,
    /// Writing the outputs.
    pub write_s: f64,
    /// Everything.
    pub total_s: f64,
    /// Peak resident memory of the process in bytes (`VmHWM`; Linux only).
    pub peak_rss_bytes: Option<u64>,
    /// The same peak as it stood once the images were decoded (or the cache opened): which
    /// phase sets the whole run's.
    pub load_peak_rss_bytes: Option<u64>,
}

/// A finished job's maps and report.
#[derive(Debug, Clone)]
pub struct FinishedEstimate {
    /// The maps written, when [`crate::EstimateConfig::keep_maps`] asked for them (the report
    /// has the counts either way).
    pub maps: Option<EstimateMaps>,
    /// The report written.
    pub report: Report,
}

/// What an estimation job produced.
#[derive(Debug, Clone)]
pub enum EstimateOutcome {
    /// A full run: the maps and the report, written.
    Maps(Box<FinishedEstimate>),
    /// A shard: its tile results and manifest written, no maps; the shard's own report.
    Shard(Box<Report>),
}
