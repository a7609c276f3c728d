//! Integration tests of the core library on synthetic renders with known frames: accuracy of
//! the symmetry estimator (fast and reference paths), the baselines, and the per-pixel Ward fit.

mod accuracy;
mod baselines;
mod capture;
mod fit;
mod materials;
mod robustness;
