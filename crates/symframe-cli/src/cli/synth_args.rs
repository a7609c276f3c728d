//! Flags of `symframe demo`, `symframe synth` and `symframe eval`.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
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
