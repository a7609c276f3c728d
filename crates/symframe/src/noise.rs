//! The noise model of a capture: what its samples can and cannot tell (docs/method.md, "Noise
//! model").
//!
//! A sample of an integer file is known to within its quantisation step; one at the sensor's
//! white level is known only to be at least that level (censored); every sample carries shot
//! noise (variance proportional to the signal) and read noise (a floor). The decoder knows the
//! first two exactly; the last two are estimated from the data (the spread of each image's
//! second differences between neighbouring pixels, against their level).
//!
//! Censored samples reach the estimator as `+inf` (the decoder's mark for a pixel with a
//! saturated channel; every other reader skips non-finite samples). With a clip level the
//! estimator reads every sample through the same pointwise map, `v -> c` wherever `v` is
//! censored or any channel reaches `c`: a symmetric slice stays symmetric under it, so the
//! clipped top of a highlight keeps its place in the symmetry measure instead of leaving a
//! hole there.

use serde::{Deserialize, Serialize};

/// How the samples were stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind", content = "bits")]
pub enum Quantisation {
    /// Floating point: no quantisation to speak of.
    #[default]
    Float,
    /// Integers of this many bits, linear in radiance.
    Linear(u32),
    /// Integers of this many bits, sRGB-encoded (steps finest in the darks).
    Srgb(u32),
}

impl Quantisation {
    /// The variance the rounding adds to a linear sample of value `v` (full scale 1): the
    /// step there squared over 12.
    pub fn variance(self, v: f64) -> f64 {
        match self {
            Quantisation::Float => 0.0,
            Quantisation::Linear(bits) => {
                let step = 1.0 / ((1u64 << bits) - 1) as f64;
                step * step / 12.0
            }
            Quantisation::Srgb(bits) => {
                // d(linear)/d(encoded) at v, times the encoded step: linear = ((e + 0.055) /
                // 1.055)^2.4 has the slope 2.4 / 1.055 ((e + 0.055) / 1.055)^1.4, which is
                // 2.4 / 1.055 v^(7/12) above the linear toe; squared, one power of v.
                let v = v.clamp(0.0, 1.0);
                let step = 1.0 / ((1u64 << bits) - 1) as f64;
                let slope2 = if v <= SRGB_TOE {
                    1.0 / (12.92 * 12.92)
                } else {
                    (2.4 / 1.055) * (2.4 / 1.055) * v.powf(7.0 / 6.0)
                };
                slope2 * step * step / 12.0
            }
        }
    }
}

/// The linear value below which sRGB's encoding is linear (slope 12.92).
pub(crate) const SRGB_TOE: f64 = 0.003_130_8;

/// A capture's noise model, in the stack's units.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct NoiseModel {
    /// How the samples were stored.
    pub quantisation: Quantisation,
    /// The level at and above which a sample is censored (known only to be at least this),
    /// common to every light: the white level over the brightest light's intensity. `None`:
    /// nothing is clipped (float captures).
    pub clip_level: Option<f32>,
    /// Shot noise: the variance per unit of signal (1 / electrons at full scale).
    pub shot: f64,
    /// Read noise: the variance floor.
    pub read: f64,
    /// The light directions' uncertainty: the RMS angle (degrees) between each light's given
    /// and true direction, as its calibration reports it (0: taken as exact). The confidence
    /// reads it (docs/method.md, "Confidence").
    #[serde(default)]
    pub light_error_deg: f64,
}

impl NoiseModel {
    /// The variance of a sample whose noise-free value is `v`.
    pub fn variance(&self, v: f64) -> f64 {
        self.quantisation.variance(v) + self.shot * v.max(0.0) + self.read
    }

    /// Reads `slice` (RGB samples per light) through the censoring map into `out`: a sample
    /// that is censored (`+inf`) or has a channel at or above the clip level becomes the clip
    /// level in every channel; NaN stays NaN. Returns whether any sample was censored; without
    /// a clip level `out` is left empty and `false` returned.
    pub fn censor(&self, slice: &[f32], out: &mut Vec<f32>) -> bool {
        out.clear();
        let Some(c) = self.clip_level else {
            return false;
        };
        let hit = |s: &[f32]| s.iter().any(|&v| v >= c);
        if !slice.chunks_exact(3).any(hit) {
            return false;
        }
        out.extend_from_slice(slice);
        for s in out.chunks_exact_mut(3) {
            if hit(s) {
                s.fill(c);
            }
        }
        true
    }

    /// Estimates shot and read noise from images (`width x height`, RGB, linear): the images'
    /// [`NoiseSamples`], fitted ([`NoiseModel::fit`], which also finds a float capture's clip
    /// level).
    pub fn estimate<'a>(
        self,
        images: impl Iterator<Item = &'a [f32]>,
        width: usize,
        mask: Option<&[bool]>,
    ) -> Self {
        let mut samples = NoiseSamples::new(&self);
        for img in images {
            samples.add(img, 3, width, mask);
        }
        self.fit(&mut samples)
    }

    /// Shot and read noise from `samples`: per level bin a robust variance (the median
    /// absolute deviation's) less the quantisation's, fitted by `shot * v + read` over the
    /// bins by least squares. On small or strongly curved images (a highlight a few pixels
    /// wide) the signal's curvature inflates it. Keeps `quantisation` and `clip_level`; a float
    /// capture without a clip level takes one where its samples show a clipped plateau
    /// ([`NoiseSamples::clip_plateau`]: a float file made from one exposure clips where the
    /// sensor did).
    pub fn fit(mut self, samples: &mut NoiseSamples) -> Self {
        if self.quantisation == Quantisation::Float && self.clip_level.is_none() {
            self.clip_level = samples.clip_plateau();
        }
        // Per bin: (level, noise variance) from the MAD of the second differences; a second
        // difference of independent noise has 1.5 times the samples' variance.
        let mut points: Vec<(f64, f64)> = Vec::new();
        for (d, l) in samples.diffs.iter_mut().zip(&mut samples.levels) {
            if d.len() < 200 {
                continue;
            }
            let med = median(d);
            let mut dev: Vec<f32> = d.iter().map(|v| (v - med).abs()).collect();
            let mad = median(&mut dev) as f64;
            let level = median(l) as f64;
            let var = (1.4826 * mad).powi(2) / 1.5 - self.quantisation.variance(level);
            points.push((level, var.max(0.0)));
        }
        if points.len() >= 2 {
            // Least squares of var = shot * v + read, both non-negative.
            let n = points.len() as f64;
            let (sx, sy) = points
                .iter()
                .fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
            let (mx, my) = (sx / n, sy / n);
            let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            let shot = if sxx > 0.0 { (sxy / sxx).max(0.0) } else { 0.0 };
            self.shot = shot;
            self.read = (my - shot * mx).max(0.0);
        }
        self
    }
}

/// The second differences the noise estimate reads, gathered image by image (one image in
/// memory at a time): per level bin (24, log-spaced from 1e-4 to the clip level) at most
/// 20,000 differences `v(x) - (v(x-1) + v(x+1)) / 2` between horizontal neighbours, and their
/// levels.
#[derive(Debug, Clone)]
pub struct NoiseSamples {
    top: f64,
    diffs: Vec<Vec<f32>>,
    levels: Vec<Vec<f32>>,
    /// The largest sample seen and how many samples had exactly that value: where a float
    /// capture clipped, and how many samples say so.
    max: f32,
    at_max: usize,
    /// Values below `max` within [`Self::PLATEAU_BAND`], each with how many samples had it (a
    /// former largest value keeps its count).
    below: Vec<(f32, usize)>,
}

impl NoiseSamples {
    const BINS: usize = 24;
    const PER_BIN: usize = 20_000;
    /// Pixels of one image visited at most (rows are skipped evenly beyond).
    const PIXELS_PER_IMAGE: usize = 4 << 20;

    /// A clipped plateau is told from the top of a smooth highlight by the samples within this
    /// share below the largest value: a smooth top puts more samples there than at any one
    /// value (the more the wider the share); a clip puts every sample beyond it at one value.
    /// Wider than an 8-bit step from about a quarter of full scale up, and than sixteen
    /// half-float steps, so quantised float files are not taken as clipped.
    const PLATEAU_BAND: f32 = 1.0 / 64.0;
    /// Fewest samples at the largest value that make a plateau.
    const PLATEAU_MIN: usize = 8;
    /// Most entries `below` keeps: beyond, they are merged into one at the largest of them
    /// (a count that stays in the band longest, so a crowded band is never undercounted and no
    /// plateau is found that the full list would refuse). Memory stays bounded on a large
    /// bright region just below the top.
    const BELOW_CAP: usize = 4096;

    /// Empty bins for a capture of `model`'s clip level.
    pub fn new(model: &NoiseModel) -> Self {
        Self {
            top: model.clip_level.map_or(1.0, |c| c as f64),
            diffs: vec![Vec::new(); Self::BINS],
            levels: vec![Vec::new(); Self::BINS],
            max: 0.0,
            at_max: 0,
            below: Vec::new(),
        }
    }

    /// The level at which the samples show a clipped plateau: at least
    /// `Self::PLATEAU_MIN` samples at exactly the largest value, and more there than in the
    /// whole band `Self::PLATEAU_BAND` below it. `None` where they do not.
    pub fn clip_plateau(&self) -> Option<f32> {
        let floor = self.floor();
        let below: usize = self
            .below
            .iter()
            .filter(|e| e.0 >= floor)
            .map(|e| e.1)
            .sum();
        let at = self.at_max;
        (self.max > 0.0 && at >= Self::PLATEAU_MIN && at > below).then_some(self.max)
    }

    /// The lower end of the band below the largest value.
    fn floor(&self) -> f32 {
        self.max * (1.0 - Self::PLATEAU_BAND)
    }

    /// Counts `v` where it is at or within the band below the largest value so far.
    fn add_top(&mut self, v: f32) {
        if !(v.is_finite() && v >= self.floor()) {
            return;
        }
        if v == self.max {
            self.at_max += 1;
            return;
        }
        if v > self.max {
            if self.at_max > 0 {
                self.below.push((self.max, self.at_max));
            }
            (self.max, self.at_max) = (v, 1);
            // The band moved up: drop what fell out of it, now and then (amortised).
            if self.below.len() >= 64 {
                let floor = self.floor();
                self.below.retain(|e| e.0 >= floor);
            }
        } else {
            self.below.push((v, 1));
        }
        if self.below.len() > Self::BELOW_CAP {
            let floor = self.floor();
            self.below.retain(|e| e.0 >= floor);
            if self.below.len() > Self::BELOW_CAP {
                let top = self.below.iter().fold(0.0f32, |a, e| a.max(e.0));
                let count = self.below.iter().map(|e| e.1).sum();
                self.below.clear();
                self.below.push((top, count));
            }
        }
    }

    /// Adds the differences of one image (`channels` interleaved, `width` wide, linear), over
    /// the pixels inside `mask` (when given, `width x height`): the rows [`Self::row_step`]
    /// picks, each as [`Self::add_row`] adds it.
    pub fn add(&mut self, img: &[f32], channels: usize, width: usize, mask: Option<&[bool]>) {
        let (ch, w) = (channels.max(1), width.max(1));
        let rows = img.len() / ch / w;
        for y in (0..rows).step_by(Self::row_step(w, rows)) {
            let row = &img[y * w * ch..(y + 1) * w * ch];
            self.add_row(row, ch, mask.map(|m| &m[y * w..(y + 1) * w]));
        }
    }

    /// Which rows of a `width x rows` image are visited: every `row_step`-th from the first
    /// (so that at most `PIXELS_PER_IMAGE` pixels are).
    pub fn row_step(width: usize, rows: usize) -> usize {
        (rows * width.max(1))
            .div_ceil(Self::PIXELS_PER_IMAGE)
            .max(1)
    }

    /// Adds the differences along one image row (`channels` interleaved, linear), over the
    /// pixels inside `mask` (the row's, when given): a reader of rows adds the rows
    /// [`Self::row_step`] picks, one at a time, as [`Self::add`] adds a whole image.
    pub fn add_row(&mut self, row: &[f32], channels: usize, mask: Option<&[bool]>) {
        let ch = channels.max(1);
        let w = row.len() / ch;
        let top = self.top;
        let bin_of = |v: f64| -> Option<usize> {
            if !(v > 1e-4 && v < 0.95 * top) {
                return None;
            }
            let t = (v / 1e-4).ln() / (top / 1e-4).ln();
            Some(((t * Self::BINS as f64) as usize).min(Self::BINS - 1))
        };
        for p in 0..w {
            if mask.is_none_or(|m| m[p]) {
                for c in 0..ch {
                    self.add_top(row[ch * p + c]);
                }
            }
        }
        for p in 1..w.saturating_sub(1) {
            if let Some(m) = mask {
                if !(m[p - 1] && m[p] && m[p + 1]) {
                    continue;
                }
            }
            for c in 0..ch {
                let (a, b, d) = (
                    row[ch * (p - 1) + c],
                    row[ch * p + c],
                    row[ch * (p + 1) + c],
                );
                if !(a.is_finite() && b.is_finite() && d.is_finite()) {
                    continue;
                }
                let Some(k) = bin_of(b as f64) else { continue };
                if self.diffs[k].len() < Self::PER_BIN {
                    self.diffs[k].push(b - 0.5 * (a + d));
                    self.levels[k].push(b);
                }
            }
        }
    }
}

/// The median of `v` (reordered), 0 when empty.
fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{Degradation, Noise};

    #[test]
    fn quantisation_variance_follows_the_encoding() {
        let q = Quantisation::Linear(8).variance(0.5);
        assert!((q - (1.0 / 255.0f64).powi(2) / 12.0).abs() < 1e-15);
        // sRGB: finer than linear in the darks, coarser in the brights.
        let s = Quantisation::Srgb(8);
        assert!(s.variance(0.01) < q && s.variance(0.9) > q);
        assert_eq!(Quantisation::Float.variance(0.5), 0.0);
        // The sRGB step at each 16-bit code, read from the decoding itself: the linear values
        // of the code and its neighbour, on both sides of the linear toe.
        let decode = crate::render::noise::srgb_to_linear;
        let s16 = Quantisation::Srgb(16);
        for code in [20u32, 2000, 2651, 2700, 30_000, 65_000] {
            let (e0, e1) = (code as f64 / 65535.0, (code + 1) as f64 / 65535.0);
            let (lo, hi) = (decode(e0), decode(e1));
            let stepped = (hi - lo).powi(2) / 12.0;
            let modelled = s16.variance(0.5 * (lo + hi));
            assert!(
                (modelled / stepped - 1.0).abs() < 1e-3,
                "code {code}: {modelled} against {stepped}"
            );
        }
    }

    #[test]
    fn censoring_is_one_pointwise_map() {
        let m = NoiseModel {
            clip_level: Some(0.9),
            ..NoiseModel::default()
        };
        let slice = [
            0.2,
            0.3,
            0.4,
            f32::INFINITY,
            f32::INFINITY,
            f32::INFINITY,
            0.95,
            0.5,
            0.1,
        ];
        let mut out = Vec::new();
        assert!(m.censor(&slice, &mut out));
        assert_eq!(out, [0.2, 0.3, 0.4, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9]);
        assert!(!m.censor(&[0.1, 0.2, 0.3], &mut out) && out.is_empty());
        assert!(!NoiseModel::default().censor(&slice, &mut out));
    }

    /// Images of a smooth highlight (a Gaussian bump peaking at `peak`), float, with shot noise
    /// of 4,000 electrons at 1 and each sample passed through `store`.
    fn highlights(peak: f32, store: impl Fn(f32) -> f32) -> (usize, Vec<Vec<f32>>) {
        let (w, h) = (96, 96);
        let d = Degradation {
            noise: Noise::Shot { photons: 4000.0 },
            seed: 9,
            ..Degradation::default()
        };
        let images = (0..4)
            .map(|i| {
                let c = (20.0 + 15.0 * i as f32, 40.0 + 10.0 * i as f32);
                let mut v: Vec<f32> = (0..w * h)
                    .flat_map(|p| {
                        let (x, y) = ((p % w) as f32 - c.0, (p / w) as f32 - c.1);
                        [0.05 + peak * (-(x * x + y * y) / 200.0).exp(); 3]
                    })
                    .collect();
                d.apply(&mut v, i);
                v.iter_mut().for_each(|s| *s = store(*s));
                v
            })
            .collect();
        (w, images)
    }

    #[test]
    fn a_float_capture_s_clip_is_found_where_it_clipped() {
        let clip_level = |images: &[Vec<f32>], w: usize| {
            NoiseModel::default()
                .estimate(images.iter().map(|v| &v[..]), w, None)
                .clip_level
        };
        // Clipped at 0.8 (a fifth of each highlight's area beyond it): found.
        let (w, clipped) = highlights(1.5, |v| v.min(0.8));
        assert_eq!(clip_level(&clipped, w), Some(0.8));
        // The same highlights unclipped, as float32, as half floats (ties at the top), and as
        // 8-bit levels in a float file: no clip.
        let (w, smooth) = highlights(0.7, |v| v);
        assert_eq!(clip_level(&smooth, w), None);
        let (w, half) = highlights(0.7, |v| {
            let step = 2f32.powi(v.log2().floor() as i32 - 10);
            (v / step).round() * step
        });
        assert_eq!(clip_level(&half, w), None);
        let (w, bytes) = highlights(0.7, |v| (v * 255.0).round() / 255.0);
        assert_eq!(clip_level(&bytes, w), None);
        // An integer capture's clip level is the decoder's, never replaced.
        let told = NoiseModel {
            quantisation: Quantisation::Linear(16),
            clip_level: Some(0.9),
            ..NoiseModel::default()
        };
        let m = told.estimate(clipped.iter().map(|v| &v[..]), w, None);
        assert_eq!(m.clip_level, Some(0.9));
    }

    #[test]
    fn shot_noise_is_recovered_from_smooth_images() {
        // A smooth ramp with shot noise of 4,000 electrons at full scale, float.
        let (w, h) = (256, 64);
        let img: Vec<f32> = (0..w * h)
            .flat_map(|p| {
                let v = 0.02 + 0.9 * (p % w) as f32 / w as f32;
                [v; 3]
            })
            .collect();
        let d = Degradation {
            noise: Noise::Shot { photons: 4000.0 },
            seed: 5,
            ..Degradation::default()
        };
        let images: Vec<Vec<f32>> = (0..8)
            .map(|i| {
                let mut v = img.clone();
                d.apply(&mut v, i);
                v
            })
            .collect();
        let m = NoiseModel::default().estimate(images.iter().map(|v| &v[..]), w, None);
        assert!(
            (m.shot * 4000.0 - 1.0).abs() < 0.15,
            "shot {}",
            m.shot * 4000.0
        );
        assert!(m.read < 2e-6, "read {}", m.read);
    }
}
