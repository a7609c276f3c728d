//! Halfway-vector geometry for the fixed view: light <-> halfway vector, the stereographic
//! projection of the cone, and a tangent-plane basis for a normal.

use glam::{DVec2, DVec3};

/// The view vector of every pixel (orthographic camera looking down -z).
pub(crate) const VIEW: DVec3 = DVec3::Z;

/// The light that a halfway vector corresponds to for the fixed view: `l(h) = 2 (v.h) h - v`.
#[inline]
pub(crate) fn light_from_halfway(halfway: DVec3) -> DVec3 {
    2.0 * halfway.z * halfway - VIEW
}

/// The halfway vector of a light for the fixed view, `normalize(l + v)`; `None` for `l = -v`.
#[inline]
pub(crate) fn halfway_from_light(light: DVec3) -> Option<DVec3> {
    (light + VIEW).try_normalize()
}

/// The unit vector whose stereographic projection `(h.x, h.y) / (1 + h.z)` is `s` (nearly even
/// in angle over a 65-degree cone: its scale varies from 0.5 to 0.7).
#[inline]
pub(crate) fn from_stereographic(s: DVec2) -> DVec3 {
    let r2 = s.length_squared();
    DVec3::new(2.0 * s.x, 2.0 * s.y, 1.0 - r2) / (1.0 + r2)
}

/// An orthonormal tangent-plane basis (u, w) for a unit normal, continuous away from `n = -z`.
#[inline]
pub(crate) fn tangent_basis(n: DVec3) -> (DVec3, DVec3) {
    // Rotate the camera x and y axes along the great circle from z to n.
    let k = 1.0 / (1.0 + n.z);
    let u = DVec3::new(1.0 - n.x * n.x * k, -n.x * n.y * k, -n.x);
    let w = DVec3::new(-n.x * n.y * k, 1.0 - n.y * n.y * k, -n.y);
    (u, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::uniform_cone_lights;

    #[test]
    fn light_and_halfway_are_inverse() {
        for l in uniform_cone_lights(50, 65.0) {
            let h = halfway_from_light(l).unwrap();
            assert!((light_from_halfway(h) - l).length() < 1e-12);
        }
    }
}
