//! symframe: per-pixel surface normals and tangents from the symmetry of measured BRDF slices
//! (Holroyd, Lawrence, Humphreys, Zickler, SIGGRAPH Asia 2008).
//!
//! Frames: the camera frame has x = image right, y = image up, z = toward the camera; the view
//! vector is `(0, 0, 1)` for every pixel (orthographic). Each pixel's local frame is (n, t, b).
//!
//! Where things live: [`rig`] (lights, halfway vectors, triangulation, point location),
//! [`slice`](mod@slice) (per-pixel interpolation), [`symmetry`] (the objective), [`objective`] (its reference and fast
//! implementations), [`optim`] (Nelder-Mead),
//! [`estimate`] (the per-pixel estimator and the whole-stack pipeline), [`brdf`] (models),
//! [`render`] (the synthetic renderer), [`stack`] (the measurement stack), [`baseline`] (the
//! photometric-stereo and max-reflectance baselines the paper compares against), [`fit`]
//! (per-pixel Ward fits in the estimated frames) and [`relight`] (rendering and editing them).
//!
//! Every per-pixel method (the estimator, each baseline, the Ward fitter) implements
//! [`PixelMethod`]; [`run_stack`] runs one over an in-memory [`Stack`], and the `symframe-job`
//! crate runs the same methods tile by tile from an on-disk cache. The method itself is written
//! up in `docs/method.md`.
//!
//! One pixel, from lights to frame: a rig, an estimator, and the pixel's samples in rig order.
//!
//! ```
//! use symframe::brdf::ward::Ward;
//! use symframe::render::{plane_frame, Scene};
//! use symframe::rig::uniform_cone_lights;
//! use symframe::symmetry::CosineMode;
//! use symframe::{Estimator, EstimatorParams, PixelStatus, Rig, RigOptions};
//!
//! // 600 lights over the default 65-degree cone; a brushed-metal patch whose normal is 30
//! // degrees from the view, rendered as a one-pixel image per light.
//! let lights = uniform_cone_lights(600, 65.0);
//! let rig = Rig::new(&lights, RigOptions::default())?;
//! let (n, t) = plane_frame(30.0, 0.0, 25.0);
//! let patch = Scene::plane(1, 1, n, t);
//! let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
//! let samples: Vec<f32> = rig
//!     .input_index
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

pub mod baseline;
pub mod brdf;
pub mod calibrate;
pub mod error;
pub mod estimate;
pub mod eval;
pub mod fit;
pub mod highlight;
pub mod integrate;
pub mod method;
pub mod objective;
pub mod optim;
pub mod relight;
pub mod render;
pub mod rig;
pub mod slice;
pub mod stack;
pub mod symmetry;

pub use baseline::{estimate_stack_baseline, Baseline, BaselineMethod};
pub use error::{Error, Result};
pub use estimate::{
    estimate_stack, EstimateMaps, Estimator, EstimatorParams, Interpolation, PixelRecord,
    PixelScratch, PixelSource, PixelStatus,
};
pub use fit::{fit_stack, FitMaps, FitMethod, FitParams, WardMaps};
pub use method::{run_stack, PixelMethod};
pub use relight::{Edits, Relighter};
pub use rig::{Rig, RigOptions};
pub use stack::Stack;
