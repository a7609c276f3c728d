//! Flags of `symframe estimate` and `symframe merge`.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use symframe::{CosineMode, EstimatorParams, Fallback, RigOptions};
use symframe_console::flags::{default_decode_memory_mib, CacheFormatArg};
use symframe_io::CacheOptions;
use symframe_job::Shard;

use super::{CacheFlags, DecodeFlags, NormalPngArg};

/// `--light-model` of estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LightModelArg {
    /// Near lights where the dataset gives light_positions.txt and K.txt.
    Auto,
    /// The light file's directions.
    Distant,
    /// Point lights and a pinhole camera.
    Near,
}

/// Which estimator `symframe estimate` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// BRDF symmetry (Holroyd et al. 2008): normals and tangents, any material.
    Symmetry,
    /// Baseline: least-squares Lambertian photometric stereo over unshadowed samples (Woodham
    /// 1980). Normals only; uses every light.
    Woodham,
    /// Baseline: Woodham, refitted without samples more than 2 standard deviations from the mean
    /// residual (the paper's Figure 4). Normals only; uses every light.
    WoodhamRobust,
    /// Baseline: the halfway vector of the brightest sample, refined between samples
    /// (specular surfaces). Normals only; uses every light.
    MaxReflectance,
    /// Baseline: normal and tangent axis from the intensity-weighted mean and second moment of
    /// the halfway vectors of the brightest samples (glossy surfaces, dense rigs).
    HighlightCentroid,
}

/// The power of `--cosine compensated` when the default measure has none: 0.5, exact for
/// Ward's lobe.
fn default_cosine_power() -> f64 {
    match EstimatorParams::default().cosine {
        CosineMode::Compensated(p) | CosineMode::Power(p) => p,
        CosineMode::CrossMultiplied | CosineMode::Raw | CosineMode::Auto => 0.5,
    }
}

/// Cosine handling in the symmetry distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CosineArg {
    /// Per pixel (default): the paper's form where a Lambertian term explains nearly all of the
    /// signal, the diffuse-compensated form at p = 0 (exact for microfacet lobes) elsewhere.
    Auto,
    /// The paper's cross-multiplied cosines (exact for diffuse).
    Cross,
    /// Raw radiances (exact for microfacet lobes, wrong for diffuse).
    Raw,
    /// Diffuse-compensated power form (see --cosine-power): exact for diffuse plus a lobe
    /// whose radiance goes as (n.l)^p; refines the paper's solution.
    Compensated,
}

impl CosineArg {
    /// The flag value of a measure (the pure power form has no flag: shown as `cross`).
    fn of(mode: CosineMode) -> Self {
        match mode {
            CosineMode::Auto => CosineArg::Auto,
            CosineMode::CrossMultiplied | CosineMode::Power(_) => CosineArg::Cross,
            CosineMode::Raw => CosineArg::Raw,
            CosineMode::Compensated(_) => CosineArg::Compensated,
        }
    }

    /// The measure this flag value asks for, with the power of `--cosine-power`.
    pub fn mode(self, power: f64) -> CosineMode {
        match self {
            CosineArg::Auto => CosineMode::Auto,
            CosineArg::Cross => CosineMode::CrossMultiplied,
            CosineArg::Raw => CosineMode::Raw,
            CosineArg::Compensated => CosineMode::Compensated(power),
        }
    }
}

/// What to do beyond the rig's reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FallbackArg {
    /// The lobe fit, a robust Lambertian fit or the highlight centroid, flagged in the source
    /// map.
    Auto,
    /// No estimate.
    None,
}

impl FallbackArg {
    /// The flag value of a fallback rule.
    fn of(f: Fallback) -> Self {
        match f {
            Fallback::Auto => FallbackArg::Auto,
            Fallback::None => FallbackArg::None,
        }
    }

    /// The rule this flag value asks for.
    pub fn rule(self) -> Fallback {
        match self {
            FallbackArg::Auto => Fallback::Auto,
            FallbackArg::None => Fallback::None,
        }
    }
}

/// Flags of `symframe estimate`.
#[derive(Debug, Clone, Args)]
pub struct EstimateArgs {
    /// A `.lp` light file, a folder holding one, or a DiLiGenT-style folder.
    pub input: PathBuf,
    /// Output folder (created; files in it with the same names are replaced).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Estimation method: the symmetry method, or a baseline to compare it with (baselines
    /// estimate normals only, use every light given, and ignore the symmetry-only flags:
    /// --theta-d-max, --min-confidence, --min-anisotropy, --min-domain, --cosine,
    /// --cosine-power, --no-tangents).
    #[arg(long, value_enum, default_value_t = MethodArg::Symmetry)]
    pub method: MethodArg,
    /// Light model: `near` (point lights and a pinhole camera, from light_positions.txt and
    /// K.txt beside the dataset; normals estimated in rounds with a depth map, written as
    /// depth.npy), `distant` (the light file's directions, whatever else is there) or `auto`
    /// (near where the positions and K.txt are there).
    #[arg(long, value_enum, default_value_t = LightModelArg::Auto)]
    pub light_model: LightModelArg,
    /// Near lights: the object's distance from the camera, the depth of its centre along the
    /// optical axis in the light positions' unit (default: that of the centre of the sphere
    /// through the lights, a dome's centre).
    #[arg(long, value_name = "D")]
    pub distance: Option<f64>,
    /// Near lights: side of the largest square of pixels that share one rig (tiles are halved
    /// where a pixel's light geometry strays too far from its rig's; 1: a rig per pixel).
    #[arg(long, default_value_t = symframe_job::NearOptions::default().tile)]
    pub rig_tile: usize,
    /// Near lights: estimation rounds at most (each but the last followed by a new depth map).
    #[arg(long, default_value_t = symframe_job::NearOptions::default().max_iterations)]
    pub rounds: usize,
    /// Mask image: only pixels where it is non-zero are estimated (default: mask.png beside
    /// the input, if any).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Light cone: lights whose halfway vector is more than this many degrees from the view are
    /// dropped.
    #[arg(long, default_value_t = RigOptions::default().theta_d_max_deg)]
    pub theta_d_max: f64,
    /// Pixels with confidence below this are culled (NaN in the maps).
    #[arg(long, default_value_t = EstimatorParams::default().min_confidence)]
    pub min_confidence: f32,
    /// Pixels with anisotropy below this get no tangent (NaN): the slice is isotropic.
    #[arg(long, default_value_t = EstimatorParams::default().min_anisotropy)]
    pub min_anisotropy: f32,
    /// The light directions' uncertainty: the RMS angle in degrees between each light's given
    /// and true direction, as its calibration reports it. The confidence counts what it moves
    /// the normals by, and the lobe fit's acceptance what it adds to the samples' noise
    /// (default 0: the lights are taken as exact).
    #[arg(long, default_value_t = 0.0)]
    pub light_error: f64,
    /// Smallest symmetry domain, in lights, that counts as non-empty (default: 1.5% of the
    /// lights used, at least 6).
    #[arg(long)]
    pub min_domain: Option<u32>,
    /// Cosine handling in the symmetry distance.
    #[arg(long, value_enum, default_value_t = CosineArg::of(EstimatorParams::default().cosine))]
    pub cosine: CosineArg,
    /// Where a normal is beyond the rig's reach: `auto` fills it from a robust Lambertian fit
    /// (diffuse pixels) or the highlight centroid, marked in the source map with a lowered
    /// confidence; `none` leaves it empty (NaN).
    #[arg(long, value_enum, default_value_t = FallbackArg::of(EstimatorParams::default().fallback))]
    pub fallback: FallbackArg,
    /// Cosine power p of `--cosine compensated` (0.5 is exact for Ward, 0 for Cook-Torrance-like
    /// lobes, 1 for Blinn-Phong).
    #[arg(long, default_value_t = default_cosine_power())]
    pub cosine_power: f64,
    /// How the images are decoded.
    #[command(flatten)]
    pub decode: DecodeFlags,
    /// Skip tangents (normals only; faster).
    #[arg(long)]
    pub no_tangents: bool,
    /// Use the reference path: triangle lookups with spherical barycentric weights in double
    /// precision at every query, every light visited (slower where the symmetry search answers,
    /// see docs/performance.md, "Per pixel"; for checking the default fast path, which does the
    /// same in single precision, on your own data).
    #[arg(long)]
    pub reference: bool,
    /// Where the tile cache goes and whether it stays.
    #[command(flatten)]
    pub cache: CacheFlags,
    /// Recognise unchanged images by path, size and modification time only, without reading
    /// them (default: by content, which reads every image once on a rerun; see the README).
    #[arg(long)]
    pub trust_mtime: bool,
    /// Estimate only the K-th of N disjoint sets of tiles (tiles t with t % N == K-1) into
    /// OUTPUT (tile results and shard.json); combine the shards with `symframe merge`.
    #[arg(long, value_name = "K/N")]
    pub tiles: Option<Shard>,
    /// Tile side in pixels (the unit of work, of resumption and of the cache layout).
    #[arg(long, default_value_t = CacheOptions::default().tile)]
    pub tile_size: usize,
    /// Memory for decoding images while the cache is built, in MiB: a batch of images is read
    /// in lockstep a band of tile rows at a time, as many as fit (each costs its reader and its
    /// band of decoded rows; at least one). A --tile-size above the default whose band of one
    /// image exceeds it is refused.
    #[arg(long, default_value_t = default_decode_memory_mib(), value_name = "MIB")]
    pub decode_memory: usize,
    /// Sample type of the tile cache: auto (u8 for 8-bit images, u16 for 16-bit ones, else
    /// f32), u8 or u16 (the images' own codes, 3 or 6 bytes per pixel per light, made linear
    /// when read: the same samples as f32), f32 (12 bytes; tiled results equal in-memory ones
    /// bit for bit) or f16 (6 bytes, 11 significant bits, HDR range kept by a power-of-two
    /// scale per block; see docs/performance.md for its effect).
    #[arg(long, value_enum, default_value_t = CacheFormatArg::Auto)]
    pub cache_format: CacheFormatArg,
    /// The y convention of normals.png (16-bit, `(n + 1) / 2` per channel): opengl (green =
    /// up: glTF, Blender) or directx (green = down: Unreal).
    #[arg(long, value_enum, default_value_t = NormalPngArg::Opengl)]
    pub normal_png: NormalPngArg,
    /// Testing aid: behave as if interrupted once this many tiles are finished.
    #[arg(long, hide = true)]
    pub stop_after_tiles: Option<usize>,
}

/// Flags of `symframe merge`.
#[derive(Debug, Clone, Args)]
pub struct MergeArgs {
    /// Output folders of `symframe estimate --tiles K/N`, one per shard.
    #[arg(required = true, num_args = 1..)]
    pub shards: Vec<PathBuf>,
    /// Output folder for the full maps.
    #[arg(short, long)]
    pub output: PathBuf,
}
