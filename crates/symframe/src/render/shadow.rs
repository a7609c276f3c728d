//! Cast shadows of height-field scenes, by marching toward the light in image space.
//!
//! Model: orthographic camera, heights in pixel units (one unit of height is one pixel width),
//! height samples at pixel centres with bilinear interpolation between them. A pixel is in cast
//! shadow from a distant light `l` when the surface, marched from the pixel toward the light's
//! image-plane direction in half-pixel steps, rises above the ray from the pixel's surface point
//! toward the light (by more than a small tolerance for the interpolation error). The march
//! stops once the ray is above the highest point of the field or leaves the frame. Beyond the
//! frame the surface is taken to continue as flat ground at height 0 (the field's base), so a
//! light at or below the horizon (`l.z <= 0`) shadows every pixel, and a light straight above
//! (`l` along z) shadows none.

use glam::DVec3;

use super::Scene;

/// Step of the march along the light's image-plane direction, in pixels.
const STEP: f64 = 0.5;
/// How far (pixel units) the surface must rise above the ray to block it.
const TOLERANCE: f64 = 0.02;

/// A shadow tester for one height field (caches the field's maximum).
pub(crate) struct ShadowTracer<'a> {
    heights: &'a [f64],
    width: usize,
    height: usize,
    max: f64,
}

impl<'a> ShadowTracer<'a> {
    /// A tracer over `heights` (`width * height`, row-major, pixel units).
    pub(crate) fn new(heights: &'a [f64], width: usize, height: usize) -> Self {
        let max = heights.iter().cloned().fold(0.0, f64::max);
        Self {
            heights,
            width,
            height,
            max,
        }
    }

    /// The bilinearly interpolated height at continuous pixel coordinates (column `u`, row `v`,
    /// pixel centres at integers), `None` outside the frame.
    fn sample(&self, u: f64, v: f64) -> Option<f64> {
        let (wm, hm) = ((self.width - 1) as f64, (self.height - 1) as f64);
        if !(0.0..=wm).contains(&u) || !(0.0..=hm).contains(&v) {
            return None;
        }
        let (c0, r0) = (u.floor() as usize, v.floor() as usize);
        let (c1, r1) = ((c0 + 1).min(self.width - 1), (r0 + 1).min(self.height - 1));
        let (fu, fv) = (u - c0 as f64, v - r0 as f64);
        let h = |c: usize, r: usize| self.heights[r * self.width + c];
        let top = h(c0, r0) * (1.0 - fu) + h(c1, r0) * fu;
        let bottom = h(c0, r1) * (1.0 - fu) + h(c1, r1) * fu;
        Some(top * (1.0 - fv) + bottom * fv)
    }

    /// Whether pixel `pixel` is in cast shadow from the unit light direction `l`.
    pub(crate) fn shadowed(&self, pixel: usize, l: DVec3) -> bool {
        if l.z <= 0.0 {
            return true;
        }
        let horizontal = l.x.hypot(l.y);
        if horizontal < 1e-12 {
            return false;
        }
        // Image-plane direction in (column, row): y up is row down.
        let (du, dv) = (l.x / horizontal, -l.y / horizontal);
        let rise = l.z / horizontal; // ray height gained per pixel travelled
        let (c, r) = ((pixel % self.width) as f64, (pixel / self.width) as f64);
        let h0 = self.heights[pixel];
        let mut s = STEP;
        loop {
            let ray = h0 + s * rise;
            if ray > self.max {
                return false;
            }
            match self.sample(c + s * du, r + s * dv) {
                None => return false,
                Some(h) if h > ray + TOLERANCE => return true,
                Some(_) => {}
            }
            s += STEP;
        }
    }
}

impl Scene {
    /// The cast-shadow mask of a height field (`width * height` heights in pixel units, row 0 at
    /// the top, `NaN` where there is no surface) under the distant light `light`, by the same
    /// march as the renderer's: how a relit image hides what an integrated relief occludes.
    /// Pixels without a height are never shadowed (and never block: `NaN` compares false).
    pub fn cast_shadows(heights: &[f64], width: usize, height: usize, light: DVec3) -> Vec<bool> {
        if width == 0 || height == 0 || heights.len() != width * height {
            return vec![false; heights.len()];
        }
        let l = light.normalize();
        let tracer = ShadowTracer::new(heights, width, height);
        (0..heights.len())
            .map(|p| heights[p].is_finite() && tracer.shadowed(p, l))
            .collect()
    }

    /// Whether pixel `pixel` is in cast shadow from the light direction `light` (module
    /// documentation); always `false` for scenes without heights. Builds a tracer per call:
    /// use [`Scene::cast_shadow_mask`] for whole images.
    pub fn in_cast_shadow(&self, pixel: usize, light: DVec3) -> bool {
        match &self.heights {
            Some(h) => {
                ShadowTracer::new(h, self.width, self.height).shadowed(pixel, light.normalize())
            }
            None => false,
        }
    }

    /// Per pixel, whether it is in cast shadow from `light` (all `false` without heights;
    /// pixels outside the mask are `false`).
    pub fn cast_shadow_mask(&self, light: DVec3) -> Vec<bool> {
        let l = light.normalize();
        match &self.heights {
            Some(h) => {
                let tracer = ShadowTracer::new(h, self.width, self.height);
                (0..self.n_pixels())
                    .map(|p| self.mask[p] && tracer.shadowed(p, l))
                    .collect()
            }
            None => vec![false; self.n_pixels()],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Bump, Scene, TangentField};
    use glam::DVec3;

    fn one_bump(size: usize) -> Scene {
        let c = size as f64 / 2.0 - 0.5;
        let bump = Bump {
            col: c,
            row: c,
            sigma: size as f64 / 8.0,
            amplitude: size as f64 / 6.0,
        };
        Scene::from_bumps(size, &[bump], TangentField::Circular)
    }

    #[test]
    fn a_grazing_light_casts_a_shadow_behind_the_bump() {
        let size = 48;
        let s = one_bump(size);
        // Light from the right, 75 degrees from the view: the shadow falls to the left.
        let a = 75f64.to_radians();
        let l = DVec3::new(a.sin(), 0.0, a.cos());
        let m = s.cast_shadow_mask(l);
        let shadowed: Vec<usize> = (0..m.len()).filter(|&p| m[p]).collect();
        assert!(shadowed.len() > 20, "{} shadowed pixels", shadowed.len());
        let mid = size / 2;
        for &p in &shadowed {
            // Left of the bump's top (with a margin for its lit flank), near its row band.
            assert!(p % size < mid, "pixel {p} shadowed on the lit side");
        }
        // The middle row: a run left of the bump, where the surface faces the light (n.l > 0)
        // but the bump blocks it.
        let row = mid * size;
        let behind: Vec<usize> = (0..mid).filter(|&c| m[row + c]).collect();
        assert!(!behind.is_empty());
        assert!(behind
            .iter()
            .any(|&c| s.normals_in_camera[row + c].dot(l) > 0.0));
        // Far from the bump on the lit side: never shadowed.
        assert!(!m[row + size - 1]);
        // The same from the other side mirrors it.
        let m2 = s.cast_shadow_mask(DVec3::new(-l.x, 0.0, l.z));
        assert_eq!(
            m2.iter().filter(|&&b| b).count(),
            shadowed.len(),
            "mirror-symmetric shadow"
        );
    }

    #[test]
    fn a_light_from_the_view_casts_no_shadow() {
        let s = one_bump(32);
        assert!(s.cast_shadow_mask(DVec3::Z).iter().all(|&b| !b));
        // Nor a light 20 degrees off: steeper than any slope of this bump.
        let a = 20f64.to_radians();
        assert!(s
            .cast_shadow_mask(DVec3::new(0.0, a.sin(), a.cos()))
            .iter()
            .all(|&b| !b));
        // Below the horizon: all shadowed.
        assert!(s.in_cast_shadow(0, DVec3::new(1.0, 0.0, -0.1)));
    }

    #[test]
    fn scenes_without_heights_have_no_cast_shadows() {
        let s = Scene::sphere(16, TangentField::Circular);
        assert!(s
            .cast_shadow_mask(DVec3::new(1.0, 0.0, 0.1))
            .iter()
            .all(|&b| !b));
        assert!(!s.in_cast_shadow(100, DVec3::new(1.0, 0.0, 0.1)));
    }

    #[test]
    fn rendering_darkens_cast_shadows_only_with_heights() {
        let s = one_bump(32);
        let a = 75f64.to_radians();
        let l = DVec3::new(a.sin(), 0.0, a.cos());
        let brdf = crate::brdf::Lambertian::new([0.8; 3]);
        let img = s.render(&brdf, l);
        let m = s.cast_shadow_mask(l);
        let mut flat = s.clone();
        flat.heights = None;
        let img_flat = flat.render(&brdf, l);
        let mut n_dark = 0;
        for p in 0..s.n_pixels() {
            if m[p] {
                assert_eq!(&img[3 * p..3 * p + 3], &[0.0; 3]);
                n_dark += (img_flat[3 * p] > 0.0) as usize;
            } else {
                assert_eq!(img[3 * p], img_flat[3 * p]);
            }
        }
        assert!(n_dark > 0, "some shadowed pixels face the light");
    }
}
