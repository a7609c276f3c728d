//! The estimate's maps and what they are made of: a pixel's status and the measure behind its
//! normal ([`PixelStatus`], [`PixelSource`], the codes of `source.npy`), its record
//! ([`PixelRecord`], as stored per tile), and the assembled maps with their counts
//! ([`EstimateMaps`], [`PixelCounts`]). Shared by the estimator, the baselines and the tiled job.

use serde::{Deserialize, Serialize};

/// What happened at a pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PixelStatus {
    /// A normal was estimated (the tangent may still be undefined: isotropic slice).
    Estimated,
    /// Outside the mask: not looked at.
    Masked,
    /// No valid sample, or no light brighter than zero: nothing to estimate from.
    NoData,
    /// A symmetry domain is empty at the solution (normal beyond the rig's reach).
    Discarded,
    /// Confidence below the user's threshold.
    Culled,
}

/// Which measure gave a pixel's normal: the map `source.npy` holds these codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[repr(u8)]
pub enum PixelSource {
    /// No normal (masked, no data, discarded).
    #[default]
    None = 0,
    /// The symmetry of the BRDF slice.
    Symmetry = 1,
    /// A robust Lambertian fit: the estimator's answer for diffuse pixels (the centre of a
    /// diffuse slice) and its fallback beyond the rig's reach, or Woodham's photometric stereo.
    Lambertian = 2,
    /// The highlight: the estimator's answer for lobes sharper than the light spacing (the
    /// peak) and its fallback beyond the reach (centroid), or the max-reflectance and
    /// highlight-centroid baselines.
    Highlight = 3,
    /// A symmetric lobe, or two sharing one frame, fitted to the samples: the estimator's
    /// smooth reconstruction of the slice, its answer wherever it explains the pixel
    /// (docs/method.md, "Lobe fit", "Two lobes").
    Lobe = 4,
}

impl PixelSource {
    /// Every source, in code order.
    pub const ALL: [PixelSource; 5] = [
        PixelSource::None,
        PixelSource::Symmetry,
        PixelSource::Lambertian,
        PixelSource::Highlight,
        PixelSource::Lobe,
    ];

    /// The source of a code of `source.npy`; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// The source's name as in reports (`none`, `symmetry`, `lambertian`, `highlight`, `lobe`).
    pub fn name(self) -> &'static str {
        match self {
            PixelSource::None => "none",
            PixelSource::Symmetry => "symmetry",
            PixelSource::Lambertian => "lambertian",
            PixelSource::Highlight => "highlight",
            PixelSource::Lobe => "lobe",
        }
    }

    /// `(code, name, description)` of every source, for the report's legend.
    pub fn legend() -> [(u8, &'static str, &'static str); 5] {
        Self::ALL.map(|s| {
            let what = match s {
                PixelSource::None => "no normal (masked, no data or discarded)",
                PixelSource::Symmetry => "the symmetry of the pixel's BRDF slice",
                PixelSource::Lambertian => {
                    "a robust Lambertian fit (diffuse pixels, beyond the rig's reach, or Woodham)"
                }
                PixelSource::Highlight => {
                    "the highlight's peak or centroid (lobes sharper than the light spacing, beyond the rig's reach, or a highlight baseline)"
                }
                PixelSource::Lobe => {
                    "a symmetric lobe fitted to the samples (the slice's smooth reconstruction)"
                }
            };
            (s as u8, s.name(), what)
        })
    }
}

/// Counts of what happened to the pixels of a stack.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PixelCounts {
    /// Pixels with a normal.
    pub estimated: usize,
    /// Estimated pixels whose tangent is defined (anisotropic slice).
    pub with_tangent: usize,
    /// Pixels below the confidence threshold.
    pub culled: usize,
    /// Pixels whose symmetry domains were empty at the solution.
    pub discarded: usize,
    /// Pixels without usable samples.
    pub no_data: usize,
    /// Pixels outside the mask.
    pub masked: usize,
}

/// The estimated maps of a whole stack, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateMaps {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Unit normals, `H x W x 3`, NaN where no estimate.
    pub normals: Vec<f32>,
    /// Unit tangents, `H x W x 3`, NaN where no estimate or isotropic.
    pub tangents: Vec<f32>,
    /// Confidence, `H x W`, NaN where nothing was estimated.
    pub confidence: Vec<f32>,
    /// Anisotropy, `H x W`, NaN where nothing was estimated.
    pub anisotropy: Vec<f32>,
    /// Tangent confidence, `H x W`: how clearly the data single out the tangent's axes, in
    /// [0, 1], 0 where the pixel has no tangent, NaN where nothing was estimated.
    pub tangent_confidence: Vec<f32>,
    /// Residual, `H x W`: the symmetry distance about the normal at the answer (see
    /// [`PixelRecord::residual`]), NaN where none was measured.
    pub residual: Vec<f32>,
    /// Per-pixel status.
    pub status: Vec<PixelStatus>,
    /// Per-pixel [`PixelSource`] code, `H x W`.
    pub source: Vec<u8>,
    /// Status counts.
    pub counts: PixelCounts,
    /// Total symmetry-objective evaluations.
    pub evals: u64,
}

impl PixelCounts {
    /// Counts one pixel of status `status` (`with_tangent`: its tangent is defined).
    pub fn add(&mut self, status: PixelStatus, with_tangent: bool) {
        match status {
            PixelStatus::Estimated => self.estimated += 1,
            PixelStatus::Masked => self.masked += 1,
            PixelStatus::NoData => self.no_data += 1,
            PixelStatus::Discarded => self.discarded += 1,
            PixelStatus::Culled => self.culled += 1,
        }
        if with_tangent {
            self.with_tangent += 1;
        }
    }
}

/// What the maps hold at one pixel: the values of [`EstimateMaps`] there, as stored per tile by
/// the tiled pipeline and assembled into maps by [`EstimateMaps::put`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelRecord {
    /// What happened.
    pub status: PixelStatus,
    /// Which measure the values come from.
    pub source: PixelSource,
    /// Unit normal (`NaN` where none).
    pub normal: [f32; 3],
    /// Unit tangent (`NaN` where none).
    pub tangent: [f32; 3],
    /// Confidence (`NaN` unless estimated or culled).
    pub confidence: f32,
    /// Anisotropy (`NaN` unless estimated or culled).
    pub anisotropy: f32,
    /// How clearly the data single out the tangent's axes, in [0, 1] (0 without a tangent;
    /// `NaN` unless estimated or culled).
    pub tangent_confidence: f32,
    /// How much of the pixel's data the answer leaves unexplained: the symmetry distance
    /// `SD_n` about the answer's normal, the share of the slice's signal that its mirror image
    /// about the normal does not reproduce (0: perfectly symmetric; docs/method.md, "Symmetry
    /// distances and the domain rule"). `NaN` where no symmetry was measured at the answer
    /// (not estimated, a fallback beyond the rig's reach, a baseline).
    pub residual: f32,
    /// Objective evaluations spent.
    pub evals: u32,
}

impl PixelRecord {
    /// A pixel outside the mask.
    pub const MASKED: PixelRecord = PixelRecord {
        status: PixelStatus::Masked,
        source: PixelSource::None,
        normal: [f32::NAN; 3],
        tangent: [f32::NAN; 3],
        confidence: f32::NAN,
        anisotropy: f32::NAN,
        tangent_confidence: f32::NAN,
        residual: f32::NAN,
        evals: 0,
    };

    /// Whether the tangent is defined.
    pub fn has_tangent(&self) -> bool {
        !self.tangent[0].is_nan()
    }
}

impl EstimateMaps {
    /// The unit vector at pixel `p` of an `H x W x 3` map such as [`EstimateMaps::normals`]
    /// or a true normal map; `None` for NaN or zero.
    pub fn vec_at(map: &[f32], p: usize) -> Option<glam::DVec3> {
        crate::eval::vec_at(map, p)
    }

    /// Maps of `width x height` pixels with nothing estimated yet (every value `NaN`, no
    /// status, counts zero): fill them with [`EstimateMaps::put`] for every pixel.
    pub fn empty(width: usize, height: usize) -> Self {
        let n = width * height;
        Self {
            width,
            height,
            normals: vec![f32::NAN; n * 3],
            tangents: vec![f32::NAN; n * 3],
            confidence: vec![f32::NAN; n],
            anisotropy: vec![f32::NAN; n],
            tangent_confidence: vec![f32::NAN; n],
            residual: vec![f32::NAN; n],
            status: vec![PixelStatus::Masked; n],
            source: vec![PixelSource::None as u8; n],
            counts: PixelCounts::default(),
            evals: 0,
        }
    }

    /// Stores pixel `p`'s record (each pixel once: the counts add up).
    pub fn put(&mut self, p: usize, r: &PixelRecord) {
        self.evals += r.evals as u64;
        self.status[p] = r.status;
        self.source[p] = r.source as u8;
        self.counts.add(r.status, r.has_tangent());
        self.confidence[p] = r.confidence;
        self.anisotropy[p] = r.anisotropy;
        self.tangent_confidence[p] = r.tangent_confidence;
        self.residual[p] = r.residual;
        self.normals[p * 3..p * 3 + 3].copy_from_slice(&r.normal);
        self.tangents[p * 3..p * 3 + 3].copy_from_slice(&r.tangent);
    }
}

impl EstimateMaps {
    /// The maps of `width x height` pixels from their records in row-major order.
    pub fn from_records(width: usize, height: usize, records: &[PixelRecord]) -> Self {
        let mut maps = Self::empty(width, height);
        for (p, r) in records.iter().enumerate() {
            maps.put(p, r);
        }
        maps
    }
}
