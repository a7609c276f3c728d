//! The sphere found in the images when its circle is not given ([`Detection::find`]), and its
//! outline: the circle refined to the rim's steepest fall along rays from the centre and a
//! robust circle fit to those points.

use glam::DVec3;

use super::Circle;
use crate::regions::{label_regions, OUTSIDE};

/// What [`Detection::find`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// The circle.
    pub circle: Circle,
    /// Share of the images whose brightest spot lies in the region.
    pub highlight_share: f64,
    /// Intersection over union of the region and its circle (1 = perfectly round).
    pub roundness: f64,
}

/// The connected regions of the mean image `mean` (`width x height`) brighter than its
/// background, the median of the image's border (non-finite values count as the brightest):
/// each pixel's label ([`OUTSIDE`] for the background), each region's size, and the image's
/// largest finite value.
fn bright_regions(width: usize, height: usize, mean: &[f32]) -> Result<BrightRegions, String> {
    if width < 3 || height < 3 || mean.len() != width * height {
        return Err("the images are too small to find a sphere in".into());
    }
    if mean.len() >= u32::MAX as usize {
        return Err("the images are too large to find a sphere in".into());
    }
    let top = mean
        .iter()
        .filter(|v| v.is_finite())
        .cloned()
        .fold(0.0f32, f32::max) as f64;
    let value = |i: usize| finite_or(mean, top, i);
    let mut border: Vec<f64> = (0..width * height)
        .filter(|&i| {
            let (r, c) = (i / width, i % width);
            r < 2 || c < 2 || r + 2 >= height || c + 2 >= width
        })
        .map(value)
        .collect();
    border.sort_by(f64::total_cmp);
    let level = border[border.len() / 2];
    let threshold = level + 1e-3 * (top - level).max(0.0) + 1e-9 * top;
    let on = |i: usize| value(i) > threshold;
    let (label, sizes) = label_regions(width, height, on).ok_or("the images are too large")?;
    Ok((label, sizes, top))
}

/// Labels, region sizes and the largest value of [`bright_regions`].
type BrightRegions = (Vec<u32>, Vec<usize>, f64);

/// `mean[i]`, or `top` where it is not finite (a clipped or broken pixel counts as bright).
fn finite_or(mean: &[f32], top: f64, i: usize) -> f64 {
    if mean[i].is_finite() {
        mean[i] as f64
    } else {
        top
    }
}

impl Detection {
    /// Finds a mirror sphere from the mean of all images (`width x height` grey values, `NaN` =
    /// saturated somewhere) and the brightest point of each image (pixel indices). See the module
    /// documentation. `Err` says why none was found.
    pub fn find(
        width: usize,
        height: usize,
        mean: &[f32],
        brightest: &[usize],
    ) -> Result<Detection, String> {
        let (label, sizes, top) = bright_regions(width, height, mean)?;
        let value = |i: usize| finite_or(mean, top, i);
        if sizes.is_empty() {
            return Err("nothing in the images is brighter than their border".into());
        }
        let mut votes = vec![0usize; sizes.len()];
        for &b in brightest {
            if let Some(&l) = label.get(b) {
                if l != OUTSIDE {
                    votes[l as usize] += 1;
                }
            }
        }
        let (best, &count) = votes
            .iter()
            .enumerate()
            .max_by_key(|(_, v)| **v)
            .ok_or("no region")?;
        let share = count as f64 / brightest.len().max(1) as f64;
        if count == 0 {
            return Err("no bright region holds the images' brightest spots".into());
        }
        let (circle, n, roundness) = region_circle(width, height, &label, best as u32, &value);
        if roundness < 0.9 {
            return Err(format!(
                "the region holding the brightest spots (centre {:.1}, {:.1}, {} pixels) is not \
             round (overlap with its circle {:.2})",
                circle.cx, circle.cy, n, roundness
            ));
        }
        Ok(Detection {
            circle,
            highlight_share: share,
            roundness,
        })
    }
}

/// The circle of region `best` of `label` (its centroid and the radius of a disc of its area,
/// then fitted to its rim in the image `value`), its pixel count and its roundness (the
/// intersection over union of the region and that first circle).
fn region_circle(
    width: usize,
    height: usize,
    label: &[u32],
    best: u32,
    value: &dyn Fn(usize) -> f64,
) -> (Circle, usize, f64) {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for (i, &l) in label.iter().enumerate() {
        if l == best {
            sx += (i % width) as f64 + 0.5;
            sy += (i / width) as f64 + 0.5;
            n += 1;
        }
    }
    let circle = Circle {
        cx: sx / n as f64,
        cy: sy / n as f64,
        r: (n as f64 / std::f64::consts::PI).sqrt(),
    };
    let (c0, c1, r0, r1) = circle.bounds(width, height);
    let mut in_circle = 0usize;
    let mut both = 0usize;
    for row in r0..r1 {
        for col in c0..c1 {
            if circle.covers(col, row) {
                in_circle += 1;
                both += usize::from(label[row * width + col] == best);
            }
        }
    }
    let union = n + in_circle - both;
    let roundness = both as f64 / union.max(1) as f64;
    // The region's circle is whole pixels: its rim is wherever the blurred edge crossed a
    // threshold near the background. The rim itself, to a few hundredths of a pixel: fitted
    // to where the mean image falls off most steeply along rays from the centre.
    let circle = refine_circle(width, height, value, circle).map_or(circle, |(c, _)| c);
    (circle, n, roundness)
}

/// The fewest pixels a region must have for [`Detection::find_all`] to take it for a sphere.
const MIN_SPHERE_PIXELS: usize = 50;

impl Detection {
    /// Finds every mirror sphere in the images for a calibration with two or more spheres: as
    /// [`Detection::find`] finds one (the connected regions brighter than the image border in the
    /// mean image `mean`), every region at least `MIN_SPHERE_PIXELS` large, round (roundness
    /// 0.9) and holding at least `min_share` of the images' brightest spots (`brightest`), largest
    /// share first. `Err` says why none was found.
    pub fn find_all(
        width: usize,
        height: usize,
        mean: &[f32],
        brightest: &[usize],
        min_share: f64,
    ) -> Result<Vec<Detection>, String> {
        let (label, sizes, top) = bright_regions(width, height, mean)?;
        let value = |i: usize| finite_or(mean, top, i);
        let mut votes = vec![0usize; sizes.len()];
        for &b in brightest {
            if let Some(&l) = label.get(b) {
                if l != OUTSIDE {
                    votes[l as usize] += 1;
                }
            }
        }
        let total = brightest.len().max(1) as f64;
        let mut found = Vec::new();
        for (region, &count) in votes.iter().enumerate() {
            let share = count as f64 / total;
            if share < min_share || sizes[region] < MIN_SPHERE_PIXELS {
                continue;
            }
            let (circle, _, roundness) =
                region_circle(width, height, &label, region as u32, &value);
            if roundness >= 0.9 {
                found.push(Detection {
                    circle,
                    highlight_share: share,
                    roundness,
                });
            }
        }
        if found.is_empty() {
            return Err(format!(
                "no round region of at least {MIN_SPHERE_PIXELS} pixels brighter than the images' \
             border holds {:.0}% of their brightest spots",
                100.0 * min_share
            ));
        }
        found.sort_by(|a, b| b.highlight_share.total_cmp(&a.highlight_share));
        Ok(found)
    }
}

impl Circle {
    /// This sphere's outline in the image `image` (`width x height` grey values, `NaN`
    /// counting as the brightest), this circle the start: the points where its rim falls off
    /// most steeply (outliers left out) and the circle fitted to them; `None` where too few
    /// rays find the rim.
    pub fn outline(
        &self,
        width: usize,
        height: usize,
        image: &[f32],
    ) -> Option<(Circle, Vec<(f64, f64)>)> {
        outline_points(width, height, image, *self)
    }
}

/// A sphere's outline in the image `image` (`width x height` grey values, `NaN` counting as
/// the brightest) near `start`: the points where its rim falls off most steeply, as
/// [`Detection::find`] refines a circle (outliers left out), and the circle fitted to them;
/// `None` where too few rays find the rim.
pub(crate) fn outline_points(
    width: usize,
    height: usize,
    image: &[f32],
    start: Circle,
) -> Option<(Circle, Vec<(f64, f64)>)> {
    if width == 0 || height == 0 || image.len() != width * height {
        return None;
    }
    let top = image
        .iter()
        .filter(|v| v.is_finite())
        .cloned()
        .fold(0.0f32, f32::max) as f64;
    let value = |i: usize| -> f64 {
        if image[i].is_finite() {
            image[i] as f64
        } else {
            top
        }
    };
    refine_circle(width, height, &value, start)
}

/// The circle fitted to the rim of a bright disc in an image (`value(i)` at pixel `i`) near
/// `start`: along rays from the centre, the outermost local steepest fall that stands out of
/// the background's noise (six robust deviations; a thousandth of the ray's steepest where the
/// background is exact) (the rim: everything beyond it is background; a highlight or shading
/// near the rim falls off inside it, and a rim may be dim beside them), to a quarter pixel by bilinear sampling and
/// then by a parabola through the steepest three; a circle fitted to those points (Kasa's
/// algebraic fit, then least squares of the distances by Gauss-Newton), points more than 3
/// robust deviations off it (a highlight on the rim, the object touching it) left out, three
/// rounds from the new centre; with the points of the last round that were kept. `None` where
/// too few rays find a rim.
fn refine_circle(
    width: usize,
    height: usize,
    value: &dyn Fn(usize) -> f64,
    start: Circle,
) -> Option<(Circle, Vec<(f64, f64)>)> {
    // Bilinear between pixel centres (at +0.5), edges clamped.
    let sample = |x: f64, y: f64| -> f64 {
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let at = |c: f64, r: f64| {
            let c = c.clamp(0.0, width as f64 - 1.0) as usize;
            let r = r.clamp(0.0, height as f64 - 1.0) as usize;
            value(r * width + c)
        };
        let top = at(x0, y0) * (1.0 - tx) + at(x0 + 1.0, y0) * tx;
        let bottom = at(x0, y0 + 1.0) * (1.0 - tx) + at(x0 + 1.0, y0 + 1.0) * tx;
        top * (1.0 - ty) + bottom * ty
    };
    const STEP: f64 = 0.25;
    let mut circle = start;
    let mut kept_points = Vec::new();
    for _ in 0..3 {
        let reach = 6.0f64.max(0.1 * circle.r);
        let rays = ((2.0 * std::f64::consts::PI * circle.r).ceil() as usize).clamp(64, 2048);
        let steps = (2.0 * reach / STEP) as usize;
        let mut points = Vec::with_capacity(rays);
        let mut profile = vec![0.0; steps + 1];
        for k in 0..rays {
            let a = k as f64 / rays as f64 * std::f64::consts::TAU;
            let (dx, dy) = (a.cos(), a.sin());
            let rho0 = (circle.r - reach).max(1.0);
            for (j, p) in profile.iter_mut().enumerate() {
                let rho = rho0 + j as f64 * STEP;
                *p = sample(circle.cx + rho * dx, circle.cy + rho * dy);
            }
            // The fall over one pixel, centred at each step.
            let span = (0.5 / STEP) as usize;
            let fall = |j: usize| profile[j - span] - profile[j + span];
            let inner = span..steps + 1 - span;
            let steepest = inner.clone().map(fall).fold(0.0, f64::max);
            if steepest.is_nan() || steepest <= 0.0 {
                continue;
            }
            // What the background's noise makes of a fall: the robust spread over the outer
            // quarter of the ray (beyond the rim).
            let mut outer: Vec<f64> = inner
                .clone()
                .skip(3 * (inner.end - inner.start) / 4)
                .map(|j| fall(j).abs())
                .collect();
            outer.sort_by(f64::total_cmp);
            let noise = 1.4826 * outer.get(outer.len() / 2).copied().unwrap_or(0.0);
            let significant = (1e-3 * steepest).max(6.0 * noise);
            let Some(j) = inner.clone().rev().find(|&j| {
                let f = fall(j);
                f >= significant
                    && (j + 1 >= inner.end || f >= fall(j + 1))
                    && (j == inner.start || f >= fall(j - 1))
            }) else {
                continue;
            };
            // A parabola through the fall at j - 1, j, j + 1 (where all three exist).
            let offset = if j > inner.start && j + 1 < inner.end {
                let (a, b, c) = (fall(j - 1), fall(j), fall(j + 1));
                let d = a - 2.0 * b + c;
                if d < 0.0 {
                    (0.5 * (a - c) / d).clamp(-1.0, 1.0)
                } else {
                    0.0
                }
            } else {
                0.0
            };
            let rho = rho0 + (j as f64 + offset) * STEP;
            // The edge of a blurred step whose inside varies (the room's reflection changes
            // fast near a mirror's rim: the steepest fall alone is pulled along that slope).
            let window: Vec<(f64, f64)> = profile
                .iter()
                .enumerate()
                .map(|(i, &v)| (rho0 + i as f64 * STEP, v))
                .filter(|(r, _)| (r - rho).abs() <= EDGE_WINDOW)
                .collect();
            let rho = fit_edge(&window, rho).unwrap_or(rho);
            points.push((circle.cx + rho * dx, circle.cy + rho * dy));
        }
        let mut keep = vec![true; points.len()];
        for _ in 0..3 {
            let kept: Vec<(f64, f64)> = points
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| *p)
                .collect();
            if kept.len() < 16 || kept.len() * 2 < rays {
                return None;
            }
            circle = fit_circle(&kept, circle)?;
            let mut residuals: Vec<f64> = points
                .iter()
                .map(|&(x, y)| ((x - circle.cx).hypot(y - circle.cy) - circle.r).abs())
                .collect();
            let mut sorted = residuals.clone();
            sorted.sort_by(f64::total_cmp);
            let mad = sorted[sorted.len() / 2];
            let limit = (3.0 * 1.4826 * mad).max(0.05);
            for (k, r) in keep.iter_mut().zip(residuals.drain(..)) {
                *k = r <= limit;
            }
        }
        kept_points = points
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .collect();
    }
    (circle.r > 0.0 && circle.cx.is_finite() && circle.cy.is_finite())
        .then_some((circle, kept_points))
}

/// Half the width of a ray's profile [`fit_edge`] reads, in pixels.
const EDGE_WINDOW: f64 = 2.5;

/// The edge `e` of a blurred step fitted to a profile `(rho, value)` near `start`: `c + (a +
/// b (rho - e)) Phi((e - rho) / s)` (outside level `c`, inside level `c + a` at the edge with
/// slope `b`, a Gaussian blur `s`) by Gauss-Newton with Levenberg-Marquardt damping. `None`
/// where it does not settle within a pixel of `start`.
fn fit_edge(profile: &[(f64, f64)], start: f64) -> Option<f64> {
    use crate::brdf::microfacet::erfc;
    if profile.len() < 8 {
        return None;
    }
    let phi = |u: f64| 0.5 * erfc(-u / std::f64::consts::SQRT_2);
    let density = |u: f64| (-0.5 * u * u).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let outside = profile.last()?.1;
    let inside = profile.first()?.1;
    // [c, a, b, e, s]
    let mut p = [outside, inside - outside, 0.0, start, 0.8];
    let cost = |p: &[f64; 5]| -> f64 {
        profile
            .iter()
            .map(|&(r, v)| {
                let u = (p[3] - r) / p[4];
                (v - p[0] - (p[1] + p[2] * (r - p[3])) * phi(u)).powi(2)
            })
            .sum()
    };
    let mut current = cost(&p);
    let mut lambda = 1e-3;
    for _ in 0..30 {
        let mut jtj = [[0.0f64; 5]; 5];
        let mut jtr = [0.0f64; 5];
        for &(r, v) in profile {
            let u = (p[3] - r) / p[4];
            let (f, d) = (phi(u), density(u));
            let inner = p[1] + p[2] * (r - p[3]);
            let j = [
                1.0,
                f,
                (r - p[3]) * f,
                -p[2] * f + inner * d / p[4],
                -inner * d * u / p[4],
            ];
            let res = v - p[0] - inner * f;
            for a in 0..5 {
                jtr[a] += j[a] * res;
                for b in 0..5 {
                    jtj[a][b] += j[a] * j[b];
                }
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut m = jtj;
            for (k, row) in m.iter_mut().enumerate() {
                row[k] += lambda * jtj[k][k].max(1e-12);
            }
            let Some(step) = solve_small(m, jtr) else {
                lambda *= 10.0;
                continue;
            };
            let mut q = p;
            for k in 0..5 {
                q[k] += step[k];
            }
            q[4] = q[4].clamp(0.2, 3.0);
            let c = cost(&q);
            if c < current {
                let gain = current - c;
                (p, current) = (q, c);
                lambda = (lambda * 0.3).max(1e-9);
                improved = gain > 1e-12 * (1.0 + current);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    ((p[3] - start).abs() <= 1.0 && p[1] > 0.0).then_some(p[3])
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None` where singular.
fn solve_small<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].is_nan() || a[pivot][col].abs() <= 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..N {
            let f = a[row][col] / pivot_row[col];
            for (v, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *v -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let tail: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - tail) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The circle through `points` (at least three): Kasa's algebraic fit (`x^2 + y^2 + D x +
/// E y + F = 0` by linear least squares), then five Gauss-Newton steps on the distances;
/// `start` where the algebraic system is singular.
fn fit_circle(points: &[(f64, f64)], start: Circle) -> Option<Circle> {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let mut m = [[0.0f64; 3]; 3];
    let mut rhs = [0.0f64; 3];
    for &(x, y) in points {
        let (u, v) = (x - mx, y - my);
        let f = [u, v, 1.0];
        let z = -(u * u + v * v);
        for a in 0..3 {
            rhs[a] += f[a] * z;
            for b in 0..3 {
                m[a][b] += f[a] * f[b];
            }
        }
    }
    let mat = glam::DMat3::from_cols_array_2d(&m);
    let mut c = if mat.determinant().abs() > 1e-12 * n.powi(3) {
        let [d, e, f] = (mat.inverse() * DVec3::from(rhs)).to_array();
        let (cx, cy) = (-d / 2.0, -e / 2.0);
        let r2 = cx * cx + cy * cy - f;
        if r2 > 0.0 {
            Circle {
                cx: cx + mx,
                cy: cy + my,
                r: r2.sqrt(),
            }
        } else {
            start
        }
    } else {
        start
    };
    for _ in 0..5 {
        let mut jtj = [[0.0f64; 3]; 3];
        let mut jtr = [0.0f64; 3];
        for &(x, y) in points {
            let d = (x - c.cx).hypot(y - c.cy);
            if d <= 0.0 {
                continue;
            }
            let j = [-(x - c.cx) / d, -(y - c.cy) / d, -1.0];
            let r = d - c.r;
            for a in 0..3 {
                jtr[a] += j[a] * r;
                for b in 0..3 {
                    jtj[a][b] += j[a] * j[b];
                }
            }
        }
        let mat = glam::DMat3::from_cols_array_2d(&jtj);
        if mat.determinant().abs() <= 1e-300 {
            break;
        }
        let step = mat.inverse() * DVec3::from(jtr);
        c = Circle {
            cx: c.cx - step.x,
            cy: c.cy - step.y,
            r: c.r - step.z,
        };
    }
    (c.r > 0.0 && c.cx.is_finite() && c.cy.is_finite()).then_some(c)
}
