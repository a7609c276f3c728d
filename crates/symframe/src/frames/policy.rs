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

use crate::baselines::BaselinePixel;
use crate::frames::lobe::{LobeFit, LobePair, LOBE_EXPLAINS};
use crate::highlight::HighlightMoments;
use crate::highlight::MIN_ELONGATION;
use crate::maps::PixelSource;

/// Default smallest symmetry anisotropy for a tangent (`--min-anisotropy`).
pub(crate) const DEFAULT_MIN_ANISOTROPY: f32 = 0.6;

/// Every setting of the estimator's choice of answer, grouped by the rule that reads it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct PolicySettings {
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
pub(crate) struct LobeSettings {
    /// A lobe leaving less than this share of the pixel's energy unexplained is the answer
    /// (source `lobe`), as is one that leaves no more than the capture's noise does (see
    /// [`LobeSettings::noise_z`]); one leaving more is no evidence, and the symmetry search
    /// decides. Fits of lobes in the family leave almost nothing noise-free; a lobe outside the
    /// family (Ashikhmin-Shirley) leaves more, with normals further off than the search's
    /// (docs/method.md, "Lobe fit"). Higher: more pixels answered by the lobe's centre, biased
    /// where the family misdescribes the material.
    pub explains: f64,
    /// A lobe explains the pixel too where what it leaves is what the noise model expects the
    /// capture's noise to leave ([`LobeFit::noise_share`]) plus the family's floor
    /// ([`LobeSettings::model_floor`]), within this many standard deviations of that share
    /// (the one-sided 0.1% point of the normal distribution): a chi-square test of the fit, in
    /// the noise's units. Higher: lobes that misdescribe the material by more than the noise
    /// hides answer too.
    pub noise_z: f64,
    /// ...and only where the data determine the lobe's centre: its standard deviation (the
    /// fit's covariance and split half with the lights' error, [`LobeFit::normal_sd`] and
    /// [`LobeFit::light_sd`]) at most this (radians; 0.5 degrees, a confidence of 0.98 of
    /// being within 1 degree). A lobe that the noise lets through but that the samples hardly
    /// pin down (a broad lobe whose tilt trades against its shape) may sit far from the
    /// symmetric centre, which the search then reads. Higher: more such lobes answer.
    pub noise_determined: f64,
    /// A lobe leaving less than this share beyond what the capture's noise leaves (its
    /// expected share plus [`LobeSettings::noise_z`] standard deviations, [`NoiseShare`]) is a
    /// plausible answer where the search doubts its own, and its axis counts as a reading of
    /// the tangent by itself (docs/method.md, "Default measure", has what a looser share
    /// cost). Higher: more doubtful searches replaced, more tangents from lobes that describe
    /// the pixel less well.
    pub plausible: f64,
    /// Where a diffuse term explains the pixel too, the lobe answers only if what it leaves
    /// beyond the noise's expected share is less than this share of what the diffuse term
    /// leaves beyond its own: the two models' misfits compared, not the noise both leave.
    /// Higher: broad lobes that pass the diffuse test answer more often (and bias the
    /// Lambertian normal).
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
            noise_z: 3.09,
            noise_determined: 0.5f64.to_radians(),
            plausible: 0.005,
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
pub(crate) struct DiffuseSettings {
    /// A pixel whose Lambertian fit leaves less than this share of its energy unexplained is
    /// diffuse: no lobe is fitted (1% RMS noise leaves 1e-4), as is one whose fit leaves no
    /// more than the capture's noise would (see [`DiffuseSettings::noise_z`]). Higher: more
    /// pixels skip the lobe.
    pub pure_share: f64,
    /// A pixel whose Lambertian fit leaves no more than the noise model expects the capture's
    /// noise to leave (quantisation, shot and read noise), within this many standard
    /// deviations of that share (the one-sided 0.1% point of the normal distribution), has no
    /// lobe the data can tell: it is diffuse, as below [`DiffuseSettings::pure_share`], and its
    /// Lambertian term answers, as below [`DiffuseSettings::specular_share`]. Higher: weaker
    /// lobes taken for noise.
    pub noise_z: f64,
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
            noise_z: 3.09,
            centre_fit: 0.99,
            specular_share: 0.005,
            spiked_fit: 0.999,
            spike_share: 0.05,
        }
    }
}

/// When the symmetry search doubts its answer, or another start overrules it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SearchSettings {
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
pub(crate) struct ShadowSettings {
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
pub(crate) struct FallbackSettings {
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
pub(crate) struct TangentSettings {
    /// Smallest symmetry anisotropy `(f45 - f0) / (f45 + f0)` of the slice (`f0`, `f45`: the
    /// tangent objective at the answer's axes and 45 degrees away) for a tangent. Higher: fewer
    /// tangents, none from weakly anisotropic slices.
    pub min_anisotropy: f64,
    /// Smallest elongation of the highlight's second moment for it to show a wide axis.
    /// Higher: the moments count as evidence only for strongly elongated highlights.
    pub min_moment_elongation: f64,
    /// Cosine of the largest angle between a fitted lobe's wide axis and a symmetry axis at
    /// which the two agree (15 degrees). Higher: stricter agreement. A plausible lobe
    /// ([`LobeSettings::plausible`]) that agrees gives a tangent whatever the slice's
    /// anisotropy (noise and light errors blur the anisotropy first).
    pub axes_agree_cos: f64,
}

impl Default for TangentSettings {
    fn default() -> Self {
        Self {
            min_anisotropy: DEFAULT_MIN_ANISOTROPY as f64,
            min_moment_elongation: MIN_ELONGATION,
            axes_agree_cos: 15f64.to_radians().cos(),
        }
    }
}

/// A fitted lobe's reading of the highlight's axes, as the tangent decision needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LobeAxis {
    /// The lobe's wide axis (unit, perpendicular to its normal).
    pub tangent: DVec3,
    /// The lobe plausibly describes the pixel ([`LobeSettings::plausible`]).
    pub plausible: bool,
    /// Whether the lobe is elongated enough, and wide enough for the rig to resolve, to have
    /// a wide axis at all.
    pub elongated: bool,
}

/// What a pixel's data say about its tangent, gathered once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TangentEvidence {
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
            l.elongated && along.max(across) >= s.axes_agree_cos && (!plausible_only || l.plausible)
        })
    }
}

/// Whether the data determine a tangent at this pixel (see the module's rule).
pub(crate) fn has_tangent(s: &TangentSettings, e: &TangentEvidence) -> bool {
    let anisotropic = e.anisotropy >= s.min_anisotropy;
    let axis_read = e.moments_elongated || e.lobe_agrees(s, false);
    (anisotropic && axis_read) || e.lobe_agrees(s, true)
}

/// How clearly the data single out the tangent's axes, in `[0, 1]`: `1 - f0 / f45`, the share
/// of the tangent objective at 45 degrees that the answer's axes remove (0 for an isotropic
/// slice, towards 1 where the slice is exactly symmetric about the answer's axes and far from
/// it about any other pair), halved where no independent reading of the highlight puts its
/// wide axis along them. Model-free: the same measure of the data for every source.
pub(crate) fn tangent_confidence(
    s: &TangentSettings,
    e: &TangentEvidence,
    f0: f64,
    f45: f64,
) -> f32 {
    if !(f0.is_finite() && f45.is_finite()) || f45 <= 0.0 {
        return 0.0;
    }
    let separation = (1.0 - f0.max(0.0) / f45).clamp(0.0, 1.0);
    let agreed = e.moments_elongated || e.lobe_agrees(s, false);
    (if agreed { separation } else { 0.5 * separation }) as f32
}

/// What a capture's noise alone would leave of a fit's unexplained share: its expectation and
/// standard deviation (both 0 for a noise-free capture). The fits' tests compare what they
/// leave with it (docs/method.md, "Noise model").
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct NoiseShare {
    /// The expected share.
    pub(crate) expected: f64,
    /// Its standard deviation.
    pub(crate) sd: f64,
}

impl NoiseShare {
    /// The share the noise leaves at most, `z` standard deviations above its expectation (a
    /// one-sided test at the normal distribution's point `z`).
    pub(crate) fn at(&self, z: f64) -> f64 {
        self.expected + z * self.sd
    }

    /// What a lobe's fit leaves to its noise.
    pub(crate) fn of_lobe(f: &LobeFit) -> Self {
        Self {
            expected: f.noise_share,
            sd: f.noise_share_sd,
        }
    }
}

/// What a pixel offers the choice of its normal, gathered before the choice.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NormalEvidence<'a> {
    /// The default measure is in force (`--cosine auto`): the lobe, diffuse and sharp-lobe
    /// rules apply; otherwise the symmetry search answers (or a lobe that explains the pixel).
    pub(crate) auto: bool,
    /// The fitted lobe (one, or two sharing a frame).
    pub(crate) lobe: Option<&'a LobeFit>,
    /// The robust Lambertian fit.
    pub(crate) lambertian: &'a BaselinePixel,
    /// The share of the well-lit energy the Lambertian term leaves unexplained (default
    /// measure only).
    pub(crate) share: Option<f64>,
    /// What the capture's noise alone would leave of that share (where it was asked: the
    /// Lambertian fit explains the pixel to [`DiffuseSettings::centre_fit`] and `share` is
    /// above [`DiffuseSettings::pure_share`]).
    pub(crate) diffuse_noise: Option<NoiseShare>,
    /// The highlight's half-maximum region holds at most [`LobeSettings::sharp_samples`]
    /// lights: a lobe narrower than the rig's spacing.
    pub(crate) sharp: bool,
}

/// Which reading answers a pixel's normal (before the search, where it is asked).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum NormalChoice<'a> {
    /// The fitted lobe's centre (source `lobe`).
    Lobe(&'a LobeFit),
    /// A sharp lobe's: the diffuse part's normal (source `lambertian`) where a diffuse term
    /// explains the samples once the spike is left out, else the highlight's peak (source
    /// `highlight`).
    Sharp(DVec3, PixelSource),
    /// The robust Lambertian fit's normal (source `lambertian`).
    Diffuse(DVec3),
    /// The symmetry search decides (source `symmetry`).
    Search,
}

/// The normal's reading, the rules in order (docs/method.md, "The choice of answer"):
/// 1. a lobe answers where it leaves less than [`LobeSettings::explains`], unless a diffuse term
///    explains the pixel nearly as well ([`LobeSettings::over_diffuse`]) or the lobe barely
///    improves on the Lambertian fit (it then stands in for the diffuse light);
/// 2. a sharp lobe (few lights on the highlight) is read by its diffuse part or its peak;
/// 3. a diffuse pixel (the Lambertian fit explains it, [`DiffuseSettings::centre_fit`] and
///    [`DiffuseSettings::specular_share`]; or all but an undersampled spike) by its Lambertian
///    term;
/// 4. anything else by the symmetry search.
///
/// `peak` reads the highlight's log-quadratic peak; it is called only where rule 2 asks for it.
pub(crate) fn choose_normal<'a>(
    s: &PolicySettings,
    e: &NormalEvidence<'a>,
    peak: impl FnOnce() -> Option<DVec3>,
) -> NormalChoice<'a> {
    let fit = e.lambertian;
    let lobe = e.lobe.filter(|f| lobe_explains(&s.lobe, f));
    let diffuse = if e.auto {
        diffuse_centre(&s.diffuse, fit, e.share, e.diffuse_noise)
            .or_else(|| spiked_diffuse(&s.diffuse, fit, lobe))
    } else {
        None
    };
    // A broad lobe passes the diffuse test too, and biases the Lambertian normal: it answers
    // only where it misfits much less than the diffuse term, beyond what the noise leaves.
    let lobe = lobe.filter(|f| match diffuse.and(e.share) {
        Some(share) => lobe_over_diffuse(&s.lobe, f, share, e.diffuse_noise),
        None => true,
    });
    // Nor where it barely improves on the robust Lambertian fit alone (the lobe model holds a
    // diffuse term too): such a lobe stands in for the diffuse light, and where its centre is
    // off at all it is far off (docs/method.md, "Default measure", for what was measured).
    let impersonated = lobe.is_some_and(|f| {
        fit.confidence as f64 >= s.diffuse.centre_fit
            && f.residual >= s.lobe.over_diffuse * (1.0 - fit.confidence as f64)
    });
    let (lobe, answering_diffuse) = if impersonated {
        (None, fit.normal)
    } else {
        (lobe, diffuse)
    };
    if let Some(f) = lobe {
        return NormalChoice::Lobe(f);
    }
    // A sharp highlight where no diffuse term explains the pixel (the test before the
    // impersonation rule): its diffuse part, else its peak.
    let sharp = if e.auto && diffuse.is_none() && e.sharp {
        match fit.normal {
            Some(m) if fit.confidence as f64 >= s.diffuse.centre_fit => {
                Some((m, PixelSource::Lambertian))
            }
            _ => peak().map(|m| (m, PixelSource::Highlight)),
        }
    } else {
        None
    };
    match (sharp, answering_diffuse) {
        (Some((m, from)), _) => NormalChoice::Sharp(m, from),
        (None, Some(m)) => NormalChoice::Diffuse(m),
        (None, None) => NormalChoice::Search,
    }
}

/// Whether the symmetry search's answer, of quality `quality` (see
/// [`SearchSettings::doubtful`]), gives way to the fitted lobe `f` (whose centre is within
/// the rig's reach where `observed()`, asked last): the search doubts its answer (cast
/// shadows that break the slice's symmetry, a lobe cut by the rig's reach) and the lobe nearly
/// explains the samples (where the search's quality is higher it is the better of the two:
/// docs/method.md, "Default measure", has the figures).
pub(crate) fn search_gives_way(
    s: &PolicySettings,
    quality: f64,
    f: &LobeFit,
    observed: impl FnOnce() -> bool,
) -> bool {
    quality < s.search.doubtful && lobe_plausible(&s.lobe, f) && f.normal.z > 0.0 && observed()
}

/// Whether the lobe `f` plausibly describes the pixel: it leaves less than
/// [`LobeSettings::plausible`] beyond what the noise leaves at [`LobeSettings::noise_z`].
pub(crate) fn lobe_plausible(s: &LobeSettings, f: &LobeFit) -> bool {
    f.residual < s.plausible + NoiseShare::of_lobe(f).at(s.noise_z)
}

/// Whether the lobe `f` describes the pixel much better than the diffuse term that leaves
/// `share` (of which the noise leaves `diffuse_noise`): its misfit, beyond the noise's expected
/// share, under [`LobeSettings::over_diffuse`] times the diffuse term's.
fn lobe_over_diffuse(
    s: &LobeSettings,
    f: &LobeFit,
    share: f64,
    diffuse_noise: Option<NoiseShare>,
) -> bool {
    let diffuse_misfit = share - diffuse_noise.map_or(0.0, |n| n.expected);
    f.residual - f.noise_share < s.over_diffuse * diffuse_misfit
}

/// The largest share of the energy the lobe `f` may leave and explain the pixel: the fixed
/// share [`LobeSettings::explains`], or what the capture's noise leaves at most (its expected
/// share and the family's floor, plus [`LobeSettings::noise_z`] standard deviations).
pub(crate) fn lobe_limit(s: &LobeSettings, f: &LobeFit) -> f64 {
    s.explains
        .max(NoiseShare::of_lobe(f).at(s.noise_z) + s.model_floor)
}

/// Whether the lobe `f` describes the samples to their noise: it leaves less than
/// [`lobe_limit`]. Its own slice then stands for the pixel's, and the reconstruction's bias is
/// read on it (docs/method.md, "Confidence").
pub(crate) fn lobe_describes(s: &LobeSettings, f: &LobeFit) -> bool {
    f.residual < lobe_limit(s, f)
}

/// Whether the lobe `f` explains the pixel: it leaves less than [`LobeSettings::explains`],
/// or less than [`lobe_limit`] with its centre determined ([`LobeSettings::noise_determined`]).
pub(crate) fn lobe_explains(s: &LobeSettings, f: &LobeFit) -> bool {
    f.residual < s.explains || (lobe_describes(s, f) && centre_determined(s, f))
}

/// Whether the samples determine the lobe's centre to [`LobeSettings::noise_determined`].
fn centre_determined(s: &LobeSettings, f: &LobeFit) -> bool {
    f.normal_sd.hypot(f.light_sd) <= s.noise_determined
}

/// Whether a pixel is diffuse enough that no lobe is fitted: its Lambertian fit explains it
/// to the noise floor ([`DiffuseSettings::pure_share`]).
pub(crate) fn pure_diffuse(
    s: &DiffuseSettings,
    fit: &BaselinePixel,
    share: Option<f64>,
    noise: Option<NoiseShare>,
) -> bool {
    fit.confidence as f64 >= s.centre_fit
        && share.is_some_and(|v| v < s.pure_share || noise.is_some_and(|n| v < n.at(s.noise_z)))
}

/// Whether two lobes sharing a frame explain the pixel (docs/method.md, "Two lobes"): they
/// leave less than the one lobe `single` may ([`lobe_limit`]: the pair is fitted to its
/// samples), the second lobe is significant (an F test), and
/// what they leave at every light (cast shadows included) is at the model floor
/// ([`LobeSettings::model_floor`]) or looks like independent noise
/// ([`LobeSettings::noise_like_z`]), not like a material they do not describe.
pub(crate) fn pair_explains(s: &LobeSettings, p: &LobePair, single: &LobeFit) -> bool {
    (p.residual < s.explains
        || (p.residual < lobe_limit(s, single)
            && p.normal_sd.hypot(p.light_sd) <= s.noise_determined))
        && p.significant()
        && (p.residual_everywhere < s.model_floor || p.structure < s.noise_like_z)
}

/// Whether the base under a sharp coat is fitted on its own (the samples at the coat's level
/// left out): the highlight is sharp and one lobe does not even plausibly explain the pixel.
pub(crate) fn reads_base(s: &LobeSettings, highlight_count: u32, f: &LobeFit) -> bool {
    highlight_count <= s.sharp_samples && !lobe_plausible(s, f)
}

/// The normal of a diffuse pixel's robust Lambertian fit, when the fit explains the samples
/// (uncentred R^2 at least [`DiffuseSettings::centre_fit`]) and leaves less than
/// [`DiffuseSettings::specular_share`] of the well-lit signal's energy unexplained (`share`).
pub(crate) fn diffuse_centre(
    s: &DiffuseSettings,
    fit: &BaselinePixel,
    share: Option<f64>,
    noise: Option<NoiseShare>,
) -> Option<DVec3> {
    fit.normal
        .filter(|_| fit.confidence as f64 >= s.centre_fit)
        .filter(|_| {
            share
                .is_some_and(|v| v < s.specular_share || noise.is_some_and(|n| v < n.at(s.noise_z)))
        })
}

/// The normal of a diffuse pixel whose specular spike the rig undersamples: no lobe explains
/// the samples, and the robust Lambertian fit explains all but a few of them nearly exactly
/// (uncentred R^2 at least [`DiffuseSettings::spiked_fit`], at most
/// [`DiffuseSettings::spike_share`] of the samples it considered left out as outliers: the
/// spike's). Such a slice is symmetric about the Lambertian normal but for the spike's few
/// samples, which mislead the search (docs/method.md, "Default measure").
pub(crate) fn spiked_diffuse(
    s: &DiffuseSettings,
    fit: &BaselinePixel,
    lobe: Option<&LobeFit>,
) -> Option<DVec3> {
    if lobe.is_some() {
        return None;
    }
    let left_out = fit.considered.saturating_sub(fit.used) as f64;
    fit.normal.filter(|_| {
        fit.confidence as f64 >= s.spiked_fit && left_out <= s.spike_share * fit.considered as f64
    })
}

/// What answers a pixel whose answer lies beyond the rig's reach, with fallbacks on: the source,
/// normal and confidence (before [`FallbackSettings::confidence`] scales it), `None` where
/// nothing does. The lobe `lobe` where it explains the pixel ([`LobeSettings::explains`])
/// unless a diffuse term explains it nearly as well, or where it explains it much better than
/// the diffuse term (the joint model's normal is the diffuse term's too, without the bias the
/// unmodelled highlight's tails give the Lambertian fit: docs/method.md, "Fallbacks and the
/// source map"); else the Lambertian fit where
/// it explains the pixel ([`FallbackSettings::diffuse_fit`]); else the highlight's centroid.
pub(crate) fn choose_fallback(
    s: &PolicySettings,
    lambert: &BaselinePixel,
    share: Option<f64>,
    moments: Option<HighlightMoments>,
    lobe: Option<&LobeFit>,
) -> Option<(PixelSource, DVec3, f32)> {
    let diffuse = lambert
        .normal
        .filter(|_| lambert.confidence as f64 >= s.fallback.diffuse_fit);
    let lobe = lobe.filter(|f| f.normal.z > 0.0).and_then(|f| {
        // Unlike within the reach, the shares themselves are compared, noise and all: a lobe
        // that beats the diffuse term only once the noise is discounted fits the part of the
        // highlight the rig sees no better than noise, which does not place a centre beyond
        // it (docs/method.md, "The policy's settings", has what discounting it here cost).
        let over_diffuse = diffuse.and(share).map(|v| s.lobe.over_diffuse * v);
        let limit = if centre_determined(&s.lobe, f) {
            lobe_limit(&s.lobe, f)
        } else {
            s.lobe.explains
        };
        let confidence = if f.residual < limit {
            1.0 - f.residual / limit
        } else {
            1.0 - f.residual / over_diffuse?
        };
        over_diffuse
            .is_none_or(|limit| f.residual < limit)
            .then_some((f, confidence))
    });
    match (lobe, diffuse) {
        (Some((f, confidence)), _) => {
            Some((PixelSource::Lobe, f.normal, confidence.max(0.0) as f32))
        }
        (None, Some(n)) => Some((PixelSource::Lambertian, n, lambert.confidence)),
        (None, None) => match moments {
            Some(m) if m.normal.z > 0.0 => {
                Some((PixelSource::Highlight, m.normal, m.contrast as f32))
            }
            _ => None,
        },
    }
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

    fn lobe(tangent: DVec3, plausible: bool, elongated: bool) -> Option<LobeAxis> {
        Some(LobeAxis {
            tangent,
            plausible,
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
            &evidence(0.9, false, lobe(DVec3::X, false, false))
        ));
    }

    #[test]
    fn an_anisotropic_slice_with_an_agreeing_reading_has_a_tangent() {
        let s = TangentSettings::default();
        assert!(has_tangent(&s, &evidence(0.7, true, None)));
        // A poor single-lobe fit (a coat and a base) whose wide axis agrees: a tangent.
        assert!(has_tangent(
            &s,
            &evidence(0.7, false, lobe(DVec3::Y, false, true))
        ));
        // ... but not when its axis is 30 degrees off both symmetry axes.
        let off = DVec3::new(30f64.to_radians().cos(), 30f64.to_radians().sin(), 0.0);
        assert!(!has_tangent(
            &s,
            &evidence(0.7, false, lobe(off, false, true))
        ));
        // Nor when the slice is not anisotropic enough.
        assert!(!has_tangent(
            &s,
            &evidence(0.3, true, lobe(DVec3::Y, false, true))
        ));
    }

    #[test]
    fn a_plausible_agreeing_lobe_gives_a_tangent_under_blurred_anisotropy() {
        let s = TangentSettings::default();
        assert!(has_tangent(
            &s,
            &evidence(0.2, false, lobe(DVec3::X, true, true))
        ));
        assert!(!has_tangent(
            &s,
            &evidence(0.2, false, lobe(DVec3::X, false, true))
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

    fn lambertian(normal: DVec3, fit: f32) -> BaselinePixel {
        BaselinePixel {
            status: crate::maps::PixelStatus::Estimated,
            normal: Some(normal),
            tangent: None,
            confidence: fit,
            used: 100,
            considered: 100,
        }
    }

    fn fitted(normal: DVec3, residual: f64) -> LobeFit {
        LobeFit {
            normal,
            tangent: DVec3::X,
            alpha: [0.2, 0.1],
            shape: 1.0,
            foreshortening: 0.0,
            diffuse: 0.1,
            specular: 1.0,
            fresnel: 0.0,
            residual,
            trimmed: 0,
            normal_sd: 0.0,
            light_sd: 0.0,
            noise_share: 0.0,
            noise_share_sd: 0.0,
            evals: 0,
        }
    }

    fn choose<'a>(
        lobe: Option<&'a LobeFit>,
        fit: &'a BaselinePixel,
        share: Option<f64>,
        sharp: bool,
        peak: Option<DVec3>,
    ) -> NormalChoice<'a> {
        let evidence = NormalEvidence {
            auto: true,
            lobe,
            lambertian: fit,
            share,
            diffuse_noise: None,
            sharp,
        };
        choose_normal(&PolicySettings::default(), &evidence, || peak)
    }

    #[test]
    fn a_lobe_explains_what_the_noise_leaves_and_no_more() {
        let b = DVec3::new(0.1, 0.0, 1.0).normalize();
        let glossy = lambertian(DVec3::Z, 0.5);
        // 1% left: refused by the fixed share, accepted where the noise expects 0.9% with a
        // spread of 0.05%, refused again where the noise expects 0.5%.
        let noisy = |share: f64| LobeFit {
            noise_share: share,
            noise_share_sd: 5e-4,
            ..fitted(b, 0.01)
        };
        let (quiet, hidden, shown) = (noisy(0.0), noisy(0.009), noisy(0.005));
        let s = LobeSettings::default();
        assert!(!lobe_explains(&s, &quiet));
        assert!(lobe_explains(&s, &hidden));
        assert!(!lobe_explains(&s, &shown));
        assert_eq!(
            choose(Some(&hidden), &glossy, Some(0.3), false, None),
            NormalChoice::Lobe(&hidden)
        );
        assert_eq!(
            choose(Some(&shown), &glossy, Some(0.3), false, None),
            NormalChoice::Search
        );
    }

    #[test]
    fn the_normal_s_reading_follows_the_rules_in_order() {
        let s = PolicySettings::default();
        let (a, b) = (DVec3::Z, DVec3::new(0.1, 0.0, 1.0).normalize());
        let matte = lambertian(a, 0.999);
        let glossy = lambertian(a, 0.5);
        let explaining = fitted(b, 1e-4);
        let poor = fitted(b, 0.05);
        // A lobe that explains a pixel no diffuse term explains answers.
        assert_eq!(
            choose(Some(&explaining), &glossy, Some(0.3), false, None),
            NormalChoice::Lobe(&explaining)
        );
        // A lobe that leaves too much: the search, or a diffuse term where one explains.
        assert_eq!(
            choose(Some(&poor), &glossy, Some(0.3), false, None),
            NormalChoice::Search
        );
        assert_eq!(
            choose(Some(&poor), &matte, Some(1e-3), false, None),
            NormalChoice::Diffuse(a)
        );
        // A lobe barely better than the Lambertian fit stands in for the diffuse light.
        let broad = fitted(b, 1e-3);
        assert_eq!(
            choose(Some(&broad), &matte, Some(1e-3), false, None),
            NormalChoice::Diffuse(a)
        );
        // A sharp highlight without a diffuse part: its peak.
        assert_eq!(
            choose(None, &glossy, Some(0.3), true, Some(b)),
            NormalChoice::Sharp(b, PixelSource::Highlight)
        );
        // Outside the default measure only an explaining lobe or the search answer.
        let paper = choose_normal(
            &s,
            &NormalEvidence {
                auto: false,
                lobe: None,
                lambertian: &matte,
                share: None,
                diffuse_noise: None,
                sharp: true,
            },
            || Some(b),
        );
        assert_eq!(paper, NormalChoice::Search);
        // The peak is read only where the sharp-lobe rule asks for it.
        let sharp_lobe = NormalEvidence {
            auto: true,
            lobe: Some(&explaining),
            lambertian: &glossy,
            share: Some(0.3),
            diffuse_noise: None,
            sharp: true,
        };
        assert_eq!(
            choose_normal(&s, &sharp_lobe, || panic!("the peak was read")),
            NormalChoice::Lobe(&explaining)
        );
    }

    #[test]
    fn a_doubtful_search_gives_way_only_to_a_plausible_lobe_within_reach() {
        let s = PolicySettings::default();
        let lobe = fitted(DVec3::Z, 0.003);
        assert!(search_gives_way(&s, 0.05, &lobe, || true));
        assert!(!search_gives_way(&s, 0.5, &lobe, || true));
        assert!(!search_gives_way(&s, 0.05, &lobe, || false));
        assert!(!search_gives_way(&s, 0.05, &fitted(DVec3::Z, 0.01), || {
            true
        }));
        // The reach is asked last: not where the search is sure of itself.
        assert!(!search_gives_way(&s, 0.5, &lobe, || panic!(
            "the reach was asked"
        )));
    }

    #[test]
    fn plausibility_and_the_comparison_with_a_diffuse_term_discount_the_noise() {
        let s = LobeSettings::default();
        let b = DVec3::new(0.1, 0.0, 1.0).normalize();
        // 1% left: implausible from a noise-free capture, plausible where the noise expects
        // 0.8% of it (with a spread of 0.05%).
        let quiet = fitted(b, 0.01);
        let noisy = LobeFit {
            noise_share: 0.008,
            noise_share_sd: 5e-4,
            ..quiet
        };
        assert!(!lobe_plausible(&s, &quiet));
        assert!(lobe_plausible(&s, &noisy));
        assert!(reads_base(&s, 1, &quiet) && !reads_base(&s, 1, &noisy));
        // Beside a diffuse term that leaves 1.2%: noise-free, the lobe's 1% is no better; where
        // both leave mostly noise (0.8% expected of the lobe's, 1% of the diffuse term's), the
        // lobe's misfit (0.2%) is the diffuse term's (0.2%) too.
        let diffuse_noise = Some(NoiseShare {
            expected: 0.01,
            sd: 5e-4,
        });
        assert!(!lobe_over_diffuse(&s, &quiet, 0.012, None));
        assert!(!lobe_over_diffuse(&s, &noisy, 0.012, diffuse_noise));
        // A diffuse term that misfits by 2% beyond its noise: the lobe describes the pixel
        // much better.
        assert!(lobe_over_diffuse(&s, &noisy, 0.03, diffuse_noise));
        assert!(!lobe_over_diffuse(&s, &quiet, 0.03, diffuse_noise));
    }

    #[test]
    fn a_lambertian_fit_leaving_only_noise_is_diffuse() {
        // Above the noise-free share, the noise test decides: under the noise's limit the
        // pixel is diffuse (no lobe fitted) and its Lambertian term answers; over it, not.
        let s = DiffuseSettings::default();
        let fit = lambertian(DVec3::Z, 0.995);
        let share = Some(10.0 * s.pure_share);
        // A noise share whose limit at the test's z is `l`.
        let limit = |l: f64| {
            Some(NoiseShare {
                expected: l - s.noise_z * 1e-6,
                sd: 1e-6,
            })
        };
        assert!(!pure_diffuse(&s, &fit, share, None));
        assert!(pure_diffuse(&s, &fit, share, limit(20.0 * s.pure_share)));
        assert!(!pure_diffuse(&s, &fit, share, limit(5.0 * s.pure_share)));
        let noisy = Some(2.0 * s.specular_share);
        assert_eq!(diffuse_centre(&s, &fit, noisy, None), None);
        assert_eq!(
            diffuse_centre(&s, &fit, noisy, limit(3.0 * s.specular_share)),
            Some(DVec3::Z)
        );
        // A fit that does not explain the pixel is no diffuse answer, whatever the noise.
        let poor = lambertian(DVec3::Z, 0.9);
        assert!(!pure_diffuse(&s, &poor, share, limit(1.0)));
    }
}
