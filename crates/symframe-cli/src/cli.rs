//! Command-line flags.

mod estimate_args;
mod fit_args;
mod synth_args;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use symframe_console::Globals;
use symframe_io::{CacheOptions, DecodeOptions};

pub use estimate_args::{EstimateArgs, LightModelArg, MergeArgs, MethodArg};
pub use fit_args::{FitArgs, RelightArgs, ViewArgs};
pub use synth_args::{DemoArgs, EvalArgs, FormatArg, ShapeArg, SynthArgs};

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

/// The decoding flags of `estimate`, `fit`, `calibrate` and `relight --from-samples`.
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

/// Solvers of `symframe integrate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum IntegrateSolverArg {
    /// Least squares on the mask (Poisson), conjugate gradients coarse to fine: fast, smooth
    /// everywhere (a depth jump becomes a slope).
    Poisson,
    /// Bilateral normal integration (Cao et al. 2022): keeps depth discontinuities; slower than
    /// Poisson (docs/capture.md, "Normal integration").
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
    /// normalised to a mean of 1 over all lights and channels. With --K, beside
    /// light_positions.txt, each light's 1/r^2 from its triangulated position taken out.
    #[arg(long, value_parser = parse_circle, allow_hyphen_values = true, value_name = "CX,CY,R")]
    pub matte_sphere: Option<symframe::Circle>,
    /// With --K: the matte sphere's radius (default: --sphere-radius).
    #[arg(long, value_name = "R", requires_all = ["matte_sphere", "k"])]
    pub matte_radius: Option<f64>,
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
