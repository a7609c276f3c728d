//! Command-line flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// Surface normals and tangents from photographs under many lights, by BRDF symmetry
/// (Holroyd et al. 2008).
#[derive(Debug, Parser)]
#[command(name = "symframe", version, about, long_about = None)]
pub struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true, value_parser = clap::value_parser!(usize))]
    pub threads: Option<usize>,
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Estimate normal and tangent maps from a capture (.lp file or DiLiGenT-style folder).
    Estimate(EstimateArgs),
    /// Render a built-in synthetic object, estimate its frames and report the error (no download).
    Demo(DemoArgs),
    /// Compare an estimate with a synthetic dataset's ground truth: eval.json, error-map
    /// pictures with colour bars, and a summary table.
    Eval(EvalArgs),
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
}

/// Cosine handling in the symmetry distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CosineArg {
    /// The paper's cross-multiplied cosines (exact for diffuse; default).
    Cross,
    /// Raw radiances (exact for microfacet lobes, wrong for diffuse).
    Raw,
    /// Diffuse-compensated power form (see --cosine-power): exact for diffuse plus a lobe
    /// whose radiance goes as (n.l)^p; refines the paper's solution.
    Compensated,
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
    /// Mask image: only pixels where it is non-zero are estimated (default: mask.png beside
    /// the input, if any).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Light cone: lights whose halfway vector is more than this many degrees from the view are
    /// dropped.
    #[arg(long, default_value_t = 65.0)]
    pub theta_d_max: f64,
    /// Pixels with confidence below this are culled (NaN in the maps).
    #[arg(long, default_value_t = 0.0)]
    pub min_confidence: f32,
    /// Pixels with anisotropy below this get no tangent (NaN): the slice is isotropic.
    #[arg(long, default_value_t = 0.6)]
    pub min_anisotropy: f32,
    /// Smallest symmetry domain, in lights, that counts as non-empty (default: 1.5% of the
    /// lights used, at least 6).
    #[arg(long)]
    pub min_domain: Option<u32>,
    /// Cosine handling in the symmetry distance.
    #[arg(long, value_enum, default_value_t = CosineArg::Cross)]
    pub cosine: CosineArg,
    /// Cosine power p of `--cosine compensated` (0.5 is exact for Ward, 0 for Cook-Torrance-like
    /// lobes, 1 for Blinn-Phong).
    #[arg(long, default_value_t = 0.5)]
    pub cosine_power: f64,
    /// Treat 8-bit images as linear (default: sRGB-decode them).
    #[arg(long)]
    pub linear: bool,
    /// Integer samples at or above this fraction of the format's maximum are saturated and
    /// excluded.
    #[arg(long, default_value_t = 0.995)]
    pub saturation: f32,
    /// Skip tangents (normals only; faster).
    #[arg(long)]
    pub no_tangents: bool,
}

/// Flags of `symframe demo`.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Output folder for the rendered dataset and the estimated maps.
    #[arg(short, long, default_value = "symframe-demo")]
    pub output: PathBuf,
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
