//! Flags of `symframe fit`, `symframe relight` and `symframe view`.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use symframe::{Edits, FitParams};

use super::{CacheFlags, DecodeFlags};

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
    /// ([`symframe::FitModel::DEFAULT`], the automatic choice per pixel).
    pub const DEFAULT: ModelArg = match symframe::FitModel::DEFAULT {
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
    /// auto model: each pixel's model is chosen from the evidence of the pixels within this
    /// many rows and columns of it. Higher is steadier on a uniform material and blurs the line
    /// between two materials; 0 judges each pixel alone (docs/method.md, "The automatic choice").
    #[arg(long, default_value_t = FitParams::default().choice_radius, value_name = "PIXELS")]
    pub choice_radius: usize,
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
    /// Relight the photographs of this capture themselves, in the fit's frames, with no
    /// model: each pixel's measured slice interpolated between the lights and read at its
    /// mirror images outside the rig (docs/method.md, "Relighting from the samples"). Loads
    /// the whole capture; no edits.
    #[arg(long, value_name = "CAPTURE")]
    pub from_samples: Option<PathBuf>,
    /// How --from-samples decodes the capture's images.
    #[command(flatten)]
    pub decode: DecodeFlags,
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
    /// Add the view `samples`: the photographs of this capture relit themselves in the maps'
    /// frames, with no model, as `symframe relight --from-samples` (docs/method.md, "Relighting
    /// from the samples"). The samples go into the page: up to 254 lights and 512 MiB of half
    /// floats (pixels x (lights + 2) x 8 bytes), no pyramid.
    #[arg(long, value_name = "CAPTURE")]
    pub from_samples: Option<PathBuf>,
    /// How --from-samples decodes the capture's images.
    #[command(flatten)]
    pub decode: DecodeFlags,
}
