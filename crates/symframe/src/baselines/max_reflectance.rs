//! The max-reflectance ("specularity") baseline: the normal is the halfway vector where the
//! slice is brightest, refined between the samples.

use glam::DVec3;

use super::{brightest, grey, BaselinePixel};
use crate::geometry::{halfway_from_light, tangent_basis};
use crate::maps::PixelStatus;

/// Neighbours of the brightest sample (in halfway space) that the max-reflectance refinement
/// fits over, besides the brightest sample itself.
pub(crate) const MAX_REFLECTANCE_NEIGHBOURS: usize = 12;

/// The max-reflectance ("specularity") method at one pixel: the normal is the halfway vector
/// `h = normalize(l + v)` where the slice is brightest. Refinement between samples:
///
/// 1. take the brightest valid sample `j` and the [`MAX_REFLECTANCE_NEIGHBOURS`] valid,
///    positive samples whose halfway vectors are nearest to `h_j`;
/// 2. map their halfway vectors to the gnomonic chart of the tangent plane at `h_j` and fit
///    `ln I = c0 + c1 u + c2 w + c3 u^2 + c4 u w + c5 w^2` by least squares (exact for a
///    Gaussian lobe: Beckmann-like highlights are quadratic in log space);
/// 3. the normal is the chart point of the fitted maximum; if the fit is degenerate, not a
///    maximum, or its peak lies outside the neighbourhood, it is `h_j` itself.
///
/// So the answer is exact for a highlight centred on the normal sampled densely enough, and
/// within the lights' spacing otherwise. It assumes the peak of the slice is a mirror-like
/// highlight: on a diffuse surface the brightest light is along the normal, so the halfway
/// vector lies halfway between the normal and the view (an error of half the normal's angle
/// from the view; the paper's Figure 4).
///
/// Confidence: the highlight's contrast, `1 - mean / max` of the valid grey values (near 1 for
/// a sharp highlight, about 0.5 for a diffuse surface under lights spread over a wide cone).
/// Allocation-free.
pub(crate) fn max_reflectance_pixel(samples: &[f32], lights: &[DVec3]) -> BaselinePixel {
    let Some((j, max)) = brightest(samples) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    let Some(hj) = halfway_from_light(lights[j]) else {
        return BaselinePixel::empty(PixelStatus::Discarded);
    };
    let (near, mean) = peak_neighbours(samples, lights, j, hj);
    let confidence = (1.0 - mean / max).clamp(0.0, 1.0) as f32;
    let normal = refine_peak(samples, lights, hj, max, &near).unwrap_or(hj);
    if normal.z <= 0.0 {
        return BaselinePixel::empty(PixelStatus::Discarded);
    }
    let used = 1 + near.iter().filter(|n| n.1 != usize::MAX).count() as u32;
    BaselinePixel {
        status: PixelStatus::Estimated,
        normal: Some(normal),
        tangent: None,
        confidence,
        used,
        considered: used,
    }
}

/// The [`MAX_REFLECTANCE_NEIGHBOURS`] valid, positive samples whose halfway vectors are nearest
/// to `hj` (the brightest sample `j`'s), as `(cos to hj, index)` sorted nearest first (index
/// `usize::MAX` where there are fewer), and the mean grey value of the valid samples.
fn peak_neighbours(
    samples: &[f32],
    lights: &[DVec3],
    j: usize,
    hj: DVec3,
) -> ([(f64, usize); MAX_REFLECTANCE_NEIGHBOURS], f64) {
    const K: usize = MAX_REFLECTANCE_NEIGHBOURS;
    let mut near = [(f64::NEG_INFINITY, usize::MAX); K];
    let (mut sum, mut count) = (0.0, 0usize);
    for (i, (s, &l)) in samples.chunks_exact(3).zip(lights).enumerate() {
        let Some(v) = grey(s) else { continue };
        sum += v;
        count += 1;
        if i == j || v <= 0.0 {
            continue;
        }
        let Some(h) = halfway_from_light(l) else {
            continue;
        };
        let c = h.dot(hj);
        if c > near[K - 1].0 {
            let mut k = K - 1;
            while k > 0 && near[k - 1].0 < c {
                near[k] = near[k - 1];
                k -= 1;
            }
            near[k] = (c, i);
        }
    }
    (near, sum / count.max(1) as f64)
}

/// The log-quadratic peak of a pixel's slice ([`max_reflectance_pixel`]'s refinement): the
/// centre of a Gaussian reconstruction of the lobe around the brightest sample; `None` where
/// there is no valid sample, or the fit is degenerate or not a maximum near the brightest
/// sample. Allocation-free.
pub(crate) fn highlight_peak(samples: &[f32], lights: &[DVec3]) -> Option<DVec3> {
    let (j, max) = brightest(samples)?;
    let hj = halfway_from_light(lights[j])?;
    let (near, _) = peak_neighbours(samples, lights, j, hj);
    refine_peak(samples, lights, hj, max, &near)
}

/// Step 2-3 of [`max_reflectance_pixel`]: the log-quadratic peak near `hj`, if well defined.
fn refine_peak(
    samples: &[f32],
    lights: &[DVec3],
    hj: DVec3,
    max: f64,
    near: &[(f64, usize); MAX_REFLECTANCE_NEIGHBOURS],
) -> Option<DVec3> {
    let (e1, e2) = tangent_basis(hj);
    let chart = |h: DVec3| {
        let d = h.dot(hj);
        (h.dot(e1) / d, h.dot(e2) / d)
    };
    // Chart radius of the neighbourhood: coordinates are scaled by it for conditioning.
    let mut radius = 0.0f64;
    let mut n_pts = 1;
    for &(c, i) in near.iter().filter(|n| n.1 != usize::MAX) {
        if c <= 0.0 {
            continue;
        }
        let (u, w) = chart(halfway_from_light(lights[i])?);
        radius = radius.max(u.hypot(w));
        n_pts += 1;
    }
    if n_pts < 7 || radius <= 0.0 {
        return None;
    }
    // Normal equations of the 6-parameter fit, augmented: [A | b].
    let mut m = [[0.0f64; 7]; 6];
    let mut add = |u: f64, w: f64, y: f64| {
        let phi = [1.0, u, w, u * u, u * w, w * w];
        for r in 0..6 {
            for c in 0..6 {
                m[r][c] += phi[r] * phi[c];
            }
            m[r][6] += phi[r] * y;
        }
    };
    add(0.0, 0.0, max.ln());
    for &(c, i) in near.iter().filter(|n| n.1 != usize::MAX) {
        if c <= 0.0 {
            continue;
        }
        let (u, w) = chart(halfway_from_light(lights[i])?);
        let y = grey(&samples[i * 3..i * 3 + 3])?;
        add(u / radius, w / radius, y.ln());
    }
    let c = solve6(m)?;
    // Stationary point: H p = -grad, H = [[2 c3, c4], [c4, 2 c5]] must be negative definite.
    let (h11, h12, h22) = (2.0 * c[3], c[4], 2.0 * c[5]);
    let det = h11 * h22 - h12 * h12;
    if !(h11 < 0.0 && det > 0.0) {
        return None;
    }
    let pu = (-c[1] * h22 + c[2] * h12) / det;
    let pw = (-c[2] * h11 + c[1] * h12) / det;
    let step = pu.hypot(pw);
    if step.is_nan() || step > 1.0 {
        return None;
    }
    (hj + radius * (pu * e1 + pw * e2)).try_normalize()
}

/// Solves a 6x6 system given as an augmented matrix by Gaussian elimination with partial
/// pivoting; `None` if (numerically) singular.
fn solve6(mut m: [[f64; 7]; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|k| m[k][k].abs()).fold(0.0, f64::max);
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for col in 0..6 {
        let piv = (col..6).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[piv][col].is_nan() || m[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(col, piv);
        let pivot_row = m[col];
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (v, p) in row.iter_mut().zip(pivot_row).skip(col) {
                *v -= f * p;
            }
        }
    }
    let mut x = [0.0f64; 6];
    for r in (0..6).rev() {
        let mut v = m[r][6];
        for c in r + 1..6 {
            v -= m[r][c] * x[c];
        }
        x[r] = v / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}
