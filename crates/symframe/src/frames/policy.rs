//! The estimator's policy for tangents: whether a pixel's data determine a tangent, from the
//! evidence gathered once per pixel ([`TangentEvidence`]), and how sure the answer is
//! ([`tangent_confidence`]); the settings it reads are grouped in [`TangentSettings`]
//! (docs/method.md, "Tangents by evidence").
//!
//! The rule in one line: a tangent where the slice is markedly more symmetric about one pair
//! of axes than about the pair 45 degrees away *and* an independent reading of the highlight
//! (its moments, or the lobe fitted to the samples) puts its wide axis along one of them; or
//! where a lobe that explains the samples as well as its family can does so on its own. Each
//! reading alone is fooled by something the other is not: the symmetry anisotropy of an
//! isotropic lobe read through few lights is interpolation noise with no preferred axis; a
//! fitted lobe's elongation under a sharp coat or a woven cross is the best one lobe can do,
//! not a measurement; together they agree only where the material has a direction.

use glam::DVec3;

use crate::frames::estimator::{DEFAULT_MIN_ANISOTROPY, LOBE_PLAUSIBLE, MIN_ELONGATION};

/// The settings of the tangent decision, each with its effect. The defaults are the
/// estimator's; `--min-anisotropy` sets [`TangentSettings::min_anisotropy`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentSettings {
    /// Smallest symmetry anisotropy `(f45 - f0) / (f45 + f0)` of the slice (`f0`, `f45`: the
    /// tangent objective at the answer's axes and 45 degrees away) for a tangent. Higher: fewer
    /// tangents, none from weakly anisotropic slices.
    pub min_anisotropy: f64,
    /// Smallest elongation of the highlight's second moment for it to show a wide axis.
    /// Higher: the moments count as evidence only for strongly elongated highlights.
    pub min_moment_elongation: f64,
    /// Cosine of the largest angle between a fitted lobe's wide axis and a symmetry axis at
    /// which the two agree (15 degrees). Higher: stricter agreement.
    pub axes_agree_cos: f64,
    /// A fitted lobe that leaves less than this share of the energy unexplained is plausible
    /// on its own: its agreement with a symmetry axis gives a tangent whatever the slice's
    /// anisotropy (noise and light errors blur the anisotropy first). Higher: more tangents
    /// from lobes that describe the pixel less well.
    pub plausible_lobe_residual: f64,
}

impl Default for TangentSettings {
    fn default() -> Self {
        Self {
            min_anisotropy: DEFAULT_MIN_ANISOTROPY as f64,
            min_moment_elongation: MIN_ELONGATION,
            axes_agree_cos: 15f64.to_radians().cos(),
            plausible_lobe_residual: LOBE_PLAUSIBLE,
        }
    }
}

/// A fitted lobe's reading of the highlight's axes, as the tangent decision needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeAxis {
    /// The lobe's wide axis (unit, perpendicular to its normal).
    pub tangent: DVec3,
    /// The share of the samples' energy the lobe leaves unexplained.
    pub residual: f64,
    /// Whether the lobe is elongated enough, and wide enough for the rig to resolve, to have
    /// a wide axis at all.
    pub elongated: bool,
}

/// What a pixel's data say about its tangent, gathered once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentEvidence {
    /// The symmetry anisotropy of the slice at the answer's frame (see
    /// [`TangentSettings::min_anisotropy`]).
    pub anisotropy: f64,
    /// The highlight's moments show a wide axis (elongated, enough samples), or under a
    /// sharp coat the base lobe does.
    pub moments_elongated: bool,
    /// The symmetry axes of the answer's frame: tangent candidate and binormal.
    pub axes: [DVec3; 2],
    /// The lobes fitted to the pixel (all samples; the base's under a sharp coat).
    pub lobes: [Option<LobeAxis>; 2],
}

impl TangentEvidence {
    /// Whether a fitted lobe's wide axis lies along one of the symmetry axes; `plausible_only`:
    /// only lobes that explain the samples count.
    fn lobe_agrees(&self, s: &TangentSettings, plausible_only: bool) -> bool {
        self.lobes.iter().flatten().any(|l| {
            let along = l.tangent.dot(self.axes[0]).abs();
            let across = l.tangent.dot(self.axes[1]).abs();
            l.elongated
                && along.max(across) >= s.axes_agree_cos
                && (!plausible_only || l.residual < s.plausible_lobe_residual)
        })
    }
}

/// Whether the data determine a tangent at this pixel (see the module's rule).
pub fn has_tangent(s: &TangentSettings, e: &TangentEvidence) -> bool {
    let anisotropic = e.anisotropy >= s.min_anisotropy;
    let axis_read = e.moments_elongated || e.lobe_agrees(s, false);
    (anisotropic && axis_read) || e.lobe_agrees(s, true)
}

/// How clearly the data single out the tangent's axes, in `[0, 1]`: `1 - f0 / f45`, the share
/// of the tangent objective at 45 degrees that the answer's axes remove (0 for an isotropic
/// slice, towards 1 where the slice is exactly symmetric about the answer's axes and far from
/// it about any other pair), halved where no independent reading of the highlight puts its
/// wide axis along them. Model-free: the same measure of the data for every source.
pub fn tangent_confidence(s: &TangentSettings, e: &TangentEvidence, f0: f64, f45: f64) -> f32 {
    if !(f0.is_finite() && f45.is_finite()) || f45 <= 0.0 {
        return 0.0;
    }
    let separation = (1.0 - f0.max(0.0) / f45).clamp(0.0, 1.0);
    let agreed = e.moments_elongated || e.lobe_agrees(s, false);
    (if agreed { separation } else { 0.5 * separation }) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evidence(anisotropy: f64, moments: bool, lobe: Option<LobeAxis>) -> TangentEvidence {
        TangentEvidence {
            anisotropy,
            moments_elongated: moments,
            axes: [DVec3::X, DVec3::Y],
            lobes: [lobe, None],
        }
    }

    fn lobe(tangent: DVec3, residual: f64, elongated: bool) -> Option<LobeAxis> {
        Some(LobeAxis {
            tangent,
            residual,
            elongated,
        })
    }

    #[test]
    fn anisotropy_alone_gives_no_tangent() {
        let s = TangentSettings::default();
        assert!(!has_tangent(&s, &evidence(0.9, false, None)));
        // A round lobe has no axis to agree on.
        assert!(!has_tangent(
            &s,
            &evidence(0.9, false, lobe(DVec3::X, 0.03, false))
        ));
    }

    #[test]
    fn an_anisotropic_slice_with_an_agreeing_reading_has_a_tangent() {
        let s = TangentSettings::default();
        assert!(has_tangent(&s, &evidence(0.7, true, None)));
        // A poor single-lobe fit (a coat and a base) whose wide axis agrees: a tangent.
        assert!(has_tangent(
            &s,
            &evidence(0.7, false, lobe(DVec3::Y, 0.03, true))
        ));
        // ... but not when its axis is 30 degrees off both symmetry axes.
        let off = DVec3::new(30f64.to_radians().cos(), 30f64.to_radians().sin(), 0.0);
        assert!(!has_tangent(
            &s,
            &evidence(0.7, false, lobe(off, 0.03, true))
        ));
        // Nor when the slice is not anisotropic enough.
        assert!(!has_tangent(
            &s,
            &evidence(0.3, true, lobe(DVec3::Y, 0.03, true))
        ));
    }

    #[test]
    fn a_plausible_agreeing_lobe_gives_a_tangent_under_blurred_anisotropy() {
        let s = TangentSettings::default();
        assert!(has_tangent(
            &s,
            &evidence(0.2, false, lobe(DVec3::X, 0.001, true))
        ));
        assert!(!has_tangent(
            &s,
            &evidence(0.2, false, lobe(DVec3::X, 0.01, true))
        ));
    }

    #[test]
    fn tangent_confidence_measures_the_separation_of_the_axes() {
        let s = TangentSettings::default();
        let agreed = evidence(0.8, true, None);
        assert!((tangent_confidence(&s, &agreed, 0.1, 1.0) - 0.9).abs() < 1e-6);
        assert_eq!(tangent_confidence(&s, &agreed, 1.0, 1.0), 0.0);
        assert_eq!(tangent_confidence(&s, &agreed, 2.0, 1.0), 0.0);
        assert_eq!(tangent_confidence(&s, &agreed, 0.1, f64::NAN), 0.0);
        let alone = evidence(0.8, false, None);
        assert!((tangent_confidence(&s, &alone, 0.1, 1.0) - 0.45).abs() < 1e-6);
    }
}
