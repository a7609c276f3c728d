//! Near lights and perspective cameras: a pinhole camera ([`Pinhole`]: each pixel's ray and
//! view direction from OpenCV's intrinsics), point lights ([`PointLight`]: each light's
//! direction and irradiance at a surface point, LEDs with a cos^mu falloff) and the sphere
//! through the lights ([`PointLight::fit_sphere`]: a dome's centre, where the object is taken to
//! be when its distance is not given); the lights' positions from chrome spheres ([`chrome`]:
//! each sphere placed by its outline, each light triangulated from its reflections).
//!
//! The estimator itself assumes distant lights and the view along +z; with near lights each
//! pixel has its own light directions, irradiances and view. docs/method.md ("Near lights and
//! perspective cameras") says how the two meet.

mod camera;
pub(crate) mod chrome;
mod depth;
mod light;
mod mesh;
mod rounds;
mod solve;
mod tiling;

pub use camera::Pinhole;
pub(crate) use light::rotation_to_z;
pub use light::PointLight;
pub use rounds::NearOutcome;
pub use solve::{NearMethod, NearParams};
