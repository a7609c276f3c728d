//! Perspective depth from camera-frame normals ([`Pinhole::integrate`]): the log-depth's
//! gradient through the pinhole integrated as heights are, each connected region scaled so that
//! the sphere through its surface is centred at the object's distance (docs/method.md, "Near
//! lights and perspective cameras").

use glam::DVec3;

use crate::error::{Error, Result};
use crate::integrate::{DepthMap, IntegrateParams};
use crate::near::{Pinhole, PointLight};
use crate::regions::{label_regions, OUTSIDE};

impl Pinhole {
    /// Integrates camera-frame normals (`H x W x 3`, NaN where none) into depths along the optical
    /// axis through this pinhole: the log-depth's gradient is `d ln z / du = -(n.r_u) / (n.r)` (and
    /// likewise in v) with `r` the pixel's ray at depth 1, integrated as the orthographic solver
    /// integrates heights ([`DepthMap::integrate`]). Each connected region's shape is so known up
    /// to a scale about the camera's centre: with `centre` (the object's distance along the optical
    /// axis) the scale puts the centre of the sphere that best fits the region's surface at that
    /// depth (the object is taken to be centred there: exact for a sphere), else, or where no
    /// sphere fits (a flat region), the region's median depth is that of `previous` over the same
    /// pixels. Pixels without a normal (or facing away from the camera) keep their `previous`
    /// depth. The map's `depth` holds the metric depths along the optical axis (NaN where
    /// `previous` is), its counts those of the log-depth's solve.
    #[allow(clippy::too_many_arguments)]
    pub fn integrate(
        &self,
        width: usize,
        height: usize,
        normals: &[f32],
        confidence: Option<&[f32]>,
        previous: &[f32],
        centre: Option<f64>,
        params: &IntegrateParams,
    ) -> Result<DepthMap> {
        let n = width * height;
        if normals.len() != 3 * n || previous.len() != n {
            return Err(Error::BadParameter(format!(
                "a {width}x{height} image needs {} normal values and {n} depths",
                3 * n
            )));
        }
        // Pseudo-normals whose orthographic slopes are the log-depth's (heights are -ln z).
        let r_u = self.ray(1.0, 0.0) - self.ray(0.0, 0.0);
        let r_v = self.ray(0.0, 1.0) - self.ray(0.0, 0.0);
        let mut pseudo = vec![f32::NAN; 3 * n];
        // Pixels facing the camera well enough to place the region's sphere.
        let mut facing = vec![false; n];
        for p in 0..n {
            let m = DVec3::from_array([0, 1, 2].map(|c| normals[3 * p + c] as f64));
            if !m.is_finite() || !previous[p].is_finite() {
                continue;
            }
            let r = self.ray((p % width) as f64, (p / width) as f64);
            let nr = m.dot(r);
            if nr >= -1e-6 {
                continue;
            }
            // h = -ln z: dh/du = (n.r_u)/(n.r), dh/dv = (n.r_v)/(n.r); the solver reads
            // dh/dcol = -mx/mz and dh/drow = +my/mz.
            facing[p] = -nr / r.length() > MIN_FIT_COSINE;
            let (hu, hv) = (m.dot(r_u) / nr, m.dot(r_v) / nr);
            let q = DVec3::new(-hu, hv, 1.0).normalize();
            pseudo[3 * p..3 * p + 3].copy_from_slice(&q.as_vec3().to_array());
        }
        let heights = DepthMap::integrate(width, height, &pseudo, confidence, params)?;
        // One scale per connected region: the median of ln z kept.
        let (label, sizes) = label_regions(width, height, |p| heights.depth[p].is_finite())
            .ok_or_else(|| {
                Error::BadParameter(format!(
                    "a {width}x{height} image is too large to integrate"
                ))
            })?;
        // Each region's pixels, in label order (a counting sort of the labels).
        let mut starts = vec![0usize; sizes.len() + 1];
        for (l, &size) in sizes.iter().enumerate() {
            starts[l + 1] = starts[l] + size;
        }
        let mut order = vec![0usize; starts[sizes.len()]];
        let mut next = starts.clone();
        for (p, &l) in label.iter().enumerate().filter(|(_, &l)| l != OUTSIDE) {
            order[next[l as usize]] = p;
            next[l as usize] += 1;
        }
        let mut out = previous.to_vec();
        let (mut logs, mut hs, mut fitted) = (Vec::new(), Vec::new(), Vec::new());
        for region in starts.windows(2).map(|w| &order[w[0]..w[1]]) {
            hs.clear();
            hs.extend(region.iter().map(|&p| heights.depth[p] as f64));
            let h_mid = median(&mut hs);
            // The region's shape at the scale where its median depth is 1 (ln z = h_mid - h).
            let relative = |p: usize| (h_mid - heights.depth[p] as f64).exp();
            fitted.clear();
            fitted.extend(region.iter().copied().filter(|&p| facing[p]));
            let c = match centre.and_then(|d| centre_scale(self, width, &fitted, &relative, d)) {
                Some(scale) => scale.ln(),
                None => {
                    logs.clear();
                    logs.extend(region.iter().map(|&p| (previous[p] as f64).ln()));
                    median(&mut logs)
                }
            };
            for &p in region {
                out[p] = (c + h_mid - heights.depth[p] as f64).exp() as f32;
            }
        }
        Ok(DepthMap {
            depth: out,
            ..heights
        })
    }
}

/// Smallest cosine between a pixel's normal and its view for its point to join the sphere fit
/// of [`centre_scale`]: the integrated depth is least sure near the outline, where the normals
/// turn away from the camera.
const MIN_FIT_COSINE: f64 = 0.3;

/// Regions of fewer pixels keep their median depth rather than a sphere's centre.
const MIN_SPHERE_PIXELS: usize = 32;

/// The scale that puts the centre of the sphere best fitting a region's surface points
/// (`relative(p)`: the depth of pixel `p` at some scale) at depth `distance`; `None` where the
/// region is small or no sphere fits it (a plane: the radius more than 4 times the points'
/// spread, or the centre not in front of the camera).
fn centre_scale(
    camera: &Pinhole,
    width: usize,
    region: &[usize],
    relative: &dyn Fn(usize) -> f64,
    distance: f64,
) -> Option<f64> {
    if region.len() < MIN_SPHERE_PIXELS {
        return None;
    }
    let points: Vec<DVec3> = region
        .iter()
        .map(|&p| camera.point((p % width) as f64, (p / width) as f64, relative(p)))
        .collect();
    let (c, r) = PointLight::fit_sphere(&points)?;
    let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let spread = points
        .iter()
        .map(|q| (*q - mean).length())
        .fold(0.0, f64::max);
    (r <= 4.0 * spread && c.z < 0.0).then(|| distance / -c.z)
}

/// The median of `v` (reordered).
pub(super) fn median(v: &mut [f64]) -> f64 {
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}
