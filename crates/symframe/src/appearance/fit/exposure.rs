//! The light intensity of a glTF fit, chosen from sampled pixels by how well fits at each
//! candidate predict their validation lights ([`ExposureChoice::select`]).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::{FitParams, PixelFitter};
use crate::appearance::gltf_fit;
use crate::error::{Error, Result};

/// One pixel's frame (camera frame; `tangent = None`: isotropic) and samples (`3 * lights`
/// values, NaN = invalid), for [`ExposureChoice::select`].
#[derive(Debug, Clone, PartialEq)]
pub struct PixelData {
    /// Unit normal.
    pub normal: DVec3,
    /// Unit tangent, if any.
    pub tangent: Option<DVec3>,
    /// The pixel's samples, RGB per light.
    pub rgb: Vec<f32>,
}

/// The light intensity a glTF fit was given by [`ExposureChoice::select`], and the evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExposureChoice {
    /// The intensity chosen.
    pub exposure: f64,
    /// Each intensity tried and the RMS error of the fits at it on the validation samples
    /// of the pixels judged, in the order tried.
    pub candidates: Vec<(f64, f64)>,
    /// Pixels judged.
    pub pixels: usize,
}

/// [`ExposureChoice::select`] keeps the lowest intensity whose validation RMS is within this share of
/// the best one's.
pub(crate) const EXPOSURE_TOLERANCE: f64 = 0.05;

/// Pixels [`ExposureChoice::select`] judges each candidate intensity on, at most.
pub(crate) const EXPOSURE_JUDGED_PIXELS: usize = 512;

/// The share of the judged pixels, those with the largest validation errors at a candidate,
/// that [`ExposureChoice::select`] leaves out of its figure: the intensity is one number for
/// the whole capture, and a pixel the glTF lobe cannot explain (a wrong frame, an
/// interreflection) has a validation error that grows with any intensity and would otherwise
/// choose it alone. Higher is more robust to such pixels and reads fewer of the others.
pub(crate) const EXPOSURE_TRIMMED: f64 = 0.05;

impl ExposureChoice {
    /// The light intensity of a glTF fit (or of an automatic fit's glTF part) from sampled
    /// pixels: the candidates are the lowest intensity that keeps 99% of the pixels' base colours
    /// within 1 (from free-scale fits, `gltf_fit::exposure_bounds`) times `2^k`, `k = -8..=4`,
    /// and the intensity the mostly dielectric pixels imply where there are enough of them, then
    /// half steps (`2^(±1/2)`) either side of the best; each is judged by the squared error of fits at it on the validation lights
    /// (`validation_lights`) of up to `EXPOSURE_JUDGED_PIXELS` of the pixels (spread over the
    /// list), the worst `EXPOSURE_TRIMMED` of them left out, and the lowest intensity whose RMS
    /// error is within `EXPOSURE_TOLERANCE` of the smallest wins.
    ///
    /// Why judged, not read off: the scale of a pixel's free fit rests on the strength of the
    /// specular layer's Fresnel term, which a metal does not fix (a bare metal is also a black
    /// dielectric under brighter lights); a lobe that is not GGX's (Beckmann brushed gold) is
    /// fitted as such a dielectric under many times the true intensity, its shape bent by the
    /// Fresnel term's growth toward grazing halfway angles, and predicts held-out lights with
    /// errors many times the brightest sample. Whatever the intensity, that growth is then scaled
    /// by it. Why the lowest of the near-best: a range of intensities predicts the validation
    /// lights almost equally well (the Fresnel term's extra freedom fits a Beckmann lobe a little
    /// better), and the higher ones put that freedom, times the intensity, into every light that
    /// is not like the rig's (docs/method.md, "Choosing the exposure").
    ///
    /// # Errors
    /// When no pixel can be fitted.
    pub fn select(
        lights: &[DVec3],
        params: &FitParams,
        pixels: &[PixelData],
    ) -> Result<ExposureChoice> {
        use rayon::prelude::*;
        PixelFitter::new(lights, params)?;
        let scales: Vec<gltf_fit::PixelScale> = pixels
            .par_iter()
            .map_init(
                || PixelFitter::checked(lights, params),
                |f, p| f.scale(p.normal, p.tangent, &p.rgb),
            )
            .flatten()
            .collect();
        let (dielectric, brightest) = gltf_fit::exposure_bounds(&scales);
        let Some(base) = brightest.or(dielectric) else {
            return Err(Error::BadParameter(
                "no pixel to choose the exposure of the glTF fit from".into(),
            ));
        };
        let stride = pixels.len().div_ceil(EXPOSURE_JUDGED_PIXELS).max(1);
        let judged: Vec<&PixelData> = pixels.iter().step_by(stride).collect();
        let mut tried: Vec<(f64, f64)> = Vec::new();
        let judge = |e: f64, tried: &mut Vec<(f64, f64)>| {
            let mut errors: Vec<(f64, usize)> = judged
                .par_iter()
                .map_init(
                    || PixelFitter::checked(lights, params),
                    |f, p| f.gltf_validation_error(p.normal, p.tangent, &p.rgb, e),
                )
                .flatten()
                .filter(|&(_, count)| count > 0)
                .collect();
            if let Some(rms) = trimmed_rms(&mut errors) {
                tried.push((e, rms));
            }
        };
        let best = |tried: &[(f64, f64)]| {
            tried
                .iter()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|&(e, _)| e)
        };
        // Coarse: factors of 2 from 1/256 to 16 times the reading, and the dielectric reading;
        // then half steps either side of the best.
        for k in -8..=4 {
            judge(base * 2f64.powi(k), &mut tried);
        }
        if let Some(d) = dielectric.filter(|&d| d != base) {
            judge(d, &mut tried);
        }
        if let Some(e) = best(&tried) {
            for f in [std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::SQRT_2] {
                judge(e * f, &mut tried);
            }
        }
        // The lowest intensity that predicts the validation lights as well as the best to within
        // EXPOSURE_TOLERANCE.
        let exposure = match tried.iter().map(|t| t.1).min_by(f64::total_cmp) {
            Some(least) => tried
                .iter()
                .filter(|t| t.1 <= (1.0 + EXPOSURE_TOLERANCE) * least)
                .map(|t| t.0)
                .min_by(f64::total_cmp)
                .unwrap_or(base),
            None => gltf_fit::choose_exposure(&scales).unwrap_or(base),
        };
        Ok(ExposureChoice {
            exposure,
            candidates: tried,
            pixels: judged.len(),
        })
    }
}

/// The RMS of the pixels' validation errors (`(sum of squares, samples)` per pixel) less the
/// [`EXPOSURE_TRIMMED`] share of pixels with the largest mean squares; `None` without a pixel.
fn trimmed_rms(errors: &mut [(f64, usize)]) -> Option<f64> {
    if errors.is_empty() {
        return None;
    }
    let mean_square = |e: &(f64, usize)| e.0 / e.1 as f64;
    errors.sort_by(|a, b| mean_square(a).total_cmp(&mean_square(b)));
    let kept = errors.len() - (errors.len() as f64 * EXPOSURE_TRIMMED).floor() as usize;
    let (sum, count) = errors[..kept]
        .iter()
        .fold((0.0, 0), |(s, c), e| (s + e.0, c + e.1));
    Some((sum / count as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_trimmed_rms_leaves_out_the_worst_pixels() {
        // 40 pixels of mean square 0.01 over 10 samples each, and one of 1e4: the one is out.
        let mut errors: Vec<(f64, usize)> = (0..40).map(|_| (0.1, 10)).collect();
        errors.push((1e5, 10));
        assert!((trimmed_rms(&mut errors).unwrap() - 0.1).abs() < 1e-12);
        // Under 20 pixels nothing is left out (5% of them is less than one).
        let mut few: Vec<(f64, usize)> = vec![(0.1, 10), (10.0, 10)];
        let all = ((0.1 + 10.0) / 20.0f64).sqrt();
        assert!((trimmed_rms(&mut few).unwrap() - all).abs() < 1e-12);
        assert_eq!(trimmed_rms(&mut []), None);
    }
}
