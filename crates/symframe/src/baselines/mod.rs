//! The baselines the paper compares against (its Figure 4): Lambertian photometric stereo
//! (Woodham 1980), the same with outlier rejection, and the max-reflectance ("specularity")
//! method. Each is good at one end of the range of materials; they are here to measure the
//! symmetry method against, on the same stacks and with the same outputs ([`EstimateMaps`]).
//!
//! Every baseline works on one value per sample, the **grey value**: the mean of the three
//! channels. For a Lambertian surface every channel gives the same normal (the albedo only
//! scales `g = albedo * n`), so averaging first loses nothing and costs a third of three fits.
//! A sample whose grey value is not finite (the stack's marker of an invalid sample) is skipped.
//!
//! One module per baseline: [`woodham`], [`max_reflectance`], [`highlight_centroid`]; this one
//! holds what they share and the driver.
//!
//! Unlike the symmetry method, the baselines use every light given: there is no light cone.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::maps::{EstimateMaps, PixelRecord, PixelSource, PixelStatus};
use crate::method::{run_stack, PixelMethod};
use crate::stack::Stack;

pub(crate) mod highlight_centroid;
pub(crate) mod max_reflectance;
pub(crate) mod woodham;

pub(crate) use highlight_centroid::highlight_centroid_pixel;
pub(crate) use max_reflectance::{highlight_peak, max_reflectance_pixel};
pub(crate) use woodham::woodham_robust_greys;
pub(crate) use woodham::{woodham_pixel, woodham_robust_pixel};

/// Which baseline to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// Least-squares Lambertian photometric stereo over the unshadowed samples.
    Woodham,
    /// As [`Baseline::Woodham`], then samples whose residual is more than
    /// [`BaselineParams::outlier_sigmas`] standard deviations from the mean residual are dropped
    /// and the fit is repeated (the paper's Figure 4 baseline).
    WoodhamRobust,
    /// The halfway vector of the brightest sample, refined by a quadratic fit of the log grey
    /// value over its nearest neighbours in halfway space.
    MaxReflectance,
    /// The intensity-weighted mean (normal) and second moment (tangent axis) of the halfway
    /// vectors of the brightest samples (the `highlight` module).
    HighlightCentroid,
}

impl Baseline {
    /// Every baseline, in a fixed order.
    pub const ALL: [Baseline; 4] = [
        Baseline::Woodham,
        Baseline::WoodhamRobust,
        Baseline::MaxReflectance,
        Baseline::HighlightCentroid,
    ];

    /// The baseline's name as on the command line and in reports (`woodham`, `woodham-robust`,
    /// `max-reflectance`).
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Woodham => "woodham",
            Baseline::WoodhamRobust => "woodham-robust",
            Baseline::MaxReflectance => "max-reflectance",
            Baseline::HighlightCentroid => "highlight-centroid",
        }
    }

    /// The measure its normals come from: a Lambertian fit or the brightest highlight.
    pub fn source(self) -> PixelSource {
        match self {
            Baseline::Woodham | Baseline::WoodhamRobust => PixelSource::Lambertian,
            Baseline::MaxReflectance | Baseline::HighlightCentroid => PixelSource::Highlight,
        }
    }
}

impl std::fmt::Display for Baseline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Parameters of the baselines.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BaselineParams {
    /// A sample is in shadow, and left out of the Woodham fits, when its grey value is below
    /// this fraction of the pixel's reference level (see `shadow_reference_quantile`; default
    /// 0.05). Zero keeps every valid sample, shadowed zeros included: plain least squares,
    /// which is biased by several degrees when lights reach far from the view (a shadowed zero
    /// is not `albedo * n.l < 0`).
    pub shadow_fraction: f64,
    /// The pixel's reference level for the shadow threshold is this quantile of its valid grey
    /// values (default 0.9; the maximum where that quantile is zero). 1 makes it the maximum:
    /// then on a glossy material a highlight 20 times brighter than the diffuse part puts every
    /// diffuse sample "in shadow" and the fit runs on the highlight alone (docs/method.md, "Cast
    /// shadows"). A high quantile is the brightness of the
    /// lit diffuse part as long as the highlight covers under 10% of the lights.
    pub shadow_reference_quantile: f64,
    /// `woodham-robust` drops samples whose residual after the first fit is more than this many
    /// standard deviations from the mean residual (default 2, the paper's Figure 4).
    pub outlier_sigmas: f64,
}

impl Default for BaselineParams {
    fn default() -> Self {
        Self {
            shadow_fraction: 0.05,
            shadow_reference_quantile: 0.9,
            outlier_sigmas: 2.0,
        }
    }
}

impl BaselineParams {
    /// Checks the ranges: `shadow_fraction` in `[0, 1)`, `shadow_reference_quantile` in
    /// `[0.5, 1]`, `outlier_sigmas` positive.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.shadow_fraction) {
            return Err(Error::BadParameter(format!(
                "shadow fraction must be in [0, 1), got {}",
                self.shadow_fraction
            )));
        }
        if !(0.5..=1.0).contains(&self.shadow_reference_quantile) {
            return Err(Error::BadParameter(format!(
                "shadow reference quantile must be in [0.5, 1], got {}",
                self.shadow_reference_quantile
            )));
        }
        if !(self.outlier_sigmas > 0.0 && self.outlier_sigmas.is_finite()) {
            return Err(Error::BadParameter(format!(
                "outlier threshold must be a positive number of standard deviations, got {}",
                self.outlier_sigmas
            )));
        }
        Ok(())
    }
}

/// The result of a baseline at one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BaselinePixel {
    /// What happened: [`PixelStatus::Estimated`], [`PixelStatus::NoData`] (no valid sample
    /// brighter than zero) or [`PixelStatus::Discarded`] (too few unshadowed samples, a
    /// degenerate fit, or a normal facing away from the camera); `Masked` from the stack driver.
    pub status: PixelStatus,
    /// Unit normal in the camera frame, when estimated.
    pub normal: Option<DVec3>,
    /// Unit tangent axis, for the baselines that estimate one (highlight centroid).
    pub tangent: Option<DVec3>,
    /// Goodness of fit in [0, 1] (0 where nothing was estimated); see each baseline's function.
    pub confidence: f32,
    /// Samples the final fit used.
    pub used: u32,
    /// Samples the fit considered before leaving out outliers ([`woodham_robust_pixel`]; the
    /// same as `used` for the other baselines).
    pub considered: u32,
}

impl BaselinePixel {
    fn empty(status: PixelStatus) -> Self {
        Self {
            status,
            normal: None,
            tangent: None,
            confidence: 0.0,
            used: 0,
            considered: 0,
        }
    }

    /// What the maps hold at this pixel, whose normal comes from `source`: the normal and,
    /// where there is one, the confidence; no anisotropy, tangent confidence or residual (`NaN`), no
    /// objective evaluations.
    pub(crate) fn record(&self, source: PixelSource) -> PixelRecord {
        PixelRecord {
            status: self.status,
            source: if self.normal.is_some() {
                source
            } else {
                PixelSource::None
            },
            normal: self
                .normal
                .map_or([f32::NAN; 3], |n| n.as_vec3().to_array()),
            tangent: self
                .tangent
                .map_or([f32::NAN; 3], |t| t.as_vec3().to_array()),
            confidence: if self.normal.is_some() {
                self.confidence
            } else {
                f32::NAN
            },
            anisotropy: f32::NAN,
            tangent_confidence: f32::NAN,
            residual: f32::NAN,
            evals: 0,
        }
    }
}

/// The grey value of one RGB sample (mean of the channels); `None` if not finite.
#[inline]
fn grey(rgb: &[f32]) -> Option<f64> {
    let v = (rgb[0] as f64 + rgb[1] as f64 + rgb[2] as f64) / 3.0;
    v.is_finite().then_some(v)
}

/// The grey values of `samples` (RGB) into `out`, NaN where invalid: for the callers that read
/// them more than once.
pub(crate) fn grey_values(samples: &[f32], out: &mut Vec<f64>) {
    out.clear();
    out.extend(samples.chunks_exact(3).map(|s| grey(s).unwrap_or(f64::NAN)));
}

/// Index and grey value of the brightest valid sample, if any is brighter than zero.
#[inline]
fn brightest(samples: &[f32]) -> Option<(usize, f64)> {
    let mut best: Option<(usize, f64)> = None;
    for (i, s) in samples.chunks_exact(3).enumerate() {
        if let Some(v) = grey(s) {
            if v > best.map_or(0.0, |b| b.1) {
                best = Some((i, v));
            }
        }
    }
    best
}

impl Baseline {
    /// The normal this baseline gives at one pixel (`samples` as [`Stack::pixel`], `lights`
    /// unit, same order; `scratch` a buffer reused between pixels), `None` where it gives none;
    /// [`BaselineMethod`] gives the pixel's whole record.
    pub fn normal(
        self,
        samples: &[f32],
        lights: &[DVec3],
        params: &BaselineParams,
        scratch: &mut Vec<f64>,
    ) -> Option<DVec3> {
        self.pixel(samples, lights, params, scratch).normal
    }

    /// Runs this baseline at one pixel (as [`Baseline::normal`]).
    pub(crate) fn pixel(
        self,
        samples: &[f32],
        lights: &[DVec3],
        params: &BaselineParams,
        scratch: &mut Vec<f64>,
    ) -> BaselinePixel {
        match self {
            Baseline::Woodham => woodham_pixel(samples, lights, params, scratch),
            Baseline::WoodhamRobust => woodham_robust_pixel(samples, lights, params, scratch),
            Baseline::MaxReflectance => max_reflectance_pixel(samples, lights),
            Baseline::HighlightCentroid => highlight_centroid_pixel(samples, lights),
        }
    }
}

/// A baseline ready to run per pixel: the method, its unit lights (one per input light) and
/// its parameters, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct BaselineMethod {
    method: Baseline,
    lights: Vec<DVec3>,
    params: BaselineParams,
}

impl BaselineMethod {
    /// Checks `params` and normalises `lights` (camera frame, one per stack image).
    pub fn new(method: Baseline, lights: &[DVec3], params: BaselineParams) -> Result<Self> {
        params.validate()?;
        Ok(Self {
            method,
            lights: baseline_lights(lights)?,
            params,
        })
    }

    /// Which baseline.
    pub fn method(&self) -> Baseline {
        self.method
    }

    /// The unit light directions, one per input light.
    pub fn unit_lights(&self) -> &[DVec3] {
        &self.lights
    }

    /// The parameters.
    pub fn params(&self) -> &BaselineParams {
        &self.params
    }
}

impl PixelMethod for BaselineMethod {
    type Scratch = Vec<f64>;
    type Output = PixelRecord;
    /// The baselines are cheap per pixel: wider bands than the symmetry estimator's.
    const BAND_ROWS: usize = 8;

    fn lights(&self) -> Option<&[usize]> {
        None
    }

    fn scratch(&self) -> Vec<f64> {
        Vec::with_capacity(self.lights.len())
    }

    fn pixel(&self, _p: usize, samples: &[f32], scratch: &mut Vec<f64>) -> PixelRecord {
        self.method
            .pixel(samples, &self.lights, &self.params, scratch)
            .record(self.method.source())
    }

    fn masked(&self) -> PixelRecord {
        PixelRecord::MASKED
    }
}

impl Baseline {
    /// Runs this baseline on every pixel of a stack (inside `mask` when given), in parallel over
    /// row bands, and returns the same maps as the symmetry estimator: tangents and anisotropy
    /// are NaN (the baselines recover normals only), confidence is the baseline's goodness of
    /// fit, `evals` is 0. Every light is used (no cone). `lights` are camera-frame directions,
    /// one per stack image (normalised here). `progress` is called with the number of pixels
    /// finished by each band.
    pub fn estimate_stack(
        self,
        stack: &Stack,
        lights: &[DVec3],
        mask: Option<&[bool]>,
        params: BaselineParams,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<EstimateMaps> {
        let method = BaselineMethod::new(self, lights, params)?;
        Stack::check_inputs(
            stack.width,
            stack.height,
            stack.n_lights,
            method.lights.len(),
            mask,
        )?;
        let records = run_stack(&method, stack, mask, progress);
        Ok(EstimateMaps::from_records(
            stack.width,
            stack.height,
            &records,
        ))
    }
}

/// The unit light directions a baseline runs with: `lights` normalised; an error if there are
/// none or one is zero or not finite.
pub(crate) fn baseline_lights(lights: &[DVec3]) -> Result<Vec<DVec3>> {
    if lights.is_empty() {
        return Err(Error::NoLights);
    }
    lights
        .iter()
        .enumerate()
        .map(|(index, l)| {
            l.try_normalize()
                .filter(|_| l.is_finite())
                .ok_or(Error::BadLight { index })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::uniform_cone_lights;
    use crate::geometry::halfway_from_light;

    /// One Lambertian pixel: `albedo * max(n.l, 0)` per channel.
    fn lambert(n: DVec3, lights: &[DVec3], albedo: [f32; 3]) -> Vec<f32> {
        lights
            .iter()
            .flat_map(|l| {
                let c = n.dot(*l).max(0.0) as f32;
                albedo.map(|a| a * c)
            })
            .collect()
    }

    fn angle_deg(a: DVec3, b: DVec3) -> f64 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn names_round_trip_through_serde() {
        for b in Baseline::ALL {
            let s = serde_json::to_string(&b).unwrap();
            assert_eq!(s, format!("\"{}\"", b.name()));
            assert_eq!(serde_json::from_str::<Baseline>(&s).unwrap(), b);
        }
    }

    #[test]
    fn woodham_is_exact_on_a_lambertian_pixel_and_ignores_invalid_samples() {
        let lights = uniform_cone_lights(200, 65.0);
        let n = DVec3::new(0.4, -0.3, 0.8).normalize();
        let mut s = lambert(n, &lights, [0.7, 0.5, 0.3]);
        // Invalid samples (NaN) are skipped.
        for k in [5, 17, 99] {
            s[k * 3..k * 3 + 3].fill(f32::NAN);
        }
        let p = BaselineParams::default();
        for r in [
            woodham_pixel(&s, &lights, &p, &mut Vec::new()),
            woodham_robust_pixel(&s, &lights, &p, &mut Vec::new()),
        ] {
            assert_eq!(r.status, PixelStatus::Estimated);
            assert!(angle_deg(r.normal.unwrap(), n) < 1e-4, "{r:?}");
            assert!(r.confidence > 0.999, "{r:?}");
        }
    }

    #[test]
    fn robust_woodham_drops_a_highlight() {
        let lights = uniform_cone_lights(300, 65.0);
        let n = DVec3::new(-0.2, 0.3, 0.9).normalize();
        let mut s = lambert(n, &lights, [0.5; 3]);
        // A few very bright samples (a highlight) near the mirror direction.
        let mirror = 2.0 * n.z * n - DVec3::Z;
        let mut by_angle: Vec<usize> = (0..lights.len()).collect();
        by_angle.sort_by(|&a, &b| lights[b].dot(mirror).total_cmp(&lights[a].dot(mirror)));
        for &k in &by_angle[..6] {
            s[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 3.0);
        }
        let p = BaselineParams::default();
        let plain = woodham_pixel(&s, &lights, &p, &mut Vec::new());
        let robust = woodham_robust_pixel(&s, &lights, &p, &mut Vec::new());
        let (ep, er) = (
            angle_deg(plain.normal.unwrap(), n),
            angle_deg(robust.normal.unwrap(), n),
        );
        assert!(ep > 1.0, "plain {ep}");
        assert!(er < 1e-3, "robust {er}, {robust:?}");
        assert!(robust.used < plain.used);
    }

    #[test]
    fn dark_and_sparse_pixels_have_no_estimate() {
        let lights = uniform_cone_lights(50, 65.0);
        let p = BaselineParams::default();
        let dark = vec![0.0f32; 150];
        let nan = vec![f32::NAN; 150];
        for m in Baseline::ALL {
            assert_eq!(
                m.pixel(&dark, &lights, &p, &mut Vec::new()).status,
                PixelStatus::NoData
            );
            assert_eq!(
                m.pixel(&nan, &lights, &p, &mut Vec::new()).status,
                PixelStatus::NoData
            );
        }
        // Two lit samples: too few for a 3-parameter fit.
        let mut two = dark.clone();
        two[0..3].fill(0.5);
        two[3..6].fill(0.4);
        assert_eq!(
            woodham_pixel(&two, &lights, &p, &mut Vec::new()).status,
            PixelStatus::Discarded
        );
        // Lights all in one plane: degenerate.
        let flat: Vec<DVec3> = (0..10)
            .map(|i| DVec3::new((i as f64 * 0.2).cos(), 0.0, (i as f64 * 0.2).sin()).normalize())
            .collect();
        let s = lambert(DVec3::new(0.3, 0.0, 0.9).normalize(), &flat, [0.5; 3]);
        assert_eq!(
            woodham_pixel(&s, &flat, &p, &mut Vec::new()).status,
            PixelStatus::Discarded
        );
    }

    #[test]
    fn max_reflectance_finds_a_gaussian_highlight_between_samples() {
        let lights = uniform_cone_lights(400, 65.0);
        let n = DVec3::new(0.25, 0.1, 0.9).normalize();
        // A Gaussian lobe in the halfway angle: exactly log-quadratic.
        let s: Vec<f32> = lights
            .iter()
            .flat_map(|&l| {
                let h = halfway_from_light(l).unwrap();
                let t2 = (1.0 / h.dot(n).powi(2) - 1.0).max(0.0);
                [(-t2 / 0.01).exp() as f32; 3]
            })
            .collect();
        let r = max_reflectance_pixel(&s, &lights);
        let (j, _) = brightest(&s).unwrap();
        let coarse = angle_deg(halfway_from_light(lights[j]).unwrap(), n);
        let fine = angle_deg(r.normal.unwrap(), n);
        assert!(
            fine < 0.05 && fine < coarse,
            "refined {fine}, brightest {coarse}"
        );
        assert!(r.confidence > 0.9, "{r:?}");
    }

    #[test]
    fn stack_driver_checks_its_inputs_and_fills_statuses() {
        let lights = uniform_cone_lights(30, 65.0);
        let mut stack = Stack::zeros(3, 2, 30);
        let n = DVec3::new(0.1, 0.2, 0.95).normalize();
        let px = lambert(n, &lights, [0.6; 3]);
        stack.pixel_mut(1).copy_from_slice(&px);
        stack.pixel_mut(4).copy_from_slice(&px);
        let mask = [true, true, true, false, true, true];
        let m = Baseline::Woodham
            .estimate_stack(
                &stack,
                &lights,
                Some(&mask),
                BaselineParams::default(),
                &|_| {},
            )
            .unwrap();
        assert_eq!(m.counts.estimated, 2);
        assert_eq!(m.counts.masked, 1);
        assert_eq!(m.counts.no_data, 3);
        assert_eq!(m.status[1], PixelStatus::Estimated);
        assert!(m.tangents.iter().all(|v| v.is_nan()));
        assert!(m.anisotropy.iter().all(|v| v.is_nan()));
        assert!(m.confidence[0].is_nan() && m.confidence[1] > 0.99);
        let got = DVec3::new(
            m.normals[3] as f64,
            m.normals[4] as f64,
            m.normals[5] as f64,
        );
        // Normalised first: a unit vector rounded to f32 is off unit length by ~1e-7.
        assert!(angle_deg(got.normalize(), n) < 1e-3);

        let e = |r: Result<EstimateMaps>| r.unwrap_err();
        let run = |l: &[DVec3], mask: Option<&[bool]>| {
            Baseline::Woodham.estimate_stack(&stack, l, mask, BaselineParams::default(), &|_| {})
        };
        assert_eq!(
            e(run(&lights[..29], None)),
            Error::LightCountMismatch { stack: 30, rig: 29 }
        );
        let mut bad = lights.clone();
        bad[7] = DVec3::ZERO;
        assert_eq!(e(run(&bad, None)), Error::BadLight { index: 7 });
        assert!(matches!(
            e(run(&lights, Some(&[false; 6]))),
            Error::BadMask(_)
        ));
        assert!(matches!(
            e(run(&lights, Some(&[true; 5]))),
            Error::BadMask(_)
        ));
        let bad_params = BaselineParams {
            shadow_fraction: 1.5,
            ..BaselineParams::default()
        };
        assert!(matches!(
            Baseline::Woodham.estimate_stack(&stack, &lights, None, bad_params, &|_| {}),
            Err(Error::BadParameter(_))
        ));
    }
}
