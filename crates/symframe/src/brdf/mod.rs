//! Analytic and measured BRDF models, each evaluated in a local frame.
//!
//! Local frame convention (shared by every model): `x` = the model's first anisotropy axis, `y` =
//! its second, `z` = the surface normal. Directions point away from the surface and are unit
//! length. Which of x or y is "the tangent" follows docs/method.md ("The widest-highlight tangent
//! rule"): the axis of the larger roughness (see [`Brdf::tangent_axis`]).

/// Which local axis of a model is the tangent (the axis of the wider highlight).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TangentAxis {
    /// The model's local x axis.
    X,
    /// The model's local y axis.
    Y,
    /// The model is isotropic: no tangent is defined.
    None,
}

impl TangentAxis {
    /// The tangent of a model with roughness `alpha_x` along x and `alpha_y` along y: the axis of
    /// the larger roughness (docs/method.md, "The widest-highlight tangent rule"), none when they
    /// are equal.
    pub fn of_roughness(alpha_x: f64, alpha_y: f64) -> Self {
        if alpha_x > alpha_y {
            TangentAxis::X
        } else if alpha_y > alpha_x {
            TangentAxis::Y
        } else {
            TangentAxis::None
        }
    }
}

/// A BRDF evaluated in the local frame (x, y, z = normal).
pub trait Brdf: Send + Sync {
    /// The BRDF value `f(light, view)` per RGB channel (1/sr), zero below the horizon.
    fn eval(&self, light_in_local: glam::DVec3, view_in_local: glam::DVec3) -> [f64; 3];

    /// Which local axis is the tangent (larger roughness); `None` for isotropic models.
    fn tangent_axis(&self) -> TangentAxis;

    /// Short human-readable name with parameters, for reports.
    fn name(&self) -> String;
}

pub(crate) mod ashikhmin_shirley;
pub(crate) mod beckmann;
pub(crate) mod blinn_phong;
pub(crate) mod cook_torrance;
pub(crate) mod ggx;
pub(crate) mod gltf;
pub(crate) mod lambertian;
pub(crate) mod layered;
pub(crate) mod merl;
pub(crate) mod microfacet;
pub(crate) mod sheen;
pub(crate) mod spec;
#[cfg(test)]
pub(crate) mod testutil;
pub(crate) mod torrance_sparrow;
pub(crate) mod ward;
pub(crate) mod woven;

pub use ashikhmin_shirley::AshikhminShirley;
pub use beckmann::Beckmann;
pub use blinn_phong::BlinnPhong;
pub use cook_torrance::CookTorrance;
pub use ggx::Ggx;
pub use gltf::GltfPbr;
pub use lambertian::Lambertian;
pub use layered::Layered;
pub(crate) use merl::Merl;
pub use sheen::Sheen;
pub use spec::parse_model;
pub use torrance_sparrow::TorranceSparrow;
pub use ward::Ward;
pub use woven::Woven;
