//! The estimator's policy: which answer a pixel gets, and whether its data determine a tangent.
//! Every setting the choice reads is here, grouped by the rule that reads it
//! ([`PolicySettings`]), each with its effect; the defaults are the estimator's
//! (docs/method.md, "Default measure", "Two lobes", "Fallbacks and the source map" and
//! "Tangents by evidence").
//!
//! The tangent rule in one line: a tangent where the slice is markedly more symmetric about one
//! pair of axes than about the pair 45 degrees away *and* an independent reading of the
//! highlight (its moments, or the lobe fitted to the samples) puts its wide axis along one of
//! them; or where a lobe that explains the samples as well as its family can does so on its
//! own. Each reading alone is fooled by something the other is not: the symmetry anisotropy of
//! an isotropic lobe read through few lights is interpolation noise with no preferred axis; a
//! fitted lobe's elongation under a sharp coat or a woven cross is the best one lobe can do,
//! not a measurement; together they agree only where the material has a direction.

use glam::DVec3;

/// Default smallest symmetry anisotropy for a tangent (`--min-anisotropy`).
pub const DEFAULT_MIN_ANISOTROPY: f32 = 0.6;

/// Smallest elongation of the highlight's second moment
/// ([`crate::frames::highlight::HighlightMoments::elongation`]) for it to show a wide axis
/// (the highlight-centroid baseline's tangent rule too).
pub const MIN_ELONGATION: f64 = 0.4;

/// [`LobeSettings::explains`]'s default: the lobe fit also retries its other starts until one
/// leaves less than this.
pub(crate) const LOBE_EXPLAINS: f64 = 0.002;

/// [`LobeSettings::plausible`]'s default.
const LOBE_PLAUSIBLE: f64 = 0.005;

/// Every setting of the estimator's choice of answer, grouped by the rule that reads it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PolicySettings {
    /// When a fitted lobe (one, or two sharing a frame) is the answer.
    pub lobe: LobeSettings,
    /// When a pixel is diffuse, and its Lambertian term the answer.
    pub diffuse: DiffuseSettings,
    /// When the symmetry search doubts its answer, or another start overrules it.
    pub search: SearchSettings,
    /// Which samples are cast shadows, left out.
    pub shadows: ShadowSettings,
    /// What answers beyond the rig's reach.
    pub fallback: FallbackSettings,
    /// Whether the data determine a tangent.
    pub tangent: TangentSettings,
}

/// When a fitted lobe is the answer (docs/method.md, "Lobe fit" and "Two lobes").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeSettings {
    /// A lobe leaving less than this share of the pixel's energy unexplained is the answer
    /// (source `lobe`); one leaving more is no evidence, and the symmetry search decides. Fits
    /// of lobes in the family leave below 1e-4 noise-free, as much under shot noise of 5,000
    /// photons at full scale; a lobe outside the family (Ashikhmin-Shirley) leaves 0.2-1% with
    /// normals 3-15 degrees off where the search is within 1. Higher: more pixels answered by
    /// the lobe's centre, biased where the family misdescribes the material.
    pub explains: f64,
    /// A lobe leaving less than this is a plausible answer where the search doubts its own,
    /// and its axis counts as a reading of the tangent by itself (at 1%, lobes on rough metal
    /// bumps under 200 lights were 9.4 degrees off where the search was 6.1). Higher: more
    /// doubtful searches replaced, more tangents from lobes that describe the pixel less well.
    pub plausible: f64,
    /// Where a diffuse term explains the pixel too, the lobe answers only if it leaves less
    /// than this share of what the diffuse term leaves. Higher: broad lobes that pass the
    /// diffuse test answer more often (and bias the Lambertian normal).
    pub over_diffuse: f64,
    /// What fits of lobes that describe a noise-free material leave: above it, two lobes
    /// explain a pixel only where their residuals look like independent noise. Higher: pairs
    /// accepted whatever their residuals' structure.
    pub model_floor: f64,
    /// The z score of neighbouring lights' residual correlation
    /// ([`crate::frames::lobe::LobePair::structure`]) up to which a pair's residuals look like
    /// independent noise: the one-sided 0.1% point of the normal distribution. Higher: more
    /// pixels whose residuals keep a smooth misfit are explained by two lobes.
    pub noise_like_z: f64,
    /// A lobe whose half-maximum region holds at most this many lights is narrower than the
    /// rig's spacing and is located by its log-quadratic peak (or the diffuse part). Higher:
    /// more lobes read as sharp.
    pub sharp_samples: u32,
    /// Smallest elongation `(a_t - a_b) / (a_t + a_b)` of a fitted lobe for a tangent at the
    /// default `--min-anisotropy` (scaled with it): widths in a ratio of 2 (an isotropic lobe
    /// read through few lights fits below). Higher: fewer tangents from fitted lobes.
    pub min_elongation: f64,
    /// A fitted lobe shows its shape only where its full width at half maximum along the wider
    /// axis spans at least this many halfway spacings of the rig. Higher: fewer tangents from
    /// narrow lobes under sparse rigs.
    pub resolved_spacings: f64,
}

impl Default for LobeSettings {
    fn default() -> Self {
        Self {
            explains: LOBE_EXPLAINS,
            plausible: LOBE_PLAUSIBLE,
            over_diffuse: 0.25,
            model_floor: 1e-4,
            noise_like_z: 3.09,
            sharp_samples: 2,
            min_elongation: 1.0 / 3.0,
            resolved_spacings: 1.5,
        }
    }
}

/// When a pixel is diffuse (docs/method.md, "Default measure").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffuseSettings {
    /// A pixel whose Lambertian fit leaves less than this share of its energy unexplained is
    /// diffuse: no lobe is fitted (1% RMS noise leaves 1e-4). Higher: more pixels skip the lobe.
    pub pure_share: f64,
    /// The robust Lambertian fit's uncentred R^2 from which its normal is a diffuse pixel's
    /// answer (and a sharp lobe's where the spike is left out). Higher: fewer Lambertian answers.
    pub centre_fit: f64,
    /// Under `--cosine auto`, a pixel whose Lambertian term leaves at least this share of the
    /// signal's energy unexplained is refined with the compensated measure. Higher: more
    /// pixels keep the paper's form.
    pub specular_share: f64,
    /// The robust Lambertian fit's uncentred R^2 from which a pixel is diffuse but for a spike
    /// the rig undersamples. Higher: fewer spiked pixels answered by the diffuse part.
    pub spiked_fit: f64,
    /// ...and the most samples that fit may leave out as the spike's (share of those it
    /// considered). Higher: wider spikes allowed.
    pub spike_share: f64,
}

impl Default for DiffuseSettings {
    fn default() -> Self {
        Self {
            pure_share: 1e-4,
            centre_fit: 0.99,
            specular_share: 0.005,
            spiked_fit: 0.999,
            spike_share: 0.05,
        }
    }
}

/// When the symmetry search doubts its answer, or another start overrules it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSettings {
    /// A symmetry answer whose quality `coverage / (1 + SD / symmetry_scale)` is below this is
    /// doubtful: a plausible lobe answers instead. Higher: more searches replaced by lobes.
    pub doubtful: f64,
    /// The symmetry distance at which the search's quality has halved. Higher: more lenient.
    pub symmetry_scale: f64,
    /// Another start overrules the search's answer only with less than this share of its
    /// full-level `SD_n`. Higher: starts overrule more easily.
    pub judge_margin: f64,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            doubtful: 0.1,
            symmetry_scale: 0.02,
            judge_margin: 0.5,
        }
    }
}

/// Which samples are cast shadows (docs/method.md, "Cast shadows").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowSettings {
    /// Shadows are looked for only where a robust Lambertian fit explains the pixel this well
    /// (uncentred R^2). Higher: fewer pixels searched for shadows.
    pub diffuse_fit: f64,
    /// A sample is in shadow below this fraction of the diffuse level predicted for it...
    /// Higher: more samples taken for shadows.
    pub fraction: f64,
    /// ...where its light is at least this far above the tangent plane (`n.l`; near grazing a
    /// small error in the normal could put a lit sample in shadow). Also the well-lit floor of
    /// the Lambertian term's unexplained share. Higher: fewer, surer shadows.
    pub min_cosine: f64,
}

impl Default for ShadowSettings {
    fn default() -> Self {
        Self {
            diffuse_fit: 0.9,
            fraction: 0.25,
            min_cosine: 0.2,
        }
    }
}

/// What answers beyond the rig's reach (docs/method.md, "Fallbacks and the source map").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FallbackSettings {
    /// The robust Lambertian fit answers when its uncentred R^2 is at least this. Higher: more
    /// such pixels left to the highlight.
    pub diffuse_fit: f64,
    /// A fallback's confidence is its own goodness of fit times this. Higher: fallbacks
    /// trusted more.
    pub confidence: f32,
}

impl Default for FallbackSettings {
    fn default() -> Self {
        Self {
            diffuse_fit: 0.95,
            confidence: 0.5,
        }
    }
}

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
