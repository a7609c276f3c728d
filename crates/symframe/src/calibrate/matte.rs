//! Light intensities from a matte (Lambertian) sphere or plane ([`CalibrationParams`]): the
//! least-squares Lambertian fit of the pixels a light reaches, the rim left out.

use glam::DVec3;

use super::{CalibrationError, CalibrationParams, Circle};

/// The RGB intensity (times the sphere's albedo) of the light `light` from a diffuse sphere of
/// circle `circle` in an RGB image (`width x height x 3`, `NaN` where saturated). The lit
/// pixels are chosen with `light` (inside the circle by at least
/// [`CalibrationParams::matte_rim_margin`], `n.l` at least
/// [`CalibrationParams::matte_min_cosine`], not saturated);
/// then, per channel, `I = b . n` is fitted by least squares over them (`n` the sphere's normal
/// at the pixel centre), refitted once without the pixels whose residual exceeds three times
/// the median one (a shadow, a highlight, a bad rim pixel), and the intensity is `|b|`. The
/// fit takes the direction from the sphere itself, so an error of the chrome sphere's light,
/// which near grazing would change `n.l` by many percent, does not enter.
pub(crate) fn matte_intensity(
    width: usize,
    height: usize,
    rgb: &[f32],
    circle: &Circle,
    light: DVec3,
    params: &CalibrationParams,
) -> Result<[f64; 3], CalibrationError> {
    let l = light.normalize();
    let inner = Circle {
        r: (circle.r - params.matte_rim_margin).max(0.0),
        ..*circle
    };
    let (x0, x1) = (
        (circle.cx - circle.r).floor().max(0.0) as usize,
        ((circle.cx + circle.r).ceil().max(0.0) as usize).min(width),
    );
    let (y0, y1) = (
        (circle.cy - circle.r).floor().max(0.0) as usize,
        ((circle.cy + circle.r).ceil().max(0.0) as usize).min(height),
    );
    let mut samples: Vec<(DVec3, [f64; 3])> = Vec::new();
    for row in y0..y1 {
        for col in x0..x1 {
            let (x, y) = (col as f64 + 0.5, row as f64 + 0.5);
            if inner.normal_at(x, y).is_none() {
                continue;
            }
            let Some(n) = circle.normal_at(x, y) else {
                continue;
            };
            let px = &rgb[3 * (row * width + col)..3 * (row * width + col) + 3];
            if n.dot(l) < params.matte_min_cosine || !px.iter().all(|v| v.is_finite()) {
                continue;
            }
            samples.push((n, [px[0] as f64, px[1] as f64, px[2] as f64]));
        }
    }
    let needed = params.matte_min_pixels.max(3);
    let too_few = |pixels: usize| CalibrationError::TooFewPixels { pixels, needed };
    if samples.len() < needed {
        return Err(too_few(samples.len()));
    }
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let all: Vec<(DVec3, f64)> = samples.iter().map(|(n, v)| (*n, v[c])).collect();
        let b = lambertian_fit(&all).ok_or_else(|| too_few(all.len()))?;
        let mut res: Vec<f64> = all.iter().map(|(n, v)| (v - b.dot(*n)).abs()).collect();
        let cut = {
            let mut r = res.clone();
            r.sort_by(f64::total_cmp);
            3.0 * r[r.len() / 2] + 1e-12
        };
        let kept: Vec<(DVec3, f64)> = all
            .iter()
            .zip(res.drain(..))
            .filter(|(_, r)| *r <= cut)
            .map(|(s, _)| *s)
            .collect();
        let b = if kept.len() >= needed {
            lambertian_fit(&kept).unwrap_or(b)
        } else {
            b
        };
        *o = b.length();
    }
    Ok(out)
}

impl CalibrationParams {
    /// The RGB intensity (times the sphere's albedo) of the distant light `light` from a
    /// diffuse sphere of circle `circle` in an RGB image (`width x height x 3`, `NaN` where
    /// saturated): `I = b . n` fitted per channel over the lit pixels, refitted without the
    /// outliers, the intensity `|b|` (the module documentation says how).
    pub fn intensity(
        &self,
        width: usize,
        height: usize,
        rgb: &[f32],
        circle: &Circle,
        light: DVec3,
    ) -> Result<[f64; 3], CalibrationError> {
        matte_intensity(width, height, rgb, circle, light, self)
    }

    /// The radiant intensity (RGB, times the sphere's albedo) of the near light `light` from a
    /// diffuse sphere of centre `centre` and radius `radius` (the camera frame of `camera`, in
    /// the light's length unit) in an RGB image (`width x height x 3`, `NaN` where saturated):
    /// `CalibrationParams::near_intensity` with the sphere's surface.
    #[allow(clippy::too_many_arguments)]
    pub fn near_sphere_intensity(
        &self,
        width: usize,
        height: usize,
        rgb: &[f32],
        camera: &crate::Pinhole,
        centre: DVec3,
        radius: f64,
        light: &crate::PointLight,
    ) -> Result<[f64; 3], CalibrationError> {
        self.near_intensity(width, height, rgb, camera, light, &|ray: DVec3| {
            // The nearer intersection of the ray `t * ray` with the sphere.
            let (a, b, c) = (
                ray.length_squared(),
                ray.dot(centre),
                centre.length_squared() - radius * radius,
            );
            let disc = b * b - a * c;
            if disc < 0.0 || radius <= 0.0 {
                return None;
            }
            let root = disc.sqrt();
            let t = (b - root) / a;
            // The cosine between the pixel's view and the sphere's normal there: pixels seeing
            // the sphere near its outline are left out.
            let facing = root / (a.sqrt() * radius);
            (t > 0.0 && facing > RIM_COSINE).then(|| {
                let p = ray * t;
                (p, (p - centre) / radius)
            })
        })
    }

    /// The radiant intensity (RGB, times the plane's albedo) of the near light `light` from a
    /// diffuse plane through `point` with unit normal `normal` (toward the camera), seen by
    /// `camera` in an RGB image (`width x height x 3`, `NaN` where saturated):
    /// `CalibrationParams::near_intensity` with the plane's surface.
    #[allow(clippy::too_many_arguments)]
    pub fn near_plane_intensity(
        &self,
        width: usize,
        height: usize,
        rgb: &[f32],
        camera: &crate::Pinhole,
        point: DVec3,
        normal: DVec3,
        light: &crate::PointLight,
    ) -> Result<[f64; 3], CalibrationError> {
        let n = normal.normalize_or_zero();
        self.near_intensity(width, height, rgb, camera, light, &|ray: DVec3| {
            let d = ray.dot(n);
            if d.abs() < 1e-12 {
                return None;
            }
            let t = point.dot(n) / d;
            (t > 0.0).then(|| (ray * t, n))
        })
    }

    /// The radiant intensity of a near light from a Lambertian surface in the frame: each pixel
    /// `(col, row)` sees the point and normal `surface(ray)` gives for its ray (`None`: not on
    /// the surface); a pixel is used where the light is at least
    /// [`CalibrationParams::matte_min_cosine`] above the surface and the camera sees its lit
    /// side; there the value is modelled as `I * E(p) * (n . l)`, `E` the light's `cos^mu / r^2` at the point
    /// ([`crate::PointLight::at`]), and `I` is fitted per channel by least squares, refitted
    /// once without the pixels whose residual exceeds three times the median one (a shadow, a
    /// highlight). The light's own intensity is not read.
    fn near_intensity(
        &self,
        width: usize,
        height: usize,
        rgb: &[f32],
        camera: &crate::Pinhole,
        light: &crate::PointLight,
        surface: &dyn Fn(DVec3) -> Option<(DVec3, DVec3)>,
    ) -> Result<[f64; 3], CalibrationError> {
        let mut samples: Vec<(f64, [f64; 3])> = Vec::new();
        for row in 0..height {
            for col in 0..width {
                let ray = camera.ray(col as f64, row as f64);
                let Some((p, n)) = surface(ray) else {
                    continue;
                };
                let Some((l, e)) = light.at(p) else {
                    continue;
                };
                let px = &rgb[3 * (row * width + col)..3 * (row * width + col) + 3];
                let cos = n.dot(l);
                if cos < self.matte_min_cosine
                    || n.dot(-p) <= 0.0
                    || e <= 0.0
                    || !px.iter().all(|v| v.is_finite())
                {
                    continue;
                }
                samples.push((e * cos, [px[0] as f64, px[1] as f64, px[2] as f64]));
            }
        }
        let needed = self.matte_min_pixels.max(3);
        let too_few = |pixels: usize| CalibrationError::TooFewPixels { pixels, needed };
        if samples.len() < needed {
            return Err(too_few(samples.len()));
        }
        let fit = |s: &[(f64, f64)]| {
            let (gg, gv) = s
                .iter()
                .fold((0.0, 0.0), |(gg, gv), &(g, v)| (gg + g * g, gv + g * v));
            (gg > 0.0).then(|| gv / gg)
        };
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let all: Vec<(f64, f64)> = samples.iter().map(|(g, v)| (*g, v[c])).collect();
            let k = fit(&all).ok_or_else(|| too_few(all.len()))?;
            let mut res: Vec<f64> = all.iter().map(|(g, v)| (v - k * g).abs()).collect();
            let cut = {
                let mut r = res.clone();
                r.sort_by(f64::total_cmp);
                3.0 * r[r.len() / 2] + 1e-12
            };
            let kept: Vec<(f64, f64)> = all
                .iter()
                .zip(res.drain(..))
                .filter(|(_, r)| *r <= cut)
                .map(|(s, _)| *s)
                .collect();
            *o = if kept.len() >= needed {
                fit(&kept).unwrap_or(k)
            } else {
                k
            };
        }
        Ok(out)
    }
}

/// A sphere's pixels whose view is at a cosine under this from the sphere's normal are left
/// out: near the outline a pixel holds some of the background.
const RIM_COSINE: f64 = 0.15;

/// The least-squares `b` of `v = b . n` over `(n, v)` samples; `None` when the normals do not
/// span three dimensions well enough to fix it.
fn lambertian_fit(samples: &[(DVec3, f64)]) -> Option<DVec3> {
    let mut ata = glam::DMat3::ZERO;
    let mut atb = DVec3::ZERO;
    for &(n, v) in samples {
        ata += glam::DMat3::from_cols(n * n.x, n * n.y, n * n.z);
        atb += n * v;
    }
    let scale = (ata.x_axis.x + ata.y_axis.y + ata.z_axis.z) / 3.0;
    if scale.is_nan() || scale <= 0.0 || ata.determinant() < 1e-9 * scale.powi(3) {
        return None;
    }
    Some(ata.inverse() * atb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_intensities_are_recovered_with_their_falloff() {
        use crate::{Pinhole, PointLight};
        let (w, h) = (64usize, 48usize);
        let camera = Pinhole::centred(w, h, 30.0);
        let (centre, radius) = (DVec3::new(0.3, -0.2, -6.0), 1.0);
        let truth = [0.7, 0.5, 0.9];
        let led = PointLight {
            position: DVec3::new(2.0, 1.5, -4.0),
            intensity: truth,
            principal: Some((centre - DVec3::new(2.0, 1.5, -4.0)).normalize()),
            mu: 1.5,
        };
        // A rendered Lambertian sphere (albedo 1) and a plane behind it, under the LED.
        let plane = (
            DVec3::new(0.0, 0.0, -9.0),
            DVec3::new(0.1, 0.0, 1.0).normalize(),
        );
        let render = |on_plane: bool| {
            let mut rgb = vec![0.0f32; w * h * 3];
            for row in 0..h {
                for col in 0..w {
                    let ray = camera.ray(col as f64, row as f64);
                    let hit = if on_plane {
                        let t = plane.0.dot(plane.1) / ray.dot(plane.1);
                        Some((ray * t, plane.1))
                    } else {
                        let (a, b) = (ray.length_squared(), ray.dot(centre));
                        let disc = b * b - a * (centre.length_squared() - radius * radius);
                        (disc >= 0.0).then(|| {
                            let p = ray * ((b - disc.sqrt()) / a);
                            (p, (p - centre) / radius)
                        })
                    };
                    if let Some((p, n)) = hit {
                        let (l, e) = led.at(p).unwrap();
                        for k in 0..3 {
                            rgb[3 * (row * w + col) + k] =
                                (truth[k] * e * n.dot(l).max(0.0)) as f32;
                        }
                    }
                }
            }
            rgb
        };
        let params = CalibrationParams::default();
        let got = params
            .near_sphere_intensity(w, h, &render(false), &camera, centre, radius, &led)
            .unwrap();
        for k in 0..3 {
            assert!((got[k] / truth[k] - 1.0).abs() < 0.01, "sphere {got:?}");
        }
        let got = params
            .near_plane_intensity(w, h, &render(true), &camera, plane.0, plane.1, &led)
            .unwrap();
        for k in 0..3 {
            assert!((got[k] / truth[k] - 1.0).abs() < 0.01, "plane {got:?}");
        }
        // Without the falloff (an isotropic light at the same place), the sphere's answer is
        // off: the cos^mu is in the pixels, not in the model.
        let iso = PointLight::isotropic(led.position);
        let off = params
            .near_sphere_intensity(w, h, &render(false), &camera, centre, radius, &iso)
            .unwrap();
        assert!((off[0] / truth[0] - 1.0).abs() > 0.02, "{off:?}");
        // A light behind the sphere leaves too few pixels.
        let behind = PointLight::isotropic(DVec3::new(0.3, -0.2, -12.0));
        assert!(matches!(
            params.near_sphere_intensity(w, h, &render(false), &camera, centre, radius, &behind),
            Err(CalibrationError::TooFewPixels { .. })
        ));
    }

    #[test]
    fn matte_intensity_recovers_a_lambertian_sphere_s_light() {
        let (w, h) = (48usize, 40usize);
        let c = Circle {
            cx: 24.0,
            cy: 20.0,
            r: 16.0,
        };
        let l = DVec3::new(0.4, -0.3, 0.6).normalize();
        let e = [0.7, 0.5, 0.9];
        let mut rgb = vec![0.0f32; w * h * 3];
        for row in 0..h {
            for col in 0..w {
                if let Some(n) = c.normal_at(col as f64 + 0.5, row as f64 + 0.5) {
                    for k in 0..3 {
                        rgb[3 * (row * w + col) + k] = (e[k] * n.dot(l).max(0.0)) as f32;
                    }
                }
            }
        }
        // A few saturated and shadowed pixels do not move the median.
        for p in [3 * (20 * w + 24), 3 * (21 * w + 25)] {
            rgb[p..p + 3].fill(f32::NAN);
        }
        rgb[3 * (18 * w + 22)..3 * (18 * w + 22) + 3].fill(0.0);
        let got = matte_intensity(w, h, &rgb, &c, l, &CalibrationParams::default()).unwrap();
        for k in 0..3 {
            assert!((got[k] - e[k]).abs() < 1e-5, "{got:?}");
        }
        // A light from behind leaves too few pixels.
        let back = DVec3::new(0.0, 0.0, -1.0);
        assert!(matches!(
            matte_intensity(w, h, &rgb, &c, back, &CalibrationParams::default()),
            Err(CalibrationError::TooFewPixels { .. })
        ));
    }
}
