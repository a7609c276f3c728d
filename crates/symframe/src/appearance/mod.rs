//! Appearance in the estimated frames: per-pixel reflectance fits ([`fit`], the driver; one
//! module per model: [`ward_fit`], [`gltf_fit`], [`lobe_fit`] for the two-lobe models
//! [`clearcoat`] and [`woven`], the last two sharing the search of [`lm`]) and rendering and
//! editing them under new lights ([`relight`]), or relighting from the samples themselves
//! ([`sample_relight`]).

pub(crate) mod clearcoat;
pub(crate) mod fit;
pub(crate) mod gltf_fit;
pub(crate) mod lm;
pub(crate) mod lobe_fit;
pub(crate) mod relight;
pub(crate) mod sample_relight;
pub(crate) mod ward_fit;
pub(crate) mod woven;
