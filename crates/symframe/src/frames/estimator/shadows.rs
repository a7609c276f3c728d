//! Cast shadows in a diffuse pixel's samples: lights the robust Lambertian fit says are well
//! above the horizon but whose samples are far below its prediction (docs/method.md, "Cast
//! shadows").

use crate::baselines::BaselinePixel;

use super::Estimator;

impl Estimator<'_> {
    /// Copies `slice` into `out` with the samples in cast shadow marked invalid (NaN), when the
    /// pixel has a diffuse part to tell them by; returns whether any was marked. A cast shadow
    /// (a light the surface faces but something else blocks) is not symmetric: left in, its
    /// zeros pull the normal away from the light (docs/method.md, "Cast shadows"). A robust
    /// Lambertian fit `g` over the unshadowed samples predicts the diffuse part; a sample far
    /// below the prediction where it is clearly lit is in shadow. Pixels the
    /// fit does not explain (metals) are left as they are: their dark samples are the lobe's
    /// tails.
    pub(super) fn mark_cast_shadows(
        &self,
        slice: &[f32],
        fit: &BaselinePixel,
        out: &mut Vec<f32>,
        scratch: &mut Vec<f64>,
    ) -> bool {
        let lights = self.rig.lights_in_camera();
        let Some(n) = fit
            .normal
            .filter(|_| fit.confidence as f64 >= self.policy.shadows.diffuse_fit)
        else {
            return false;
        };
        // The albedo along n: the mean of I / (n.l) over the well-lit samples the fit used is
        // not at hand, so take the brightest diffuse-looking level, the 90th percentile of
        // I / (n.l) over lights with n.l >= 0.3.
        scratch.clear();
        for (s, l) in slice.chunks_exact(3).zip(lights) {
            let nl = n.dot(*l);
            let v = (s[0] + s[1] + s[2]) as f64;
            if nl >= 0.3 && v.is_finite() {
                scratch.push(v / nl);
            }
        }
        if scratch.len() < 8 {
            return false;
        }
        let k = scratch.len() * 9 / 10;
        let (_, &mut albedo, _) = scratch.select_nth_unstable_by(k, f64::total_cmp);
        out.clear();
        out.extend_from_slice(slice);
        let mut marked = false;
        for (s, l) in out.chunks_exact_mut(3).zip(lights) {
            let nl = n.dot(*l);
            let v = (s[0] + s[1] + s[2]) as f64;
            if nl >= self.policy.shadows.min_cosine
                && v < self.policy.shadows.fraction * albedo * nl
            {
                s.fill(f32::NAN);
                marked = true;
            }
        }
        marked
    }
}
