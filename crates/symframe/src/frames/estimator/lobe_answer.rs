//! The lobe's answer: the lobe fitted to a pixel, its estimate (frame, anisotropy, tangent,
//! the confidence the data's symmetry allows it) and whether it gives a tangent.

use glam::DVec3;

use crate::frames::lobe::{fit_lobe, LobeFit, LobeScratch, LobeStart};
use crate::frames::objective::{Level, Objective};
use crate::frames::policy::{
    self, tangent_confidence, LobeAxis, TangentEvidence, DEFAULT_MIN_ANISOTROPY,
};
use crate::frames::symmetry::{CosineMode, SymmetryTerm};
use crate::maps::{PixelSource, PixelStatus};

use super::confidence::{unconfirmed, within_confident, JUDGE_LIGHTS};
use super::{Estimator, PixelEstimate};

/// Smallest width the lobe fit starts from (slope units): a highlight of one sample has no
/// moment to measure it by.
const LOBE_START_WIDTH: f64 = 0.02;

impl Estimator<'_> {
    /// The symmetric lobe fitted to a pixel, from the highlight's centre `normal`, widest axis
    /// `tangent` and RMS angular `radius`.
    pub(super) fn lobe_fit(
        &self,
        slice: &[f32],
        normal: DVec3,
        tangent: DVec3,
        radius: f64,
        scratch: &mut LobeScratch,
    ) -> Option<LobeFit> {
        let rig = self.rig;
        let r = radius.tan().max(LOBE_START_WIDTH);
        let start = LobeStart {
            normal,
            tangent,
            alpha: [1.2 * r, 0.8 * r],
        };
        fit_lobe(slice, rig, start, &self.params.noise, scratch)
    }

    /// The estimate of a pixel the lobe `f` explains (its normal within the rig's reach): the
    /// lobe's frame, its elongation as the anisotropy, a tangent where the lobe is elongated.
    pub(super) fn lobe_estimate<O: Objective>(
        &self,
        slice: &[f32],
        objective: &O,
        cosine: CosineMode,
        f: &LobeFit,
        term_n: &SymmetryTerm,
        sd_n: f64,
    ) -> PixelEstimate {
        let anisotropy = f.elongation();
        let tangent = (self.params.tangents && self.lobe_has_tangent(f)).then_some(f.tangent);
        // The data's symmetry judges the lobe's centre, which is only as certain as the
        // symmetry can confirm it: its own variance (up to the stencil's resolution) is added,
        // and where the slice is more symmetric about a normal nearby than the two readings'
        // uncertainties allow, the lobe does not describe the material and its centre may be
        // biased by as much (docs/method.md, "Confidence").
        // On the first JUDGE_LIGHTS of the query order (evenly spread; all of them on small
        // rigs), as the tangent's confidence below, and without the split halves.
        let judged_on = Level::Coarse(JUDGE_LIGHTS);
        let centre = objective.normal_term(f.normal, cosine, judged_on);
        let (judged, evals) =
            self.symmetry_sd(objective, f.normal, cosine, judged_on, false, &centre);
        let own = f.normal_sd.powi(2);
        let sd = (own + f.light_sd.powi(2) + unconfirmed(&judged, own)).sqrt();
        let confidence = (self.coverage(slice, f.normal, term_n) * within_confident(sd)) as f32;
        let status = self.status_of(confidence);
        let keep = status == PixelStatus::Estimated;
        // The tangent's confidence is the data's, as for the search: how much more symmetric
        // the slice is about the lobe's axes than about the pair 45 degrees away.
        let (tangent_confidence, evals) = match tangent {
            Some(t) if keep => {
                let b = f.normal.cross(t);
                let at = |a: DVec3| {
                    self.tangent_distance(objective, f.normal, a, cosine, judged_on)
                        .0
                };
                let evidence = TangentEvidence {
                    anisotropy,
                    moments_elongated: false,
                    axes: [t, b],
                    lobes: [Some(self.lobe_axis(f)), None],
                };
                let c = tangent_confidence(
                    &self.policy.tangent,
                    &evidence,
                    at(t),
                    at((t + b).normalize()),
                );
                (c, evals + 3)
            }
            _ => (0.0, evals + 1),
        };
        PixelEstimate {
            status,
            source: PixelSource::Lobe,
            normal: keep.then_some(f.normal),
            tangent: if keep { tangent } else { None },
            confidence,
            anisotropy: anisotropy as f32,
            tangent_confidence,
            residual: [sd_n, f.residual, 0.0],
            evals,
        }
    }

    /// Whether a fitted lobe is elongated enough for a tangent, and wide enough for the rig to
    /// tell: `--min-anisotropy` scales the elongation threshold (its default asks for widths in
    /// a ratio of 2); the rig tells a lobe's shape only where its long axis spans several
    /// lights (narrower, it reads as elongated or round by where the lights happen to be).
    pub(super) fn lobe_has_tangent(&self, f: &LobeFit) -> bool {
        let threshold = self.policy.lobe.min_elongation * self.params.min_anisotropy as f64
            / DEFAULT_MIN_ANISOTROPY as f64;
        let resolved = f.full_width().atan()
            >= self.policy.lobe.resolved_spacings * self.rig.halfway_spacing();
        f.elongation() >= threshold && resolved
    }

    /// A fitted lobe's reading of the highlight's axes, for the tangent decision.
    pub(super) fn lobe_axis(&self, f: &LobeFit) -> LobeAxis {
        LobeAxis {
            tangent: f.tangent,
            plausible: policy::lobe_plausible(&self.policy.lobe, f),
            elongated: self.lobe_has_tangent(f),
        }
    }
}
