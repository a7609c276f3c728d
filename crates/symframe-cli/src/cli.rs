//! Command-line flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use symframe::{CosineMode, Edits, EstimatorParams, Fallback, FitParams, RigOptions};
use symframe_console::flags::{default_decode_memory_mib, CacheFormatArg};
use symframe_console::Globals;
use symframe_io::{CacheOptions, DecodeOptions};
use symframe_job::Shard;

/// Surface normals and tangents from photographs under many lights, by BRDF symmetry
/// (Holroyd et al. 2008).
#[derive(Debug, Parser)]
#[command(name = "symframe", version, about, long_about = None)]
pub struct Cli {
    /// `--threads` and `--quiet`.
    #[command(flatten)]
    pub globals: Globals,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Estimate normal and tangent maps from a capture (.lp file or DiLiGenT-style folder).
    Estimate(EstimateArgs),
    /// Combine the outputs of `estimate --tiles K/N` shards into the full maps.
    Merge(MergeArgs),
    /// Fit a BRDF per pixel in estimated frames: glTF metallic-roughness (the default) or
    /// anisotropic Ward (for relighting, editing and export).
    Fit(FitArgs),
    /// Render fitted maps (glTF or Ward) under new lights, optionally edited.
    Relight(RelightArgs),
    /// Write one self-contained HTML page that relights a fit (or an estimate) in the browser
    /// (WebGL2): drag the light, edit as `relight` does, switch to the maps, zoom and pan.
    View(ViewArgs),
    /// Render a built-in synthetic object, estimate its frames and report the error, then fit,
    /// relight and write the viewer page (no download).
    Demo(DemoArgs),
    /// Render a synthetic capture with known normals and tangents into an .lp dataset folder.
    Synth(SynthArgs),
    /// Compare an estimate with a synthetic dataset's ground truth: eval.json, error-map
    /// pictures with colour bars, and a summary table.
    Eval(EvalArgs),
    /// Light directions from a mirror (chrome) sphere in the images: writes an .lp file, a
    /// picture of the detected highlights and a JSON record beside it.
    Calibrate(CalibrateArgs),
    /// Integrate an estimate's normal map into a height map and a mesh (depth.npy, depth.exr,
    /// depth.png, mesh.ply).
    Integrate(IntegrateArgs),
    /// Export a fit's (or an estimate's) maps as an asset for renderers: `export gltf DIR -o
    /// FILE.gltf|.glb`.
    Export(ExportArgs),
}

/// Values of `--gamma`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GammaArg {
    /// sRGB-decode 8- and 16-bit samples.
    Srgb,
    /// Take 8- and 16-bit samples as linear.
    Linear,
}

/// The decoding flags of `estimate`, `fit` and `calibrate`.
#[derive(Debug, Clone, Args)]
pub struct DecodeFlags {
    /// Transfer curve of 8- and 16-bit PNG, TIFF and JPEG images: `srgb` (e.g. 16-bit files
    /// from raw converters) or `linear` (default: 8-bit sRGB, 16-bit linear; float is linear).
    #[arg(long, value_enum, conflicts_with = "linear")]
    pub gamma: Option<GammaArg>,
    /// Same as `--gamma linear`.
    #[arg(long)]
    pub linear: bool,
    /// The EXR layer holding the radiance: `beauty` for channels `beauty.R`, `beauty.G`,
    /// `beauty.B` (default: the channels without a layer name, R, G, B or Y).
    #[arg(long, value_name = "NAME")]
    pub exr_layer: Option<String>,
    /// Integer samples at or above this fraction of the format's maximum are saturated and
    /// excluded.
    #[arg(long, default_value_t = DecodeOptions::default().saturation)]
    pub saturation: f32,
}

impl DecodeFlags {
    /// The decoding options the flags ask for, `--saturation` checked.
    pub fn options(&self) -> anyhow::Result<DecodeOptions> {
        if !(self.saturation > 0.0 && self.saturation <= 1.0) {
            anyhow::bail!("--saturation must be in (0, 1], got {}", self.saturation);
        }
        let gamma = match (self.gamma, self.linear) {
            (Some(GammaArg::Linear), _) | (None, true) => symframe_io::Gamma::Linear,
            (Some(GammaArg::Srgb), _) => symframe_io::Gamma::Srgb,
            (None, false) => symframe_io::Gamma::Auto,
        };
        Ok(DecodeOptions {
            gamma,
            saturation: self.saturation,
            exr_layer: self.exr_layer.clone(),
        })
    }
}

/// The tile-cache flags of `estimate` and `fit`.
#[derive(Debug, Clone, Args)]
pub struct CacheFlags {
    /// Folder of the on-disk tile cache of the decoded images (default: OUTPUT/.symframe-cache;
    /// for `fit`, the estimate's FRAMES/.symframe-cache when it exists, so nothing is decoded
    /// again). A cache of the same images is reused; several runs (shards) may share one folder.
    #[arg(long = "cache", value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Delete the tile cache once the job has finished (default: keep it, so a rerun with other
    /// parameters does not decode the images again).
    #[arg(long)]
    pub no_keep_cache: bool,
}

impl CacheFlags {
    /// The tile cache the flags ask for, laid out by `options`.
    pub fn config(&self, options: CacheOptions) -> symframe_job::CacheConfig {
        symframe_job::CacheConfig {
            dir: self.dir.clone(),
            remove_after: self.no_keep_cache,
            options,
        }
    }
}

/// Values of `symframe fit --model`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// Anisotropic Ward (the paper's model): kd, ks, alpha_t, alpha_b.
    Ward,
    /// glTF 2.0 metallic-roughness GGX with KHR_materials_anisotropy: base colour, metallic,
    /// roughness, anisotropy strength (direction = the tangent).
    Gltf,
    /// Per pixel, Ward, glTF, clear coat or woven, whichever predicts the pixel's validation
    /// lights (one training light in five, set aside) best; the choice is written to model.npy
    /// and model.png.
    Auto,
    /// A sharp isotropic clear coat over an anisotropic GGX base (car paint, lacquered
    /// brushed metal): lobes_kd, lobes_ka (base), lobes_kb (coat), lobes_alpha_t/_b/_c.
    Clearcoat,
    /// Two perpendicular anisotropic GGX lobes over a diffuse base (woven satin: warp and
    /// weft): lobes_kd, lobes_ka (warp), lobes_kb (weft), lobes_alpha_t/_b.
    Woven,
}

impl ModelArg {
    /// The library's model.
    pub fn model(self) -> symframe::FitModel {
        match self {
            ModelArg::Ward => symframe::FitModel::Ward,
            ModelArg::Gltf => symframe::FitModel::Gltf,
            ModelArg::Auto => symframe::FitModel::Auto,
            ModelArg::Clearcoat => symframe::FitModel::Clearcoat,
            ModelArg::Woven => symframe::FitModel::Woven,
        }
    }

    /// The default of `--model`: the library's default model
    /// ([`symframe::DEFAULT_MODEL`], the automatic choice per pixel).
    pub const DEFAULT: ModelArg = match symframe::DEFAULT_MODEL {
        symframe::FitModel::Ward => ModelArg::Ward,
        symframe::FitModel::Gltf => ModelArg::Gltf,
        symframe::FitModel::Auto => ModelArg::Auto,
        symframe::FitModel::Clearcoat => ModelArg::Clearcoat,
        symframe::FitModel::Woven => ModelArg::Woven,
    };
}

/// A value of `symframe fit --exposure`: a light intensity, `None` for `auto`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureArg(pub Option<f64>);

/// Parses `symframe fit --exposure`: `auto` or a positive number.
fn parse_exposure(s: &str) -> Result<ExposureArg, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(ExposureArg(None));
    }
    match s.trim().parse::<f64>() {
        Ok(x) if x > 0.0 && x.is_finite() => Ok(ExposureArg(Some(x))),
        _ => Err(format!(
            "expected 'auto' or a positive finite number, got '{s}'"
        )),
    }
}

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
    /// Near lights: side of the square of pixels that share one rig (1: a rig per pixel).
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
    /// precision at every query, every light visited (about 5x slower; for checking the
    /// default fast path, which does the same in single precision, on your own data).
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

/// Flags of `symframe demo`.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Output folder for the rendered dataset and the estimated maps (dataset/, estimate/,
    /// fit/, relit/, relit-edited/ and region.png in it are replaced). A folder holding any of
    /// them, not empty, must hold the `.symframe-demo` marker of an earlier demo run, else it
    /// is refused (see --force).
    #[arg(short, long, default_value = "symframe-demo")]
    pub output: PathBuf,
    /// Write into a folder that the demo did not write, replacing its dataset/, estimate/,
    /// fit/, relit/, relit-edited/ and region.png.
    #[arg(long)]
    pub force: bool,
    /// Image size in pixels (the sphere fills it).
    #[arg(long, default_value_t = 96)]
    pub size: usize,
    /// Number of lights, uniform over the 65-degree cone.
    #[arg(long, default_value_t = 1000)]
    pub lights: usize,
}

/// Flags of `symframe eval`.
#[derive(Debug, Clone, Args)]
pub struct EvalArgs {
    /// Synthetic dataset folder (or its `.lp` file) holding `gt_normals.npy`, optionally
    /// `gt_tangents.npy` and `mask.png`.
    pub dataset: PathBuf,
    /// Output folder of `symframe estimate` (`normals.npy`, optionally `tangents.npy`);
    /// `eval.json`, `normal_error.png` and `tangent_error.png` are written into it.
    pub estimate: PathBuf,
    /// Only pixels whose true normal is within this many degrees of the view are evaluated.
    #[arg(long, default_value_t = 60.0)]
    pub max_angle: f64,
    /// Top of the error pictures' colour scale, degrees (default: a round number near the
    /// 95th percentile of each map; fix it to compare pictures of several runs).
    #[arg(long)]
    pub scale_max: Option<f64>,
}

/// Shapes of `symframe synth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ShapeArg {
    /// A sphere filling the frame (head-on).
    Sphere,
    /// A cylinder with its axis along image y, filling the frame.
    Cylinder,
    /// A flat patch (see --normal-angle, --normal-azimuth, --tangent-angle).
    Plane,
    /// Seeded random Gaussian bumps on flat ground, with cast shadows (see --bumps, --relief).
    Bumps,
}

/// Image formats of `symframe synth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Float32 OpenEXR: exact, unclipped linear values.
    Exr,
    /// 16-bit linear PNG (values clipped to [0, 1]; 1 reads back as saturated).
    Png16,
    /// 8-bit sRGB PNG (values clipped to [0, 1]; 1 reads back as saturated).
    Png8,
}

/// Flags of `symframe synth`.
#[derive(Debug, Clone, Args)]
pub struct SynthArgs {
    /// Output dataset folder (created; images/, lights.lp, gt_normals.npy, gt_tangents.npy,
    /// mask.png and scene.json in it are replaced). A folder that is not empty must hold the
    /// `.symframe-synth` marker of an earlier synth run, else it is refused (see --force).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write into a non-empty folder that synth did not write, replacing its images/ folder
    /// and the dataset's files.
    #[arg(long)]
    pub force: bool,
    /// The rendered surface.
    #[arg(long, value_enum, default_value_t = ShapeArg::Sphere)]
    pub shape: ShapeArg,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    /// Reflectance model spec, e.g. `lambertian`, `ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5`,
    /// `ggx:ax=0.3,ay=0.1`, `merl:path=FILE`.
    #[arg(long, default_value = "ward")]
    pub model: String,
    /// Tangent field: `circular` (default), `radial`, `swirl[:DEG]`, `axial:DEG` (image-plane
    /// direction, degrees counter-clockwise from x) or `axial:X/Y/Z`.
    #[arg(long)]
    pub tangent_field: Option<String>,
    /// Light rig: `cone:N[:THETA_D]` (N lights uniform over the cone of halfway angles up to
    /// THETA_D degrees, default 65), `diligent` (96 lights on a 12 x 8 grid within 45 degrees
    /// of the view) or `lp:PATH` (the lights of an .lp file or dataset).
    #[arg(long, default_value = "cone:1000")]
    pub rig: String,
    /// Plane only: angle between the normal and the view, degrees (default 0).
    #[arg(long)]
    pub normal_angle: Option<f64>,
    /// Plane only: image-plane direction the normal tilts toward, degrees counter-clockwise
    /// from x (default 0: the normal lies in the x-z plane).
    #[arg(long)]
    pub normal_azimuth: Option<f64>,
    /// Plane only: tangent angle about the normal from the projection of x, degrees
    /// counter-clockwise as seen from the camera (default 0).
    #[arg(long)]
    pub tangent_angle: Option<f64>,
    /// Bumps only: number of bumps (default 12).
    #[arg(long)]
    pub bumps: Option<usize>,
    /// Bumps only: height scale; at 1 a lone bump's steepest slope is 20 to 40 degrees
    /// (default 1).
    #[arg(long)]
    pub relief: Option<f64>,
    /// Sensor noise: `none`, `gaussian:SIGMA` (standard deviation, 1 = full scale) or
    /// `shot:PHOTONS` (photons at full scale).
    #[arg(long, default_value = "none")]
    pub noise: String,
    /// Image file format.
    #[arg(long, value_enum, default_value_t = FormatArg::Exr)]
    pub format: FormatArg,
    /// Scale applied to the rendered radiance before noise and quantisation.
    #[arg(long, default_value_t = 1.0)]
    pub exposure: f64,
    /// Seed of the noise and of the bump layout.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Put a mirror (chrome) sphere beside the object, for `symframe calibrate`: the images
    /// become twice as wide, the sphere in the right half, 1/16 of it from its edges (a perfect
    /// mirror reflecting a lamp of 0.5 degrees and a dim room, anti-aliased, with a lens blur of
    /// 0.7 px; the lamp clips in integer formats). Its circle is recorded in scene.json; the
    /// mask and ground truth cover the object only. With --near: two chrome spheres where the
    /// object's are (the object taken away), under the same lights and camera, in `chrome/`
    /// (for `symframe calibrate --K`).
    #[arg(long)]
    pub chrome_sphere: bool,
    /// With --chrome-sphere: a matte sphere (Lambertian, grey albedo 0.5) to the right of the
    /// chrome one, for `symframe calibrate --matte-sphere` (the images become three times as
    /// wide; its circle is recorded in scene.json).
    #[arg(long, requires = "chrome_sphere")]
    pub matte_sphere: bool,
    /// Per-light RGB intensities drawn uniformly from [1 - S, 1 + S] (seeded by --seed), the
    /// truth written as gt_light_intensities.txt (default 0: every light of intensity 1).
    #[arg(long, default_value_t = 0.0, value_name = "S")]
    pub intensity_spread: f64,
    /// Near lights and a pinhole camera instead: two unit spheres side by side (the left of
    /// --model, the right of --second-model), isotropic point lights on a dome about them, a
    /// perspective camera; written as a DiLiGenT folder with light_positions.txt, K.txt,
    /// light_directions.txt (from the dome's centre) and gt_depth.npy. --size is the image
    /// width (the height is half of it); --shape, --rig and the sphere and plane flags do not
    /// apply.
    #[arg(long)]
    pub near: bool,
    /// With --near: the right sphere's reflectance model (default: a brushed Ward,
    /// `ward:kd=0.1,ks=0.6,ax=0.08,ay=0.3`; the left one's default is then
    /// `ggx:kd=0.4,f0=0.04,ax=0.15,ay=0.15` unless --model is given).
    #[arg(long, requires = "near")]
    pub second_model: Option<String>,
    /// With --near: the number of lights on the dome.
    #[arg(long, requires = "near", default_value_t = 150)]
    pub dome_lights: usize,
    /// With --near: the dome's radius over the object's width (the pair of spheres, 4.2 units).
    #[arg(long, requires = "near", default_value_t = 2.0)]
    pub dome_ratio: f64,
    /// With --near: the camera's distance from the spheres' centres over the object's width.
    #[arg(long, requires = "near", default_value_t = 3.0)]
    pub camera_ratio: f64,
}

/// Flags of `symframe fit`.
#[derive(Debug, Clone, Args)]
pub struct FitArgs {
    /// A `.lp` light file, a folder holding one, or a DiLiGenT-style folder (as for estimate).
    pub input: PathBuf,
    /// Output folder of `symframe estimate` for the same input (normals.npy, tangents.npy).
    #[arg(long)]
    pub frames: PathBuf,
    /// Output folder (created; files in it with the same names are replaced).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Leave this many lights (evenly spaced in the input's order) out of the fit and report
    /// the error on them.
    #[arg(long, default_value_t = 0)]
    pub holdout: usize,
    /// Mask image: only pixels where it is non-zero are fitted (default: mask.png beside the
    /// input, if any).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// How the images are decoded.
    #[command(flatten)]
    pub decode: DecodeFlags,
    /// The reflectance model fitted per pixel (default: auto, each pixel's better predictor
    /// of its validation lights; ward or gltf forces one model everywhere).
    #[arg(long, value_enum, default_value_t = ModelArg::DEFAULT)]
    pub model: ModelArg,
    /// glTF and auto models: the intensity of the lights in the images' units (a white
    /// diffuse surface facing a light of intensity E has radiance E/pi), or `auto`: the
    /// candidate intensity whose fits of sampled pixels best predict their validation lights
    /// (docs/method.md, "Choosing the exposure"). Recorded in fit.json and used by relight,
    /// view and export.
    #[arg(long, default_value = "auto", value_parser = parse_exposure, value_name = "E|auto")]
    pub exposure: ExposureArg,
    /// glTF model: the smallest roughness the fit may return.
    #[arg(long, default_value_t = FitParams::default().roughness_min)]
    pub roughness_min: f64,
    /// Levenberg-Marquardt iterations per pixel at most.
    #[arg(long, default_value_t = FitParams::default().max_iterations)]
    pub max_iterations: u32,
    /// The fitted highlight's peak may be at most this many times the pixel's brightest sample.
    #[arg(long, default_value_t = FitParams::default().max_peak_ratio)]
    pub max_peak_ratio: f64,
    /// Where the tile cache goes and whether it stays.
    #[command(flatten)]
    pub cache: CacheFlags,
}

/// Parses a light direction written `x,y,z`.
fn parse_light(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected x,y,z (three numbers), got '{s}'"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) && v.iter().any(|&c| c != 0.0) => {
            Ok([x, y, z])
        }
        _ => Err(format!(
            "expected x,y,z: three finite numbers, not all zero, got '{s}'"
        )),
    }
}

/// Flags of `symframe relight`.
#[derive(Debug, Clone, Args)]
#[command(group = clap::ArgGroup::new("light-source").required(true).multiple(true).args(["light", "lights"]))]
pub struct RelightArgs {
    /// Output folder of `symframe fit` (its model's maps, normals and tangents .npy).
    pub fit_dir: PathBuf,
    /// Output folder: relit_000.exr (linear) and relit_000.png (tone-mapped) per light.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A light direction `x,y,z` (camera frame: x right, y up, z toward the camera; surface
    /// toward light). Repeat for several images; they come before those of --lights.
    #[arg(long, value_parser = parse_light, allow_hyphen_values = true)]
    pub light: Vec<[f64; 3]>,
    /// A file of light directions: `.lp` (names ignored) or `x y z` rows.
    #[arg(long)]
    pub lights: Option<PathBuf>,
    /// Factor on the specular albedo.
    #[arg(long, default_value_t = Edits::default().specular_scale)]
    pub specular_scale: f64,
    /// Factor on the diffuse albedo.
    #[arg(long, default_value_t = Edits::default().diffuse_scale)]
    pub diffuse_scale: f64,
    /// Factor on both roughnesses (below 1 = glossier).
    #[arg(long, default_value_t = Edits::default().roughness_scale)]
    pub roughness_scale: f64,
    /// Rotate the tangents about the normal by this many degrees (inside --region if given).
    #[arg(long, allow_hyphen_values = true)]
    pub rotate_tangents: Option<f64>,
    /// Mask image limiting --rotate-tangents to its non-zero pixels.
    #[arg(long, requires = "rotate_tangents")]
    pub region: Option<PathBuf>,
    /// Exposure of the PNG pictures in stops (linear values times 2^E, then clamped and
    /// sRGB-encoded); the EXR files are not affected.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f64,
    /// Cast shadows from the integrated height map (ray-marched toward each light): pixels the
    /// relief hides from a light are dark.
    #[arg(long)]
    pub shadows: bool,
    /// With --shadows: the height map, `depth.npy` of `symframe integrate` (default:
    /// FIT_DIR/depth.npy).
    #[arg(long, requires = "shadows")]
    pub depth: Option<PathBuf>,
}

/// Flags of `symframe view`.
#[derive(Debug, Clone, Args)]
pub struct ViewArgs {
    /// Output folder of `symframe fit` (its model's maps, normals and tangents .npy), or of
    /// `symframe estimate` (normals, tangents, confidence, anisotropy and source, shaded with
    /// a stand-in grey material).
    pub fit_dir: PathBuf,
    /// The HTML file to write (default: FIT_DIR/viewer.html).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Output folder of the estimate the fit was made in, for the confidence, anisotropy and
    /// source views (default: the folder fit.json records, if it is still there).
    #[arg(long)]
    pub frames: Option<PathBuf>,
    /// Maps wider or taller than this many pixels go to a tile pyramid in the folder NAME_files
    /// beside the page NAME.html, which the page loads as it zooms (0: always).
    #[arg(long, value_name = "PIXELS", default_value_t = symframe_job::DEFAULT_PYRAMID_ABOVE)]
    pub pyramid_above: usize,
    /// Side of the pyramid's square tiles, pixels (8 to 4096).
    #[arg(long, value_name = "PIXELS", default_value_t = symframe_job::DEFAULT_TILE_SIZE)]
    pub tile_size: usize,
}

/// Solvers of `symframe integrate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum IntegrateSolverArg {
    /// Least squares on the mask (Poisson), conjugate gradients coarse to fine: fast, smooth
    /// everywhere (a depth jump becomes a slope).
    Poisson,
    /// Bilateral normal integration (Cao et al. 2022): keeps depth discontinuities; about 10 to
    /// 50 times the time of Poisson.
    Bilateral,
}

/// Flags of `symframe integrate`.
#[derive(Debug, Clone, Args)]
pub struct IntegrateArgs {
    /// Output folder of `symframe estimate` (normals.npy; confidence.npy weights the fit).
    pub estimate: PathBuf,
    /// Output folder (created; depth.npy, depth.exr, depth.png, mesh.ply, integrate.json in it
    /// are replaced).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The solver.
    #[arg(long, value_enum, default_value_t = IntegrateSolverArg::Bilateral)]
    pub solver: IntegrateSolverArg,
    /// Bilateral only: sharpness of the side weights (larger breaks the surface more readily).
    #[arg(long, default_value_t = 10.0)]
    pub k: f64,
    /// Bilateral only: reweighting iterations at most.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Relative residual at which each conjugate-gradient solve stops.
    #[arg(long, default_value_t = 1e-7)]
    pub tolerance: f64,
    /// Ignore confidence.npy (weight every pixel alike).
    #[arg(long)]
    pub no_confidence: bool,
    /// Mesh: leave out triangles with an edge whose height step departs from the normals'
    /// prediction by more than this many pixels times (1 + the predicted step).
    #[arg(long, default_value_t = 2.0)]
    pub max_jump: f64,
    /// A pinhole camera's intrinsics (`K.txt`, OpenCV's 3 x 3 convention): a perspective depth
    /// map (along the optical axis) and a mesh in the camera frame. Default: the camera a
    /// near-light estimate's report.json records, else an orthographic height map.
    #[arg(long = "K", value_name = "K.txt")]
    pub camera: Option<PathBuf>,
    /// With a camera: the depth of the object's centre along the optical axis (the depths'
    /// unit), where the estimate wrote no depth.npy to scale by.
    #[arg(long)]
    pub distance: Option<f64>,
}

/// Flags of `symframe calibrate`.
#[derive(Debug, Clone, Args)]
pub struct CalibrateArgs {
    /// A folder of images (every image file in it, sorted by name; `mask.*` left out), an
    /// `.lp` file (its images), or a list file of image paths (one per line, relative to it).
    pub images: PathBuf,
    /// The mirror sphere's circle in pixels: CX,CY,R with x right from the left edge, y down
    /// from the top edge, the centre of the top-left pixel at (0.5, 0.5). Without it the sphere
    /// is looked for (and what was found is printed). With --K, once per chrome sphere (two or
    /// more; none: they are looked for).
    #[arg(long, value_parser = parse_circle, allow_hyphen_values = true)]
    pub sphere: Vec<symframe::Circle>,
    /// The `.lp` file to write (image paths relative to its folder); `<stem>-highlights.png`
    /// and `<stem>-calibration.json` are written beside it. With --K: the
    /// `light_positions.txt` to write (one row per image), `<stem>-calibration.json` beside it
    /// and `K.txt` where that folder has none.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Light positions instead of directions: the camera's intrinsics (`K.txt`, OpenCV's 3 x 3
    /// convention); two or more chrome spheres of --sphere-radius in the images are placed by
    /// their outlines and each light triangulated from its reflections in them.
    #[arg(long = "K", value_name = "K.txt", requires = "sphere_radius")]
    pub k: Option<PathBuf>,
    /// With --K: the chrome spheres' radius, in the unit the positions are written in.
    #[arg(long, value_name = "R", requires = "k")]
    pub sphere_radius: Option<f64>,
    /// A highlight is the pixels above this fraction of its peak (above the sphere's median).
    #[arg(long, default_value_t = 0.3)]
    pub threshold: f64,
    /// Fail on the first image without a single clear highlight (default: drop it, warn).
    #[arg(long)]
    pub strict: bool,
    /// A matte (diffuse, grey) sphere's circle CX,CY,R (as --sphere): per light, its RGB
    /// intensity is measured there and written as light_intensities.txt beside the .lp,
    /// normalised to a mean of 1 over all lights and channels.
    #[arg(long, value_parser = parse_circle, allow_hyphen_values = true, value_name = "CX,CY,R")]
    pub matte_sphere: Option<symframe::Circle>,
    /// How the images are decoded.
    #[command(flatten)]
    pub decode: DecodeFlags,
}

/// Parses a circle written `CX,CY,R` (`--sphere`, `--matte-sphere`).
fn parse_circle(s: &str) -> Result<symframe::Circle, String> {
    symframe::Circle::parse(s)
}

/// Formats of `symframe export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// glTF 2.0 (.gltf with .bin and PNG textures beside it, or a single .glb): metallic-
    /// roughness material, tangent-space normal texture, KHR_materials_anisotropy.
    Gltf,
}

/// Flags of `symframe export`.
#[derive(Debug, Clone, Args)]
pub struct ExportArgs {
    /// The asset format.
    #[arg(value_enum)]
    pub format: ExportFormat,
    /// Output folder of `symframe fit` (its model's maps, normals and tangents .npy) or of
    /// `symframe estimate` (normals, tangents, anisotropy .npy).
    pub input: PathBuf,
    /// The file to write: `.gltf` (textures and `.bin` beside it) or `.glb` (all in one).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Export the integrated mesh (one vertex per pixel) instead of a flat quad.
    #[arg(long)]
    pub mesh: bool,
    /// With --mesh: the height map of `symframe integrate` (default: INPUT/depth.npy).
    #[arg(long, requires = "mesh")]
    pub depth: Option<PathBuf>,
    /// With --mesh: leave out triangles across depth jumps (as `integrate --max-jump`).
    #[arg(long, default_value_t = 2.0)]
    pub max_jump: f64,
    /// With --mesh: the depth map is a perspective one through this camera (`K.txt`), the
    /// mesh metric in the camera frame. Default: the camera recorded beside the depth map
    /// (integrate.json, or a near-light estimate's report.json), else a height map.
    #[arg(long = "K", value_name = "K.txt", requires = "mesh")]
    pub k: Option<PathBuf>,
}

/// The y convention of `normals.png`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum NormalPngArg {
    /// Green = +y (up): OpenGL, glTF, Blender.
    Opengl,
    /// Green = -y (down): DirectX, Unreal.
    Directx,
}

impl From<NormalPngArg> for symframe_io::NormalPng {
    fn from(a: NormalPngArg) -> Self {
        match a {
            NormalPngArg::Opengl => symframe_io::NormalPng::OpenGl,
            NormalPngArg::Directx => symframe_io::NormalPng::DirectX,
        }
    }
}
