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
    /// Fit an anisotropic Ward BRDF per pixel in estimated frames (for relighting and editing).
    Fit(FitArgs),
    /// Render fitted Ward maps under new lights, optionally edited.
    Relight(RelightArgs),
    /// Render a built-in synthetic object, estimate its frames and report the error (no download).
    Demo(DemoArgs),
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
    /// Treat 8-bit images as linear (default: sRGB-decode them).
    #[arg(long)]
    pub linear: bool,
    /// Integer samples at or above this fraction of the format's maximum are saturated and
    /// excluded.
    #[arg(long, default_value_t = 0.995)]
    pub saturation: f32,
    /// Levenberg-Marquardt iterations per pixel at most.
    #[arg(long, default_value_t = 60)]
    pub max_iterations: u32,
    /// The fitted highlight's peak may be at most this many times the pixel's brightest sample.
    #[arg(long, default_value_t = 8.0)]
    pub max_peak_ratio: f64,
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
    /// Output folder of `symframe fit` (kd, ks, alpha_t, alpha_b, normals, tangents .npy).
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
    #[arg(long, default_value_t = 1.0)]
    pub specular_scale: f64,
    /// Factor on the diffuse albedo.
    #[arg(long, default_value_t = 1.0)]
    pub diffuse_scale: f64,
    /// Factor on both roughnesses (below 1 = glossier).
    #[arg(long, default_value_t = 1.0)]
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
}
