//! Error figures of estimated maps against ground truth: normal angular error, tangent axis
//! error (`acos |t . t_gt|`, and with t and b allowed to swap), coverage.

use glam::DVec3;
use serde::Serialize;

/// Summary statistics of an angular error, degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct ErrorStats {
    /// Number of pixels the statistics are over.
    pub count: usize,
    /// Mean error.
    pub mean: f64,
    /// Median error.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// Largest error.
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of a list of errors (consumed for sorting). NaN statistics for an empty list.
    pub fn of(mut errors: Vec<f64>) -> Self {
        if errors.is_empty() {
            return Self {
                count: 0,
                mean: f64::NAN,
                median: f64::NAN,
                p90: f64::NAN,
                max: f64::NAN,
            };
        }
        errors.sort_by(f64::total_cmp);
        let n = errors.len();
        let q = |p: f64| errors[((p * (n - 1) as f64).round() as usize).min(n - 1)];
        Self {
            count: n,
            mean: errors.iter().sum::<f64>() / n as f64,
            median: q(0.5),
            p90: q(0.9),
            max: errors[n - 1],
        }
    }
}

/// How estimated maps compare with ground truth over the evaluated pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Evaluation {
    /// Only pixels whose true normal is within this angle of the view are evaluated (degrees).
    pub max_normal_angle_deg: f64,
    /// Pixels evaluated (valid ground truth inside the angle).
    pub pixels: usize,
    /// Share of those with a normal estimate.
    pub coverage: f64,
    /// Normal angular error.
    pub normal_error: ErrorStats,
    /// Share of estimated pixels that have a tangent.
    pub tangent_coverage: f64,
    /// Tangent axis error `acos |t . t_gt|`.
    pub tangent_error: ErrorStats,
    /// Tangent axis error when t and b may swap (judges the frame, not the t/b heuristic).
    pub tangent_error_swap_free: ErrorStats,
    /// Share of tangents closer to the true binormal than to the true tangent.
    pub swapped_share: f64,
}

/// Reads the unit vector at pixel `p` of an `H x W x 3` map; `None` for NaN or zero
/// ([`EstimateMaps::vec_at`](crate::EstimateMaps::vec_at) outside the crate).
pub(crate) fn vec_at(v: &[f32], p: usize) -> Option<DVec3> {
    let s = &v[p * 3..p * 3 + 3];
    s.iter()
        .all(|x| x.is_finite())
        .then(|| DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64))
        .and_then(|d| d.try_normalize())
}

/// Compares estimated normal/tangent maps (`H x W x 3`, NaN = none) with ground truth over the
/// pixels inside `mask` (when given) whose true normal is within `max_normal_angle_deg` of the
/// view. `gt_tangents` may be absent (isotropic scenes): tangent figures are then empty.
/// `view(p)`, when given, is the unit vector from pixel `p`'s surface toward the camera (a
/// pinhole camera's `view(col, row)`); without it every pixel's view is `(0, 0, 1)`
/// (orthographic).
pub fn evaluate(
    normals: &[f32],
    tangents: &[f32],
    gt_normals: &[f32],
    gt_tangents: Option<&[f32]>,
    mask: Option<&[bool]>,
    max_normal_angle_deg: f64,
    view: Option<&dyn Fn(usize) -> DVec3>,
) -> Evaluation {
    let cos_max = max_normal_angle_deg.to_radians().cos();
    let (mut ne, mut te, mut tse) = (Vec::new(), Vec::new(), Vec::new());
    let (mut pixels, mut swapped) = (0usize, 0usize);
    for p in 0..gt_normals.len() / 3 {
        if mask.is_some_and(|m| !m[p]) {
            continue;
        }
        let Some(gn) = vec_at(gt_normals, p) else {
            continue;
        };
        if gn.dot(view.map_or(DVec3::Z, |v| v(p))) < cos_max {
            continue;
        }
        pixels += 1;
        let Some(n) = vec_at(normals, p) else {
            continue;
        };
        ne.push(n.dot(gn).clamp(-1.0, 1.0).acos().to_degrees());
        let (Some(t), Some(gt)) = (vec_at(tangents, p), gt_tangents.and_then(|g| vec_at(g, p)))
        else {
            continue;
        };
        let gb = gn.cross(gt).normalize();
        let et = t.dot(gt).abs().min(1.0).acos().to_degrees();
        let eb = t.dot(gb).abs().min(1.0).acos().to_degrees();
        if eb < et {
            swapped += 1;
        }
        te.push(et);
        tse.push(et.min(eb));
    }
    let estimated = ne.len();
    let with_tangent = te.len();
    Evaluation {
        max_normal_angle_deg,
        pixels,
        coverage: estimated as f64 / pixels.max(1) as f64,
        normal_error: ErrorStats::of(ne),
        tangent_coverage: with_tangent as f64 / estimated.max(1) as f64,
        tangent_error: ErrorStats::of(te),
        tangent_error_swap_free: ErrorStats::of(tse),
        swapped_share: swapped as f64 / with_tangent.max(1) as f64,
    }
}

impl Evaluation {
    /// Per-pixel normal angular error map (degrees, NaN where either side has no normal).
    pub fn normal_error_map(normals: &[f32], gt_normals: &[f32]) -> Vec<f32> {
        (0..gt_normals.len() / 3)
            .map(|p| match (vec_at(normals, p), vec_at(gt_normals, p)) {
                (Some(n), Some(g)) => n.dot(g).clamp(-1.0, 1.0).acos().to_degrees() as f32,
                _ => f32::NAN,
            })
            .collect()
    }

    /// Per-pixel tangent axis error map (degrees, NaN where either side has no tangent).
    pub fn tangent_error_map(tangents: &[f32], gt_tangents: &[f32]) -> Vec<f32> {
        (0..gt_tangents.len() / 3)
            .map(|p| match (vec_at(tangents, p), vec_at(gt_tangents, p)) {
                (Some(t), Some(g)) => t.dot(g).abs().min(1.0).acos().to_degrees() as f32,
                _ => f32::NAN,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_errors_on_constructed_maps() {
        // Pixel 0: normal off by exactly 10 degrees, tangent exact up to sign.
        // Pixel 1: normal exact, tangent along the true binormal (a swap).
        // Pixel 2: no estimate. Pixel 3: true normal 70 degrees from the view (not evaluated).
        let a = 10f64.to_radians();
        let gt_n = [
            0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.9397, 0.3420,
        ];
        let gt_t = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let n = [
            a.sin() as f32,
            0.0,
            a.cos() as f32,
            0.0,
            0.0,
            1.0,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            0.0,
            0.9397,
            0.3420,
        ];
        let t = [
            -1.0,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            f32::NAN,
            0.0,
            0.0,
            1.0,
            0.0,
            0.0,
        ];
        let e = evaluate(&n, &t, &gt_n, Some(&gt_t), None, 60.0, None);
        assert_eq!(e.pixels, 3);
        assert!((e.coverage - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(e.normal_error.count, 2);
        assert!(
            (e.normal_error.mean - 5.0).abs() < 1e-4,
            "{:?}",
            e.normal_error
        );
        assert!((e.normal_error.max - 10.0).abs() < 1e-4);
        assert!(
            (e.tangent_error.mean - 45.0).abs() < 1e-4,
            "{:?}",
            e.tangent_error
        );
        assert!(e.tangent_error_swap_free.max < 1e-3);
        assert!((e.swapped_share - 0.5).abs() < 1e-12);
        let m = Evaluation::normal_error_map(&n, &gt_n);
        assert!((m[0] - 10.0).abs() < 1e-3 && m[1].abs() < 1e-3 && m[2].is_nan());
    }

    #[test]
    fn stats_of_a_list() {
        let s = ErrorStats::of(vec![4.0, 1.0, 3.0, 2.0, 5.0]);
        assert_eq!((s.count, s.mean, s.median, s.max), (5, 3.0, 3.0, 5.0));
        assert!(ErrorStats::of(vec![]).mean.is_nan());
    }
}
