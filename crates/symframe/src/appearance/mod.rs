//! Appearance in the estimated frames: per-pixel anisotropic Ward fits ([`fit`]) and rendering
//! and editing them under new lights ([`relight`]).

pub mod fit;
pub mod relight;
