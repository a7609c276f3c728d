//! Image degradations for synthetic captures: exposure, sensor noise, saturation and
//! quantisation, applied in memory to interleaved linear RGB images.
//!
//! Units: the *full scale* of an image is 1.0, the white level of the integer formats (PNG
//! writers clamp to `[0, 1]`). Noise levels are given in these units, not relative to each
//! image's maximum, so dim images are as noisy as bright ones in absolute terms (as on a real
//! sensor).
//!
//! Determinism: every random draw comes from [`Rng`] (SplitMix64) seeded from a user seed and
//! the image's index ([`Rng::for_image`]), so the result does not depend on the order or the
//! threads the images are processed in.

use std::fmt;

use crate::noise::SRGB_TOE;

/// A small deterministic random generator (SplitMix64) with Gaussian and Poisson samplers.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare_normal: Option<f64>,
}

/// The SplitMix64 output mix (also a good 64-bit hash).
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed,
            spare_normal: None,
        }
    }

    /// An independent stream for image `index` under `seed` (hashing both, so that neighbouring
    /// indices do not give shifted copies of one sequence).
    pub fn for_image(seed: u64, index: u64) -> Self {
        Self::new(mix64(
            seed ^ mix64(index.wrapping_add(0x5851_F42D_4C95_7F2D)),
        ))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)` (53 random bits).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// A standard normal sample (Box-Muller; the second value of each pair is kept for the next
    /// call).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]: ln is finite
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare_normal = Some(r * s);
        r * c
    }

    /// A Poisson sample of mean `lambda` (exact by multiplication below 30, the rounded normal
    /// approximation above; 0 for `lambda <= 0`).
    pub fn poisson(&mut self, lambda: f64) -> f64 {
        if lambda.is_nan() || lambda <= 0.0 {
            return 0.0;
        }
        if lambda < 30.0 {
            let limit = (-lambda).exp();
            let mut k = 0u32;
            let mut p = self.uniform();
            while p > limit {
                k += 1;
                p *= self.uniform();
            }
            return k as f64;
        }
        (lambda + lambda.sqrt() * self.normal()).round().max(0.0)
    }
}

/// Sensor noise added to every sample (all pixels, all channels independently).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Noise {
    /// No noise.
    #[default]
    None,
    /// Additive Gaussian noise of standard deviation `sigma` in full-scale units (1.0 = the
    /// white level). Results are not clipped (they may go negative): see `clip`.
    Gaussian {
        /// Standard deviation, full-scale units.
        sigma: f64,
    },
    /// Shot (photon) noise: a sample `v` stands for `v * photons` photons; the result is a
    /// Poisson draw of that mean divided by `photons`, so the relative noise is
    /// `1 / sqrt(v * photons)`. Non-positive samples stay 0.
    Shot {
        /// Photons collected at full scale.
        photons: f64,
    },
}

impl Noise {
    /// Parses `none`, `gaussian:SIGMA` (full-scale units, >= 0) or `shot:PHOTONS` (> 0).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let spec = spec.trim();
        let (name, arg) = match spec.split_once(':') {
            Some((n, a)) => (n.trim().to_ascii_lowercase(), Some(a.trim())),
            None => (spec.to_ascii_lowercase(), None),
        };
        let value = |what: &str| -> Result<f64, String> {
            let a = arg.ok_or_else(|| format!("noise '{spec}': expected {name}:{what}"))?;
            a.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| format!("noise '{spec}': {what} must be a number >= 0"))
        };
        match name.as_str() {
            "none" if arg.is_none() => Ok(Noise::None),
            "gaussian" => Ok(Noise::Gaussian {
                sigma: value("SIGMA")?,
            }),
            "shot" => {
                let photons = value("PHOTONS")?;
                if photons == 0.0 {
                    return Err(format!("noise '{spec}': PHOTONS must be positive"));
                }
                Ok(Noise::Shot { photons })
            }
            _ => Err(format!(
                "unknown noise '{spec}' (valid: none, gaussian:SIGMA, shot:PHOTONS)"
            )),
        }
    }

    /// Adds the noise to `img` in place (NaN samples stay NaN).
    pub fn apply(&self, img: &mut [f32], rng: &mut Rng) {
        match *self {
            Noise::None => {}
            Noise::Gaussian { sigma } => {
                for v in img.iter_mut() {
                    *v = (*v as f64 + sigma * rng.normal()) as f32;
                }
            }
            Noise::Shot { photons } => {
                for v in img.iter_mut() {
                    if !v.is_nan() {
                        *v = (rng.poisson(*v as f64 * photons) / photons) as f32;
                    }
                }
            }
        }
    }
}

impl fmt::Display for Noise {
    /// The spelling [`Noise::parse`] reads back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Noise::None => write!(f, "none"),
            Noise::Gaussian { sigma } => write!(f, "gaussian:{sigma}"),
            Noise::Shot { photons } => write!(f, "shot:{photons}"),
        }
    }
}

/// Clips every sample to `[0, level]` (a sensor's black level and saturation); NaN stays NaN.
pub(crate) fn clip(img: &mut [f32], level: f32) {
    for v in img.iter_mut() {
        if !v.is_nan() {
            *v = v.clamp(0.0, level);
        }
    }
}

/// Marks saturated pixels the way the dataset reader does: a pixel (RGB triple) with any
/// channel at or above `level` becomes `+inf` (censored) in all three channels. Returns how
/// many pixels were marked.
pub(crate) fn mark_saturated(img: &mut [f32], level: f32) -> usize {
    let mut n = 0;
    for px in img.chunks_exact_mut(3) {
        if px.iter().any(|&v| v >= level) {
            px.fill(f32::INFINITY);
            n += 1;
        }
    }
    n
}

/// Linear quantisation to `bits` bits: each sample is clamped to `[0, 1]` and rounded to the
/// nearest of `2^bits` evenly spaced levels (`k / (2^bits - 1)`). NaN stays NaN. (The 8-bit PNG
/// writer quantises after sRGB encoding instead, which gives finer steps in the darks.)
///
/// # Panics
/// If `bits` is not in `1..=24`.
pub(crate) fn quantise(img: &mut [f32], bits: u32) {
    assert!((1..=24).contains(&bits), "quantise: bits must be 1..=24");
    let m = ((1u32 << bits) - 1) as f32;
    for v in img.iter_mut() {
        if !v.is_nan() {
            *v = (v.clamp(0.0, 1.0) * m).round() / m;
        }
    }
}

/// sRGB quantisation as an 8-bit (or `bits`-bit) sRGB file stores a linear image and a reader
/// decodes it: each sample clamped to `[0, 1]`, sRGB-encoded, rounded to `2^bits` levels and
/// decoded back to linear (the steps are finest in the darks). NaN stays NaN.
pub(crate) fn quantise_srgb(img: &mut [f32], bits: u32) {
    assert!(
        (1..=24).contains(&bits),
        "bits must be in 1..=24, got {bits}"
    );
    let m = ((1u64 << bits) - 1) as f64;
    for v in img.iter_mut().filter(|v| !v.is_nan()) {
        let e = linear_to_srgb(v.clamp(0.0, 1.0) as f64);
        *v = srgb_to_linear((e * m).round() / m) as f32;
    }
}

/// The sRGB transfer function (linear in `[0, 1]` to encoded).
fn linear_to_srgb(v: f64) -> f64 {
    if v <= SRGB_TOE {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Its inverse (encoded in `[0, 1]` to linear).
pub(crate) fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A full degradation pipeline, applied in this order: multiply by `exposure`, add `noise`,
/// clip to `[0, clip]` when set, quantise to `quantise_bits` when set (in the sRGB domain when
/// `srgb`), then mark saturated pixels as the dataset reader does when `saturation` is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Degradation {
    /// Scale applied to the rendered radiance first.
    pub exposure: f32,
    /// Sensor noise.
    pub noise: Noise,
    /// Saturation level (full-scale units), if samples are clipped.
    pub clip: Option<f32>,
    /// Quantisation, if any (linear, or sRGB-encoded when `srgb`).
    pub quantise_bits: Option<u32>,
    /// Quantise in the sRGB-encoded domain (as an 8-bit sRGB PNG or JPEG stores it).
    pub srgb: bool,
    /// The reader's saturation rule: a pixel with any channel at or above this linear level
    /// becomes NaN in all three channels.
    pub saturation: Option<f32>,
    /// Seed of the noise; each image draws from [`Rng::for_image`]`(seed, index)`.
    pub seed: u64,
}

impl Default for Degradation {
    /// Exposure 1, nothing else: leaves images unchanged.
    fn default() -> Self {
        Self {
            exposure: 1.0,
            noise: Noise::None,
            clip: None,
            quantise_bits: None,
            srgb: false,
            saturation: None,
            seed: 0,
        }
    }
}

impl Degradation {
    /// The clip point of a clean `stack` for a share `clipped` of its samples to clip: the sample
    /// value (the brightest channel of a pixel under one light, pixels inside `mask`) that share
    /// exceeds; the brightest when 0, 1 when there is none. An exposure of its inverse clips them.
    pub fn clip_point(stack: &crate::Stack, mask: &[bool], clipped: f64) -> f32 {
        let mut v: Vec<f32> = (0..stack.n_pixels())
            .filter(|&p| mask[p])
            .flat_map(|p| {
                stack
                    .pixel(p)
                    .chunks_exact(3)
                    .map(|s| s[0].max(s[1]).max(s[2]))
                    .collect::<Vec<_>>()
            })
            .filter(|x| x.is_finite())
            .collect();
        if v.is_empty() {
            return 1.0;
        }
        let k = ((1.0 - clipped.clamp(0.0, 1.0)) * (v.len() - 1) as f64).round() as usize;
        let (_, at, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
        *at
    }

    /// Degrades image number `index` of a stack in place (deterministic in `seed` and `index`).
    pub fn apply(&self, img: &mut [f32], index: usize) {
        if self.exposure != 1.0 {
            img.iter_mut().for_each(|v| *v *= self.exposure);
        }
        self.noise
            .apply(img, &mut Rng::for_image(self.seed, index as u64));
        if let Some(level) = self.clip {
            clip(img, level);
        }
        match (self.quantise_bits, self.srgb) {
            (Some(bits), true) => quantise_srgb(img, bits),
            (Some(bits), false) => quantise(img, bits),
            (None, _) => {}
        }
        if let Some(level) = self.saturation {
            mark_saturated(img, level);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mean_std(v: &[f32]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, var.sqrt())
    }

    #[test]
    fn srgb_quantisation_has_fine_steps_in_the_darks() {
        let mut v = vec![0.001f32, 0.0011, 0.5, 0.5015, 1.2, f32::NAN];
        quantise_srgb(&mut v, 8);
        // Two darks 10% apart stay apart (sRGB's step there is ~0.0003 linear); near 0.5 the
        // step is ~0.004, so 0.5 and 0.5015 fall on one level.
        assert!(v[0] != v[1], "{v:?}");
        assert_eq!(v[2], v[3]);
        assert_eq!(v[4], 1.0);
        assert!(v[5].is_nan());
    }

    #[test]
    fn uniform_and_normal_have_the_right_moments() {
        let mut r = Rng::new(7);
        let u: Vec<f32> = (0..100_000).map(|_| r.uniform() as f32).collect();
        let (m, s) = mean_std(&u);
        assert!((m - 0.5).abs() < 0.005 && (s - (1.0f64 / 12.0).sqrt()).abs() < 0.005);
        assert!(u.iter().all(|&x| (0.0..1.0).contains(&x)));
        let z: Vec<f32> = (0..100_000).map(|_| r.normal() as f32).collect();
        let (m, s) = mean_std(&z);
        assert!(m.abs() < 0.01 && (s - 1.0).abs() < 0.01, "{m} {s}");
    }

    #[test]
    fn gaussian_noise_statistics_and_determinism() {
        let d = Degradation {
            noise: Noise::Gaussian { sigma: 0.02 },
            seed: 42,
            ..Degradation::default()
        };
        let base = vec![0.5f32; 60_000];
        let mut a = base.clone();
        d.apply(&mut a, 3);
        let (m, s) = mean_std(&a);
        assert!((m - 0.5).abs() < 0.0005, "mean {m}");
        assert!((s - 0.02).abs() < 0.0005, "std {s}");
        // Same seed and index: identical; another index or seed: different.
        let mut b = base.clone();
        d.apply(&mut b, 3);
        assert_eq!(a, b);
        let mut c = base.clone();
        d.apply(&mut c, 4);
        assert_ne!(a, c);
        let mut e = base.clone();
        Degradation { seed: 43, ..d }.apply(&mut e, 3);
        assert_ne!(a, e);
        // Neighbouring streams are not shifted copies of each other.
        assert_ne!(&a[1..100], &c[..99]);
    }

    #[test]
    fn shot_noise_is_poisson_scaled() {
        for (v, photons) in [(0.25f32, 40.0), (0.5, 1000.0)] {
            let d = Degradation {
                noise: Noise::Shot { photons },
                seed: 1,
                ..Degradation::default()
            };
            let mut a = vec![v; 60_000];
            d.apply(&mut a, 0);
            let (m, s) = mean_std(&a);
            let expect = (v as f64 / photons).sqrt();
            assert!((m - v as f64).abs() < 0.01 * v as f64, "mean {m}");
            assert!((s - expect).abs() < 0.03 * expect, "std {s} vs {expect}");
        }
        let mut z = vec![0.0f32, -1.0, f32::NAN];
        Noise::Shot { photons: 10.0 }.apply(&mut z, &mut Rng::new(0));
        assert_eq!(&z[..2], &[0.0, 0.0]);
        assert!(z[2].is_nan());
    }

    #[test]
    fn quantisation_levels() {
        let mut img: Vec<f32> = (0..=1000).map(|i| i as f32 / 1000.0).collect();
        img.extend([-0.5, 1.5, f32::NAN]);
        let mut q8 = img.clone();
        quantise(&mut q8, 8);
        let mut levels: Vec<u32> = q8[..1001]
            .iter()
            .map(|&v| (v * 255.0).round() as u32)
            .collect();
        for (&q, &v) in q8.iter().zip(&img).take(1001) {
            assert!((q - v).abs() <= 0.5 / 255.0 + 1e-6);
            assert!(((q * 255.0) - (q * 255.0).round()).abs() < 1e-4);
        }
        levels.dedup();
        assert_eq!(levels.len(), 256);
        assert_eq!((q8[1001], q8[1002]), (0.0, 1.0));
        assert!(q8[1003].is_nan());
        let mut q1 = vec![0.2f32, 0.6];
        quantise(&mut q1, 1);
        assert_eq!(q1, vec![0.0, 1.0]);
        let mut q16 = vec![0.123456f32];
        quantise(&mut q16, 16);
        assert!((q16[0] - 0.123456).abs() <= 0.5 / 65535.0 + 1e-7);
    }

    #[test]
    fn clipping_and_saturation_marks() {
        let mut img = vec![0.2f32, 1.4, 0.1, -0.1, 0.3, 0.4];
        let d = Degradation {
            exposure: 2.0,
            clip: Some(1.0),
            ..Degradation::default()
        };
        d.apply(&mut img, 0);
        assert_eq!(img, vec![0.4, 1.0, 0.2, 0.0, 0.6, 0.8]);
        assert_eq!(mark_saturated(&mut img, 0.995), 1);
        assert!(img[..3].iter().all(|v| *v == f32::INFINITY));
        assert_eq!(&img[3..], &[0.0, 0.6, 0.8]);
    }

    #[test]
    fn noise_specs_parse_and_print_back() {
        for s in ["none", "gaussian:0.01", "shot:500"] {
            assert_eq!(Noise::parse(s).unwrap().to_string(), s);
        }
        for bad in [
            "gauss:1",
            "gaussian",
            "gaussian:-1",
            "shot:0",
            "shot:x",
            "none:1",
        ] {
            assert!(Noise::parse(bad).is_err(), "{bad}");
        }
    }
}
