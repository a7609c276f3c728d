//! What the near-light calibration records in `<stem>-calibration.json`: the spheres, each
//! light (its position, how it was placed, its highlights and residuals) and the matte sphere.

use std::path::PathBuf;

use serde::Serialize;
use symframe::Circle;

/// The matte sphere in `<stem>-calibration.json`.
#[derive(Debug, Clone, Serialize)]
pub struct MatteRecord {
    /// Its circle in the image (the chrome spheres' pixel convention).
    pub circle: Circle,
    /// Its radius (the positions' unit).
    pub radius: f64,
    /// `image` (the rim found in the mean image) or `circle` (the circle's own rim).
    pub outline: &'static str,
    /// Its centre, camera frame.
    pub centre: [f64; 3],
    /// The mean of the lights' intensities over lights and channels before normalising to 1
    /// (times the sphere's albedo).
    pub intensity_mean_raw: f64,
}

/// One sphere in `<stem>-calibration.json`.
#[derive(Debug, Clone, Serialize)]
pub struct SphereRecord {
    /// Its circle in the image (pixels, x right, y down, top-left pixel centre (0.5, 0.5)).
    pub circle: Circle,
    /// `given` or `detected`.
    pub circle_source: &'static str,
    /// Where its outline came from: `image` (the rim found in the mean image) or `circle` (the
    /// circle's own rim, where the image gave none).
    pub outline: &'static str,
    /// Points of the outline the cone was fitted to.
    pub outline_points: usize,
    /// Its centre, camera frame.
    pub centre: [f64; 3],
}

/// One light in `<stem>-calibration.json`.
#[derive(Debug, Clone, Serialize)]
pub struct LightRecord {
    /// The image.
    pub image: String,
    /// The position written (camera frame).
    pub position: [f64; 3],
    /// `triangulated` (two or more rays) or `dome` (one ray, or rays that fix it poorly: each
    /// met with the sphere through the other lights, the meetings averaged).
    pub placed_by: &'static str,
    /// Per sphere, the highlight's centre in pixels, or why none.
    pub highlights: Vec<Result<[f64; 2], String>>,
    /// The root mean square distance from the position to its rays (triangulated lights).
    pub residual_rms: Option<f64>,
    /// The largest distance from the position to its rays (triangulated lights).
    pub residual_max: Option<f64>,
    /// The widest angle between two of its rays, degrees (triangulated lights).
    pub spread_deg: Option<f64>,
    /// Its RGB intensity from the matte sphere, before normalising (times the sphere's albedo).
    pub intensity: Option<[f64; 3]>,
}

/// What `<stem>-calibration.json` holds.
#[derive(Debug, Serialize)]
pub struct NearCalibrationReport {
    /// symframe version.
    pub version: &'static str,
    /// The camera's intrinsics (OpenCV's convention, row-major).
    pub k: [[f64; 3]; 3],
    /// The spheres' radius.
    pub sphere_radius: f64,
    /// The spheres.
    pub spheres: Vec<SphereRecord>,
    /// Images (lights) read.
    pub images: usize,
    /// Lights triangulated from two or more spheres.
    pub triangulated: usize,
    /// The median and the largest of the triangulated lights' rms residuals.
    pub residual_rms_median: f64,
    /// The largest rms residual.
    pub residual_rms_max: f64,
    /// The sphere through the light positions (centre, radius), when they lie on one.
    pub dome: Option<([f64; 3], f64)>,
    /// The matte sphere, when intensities were measured.
    pub matte: Option<MatteRecord>,
    /// Per light, in the images' order.
    pub records: Vec<LightRecord>,
    /// The conventions of the figures.
    pub conventions: &'static str,
    /// The files written: `light_positions.txt`, the report, `light_intensities.txt` with a
    /// matte sphere, and `K.txt` where it was written.
    #[serde(skip)]
    pub written: Vec<PathBuf>,
}
