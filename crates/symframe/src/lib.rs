//! symframe: per-pixel surface normals and tangents from the symmetry of measured BRDF slices
//! (Holroyd, Lawrence, Humphreys, Zickler, SIGGRAPH Asia 2008).
//!
//! Frames: the camera frame has x = image right, y = image up, z = toward the camera; the view
//! vector is `(0, 0, 1)` for every pixel (orthographic). Each pixel's local frame is (n, t, b).
//!
//! What the crate offers, named at its root:
//!
//! - Datasets and rigs: a measurement [`Stack`] ([`Stack::check_inputs`]), its lights as a [`Rig`]
//!   ([`RigOptions`], [`uniform_cone_lights`]), the capture's [`NoiseModel`], and a check of the
//!   lights' axes ([`AxesCheck`]).
//! - Estimating frames: the [`Estimator`] and its [`EstimatorParams`], run over a stack by
//!   [`estimate_stack`]; the paper's baselines ([`Baseline`], [`Baseline::estimate_stack`]); the
//!   [`PixelMethod`] interface every per-pixel method implements, and its in-memory driver
//!   [`Stack::run`].
//! - Maps: what an estimate holds per pixel ([`EstimateMaps`], [`PixelRecord`]) and its error
//!   against ground truth ([`evaluate`], [`Evaluation`]).
//! - Fit and relight: per-pixel Ward or glTF metallic-roughness fits in the estimated frames
//!   ([`FitParams::fit_stack`], [`FitMaps`]), rendered and edited by a [`Relighter`].
//! - Integrate: a depth map from the normals ([`DepthMap::integrate`]; seen through a pinhole,
//!   [`Pinhole::integrate`]) and its mesh ([`DepthMap::mesh`]).
//! - Calibrate: light directions from chrome and matte spheres ([`Highlight::find`],
//!   [`Detection::find`], [`CalibrationParams::intensity`]); near lights and perspective cameras
//!   ([`Pinhole`], [`PointLight`], [`NearParams`], [`Triangulation`]).
//! - [`brdf`] (reflectance models) and [`render`] (the synthetic renderer that tests and
//!   experiments measure against).
//!
//! The `symframe-job` crate runs the same methods tile by tile from an on-disk cache. The method
//! itself is written up in `docs/method.md`.
//!
//! One pixel, from lights to frame: a rig, an estimator, and the pixel's samples in rig order.
//!
//! ```
//! use symframe::brdf::Ward;
//! use symframe::render::Scene;
//! use symframe::{
//!     uniform_cone_lights, CosineMode, Estimator, EstimatorParams, PixelStatus, Rig, RigOptions,
//! };
//!
//! // 600 lights over the default 65-degree cone; a brushed-metal patch whose normal is 30
//! // degrees from the view, rendered as a one-pixel image per light.
//! let lights = uniform_cone_lights(600, 65.0);
//! let rig = Rig::new(&lights, RigOptions::default())?;
//! let (n, t) = Scene::plane_frame(30.0, 0.0, 25.0);
//! let patch = Scene::plane(1, 1, n, t);
//! let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
//! let samples: Vec<f32> = rig
//!     .input_index()
//!     .iter()
//!     .flat_map(|&i| patch.render(&brdf, lights[i]))
//!     .collect();
//!
//! // The diffuse-compensated measure with Ward's cosine power (docs/method.md, "Cosine forms").
//! let params = EstimatorParams {
//!     cosine: CosineMode::Compensated(0.5),
//!     ..EstimatorParams::default()
//! };
//! let estimate = Estimator::new(&rig, params).estimate_pixel(&samples);
//! assert_eq!(estimate.status, PixelStatus::Estimated);
//! let normal = estimate.normal.expect("estimated");
//! assert!(normal.angle_between(n).to_degrees() < 1.0);
//! let tangent = estimate.tangent.expect("anisotropic");
//! assert!(tangent.dot(t).abs() > 0.999); // an axis: t or -t
//! # Ok::<(), symframe::Error>(())
//! ```
//!
//! A whole capture, from images to maps, their error and a depth map: a brushed-metal sphere
//! rendered under 300 lights, its frames estimated, compared with the truth, and integrated.
//!
//! ```
//! use symframe::brdf::Ward;
//! use symframe::render::{Scene, TangentField};
//! use symframe::{
//!     estimate_stack, evaluate, uniform_cone_lights, DepthMap, EstimatorParams, IntegrateParams,
//!     Rig, RigOptions,
//! };
//!
//! let scene = Scene::sphere(24, TangentField::Circular);
//! let lights = uniform_cone_lights(300, 65.0);
//! let stack = scene.render_stack(&Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5), &lights);
//! let rig = Rig::new(&lights, RigOptions::default())?;
//! let params = EstimatorParams::default();
//! let maps = estimate_stack(&stack, &rig, Some(&scene.mask), params, &|_| {})?;
//!
//! // Median normal error over the pixels whose true normal is within 60 degrees of the view.
//! let truth = scene.gt_normals();
//! let mask = Some(&scene.mask[..]);
//! let e = evaluate(&maps.normals, &maps.tangents, &truth, None, mask, 60.0, None);
//! assert!(e.normal_error.median < 1.0, "{e:?}");
//!
//! // Heights from the normals (a sphere: highest in the middle).
//! let depth = DepthMap::integrate(24, 24, &maps.normals, None, &IntegrateParams::default())?;
//! assert!(depth.depth[12 * 24 + 12] > depth.depth[12 * 24 + 3]);
//! # Ok::<(), symframe::Error>(())
//! ```

#![deny(unnameable_types)]
#![deny(unreachable_pub)]

mod appearance;
mod baselines;
pub mod brdf;
mod calibrate;
mod error;
mod eval;
mod frames;
mod geometry;
mod highlight;
mod integrate;
mod maps;
mod method;
mod near;
mod noise;
mod orientation;
mod regions;
pub mod render;
mod stack;

// The library's surface: what a Rust user of the method needs, named at the root. The
// reflectance models and the synthetic renderer are the two namespaces below it (`brdf`,
// `render`).

// Datasets and rigs: the measurement stack, its lights and their triangulation.
pub use frames::rig::{uniform_cone_lights, Rig, RigOptions};
pub use noise::{NoiseModel, NoiseSamples, Quantisation};
pub use orientation::{AxesCheck, LightAxes};
pub use stack::Stack;

// Estimating frames: the estimator, its parameters, the per-pixel interface and its drivers.
pub use baselines::{Baseline, BaselineMethod, BaselineParams};
pub use frames::estimator::{
    estimate_stack, Estimator, EstimatorParams, Fallback, Interpolation, PixelEstimate,
    PixelScratch,
};
pub use frames::symmetry::CosineMode;
pub use method::PixelMethod;

// The maps an estimate writes, and their error against ground truth.
pub use eval::{evaluate, ErrorStats, Evaluation};
pub use maps::{EstimateMaps, PixelCounts, PixelRecord, PixelSource, PixelStatus};

// Fitting a BRDF per pixel in the estimated frames, and relighting the fit.
pub use appearance::fit::{
    ExposureChoice, FitMaps, FitMethod, FitModel, FitParams, FitSummary, GltfMaps, HoldoutError,
    LobeMaps, ModelEvidence, PixelData, PixelFitter, PixelOutcome, WardFit, WardMaps,
};
pub use appearance::gltf_fit::GltfFit;
pub use appearance::lobe_fit::{LobeFit, LobeKind, LobeModel};
pub use appearance::relight::{Edits, Relighter};
pub use appearance::sample_relight::SampleRelighter;

// Depth from normals, and a mesh of it.
pub use integrate::{DepthMap, IntegrateParams, Mesh, Solver};

// Light calibration: chrome and matte spheres.
pub use calibrate::{CalibrationError, CalibrationParams, Circle, Detection, Highlight};

// Near lights and perspective cameras.
pub use near::chrome::Triangulation;
pub use near::{NearMethod, NearOutcome, NearParams, Pinhole, PointLight};

pub use error::{Error, Result};
