//! One image's highlight on the chrome sphere ([`Highlight::find`]): the brightest connected
//! spot, located by its centroid over a halo (small spots) or by the weighted mean of the
//! normals under it (broad ones), and the light mirrored about the normal there.

use glam::DVec3;

use super::{light_from_normal, CalibrationError, CalibrationParams, Circle};

/// A located highlight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Highlight {
    /// Centre in image pixels (x right, y down; the [`Circle`] convention).
    pub x: f64,
    /// Centre, y (down).
    pub y: f64,
    /// Sphere normal at the centre.
    pub normal: DVec3,
    /// Light direction (surface toward light).
    pub light: DVec3,
    /// Pixels in the spot.
    pub pixels: usize,
    /// Saturated pixels in the spot.
    pub saturated: usize,
    /// Peak value over the sphere's median.
    pub contrast: f64,
}

/// The margin in pixels around a highlight's spot its centroid reads: three standard
/// deviations of a typical lens blur (0.7 pixels) beyond the thresholded spot.
const HALO: usize = 3;

/// The fewest pixels above the threshold up to which a highlight's spot is located by its
/// centroid in the image (a 4 x 4 block: a lamp's reflection smaller than a pixel, blurred by
/// the lens); on a larger ball up to a square a seventh of its radius across, where the
/// ball's squeeze changes little over the spot (docs/capture.md, "Light calibration from a
/// chrome sphere", says why not a fixed size). A larger spot is located in normal space.
const SMALL_SPOT: usize = 16;

impl Highlight {
    /// Locates the highlight of a mirror sphere in one image of `width x height` grey values
    /// (linear; `NaN` = saturated). See the module documentation.
    pub fn find(
        width: usize,
        height: usize,
        grey: &[f32],
        circle: &Circle,
        params: &CalibrationParams,
    ) -> Result<Highlight, CalibrationError> {
        let (c0, c1, r0, r1) = circle.bounds(width, height);
        let mut inside = Vec::new();
        for row in r0..r1 {
            for col in c0..c1 {
                if circle.covers(col, row) {
                    inside.push(row * width + col);
                }
            }
        }
        if inside.is_empty() {
            return Err(CalibrationError::OffImage);
        }
        let mut finite: Vec<f32> = inside
            .iter()
            .map(|&i| grey[i])
            .filter(|v| v.is_finite())
            .collect();
        let saturated_any = finite.len() < inside.len();
        finite.sort_by(f32::total_cmp);
        let median = finite
            .get(finite.len() / 2)
            .copied()
            .unwrap_or(0.0)
            .max(0.0) as f64;
        let peak = finite.last().copied().unwrap_or(0.0) as f64;
        // Saturated pixels are at least as bright as anything measured, and stand out.
        let top = if saturated_any {
            peak.max(median * params.highlight_min_contrast).max(1e-6)
        } else {
            peak.max(median)
        };
        let floor = 1e-6 * top.max(1e-12);
        let contrast = top / (median + floor);
        let stands_out = contrast >= params.highlight_min_contrast && top > 0.0;
        if !(saturated_any || stands_out) {
            return Err(CalibrationError::None {
                contrast,
                min: params.highlight_min_contrast,
            });
        }
        let threshold = median + params.highlight_fraction * (top - median);
        let value = |i: usize| -> f64 {
            let v = grey[i];
            if v.is_finite() {
                v as f64
            } else {
                top
            }
        };
        let bright = |i: usize| !grey[i].is_finite() || grey[i] as f64 > threshold;
        // Connected spots (8-neighbours) among the bright sphere pixels.
        let mut seen = std::collections::HashSet::new();
        let mut spots: Vec<(f64, Vec<usize>)> = Vec::new();
        for &start in &inside {
            if !bright(start) || !seen.insert(start) {
                continue;
            }
            let mut members = vec![start];
            let mut k = 0;
            while k < members.len() {
                let i = members[k];
                k += 1;
                let (row, col) = ((i / width) as isize, (i % width) as isize);
                for dr in -1..=1 {
                    for dc in -1..=1 {
                        let (rr, cc) = (row + dr, col + dc);
                        if rr < 0 || cc < 0 || rr as usize >= height || cc as usize >= width {
                            continue;
                        }
                        let j = rr as usize * width + cc as usize;
                        if circle.covers(cc as usize, rr as usize) && bright(j) && seen.insert(j) {
                            members.push(j);
                        }
                    }
                }
            }
            let weight: f64 = members.iter().map(|&i| value(i) - threshold).sum();
            spots.push((weight, members));
        }
        spots.sort_by(|a, b| b.0.total_cmp(&a.0));
        // The spot's centre: the centroid in the image of everything above the local background
        // over the spot and a halo around it (no threshold: a thresholded centroid is pulled
        // toward the brightest pixel's centre, a tenth of a pixel and degrees of light on a small
        // ball). A lens's blur makes the spot band-limited, so its sampled centroid is its centre
        // to a few hundredths of a pixel; the mirror maps that point to the normal.
        let in_spot: std::collections::HashMap<usize, usize> = spots
            .iter()
            .enumerate()
            .flat_map(|(k, (_, m))| m.iter().map(move |&i| (i, k)))
            .collect();
        let centre = |k: usize| -> (DVec3, usize) {
            let members = &spots[k].1;
            let sat = members.iter().filter(|&&i| !grey[i].is_finite()).count();
            // A broad spot (a rough ball's lobe, a large saturated core) is squeezed toward the
            // rim in the image: its centre is the mean of the sphere normals under the spot
            // above the threshold (in normal space, as the squeeze does not pull it). A spot
            // small against the ball ([`SMALL_SPOT`]) is the blur of a lamp smaller than a
            // pixel, clipped or not: its centroid in the image.
            if members.len() as f64 > (circle.r / 7.0).powi(2).max(SMALL_SPOT as f64) {
                let mut sum = DVec3::ZERO;
                for &i in members {
                    let (x, y) = ((i % width) as f64 + 0.5, (i / width) as f64 + 0.5);
                    if let Some(n) = circle.normal_at(x, y) {
                        sum += (value(i) - threshold).max(0.0) * n;
                    }
                }
                return (sum.normalize_or(DVec3::Z), sat);
            }
            let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
            for &i in members {
                let (col, row) = (i % width, i / width);
                (x0, x1, y0, y1) = (x0.min(col), x1.max(col), y0.min(row), y1.max(row));
            }
            // The halo: pixels within HALO of the spot's box, on the sphere, in no other spot.
            // A wider spot (a clipped core) has tails as wide.
            let halo = HALO.max((x1 - x0).max(y1 - y0) / 2 + 1);
            let (x0, y0) = (x0.saturating_sub(halo), y0.saturating_sub(halo));
            let (x1, y1) = ((x1 + halo).min(width - 1), (y1 + halo).min(height - 1));
            let (mx, my) = ((x0 + x1) as f64 / 2.0, (y0 + y1) as f64 / 2.0);
            let mut window = Vec::new();
            // The local background: a plane `a + b x + c y` fitted to the window's edge (the room's
            // reflection changes across the window; a constant would pull the centroid along it).
            let mut normal_eq = [[0.0f64; 3]; 3];
            let mut rhs = [0.0f64; 3];
            for row in y0..=y1 {
                for col in x0..=x1 {
                    let i = row * width + col;
                    if !circle.covers(col, row) || in_spot.get(&i).is_some_and(|&o| o != k) {
                        continue;
                    }
                    window.push(i);
                    let edge = row == y0 || row == y1 || col == x0 || col == x1;
                    if edge && !in_spot.contains_key(&i) && grey[i].is_finite() {
                        let f = [1.0, col as f64 - mx, row as f64 - my];
                        for a in 0..3 {
                            rhs[a] += f[a] * grey[i] as f64;
                            for b in 0..3 {
                                normal_eq[a][b] += f[a] * f[b];
                            }
                        }
                    }
                }
            }
            // Too few edge pixels for a plane (a spot filling its window): the sphere's median.
            let m = glam::DMat3::from_cols_array_2d(&normal_eq);
            let plane = Some(m)
                .filter(|m| m.determinant().abs() > 1e-12 * (1.0 + normal_eq[0][0]).powi(3))
                .map(|m| (m.inverse() * DVec3::from(rhs)).to_array())
                .filter(|p| p.iter().all(|v| v.is_finite()))
                .unwrap_or([median, 0.0, 0.0]);
            let background = |i: usize| {
                let v = plane[0]
                    + plane[1] * ((i % width) as f64 - mx)
                    + plane[2] * ((i / width) as f64 - my);
                v.min(threshold)
            };
            let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
            for &i in &window {
                let w = value(i) - background(i);
                sx += w * ((i % width) as f64 + 0.5);
                sy += w * ((i / width) as f64 + 0.5);
                sw += w;
            }
            let normal = if sw > 0.0 {
                let (x, y) = (sx / sw, sy / sw);
                // A centre on the rim (a light behind the ball) is held just inside it.
                circle.normal_at(x, y).unwrap_or_else(|| {
                    let (nx, ny) = ((x - circle.cx) / circle.r, -(y - circle.cy) / circle.r);
                    DVec3::new(nx, ny, 1e-6).normalize()
                })
            } else {
                DVec3::Z
            };
            (normal, sat)
        };
        let (main_w, main) = &spots[0];
        let (normal, saturated) = centre(0);
        if let Some((second_w, _)) = spots.get(1) {
            if *second_w > params.highlight_several_ratio * main_w {
                let (n2, _) = centre(1);
                let ((x1, y1), (x2, y2)) = (circle.point_of(normal), circle.point_of(n2));
                return Err(CalibrationError::Several {
                    count: spots.len(),
                    share: 100.0 * second_w / main_w,
                    x1,
                    y1,
                    x2,
                    y2,
                });
            }
        }
        let (x, y) = circle.point_of(normal);
        Ok(Highlight {
            x,
            y,
            normal,
            light: light_from_normal(normal),
            pixels: main.len(),
            saturated,
            contrast,
        })
    }
}
