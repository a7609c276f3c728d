//! A mirror (chrome) ball as a camera records it for light calibration: an orthographic view of
//! a perfect mirror sphere anywhere in the frame (sub-pixel centre and radius), reflecting a
//! lamp of finite angular size and a dim room, each pixel the mean over a grid of points inside
//! it (the rim and the lamp's reflection anti-aliased), then blurred by the lens (a Gaussian
//! point spread of `blur` pixels): a small lamp's reflection is smaller than a pixel on most
//! balls, and only the blur spreads it over the pixels a centroid reads.
//!
//! Formula: a point `(x, y)` of the image inside the circle sees the sphere's normal
//! `n = ((x - cx) / r, -(y - cy) / r, sqrt(1 - ...))` and the reflected direction
//! `d = 2 (n.z) n - z`; its radiance is `reflectance * lamp` where `d` is within `lamp_radius`
//! of the light, else `reflectance * room * (0.5 + 0.5 d.y)` (a room lit from above). Outside
//! the circle: `background`. The pixel values are the means over `samples x samples` points,
//! convolved with a Gaussian of standard deviation `blur` pixels.
//!
//! It is independent of [`crate::calibrate`]'s geometry on purpose (its own pixel sampling and
//! its own reflection), so calibration is measured against it, not against itself.

use glam::DVec3;

use crate::brdf::microfacet::erfc;

/// A mirror ball in the frame and what it reflects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MirrorBall {
    /// Centre, x right from the image's left edge, in pixels (the top-left pixel's centre is
    /// at 0.5).
    pub cx: f64,
    /// Centre, y down from the top edge.
    pub cy: f64,
    /// Radius in pixels.
    pub r: f64,
    /// The lamp's angular radius in radians (a small LED diffuser: about 0.5 degrees).
    pub lamp_radius: f64,
    /// The lamp's radiance.
    pub lamp: f64,
    /// The room's radiance, lit from above (the lamp's reflection stands out of it).
    pub room: f64,
    /// The mirror's reflectance (a constant: chrome's Fresnel changes little below grazing).
    pub reflectance: f64,
    /// The value off the ball.
    pub background: f64,
    /// Points per pixel along each axis (4: 16 points a pixel).
    pub samples: usize,
    /// The lens's point spread, a Gaussian's standard deviation in pixels (0: none).
    pub blur: f64,
}

impl MirrorBall {
    /// A ball at `(cx, cy)` of radius `r` with a 0.5-degree lamp of radiance 2000, a room of
    /// radiance 1 (the ball stands out of a dark background), reflectance 0.8, black
    /// background, 8 x 8 points a pixel and a lens blur of 0.7 pixels.
    pub fn new(cx: f64, cy: f64, r: f64) -> Self {
        Self {
            cx,
            cy,
            r,
            lamp_radius: 0.5f64.to_radians(),
            lamp: 2000.0,
            room: 1.0,
            reflectance: 0.8,
            background: 0.0,
            samples: 8,
            blur: 0.7,
        }
    }

    /// The room's radiance a point of the image records (`None` off the ball) and whether
    /// it sees the lamp in direction `light` (unit, camera frame: x right, y up, z toward the
    /// camera).
    fn at(&self, x: f64, y: f64, light: DVec3, cos_lamp: f64) -> Option<(f64, bool)> {
        let (nx, ny) = ((x - self.cx) / self.r, -(y - self.cy) / self.r);
        let s = nx * nx + ny * ny;
        if s >= 1.0 {
            return None;
        }
        let n = DVec3::new(nx, ny, (1.0 - s).sqrt());
        let d = 2.0 * n.z * n - DVec3::Z;
        Some((
            self.reflectance * self.room * (0.5 + 0.5 * d.y),
            d.dot(light) >= cos_lamp,
        ))
    }

    /// The image (`width x height` grey values, row-major) under the lamp in direction
    /// `light`. The room and the rim: each pixel the mean of its points, then blurred; the
    /// lamp: every point of a pixel that sees it spreads its radiance by the lens's blur
    /// integrated over the pixels around (a blur after the pixels' box would lose where in a
    /// pixel a reflection smaller than it lies). Pixels far from the rim and from the lamp's
    /// reflection take one point: the room varies slowly there.
    pub fn render(&self, width: usize, height: usize, light: DVec3) -> Vec<f32> {
        let light = light.normalize();
        let cos_lamp = self.lamp_radius.cos();
        let k = self.samples.max(1);
        let mut room = vec![self.background; width * height];
        let mut hits: Vec<(f64, f64, f64)> = Vec::new();
        // Where the mirror sends the view to the lamp's centre: the pixels around it are read
        // on the finest grid whether or not a point of the coarser one sees the lamp (on a small
        // ball the lamp's reflection is smaller than the coarser grid's spacing).
        let mirror = {
            let n = (light + DVec3::Z).normalize_or(DVec3::Z);
            (n.z > 0.0).then_some((self.cx + self.r * n.x, self.cy - self.r * n.y))
        };
        for row in 0..height {
            for col in 0..width {
                let (x, y) = (col as f64 + 0.5, row as f64 + 0.5);
                let rho = ((x - self.cx).powi(2) + (y - self.cy).powi(2)).sqrt();
                if rho > self.r + 1.0 {
                    continue;
                }
                // Near the rim, or where the reflected direction moves across a pixel by more
                // than the distance to the lamp: every point.
                let fine = rho > self.r - 1.5 || {
                    let s = (rho / self.r).min(1.0);
                    let nz = (1.0 - s * s).sqrt().max(1e-3);
                    let n = DVec3::new((x - self.cx) / self.r, -(y - self.cy) / self.r, nz);
                    let d = 2.0 * nz * n - DVec3::Z;
                    // A pixel spans up to 2 / (r n.z) radians of reflected direction.
                    let span = 2.0 / (self.r * nz);
                    d.dot(light).clamp(-1.0, 1.0).acos() < self.lamp_radius + 2.0 * span
                };
                let points = pixel_points(col, row, k, fine);
                let share = 1.0 / points.len() as f64;
                let mut sum = 0.0;
                let mut lit = false;
                for (px, py) in points {
                    match self.at(px, py, light, cos_lamp) {
                        None => sum += self.background,
                        Some((r, lamp)) => {
                            sum += r;
                            lit |= lamp;
                        }
                    }
                }
                room[row * width + col] = sum * share;
                lit |=
                    mirror.is_some_and(|(mx, my)| (x - mx).abs() <= 1.5 && (y - my).abs() <= 1.5);
                // A pixel that sees the lamp: where, on a grid eight times finer (the lamp's
                // reflection is a fraction of a pixel across).
                if lit {
                    lamp_hits(
                        col,
                        row,
                        k,
                        self.reflectance,
                        self.lamp,
                        &mut hits,
                        |px, py| matches!(self.at(px, py, light, cos_lamp), Some((_, true))),
                    );
                }
            }
        }
        develop(&room, &hits, width, height, self.blur)
    }
}

/// Pushes to `hits` the points of pixel `(col, row)`, on a grid `8k` x `8k`, that `sees_lamp`,
/// each with its share of `reflectance * lamp`: one lamp reading for both mirror renders.
pub(super) fn lamp_hits(
    col: usize,
    row: usize,
    k: usize,
    reflectance: f64,
    lamp: f64,
    hits: &mut Vec<(f64, f64, f64)>,
    sees_lamp: impl Fn(f64, f64) -> bool,
) {
    let m = 8 * k;
    let share = 1.0 / (m * m) as f64;
    for q in 0..m * m {
        let (i, j) = (q / m, q % m);
        let px = col as f64 + (j as f64 + 0.5) / m as f64;
        let py = row as f64 + (i as f64 + 0.5) / m as f64;
        if sees_lamp(px, py) {
            hits.push((px, py, share * reflectance * lamp));
        }
    }
}

/// The room's pixel means blurred by the lens plus the lamp's `hits` splatted by the same blur,
/// as `f32`: one ending for both mirror renders.
pub(super) fn develop(
    room: &[f64],
    hits: &[(f64, f64, f64)],
    width: usize,
    height: usize,
    sigma: f64,
) -> Vec<f32> {
    let mut out: Vec<f32> = room.iter().map(|&v| v as f32).collect();
    blur(&mut out, width, height, sigma);
    for &(px, py, value) in hits {
        splat(&mut out, width, height, px, py, value, sigma);
    }
    out
}

/// Adds `value` at image point `(x, y)` spread by a Gaussian of standard deviation `sigma`
/// pixels, integrated over each pixel (all of it to the pixel holding the point where
/// `sigma` is 0).
pub(super) fn splat(
    img: &mut [f32],
    width: usize,
    height: usize,
    x: f64,
    y: f64,
    value: f64,
    sigma: f64,
) {
    if sigma <= 0.0 {
        let (c, r) = (x as usize, y as usize);
        if c < width && r < height {
            img[r * width + c] += value as f32;
        }
        return;
    }
    let reach = (4.0 * sigma).ceil() as isize;
    // The share of a unit Gaussian about `m` falling in the pixel `[a, a + 1)`.
    let cdf = |t: f64| 0.5 * erfc(-t / (sigma * std::f64::consts::SQRT_2));
    let share = |a: isize, m: f64| cdf(a as f64 + 1.0 - m) - cdf(a as f64 - m);
    let (c0, r0) = (x.floor() as isize, y.floor() as isize);
    for r in (r0 - reach).max(0)..=(r0 + reach).min(height as isize - 1) {
        let wy = share(r, y);
        for c in (c0 - reach).max(0)..=(c0 + reach).min(width as isize - 1) {
            img[r as usize * width + c as usize] += (value * wy * share(c, x)) as f32;
        }
    }
}

/// Convolves the `width x height` image with a Gaussian of standard deviation `sigma` pixels
/// (separable, truncated at 4 sigma, edges clamped).
pub(super) fn blur(img: &mut [f32], width: usize, height: usize, sigma: f64) {
    if sigma <= 0.0 {
        return;
    }
    let reach = (4.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-reach..=reach)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    let pass = |src: &[f32], dst: &mut [f32], along_rows: bool| {
        for row in 0..height {
            for col in 0..width {
                let mut sum = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let d = k as isize - reach;
                    let (r, c) = if along_rows {
                        (
                            row as isize,
                            (col as isize + d).clamp(0, width as isize - 1),
                        )
                    } else {
                        (
                            (row as isize + d).clamp(0, height as isize - 1),
                            col as isize,
                        )
                    };
                    sum += w * src[r as usize * width + c as usize] as f64;
                }
                dst[row * width + col] = (sum / total) as f32;
            }
        }
    };
    let mut tmp = vec![0f32; img.len()];
    pass(img, &mut tmp, true);
    pass(&tmp, img, false);
}

/// Where pixel `(col, row)` is sampled: its centre, or with `fine` a `k` x `k` grid of points
/// at the centres of its sub-pixels.
pub(super) fn pixel_points(col: usize, row: usize, k: usize, fine: bool) -> Vec<(f64, f64)> {
    if !fine {
        return vec![(col as f64 + 0.5, row as f64 + 0.5)];
    }
    (0..k * k)
        .map(|q| {
            let (i, j) = (q / k, q % k);
            (
                col as f64 + (j as f64 + 0.5) / k as f64,
                row as f64 + (i as f64 + 0.5) / k as f64,
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lamp_s_reflection_is_where_the_mirror_sends_the_view() {
        let ball = MirrorBall::new(40.3, 38.7, 30.2);
        // A light 60 degrees to the right: the mirror normal halfway, 30 degrees.
        let l = DVec3::new(60f64.to_radians().sin(), 0.0, 60f64.to_radians().cos());
        let img = ball.render(80, 80, l);
        let (i, _) = img
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        let x = (i % 80) as f64 + 0.5;
        let expect = 40.3 + 30.2 * 30f64.to_radians().sin();
        assert!((x - expect).abs() <= 1.0, "{x} vs {expect}");
        // Off the ball: background; the rim anti-aliased between it and the room.
        assert_eq!(img[0], 0.0);
        let rim = img[38 * 80 + 10];
        assert!(rim > 0.0 && rim < 0.8, "{rim}");
        // The blur keeps the total: the lamp's reflection holds its solid angle's share.
        let sharp = MirrorBall { blur: 0.0, ..ball }.render(80, 80, l);
        let total = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
        assert!((total(&img) / total(&sharp) - 1.0).abs() < 1e-3);
    }
}
