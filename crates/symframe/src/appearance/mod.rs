//! Appearance in the estimated frames: per-pixel anisotropic Ward or glTF fits ([`fit`],
//! [`gltf_fit`]) and rendering
//! and editing them under new lights ([`relight`]).

pub(crate) mod fit;
pub(crate) mod gltf_fit;
pub(crate) mod relight;
