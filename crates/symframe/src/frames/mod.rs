//! Finding a pixel's frame (n, t, b): the method itself.
//!
//! In the order a pixel meets them: [`rig`] (lights, halfway vectors, their triangulation and
//! point location), [`slice`](mod@slice) (a pixel's measured BRDF slice, interpolated between
//! the samples), [`symmetry`] (the symmetry distances), [`objective`] (their reference and fast
//! implementations), [`optim`] (Nelder-Mead), [`policy`] (the settings of the choice of answer, grouped by rule; whether the data
//! determine a tangent, and how surely)
//! and [`estimator`] (the per-pixel search, confidence, anisotropy and fallbacks, and the
//! whole-stack pipeline).

pub(crate) mod estimator;
pub(crate) mod lobe;
pub(crate) mod objective;
pub(crate) mod optim;
pub(crate) mod policy;
pub(crate) mod rig;
pub(crate) mod slice;
pub(crate) mod symmetry;
