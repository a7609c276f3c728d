//! Clipped samples in the lobe fit (docs/method.md, "Clipped samples in the lobe fit"): a
//! clipped sample is known only to be at or above its clip level, a lower bound. The lobe fit
//! leaves the clipped samples out; its answer is then checked against their bounds. Where it
//! predicts a clipped sample below its bound, the pixel is fitted again with such samples held
//! at their bound (until the held set settles: the active-set fit under the bounds), and how far
//! that moves the normal joins the normal's uncertainty: a fit that breaks the bounds of the
//! samples that carry its highlight is only as certain as the bounds let it be.

use crate::frames::lobe::{predicted_greys, LobeFit, LobeScratch};

use super::Estimator;

/// Rounds of holding and refitting at most. Each round is one more lobe fit of the pixel;
/// higher is slower, only on pixels whose fit breaks a bound.
const CENSORED_ROUNDS: usize = 3;

/// Per-thread buffers of the bounds' check: the clipped samples' lights, their lower bounds,
/// which are held at their bound and the fit's prediction there; the held fit's samples and
/// its own lobe-fit buffers (the pixel's lobe fit keeps its own for the two-lobe fit).
#[derive(Debug, Clone, Default)]
pub(super) struct Censoring {
    lights: Vec<u32>,
    bounds: Vec<f64>,
    held: Vec<bool>,
    predicted: Vec<f64>,
    input: Vec<f32>,
    scratch: LobeScratch,
}

impl Censoring {
    /// Copies `slice` (the pixel's samples, clipped ones through the censoring map) into `out`
    /// with the clipped samples (any channel at `clip` or above) left out (NaN), and records
    /// their lights and their lower bounds: the grey value of the sample as recorded, `raw`,
    /// each channel at most `clip`.
    pub(super) fn leave_out(&mut self, raw: &[f32], slice: &[f32], clip: f32, out: &mut Vec<f32>) {
        self.lights.clear();
        self.bounds.clear();
        out.clear();
        out.extend_from_slice(slice);
        for (j, (s, r)) in out.chunks_exact_mut(3).zip(raw.chunks_exact(3)).enumerate() {
            if s[0] >= clip {
                s.fill(f32::NAN);
                self.lights.push(j as u32);
                self.bounds
                    .push(r.iter().map(|&v| v.min(clip) as f64).sum::<f64>());
            }
        }
    }
}

impl Estimator<'_> {
    /// The lobe fit `first` of `input` (as [`Censoring::leave_out`] made it from `raw`) with
    /// the bounds' check: where `first` predicts a clipped sample below its bound, the normal's
    /// uncertainty grows by how far [`Estimator::held_fit`] moves it. The frame and the other
    /// figures are `first`'s.
    pub(super) fn bounds_checked(
        &self,
        first: LobeFit,
        input: &[f32],
        raw: &[f32],
        censoring: &mut Censoring,
    ) -> LobeFit {
        match self.held_fit(&first, input, raw, censoring) {
            Some((held, evals)) => LobeFit {
                normal_sd: first
                    .normal_sd
                    .hypot(held.normal.angle_between(first.normal)),
                evals: first.evals + evals,
                ..first
            },
            None => first,
        }
    }

    /// The fit under the clipped samples' bounds, from `first` (the fit of `input`, the
    /// clipped samples left out): the clipped samples it predicts below their bound held at
    /// it (their channels as recorded, each at most the clip level) and the pixel fitted
    /// again, until no held sample is predicted above its bound nor a left-out one below (at
    /// most [`CENSORED_ROUNDS`] fits), with the evaluations it took. `None` where `first`
    /// keeps every bound (or the held samples leave nothing to fit).
    pub(super) fn held_fit(
        &self,
        first: &LobeFit,
        input: &[f32],
        raw: &[f32],
        censoring: &mut Censoring,
    ) -> Option<(LobeFit, u32)> {
        let clip = self.params.noise.clip_level?;
        let Censoring {
            lights,
            bounds,
            held,
            predicted,
            input: samples,
            scratch,
        } = censoring;
        if lights.is_empty() {
            return None;
        }
        // Most fits keep every bound: the samples are copied only once one is broken.
        predicted_greys(first, lights, self.rig, scratch, predicted);
        if !predicted.iter().zip(bounds.iter()).any(|(p, b)| p < b) {
            return None;
        }
        held.clear();
        held.resize(lights.len(), false);
        samples.clear();
        samples.extend_from_slice(input);
        let (mut fit, mut evals) = (*first, 0);
        for round in 0..CENSORED_ROUNDS {
            if round > 0 {
                predicted_greys(&fit, lights, self.rig, scratch, predicted);
            }
            let mut changed = false;
            for (k, &j) in lights.iter().enumerate() {
                let hold = predicted[k] < bounds[k];
                if hold == held[k] {
                    continue;
                }
                changed = true;
                held[k] = hold;
                let j = 3 * j as usize;
                let sample = &mut samples[j..j + 3];
                if hold {
                    for (s, r) in sample.iter_mut().zip(&raw[j..j + 3]) {
                        *s = r.min(clip);
                    }
                } else {
                    sample.fill(f32::NAN);
                }
            }
            if !changed {
                break;
            }
            let radius = fit.alpha[0].atan();
            fit = self.lobe_fit(samples, fit.normal, fit.tangent, radius, scratch)?;
            evals += fit.evals;
        }
        Some((fit, evals))
    }
}

/// `slice` (RGB per light, through the censoring map: a clipped sample is the clip level `clip`
/// in every channel) into `out` with each clipped sample given the colour of the highlight
/// where it clipped, at the clip level in its brightest channel; NaN stays NaN. A clipped
/// sample is known only to have a channel at or above the clip level; filled grey, it differs
/// from an unclipped neighbour on the other side of a symmetric highlight by the darker
/// channels' gap (large on a coloured material), a step the true slice does not have and the
/// reconstruction between lights places differently on the two sides. The colour is that of
/// the brightest unclipped sample (the nearest to the clip in level; a coat's highlight whitens
/// towards its top), grey where no sample reaches half the clip level.
pub(super) fn clipped_in_colour(slice: &[f32], clip: f32, out: &mut Vec<f32>) {
    let brightest = |s: &[f32]| s[0].max(s[1]).max(s[2]);
    let top = slice
        .chunks_exact(3)
        .filter(|s| {
            let m = brightest(s);
            m.is_finite() && m < clip && m >= 0.5 * clip
        })
        .max_by(|a, b| brightest(a).total_cmp(&brightest(b)));
    let colour = match top {
        Some(s) => {
            let m = brightest(s);
            [s[0] / m, s[1] / m, s[2] / m]
        }
        None => [1.0; 3],
    };
    out.clear();
    out.extend_from_slice(slice);
    for s in out.chunks_exact_mut(3) {
        if s[0] >= clip {
            for (v, c) in s.iter_mut().zip(colour) {
                *v = clip * c;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    use crate::brdf::{Ggx, Layered};
    use crate::frames::estimator::EstimatorParams;
    use crate::frames::lobe::tests::slice;
    use crate::frames::rig::{uniform_cone_lights, Rig, RigOptions};
    use crate::geometry::tangent_basis;
    use crate::noise::NoiseModel;

    #[test]
    fn a_fit_that_breaks_the_clipped_samples_bounds_is_less_certain() {
        // A sharp clear coat over a glossy base under a sparse rig, each pixel clipped at half
        // its brightest sample: the unclipped flanks of two lobes place one lobe loosely.
        let rig = Rig::new(&uniform_cone_lights(200, 65.0), RigOptions::default()).unwrap();
        let brdf = Layered::new(0.05, 1.5, Box::new(Ggx::new([0.3; 3], [0.04; 3], 0.3, 0.3)));
        let (mut first_error, mut held_error, mut broken) = (0.0, 0.0, 0);
        let (mut covered, mut covered_before, mut pixels) = (0, 0, 0);
        for k in 0..24 {
            let (theta, phi) = (0.5 * (k % 6) as f64 / 6.0, 2.4 * k as f64);
            let n = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let (t, _) = tangent_basis(n);
            let rendered = slice(&rig, &brdf, n, t);
            let clip = 0.5 * rendered.iter().copied().fold(0.0, f32::max);
            let raw: Vec<f32> = rendered.iter().map(|&v| v.min(clip)).collect();
            let noise = NoiseModel {
                clip_level: Some(clip),
                ..NoiseModel::default()
            };
            let params = EstimatorParams {
                noise,
                ..EstimatorParams::default()
            };
            let estimator = Estimator::new(&rig, params);
            let (mut censoring, mut scratch) = (Censoring::default(), LobeScratch::default());
            let mut input = Vec::new();
            censoring.leave_out(&raw, &raw, clip, &mut input);
            assert!(!censoring.lights.is_empty());
            let Some(first) = estimator.lobe_fit(&input, n, t, 0.1, &mut scratch) else {
                continue;
            };
            pixels += 1;
            let error = first.normal.angle_between(n);
            first_error += error.to_degrees();
            covered_before += usize::from(error <= 2.0 * first.normal_sd);
            let checked = estimator.bounds_checked(first, &input, &raw, &mut censoring);
            assert_eq!(checked.normal, first.normal);
            covered += usize::from(error <= 2.0 * checked.normal_sd);
            let Some((held, _)) = estimator.held_fit(&first, &input, &raw, &mut censoring) else {
                assert_eq!(checked, first);
                held_error += error.to_degrees();
                continue;
            };
            broken += 1;
            assert!(checked.normal_sd > first.normal_sd);
            // Under the bounds: no clipped sample predicted far below what it recorded.
            let mut predicted = Vec::new();
            predicted_greys(&held, &censoring.lights, &rig, &mut scratch, &mut predicted);
            for (p, b) in predicted.iter().zip(&censoring.bounds) {
                assert!(
                    *p >= 0.9 * b,
                    "pixel {k}: predicted {p} under the bound {b}"
                );
            }
            held_error += held.normal.angle_between(n).to_degrees();
        }
        let (first_error, held_error) = (first_error / pixels as f64, held_error / pixels as f64);
        eprintln!(
            "{pixels} pixels, {broken} broke a bound: {first_error:.3} -> {held_error:.3} deg; \
             within 2 sd {covered_before} -> {covered}"
        );
        assert!(
            broken >= pixels / 4,
            "only {broken} of {pixels} first fits broke a bound"
        );
        // The fit under the bounds is the closer one, so the first fit's distance from it is
        // its error's evidence.
        assert!(held_error < first_error, "{first_error} -> {held_error}");
        assert!(covered >= covered_before, "{covered_before} -> {covered}");
    }

    #[test]
    fn clipped_samples_take_the_highlight_s_colour() {
        let clip = 0.9f32;
        let colour = [1.0f32, 0.6, 0.3];
        let at = |m: f32| colour.map(|c| c * m);
        // A coloured highlight whose top clipped (the censoring map's grey fill), its flanks
        // below the clip, a dark diffuse sample and an invalid one.
        let mut slice = Vec::new();
        for s in [
            [clip; 3],
            at(0.85),
            at(0.6),
            [clip; 3],
            [0.05, 0.04, 0.03],
            [f32::NAN; 3],
        ] {
            slice.extend_from_slice(&s);
        }
        let mut out = Vec::new();
        clipped_in_colour(&slice, clip, &mut out);
        // The clipped samples continue their flanks: the highlight's colour at the clip level
        // in the brightest channel, where the grey fill jumped by the darker channels' gap.
        for j in [0, 3] {
            for k in 0..3 {
                assert!((out[j * 3 + k] - clip * colour[k]).abs() < 1e-6, "{out:?}");
            }
        }
        // Every other sample as it was (NaN stays NaN).
        assert_eq!(out[3..9], slice[3..9]);
        assert_eq!(out[12..15], slice[12..15]);
        assert!(out[15..].iter().all(|v| v.is_nan()));
        // Nothing bright enough to tell the colour: the grey fill stays.
        let dark = [clip, clip, clip, 0.1, 0.2, 0.05];
        clipped_in_colour(&dark, clip, &mut out);
        assert_eq!(out, dark);
    }
}
