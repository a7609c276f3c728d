//! The highlight-centroid baseline: the highlight's mean halfway vector and widest axis.

use glam::DVec3;

use super::BaselinePixel;
use crate::geometry::halfway_from_light;
use crate::highlight::highlight_moments_by;
use crate::maps::PixelStatus;

/// Smallest elongation of the highlight for the highlight-centroid baseline to report a
/// tangent (the estimator's own rule, [`crate::highlight::MIN_ELONGATION`]).
const CENTROID_MIN_ELONGATION: f64 = crate::highlight::MIN_ELONGATION;

/// The highlight-centroid baseline at one pixel: the normal is the intensity-weighted mean of
/// the halfway vectors of the samples at or above half the brightest grey value, the tangent
/// the widest axis of their weighted second moment where the highlight is elongated
/// (the highlight's moments, `highlight_moments_of_greys` in `highlight.rs`). Strong on glossy
/// materials under dense rigs; on diffuse surfaces it shares max-reflectance's bias (half the
/// normal's angle from the view). Confidence: the highlight's contrast. Allocation-free.
pub(crate) fn highlight_centroid_pixel(samples: &[f32], lights: &[DVec3]) -> BaselinePixel {
    let Some(m) = highlight_moments_by(samples, |i| halfway_from_light(lights[i])) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    if m.normal.z <= 0.0 {
        return BaselinePixel::empty(PixelStatus::Discarded);
    }
    BaselinePixel {
        status: PixelStatus::Estimated,
        normal: Some(m.normal),
        tangent: m.has_tangent(CENTROID_MIN_ELONGATION).then_some(m.tangent),
        confidence: m.contrast as f32,
        used: m.count,
        considered: m.count,
    }
}
