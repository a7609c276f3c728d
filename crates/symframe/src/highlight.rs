//! The highlight's moments in halfway space: the intensity-weighted mean and second moment of
//! the halfway vectors of a pixel's brightest samples. The mean is a normal estimate that is
//! strong on glossy materials under dense rigs (the peak of a lobe symmetric about `n` is at
//! `h = n`); the second moment's widest axis is a tangent estimate (the widest-highlight rule).
//! It serves as the `highlight-centroid` baseline and as a start of the symmetry search
//! (docs/method.md, "Search").

use glam::DVec3;

use crate::geometry::tangent_basis;

/// Samples at or above this fraction of the pixel's brightest grey value are "the highlight";
/// each weighs by how far it rises above that level, so the mean follows the lobe's peak and
/// a sample at the threshold enters with weight zero (no jump as it crosses).
pub(crate) const HIGHLIGHT_LEVEL: f64 = 0.5;

/// Fewest highlight samples for a tangent: the second moment of fewer points says more about
/// where the lights happen to be than about the lobe.
const MIN_SAMPLES_FOR_TANGENT: u32 = 4;

/// Smallest elongation of the highlight's second moment ([`HighlightMoments::elongation`])
/// for it to show a wide axis: the estimator's default and the highlight-centroid baseline's
/// tangent rule.
pub(crate) const MIN_ELONGATION: f64 = 0.4;

/// The moments of a pixel's highlight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HighlightMoments {
    /// Unit intensity-weighted mean of the highlight samples' halfway vectors.
    pub normal: DVec3,
    /// Unit widest axis of the weighted second moment about `normal` (perpendicular to it).
    pub tangent: DVec3,
    /// `(l1 - l2) / (l1 + l2)` of the second moment's eigenvalues, in [0, 1]: 0 for a round
    /// highlight (or one sample), towards 1 for an elongated one.
    pub elongation: f64,
    /// Angular radius of the highlight about `normal` (radians): the weighted RMS angle.
    pub radius: f64,
    /// Samples in the highlight.
    pub count: u32,
    /// The highlight's contrast `1 - mean / max` over the valid grey values, in [0, 1].
    pub contrast: f64,
}

impl HighlightMoments {
    /// Whether the highlight is elongated enough, over enough samples, for its widest axis to be
    /// a tangent (`min_elongation` in [0, 1]).
    pub(crate) fn has_tangent(&self, min_elongation: f64) -> bool {
        self.count >= MIN_SAMPLES_FOR_TANGENT && self.elongation >= min_elongation
    }
}

/// The moments of the highlight of one pixel: `samples` RGB (`halfways.len() * 3` values, NaN
/// = invalid), `halfways` the unit halfway vector of each sample's light. `None` when no valid
/// sample is brighter than zero. Allocation-free (two passes over the samples).
#[cfg(test)]
pub(crate) fn highlight_moments(samples: &[f32], halfways: &[DVec3]) -> Option<HighlightMoments> {
    highlight_moments_by(samples, |i| Some(halfways[i]))
}

/// The highlight's moments ([`HighlightMoments`]) with the halfway vector of sample `i` given by `halfway(i)` (`None`:
/// the sample has none, e.g. a light behind the view, and is left out).
pub(crate) fn highlight_moments_by(
    samples: &[f32],
    halfway: impl Fn(usize) -> Option<DVec3>,
) -> Option<HighlightMoments> {
    let sample = |i: usize| &samples[3 * i..3 * i + 3];
    let grey = |i: usize| {
        let s = sample(i);
        let v = (s[0] as f64 + s[1] as f64 + s[2] as f64) / 3.0;
        v.is_finite().then_some(v)
    };
    // Samples whose channel sum is clearly below the level are skipped before the division
    // (the division by 3 rounds by far less than this margin; the others are tested exactly):
    // the highlight is a small share of the samples, and a division per sample is most of a
    // pass's cost.
    let reaches = |i: usize, level: f64| {
        let s = sample(i);
        s[0] as f64 + s[1] as f64 + s[2] as f64 >= 3.0 * level * (1.0 - 1e-9)
    };
    moments(samples.len() / 3, grey, reaches, halfway)
}

/// The highlight's moments ([`HighlightMoments`]) from the pixel's grey values (`(r + g + b) / 3`, NaN where invalid):
/// for a caller that has them.
pub(crate) fn highlight_moments_of_greys(
    greys: &[f64],
    halfways: &[DVec3],
) -> Option<HighlightMoments> {
    let grey = |i: usize| Some(greys[i]).filter(|v| v.is_finite());
    moments(greys.len(), grey, |_, _| true, |i| Some(halfways[i]))
}

/// The moments of `n` samples: `grey(i)` the grey value of sample `i` (`None` where invalid),
/// `reaches(i, level)` false where it is surely below `level` (a cheaper test than `grey`),
/// `halfway(i)` its halfway vector.
#[inline(always)]
fn moments(
    n: usize,
    grey: impl Fn(usize) -> Option<f64>,
    reaches: impl Fn(usize, f64) -> bool,
    halfway: impl Fn(usize) -> Option<DVec3>,
) -> Option<HighlightMoments> {
    let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    for i in 0..n {
        if let Some(v) = grey(i) {
            max = max.max(v);
            sum += v;
            count += 1;
        }
    }
    if max <= 0.0 {
        return None;
    }
    let level = HIGHLIGHT_LEVEL * max;
    let mut mean = DVec3::ZERO;
    let mut n_samples = 0u32;
    for i in 0..n {
        if !reaches(i, level) {
            continue;
        }
        if let (Some(v), Some(h)) = (grey(i).filter(|&v| v >= level), halfway(i)) {
            // The brightest sample has weight 1 - HIGHLIGHT_LEVEL; one at the level, 0.
            mean += (v - level).max(1e-12 * max) * h;
            n_samples += 1;
        }
    }
    let normal = mean.try_normalize()?;
    let (u, w) = tangent_basis(normal);
    let (mut cuu, mut cuw, mut cww, mut total) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        if !reaches(i, level) {
            continue;
        }
        if let (Some(v), Some(h)) = (grey(i).filter(|&v| v >= level), halfway(i)) {
            let weight = (v - level).max(1e-12 * max);
            // Gnomonic chart of the tangent plane at the mean.
            let d = h.dot(normal).max(1e-6);
            let (x, y) = (h.dot(u) / d, h.dot(w) / d);
            cuu += weight * x * x;
            cuw += weight * x * y;
            cww += weight * y * y;
            total += weight;
        }
    }
    let (cuu, cuw, cww) = (cuu / total, cuw / total, cww / total);
    // Eigen-decomposition of the symmetric 2x2 second moment.
    let half_trace = 0.5 * (cuu + cww);
    let spread = (0.25 * (cuu - cww).powi(2) + cuw * cuw).sqrt();
    let (l1, l2) = (half_trace + spread, (half_trace - spread).max(0.0));
    let angle = 0.5 * (2.0 * cuw).atan2(cuu - cww);
    let tangent = u * angle.cos() + w * angle.sin();
    Some(HighlightMoments {
        normal,
        tangent,
        elongation: if l1 + l2 > 0.0 {
            (l1 - l2) / (l1 + l2)
        } else {
            0.0
        },
        radius: (cuu + cww).sqrt().atan(),
        count: n_samples,
        contrast: (1.0 - sum / count as f64 / max).clamp(0.0, 1.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::uniform_cone_lights;
    use crate::frames::rig::{Rig, RigOptions};

    /// An anisotropic Gaussian lobe about `n` with widths `at` along `t`, `ab` along `n x t`.
    fn lobe(rig: &Rig, n: DVec3, t: DVec3, at: f64, ab: f64) -> Vec<f32> {
        let b = n.cross(t);
        rig.halfway_in_camera()
            .iter()
            .flat_map(|&h| {
                let hn = h.dot(n).max(1e-6);
                let v = (-((h.dot(t) / hn / at).powi(2) + (h.dot(b) / hn / ab).powi(2))).exp();
                [v as f32; 3]
            })
            .collect()
    }

    #[test]
    fn the_moments_find_the_centre_and_the_wide_axis_of_a_lobe() {
        let rig = Rig::new(&uniform_cone_lights(1500, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(0.3, -0.2, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        let t = (u + 0.5 * w).normalize();
        let m = highlight_moments(&lobe(&rig, n, t, 0.3, 0.1), rig.halfway_in_camera()).unwrap();
        assert!(m.normal.angle_between(n).to_degrees() < 1.0, "{m:?}");
        assert!(m.tangent.dot(t).abs() > 0.99, "{m:?}");
        assert!(m.has_tangent(0.3), "{m:?}");
        let round =
            highlight_moments(&lobe(&rig, n, t, 0.2, 0.2), rig.halfway_in_camera()).unwrap();
        assert!(round.elongation < 0.15, "{round:?}");
        assert!(highlight_moments(&vec![0.0; rig.n_used() * 3], rig.halfway_in_camera()).is_none());
    }
}
