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

pub mod baseline;
pub mod brdf;
pub mod calibrate;
pub mod error;
pub mod estimate;
pub mod eval;
pub mod fit;
pub mod integrate;
pub mod objective;
pub mod optim;
pub mod relight;
pub mod render;
pub mod rig;
pub mod slice;
pub mod stack;
pub mod symmetry;

pub use baseline::{estimate_stack_baseline, Baseline};
pub use error::{Error, Result};
pub use estimate::{
    estimate_block, estimate_pixels, estimate_stack, BlockScratch, EstimateMaps, Estimator,
    EstimatorParams, Interpolation, PixelRecord, PixelScratch, PixelStatus,
};
pub use fit::{fit_stack, FitMaps, FitParams, WardMaps};
pub use relight::{Edits, Relighter};
pub use rig::{Rig, RigOptions};
pub use stack::Stack;
