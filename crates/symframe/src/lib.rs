//! symframe: per-pixel surface normals and tangents from the symmetry of measured BRDF slices
//! (Holroyd, Lawrence, Humphreys, Zickler, SIGGRAPH Asia 2008).
//!
//! Frames: the camera frame has x = image right, y = image up, z = toward the camera; the view
//! vector is `(0, 0, 1)` for every pixel (orthographic). Each pixel's local frame is (n, t, b).

pub mod brdf;
pub mod stack;

pub use stack::Stack;
