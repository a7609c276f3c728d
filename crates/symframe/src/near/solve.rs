//! Normals and tangents under near lights and a pinhole camera, with the estimator of distant
//! lights ([`Estimator`]) and per-tile rigs.
//!
//! A pixel's lights are exact for its own surface point `p`: their directions `l_i =
//! normalize(L_i - p)`, their irradiances `E_i(p)` ([`PointLight::at`]) and the view `v =
//! normalize(-p)`. The estimator assumes one set of light directions for every pixel and the
//! view along +z, so each tile of `tile x tile` pixels gets its own rig: the lights as seen from
//! the tile's mean surface point, turned by the rotation that takes the tile's view to +z. A
//! pixel's samples are divided by its own irradiances (`1/r^2`, the LED's `cos^mu`), the pixel
//! is estimated in the tile's frame, and its normal and tangent are turned back into the camera
//! frame. Within a tile the directions are those of the tile's point, not the pixel's: the
//! error this leaves shrinks with the tile (`tile = 1` is exact) and is measured in
//! docs/method.md.
//!
//! The surface points need depths, which are unknown: [`estimate_near_stack`] starts from a
//! plane at the object's distance, estimates, integrates the normals into a perspective depth
//! map ([`depth_from_normals`]) whose median over each connected region stays that of the
//! start, and repeats until the normals change by less than a tolerance.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::frames::estimator::{Estimator, EstimatorParams, PixelScratch};
use crate::frames::rig::{Rig, RigOptions};
use crate::integrate::{integrate, DepthMap, IntegrateParams};
use crate::maps::{EstimateMaps, PixelRecord, PixelStatus};
use crate::method::{run_stack, PixelMethod};
use crate::near::{rotation_to_z, Pinhole, PointLight};
use crate::regions::{label_regions, OUTSIDE};
use crate::stack::Stack;

/// Parameters of the near-light estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearParams {
    /// The light cone of every tile's rig.
    pub rig: RigOptions,
    /// The estimator's parameters.
    pub estimator: EstimatorParams,
    /// Side of a rig's tile, pixels (1: one rig per pixel, exact).
    pub tile: usize,
    /// Estimation rounds at most (each but the last followed by a depth update).
    pub max_iterations: usize,
    /// The rounds stop once the mean change of the normals is below this, degrees.
    pub tolerance_deg: f64,
}

impl Default for NearParams {
    /// The default cone and estimator, 4-pixel tiles, at most 5 rounds, 0.05 degrees.
    fn default() -> Self {
        Self {
            rig: RigOptions::default(),
            estimator: EstimatorParams::default(),
            tile: 4,
            max_iterations: 5,
            tolerance_deg: 0.05,
        }
    }
}

/// One tile's rig: the lights seen from the tile's surface point in the frame whose +z is the
/// tile's view.
#[derive(Debug, Clone)]
struct TileRig {
    rig: Rig,
    /// Camera frame to the tile's frame.
    to_tile: DMat3,
    /// `1 / mean_i E_i` at the tile's point: the samples divided by a pixel's irradiances are
    /// multiplied by it, so that they keep about their size.
    scale: f64,
}

/// The per-pixel method of one round: per-tile rigs at the current depths.
#[derive(Debug, Clone)]
pub struct NearMethod<'a> {
    camera: Pinhole,
    lights: &'a [PointLight],
    width: usize,
    tile: usize,
    tiles_x: usize,
    depth: &'a [f32],
    rigs: Vec<Option<TileRig>>,
    params: EstimatorParams,
    /// The rig with the most lights (sizes the per-thread buffers).
    largest: Option<usize>,
}

/// Per-thread buffers of [`NearMethod`].
#[derive(Debug, Clone)]
pub struct NearScratch {
    pixel: Option<PixelScratch>,
    samples: Vec<f32>,
}

impl<'a> NearMethod<'a> {
    /// The rigs of every tile that holds a pixel inside `mask` with a finite depth (`depth`: per
    /// pixel, along the optical axis). A tile whose rig cannot be built (fewer than three lights
    /// in its cone) leaves its pixels without data.
    pub fn new(
        camera: Pinhole,
        lights: &'a [PointLight],
        width: usize,
        height: usize,
        depth: &'a [f32],
        mask: Option<&[bool]>,
        params: &NearParams,
    ) -> Result<Self> {
        let n = width * height;
        if depth.len() != n || mask.is_some_and(|m| m.len() != n) {
            return Err(Error::BadParameter(format!(
                "a {width}x{height} image needs {n} depths and mask values"
            )));
        }
        if lights.is_empty() {
            return Err(Error::NoLights);
        }
        if params.tile == 0 {
            return Err(Error::BadParameter(
                "the rig tile must be at least 1 pixel".into(),
            ));
        }
        let tile = params.tile;
        let (tiles_x, tiles_y) = (width.div_ceil(tile), height.div_ceil(tile));
        let rigs: Vec<Option<TileRig>> = (0..tiles_x * tiles_y)
            .into_par_iter()
            .map(|t| {
                let (tx, ty) = (t % tiles_x, t / tiles_x);
                let (mut sum, mut count) = (DVec3::ZERO, 0usize);
                for row in ty * tile..((ty + 1) * tile).min(height) {
                    for col in tx * tile..((tx + 1) * tile).min(width) {
                        let p = row * width + col;
                        let d = depth[p] as f64;
                        if mask.is_none_or(|m| m[p]) && d.is_finite() && d > 0.0 {
                            sum += camera.point(col as f64, row as f64, d);
                            count += 1;
                        }
                    }
                }
                (count > 0).then(|| tile_rig(lights, sum / count as f64, params.rig))?
            })
            .collect();
        let largest = (0..rigs.len())
            .filter(|&t| rigs[t].is_some())
            .max_by_key(|&t| rigs[t].as_ref().map_or(0, |r| r.rig.n_used()));
        Ok(Self {
            camera,
            lights,
            width,
            tile,
            tiles_x,
            depth,
            rigs,
            params: params.estimator,
            largest,
        })
    }

    /// Tiles with a rig.
    pub fn n_rigs(&self) -> usize {
        self.rigs.iter().filter(|r| r.is_some()).count()
    }
}

/// The rig of a tile whose surface point is `point`; `None` where it cannot be built.
fn tile_rig(lights: &[PointLight], point: DVec3, options: RigOptions) -> Option<TileRig> {
    let to_tile = rotation_to_z((-point).try_normalize()?);
    let mut total = 0.0;
    let mut dirs = Vec::with_capacity(lights.len());
    for light in lights {
        let (l, e) = light.at(point)?;
        total += e;
        dirs.push(to_tile * l);
    }
    let mean = total / lights.len() as f64;
    let rig = Rig::new(&dirs, options).ok()?;
    (mean > 0.0).then_some(TileRig {
        rig,
        to_tile,
        scale: 1.0 / mean,
    })
}

/// A pixel inside the mask that cannot be estimated.
const NO_DATA: PixelRecord = PixelRecord {
    status: PixelStatus::NoData,
    ..PixelRecord::MASKED
};

impl PixelMethod for NearMethod<'_> {
    type Scratch = NearScratch;
    type Output = PixelRecord;

    fn lights(&self) -> Option<&[usize]> {
        None
    }

    fn scratch(&self) -> NearScratch {
        let largest = self.largest.and_then(|t| self.rigs[t].as_ref());
        NearScratch {
            pixel: largest.map(|r| PixelScratch::new(&r.rig)),
            samples: Vec::with_capacity(largest.map_or(0, |r| r.rig.n_used() * 3)),
        }
    }

    fn pixel(&self, p: usize, samples: &[f32], scratch: &mut NearScratch) -> PixelRecord {
        let (col, row) = (p % self.width, p / self.width);
        let t = (row / self.tile) * self.tiles_x + col / self.tile;
        let (Some(tr), Some(pixel_scratch)) = (self.rigs[t].as_ref(), scratch.pixel.as_mut())
        else {
            return NO_DATA;
        };
        let depth = self.depth[p] as f64;
        if !(depth.is_finite() && depth > 0.0) {
            return NO_DATA;
        }
        let point = self.camera.point(col as f64, row as f64, depth);
        let buf = &mut scratch.samples;
        buf.clear();
        for &i in tr.rig.input_index() {
            let s = &samples[3 * i..3 * i + 3];
            let k = match self.lights[i].at(point) {
                Some((_, e)) if e > 0.0 => (tr.scale / e) as f32,
                _ => f32::NAN,
            };
            buf.extend(s.iter().map(|&v| v * k));
        }
        let est = Estimator::new(&tr.rig, self.params).estimate_pixel_with(buf, pixel_scratch);
        let back = tr.to_tile.transpose();
        let mut record = PixelRecord::from_estimate(&est);
        if let Some(n) = est.normal {
            record.normal = (back * n).as_vec3().to_array();
        }
        if let Some(t) = est.tangent {
            record.tangent = (back * t).as_vec3().to_array();
        }
        record
    }

    fn masked(&self) -> PixelRecord {
        PixelRecord::MASKED
    }
}

/// Integrates camera-frame normals (`H x W x 3`, NaN where none) into depths along the optical
/// axis through the pinhole `camera`: the log-depth's gradient is `d ln z / du = -(n.r_u) /
/// (n.r)` (and likewise in v) with `r` the pixel's ray at depth 1, integrated as the orthographic
/// solver integrates heights ([`integrate`]). Each connected region's shape is so known up to a
/// scale about the camera's centre: with `centre` (the object's distance along the optical
/// axis) the scale puts the centre of the sphere that best fits the region's surface at that
/// depth (the object is taken to be centred there: exact for a sphere), else, or where no sphere
/// fits (a flat region), the region's median depth is that of `previous` over the same pixels.
/// Pixels without a normal (or facing away from the camera) keep their `previous` depth.
#[allow(clippy::too_many_arguments)]
pub fn depth_from_normals(
    camera: &Pinhole,
    width: usize,
    height: usize,
    normals: &[f32],
    confidence: Option<&[f32]>,
    previous: &[f32],
    centre: Option<f64>,
    params: &IntegrateParams,
) -> Result<Vec<f32>> {
    perspective_depth(
        camera, width, height, normals, confidence, previous, centre, params,
    )
    .map(|d| d.depth)
}

/// [`depth_from_normals`] with the integration's figures: the map's `depth` holds the metric
/// depths along the optical axis (NaN where `previous` is), its counts those of the log-depth's
/// solve.
#[allow(clippy::too_many_arguments)]
pub fn perspective_depth(
    camera: &Pinhole,
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
    let r_u = camera.ray(1.0, 0.0) - camera.ray(0.0, 0.0);
    let r_v = camera.ray(0.0, 1.0) - camera.ray(0.0, 0.0);
    let mut pseudo = vec![f32::NAN; 3 * n];
    // Pixels facing the camera well enough to place the region's sphere.
    let mut facing = vec![false; n];
    for p in 0..n {
        let m = DVec3::from_array([0, 1, 2].map(|c| normals[3 * p + c] as f64));
        if !m.is_finite() || !previous[p].is_finite() {
            continue;
        }
        let r = camera.ray((p % width) as f64, (p / width) as f64);
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
    let heights = integrate(width, height, &pseudo, confidence, params)?;
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
        let c = match centre.and_then(|d| centre_scale(camera, width, &fitted, &relative, d)) {
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
    let (c, r) = crate::near::fit_sphere(&points)?;
    let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let spread = points
        .iter()
        .map(|q| (*q - mean).length())
        .fold(0.0, f64::max);
    (r <= 4.0 * spread && c.z < 0.0).then(|| distance / -c.z)
}

fn median(v: &mut [f64]) -> f64 {
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// What [`estimate_near_stack`] found.
#[derive(Debug, Clone)]
pub struct NearOutcome {
    /// The last round's maps (normals and tangents in the camera frame).
    pub maps: EstimateMaps,
    /// Depth along the optical axis integrated from the last round's normals (NaN outside the
    /// mask).
    pub depth: Vec<f32>,
    /// Rounds run.
    pub iterations: usize,
    /// Mean change of the normals from the round before, degrees, per round after the first.
    pub changes_deg: Vec<f64>,
}

/// Mean angle (degrees) between two normal maps over the pixels where both have a normal.
pub fn mean_change_deg(a: &[f32], b: &[f32]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for (x, y) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
        let (x, y) = (
            DVec3::new(x[0] as f64, x[1] as f64, x[2] as f64),
            DVec3::new(y[0] as f64, y[1] as f64, y[2] as f64),
        );
        if x.is_finite() && y.is_finite() {
            sum += x.angle_between(y).to_degrees();
            count += 1;
        }
    }
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
}

/// Estimates every pixel of `stack` (inside `mask`) under `lights` (one per image) seen by
/// `camera`, the object's surface started as the plane at `distance` along the optical axis:
/// rounds of [`NearMethod`] and [`depth_from_normals`] until the normals change by less than
/// `params.tolerance_deg` on average or `params.max_iterations` rounds have run. `progress` is
/// told the pixels finished, round after round.
pub fn estimate_near_stack(
    stack: &Stack,
    mask: Option<&[bool]>,
    camera: &Pinhole,
    lights: &[PointLight],
    distance: f64,
    params: &NearParams,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<NearOutcome> {
    crate::stack::check_inputs(
        stack.width,
        stack.height,
        stack.n_lights,
        lights.len(),
        mask,
    )?;
    if !(distance.is_finite() && distance > 0.0) {
        return Err(Error::BadParameter(format!(
            "the object's distance must be a positive number, got {distance}"
        )));
    }
    let (w, h) = (stack.width, stack.height);
    let inside = |p: usize| mask.is_none_or(|m| m[p]);
    let mut depth: Vec<f32> = (0..w * h)
        .map(|p| if inside(p) { distance as f32 } else { f32::NAN })
        .collect();
    let mut changes = Vec::new();
    let mut previous: Option<EstimateMaps> = None;
    let integrate_params = IntegrateParams::default();
    let rounds = params.max_iterations.max(1);
    let mut round = 0;
    loop {
        round += 1;
        let method = NearMethod::new(*camera, lights, w, h, &depth, mask, params)?;
        let records = run_stack(&method, stack, mask, progress);
        let maps = EstimateMaps::from_records(w, h, &records);
        let change = previous
            .as_ref()
            .map(|prev| mean_change_deg(&prev.normals, &maps.normals));
        changes.extend(change);
        let settled = change.is_some_and(|c| c < params.tolerance_deg);
        let next = depth_from_normals(
            camera,
            w,
            h,
            &maps.normals,
            Some(&maps.confidence),
            &depth,
            Some(distance),
            &integrate_params,
        )?;
        if settled || round == rounds {
            let depth = next
                .iter()
                .enumerate()
                .map(|(p, &d)| if inside(p) { d } else { f32::NAN })
                .collect();
            return Ok(NearOutcome {
                maps,
                depth,
                iterations: round,
                changes_deg: changes,
            });
        }
        depth = next;
        previous = Some(maps);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{Brdf, Ward};
    use crate::render::perspective::{dome_lights, Ball, NearScene};

    /// A brushed sphere of radius 1 at depth 6, a dome of radius 4 about it.
    fn scene(width: usize) -> (NearScene, Vec<PointLight>) {
        let cam = Pinhole::centred(width, width, 24.0);
        let ball = Ball {
            centre: DVec3::new(0.0, 0.0, -6.0),
            radius: 1.0,
            material: 0,
        };
        let lights = dome_lights(120, ball.centre, 4.0, 5.0, 16.0);
        (NearScene::spheres(width, width, cam, &[ball]), lights)
    }

    #[test]
    fn true_normals_integrate_to_the_true_depth() {
        let (s, _) = scene(48);
        let mask = s.mask();
        let start: Vec<f32> = mask
            .iter()
            .map(|&m| if m { 6.0 } else { f32::NAN })
            .collect();
        let params = IntegrateParams::default();
        let truth = s.depth();
        let err = |d: &[f32]| {
            d.iter()
                .zip(&truth)
                .filter(|(a, b)| a.is_finite() && b.is_finite())
                .map(|(a, b)| (a - b).abs() as f64)
                .fold((0.0, 0.0), |(sum, n), e| (sum + e, n + 1.0))
        };
        let mean = |d: &[f32]| {
            let (sum, n) = err(d);
            sum / n
        };
        // The sphere's centre at depth 6: the surface found to about a hundredth of its radius
        // on average at this resolution (a radius of 19 pixels; the one-sided differences of
        // the integration leave that much), the rim pixels aside.
        let d = depth_from_normals(
            &s.camera,
            48,
            48,
            &s.gt_normals(),
            None,
            &start,
            Some(6.0),
            &params,
        )
        .unwrap();
        let inner: Vec<f32> = d
            .iter()
            .enumerate()
            .map(|(p, &v)| {
                if s.normals[p].dot(-s.points[p].normalize()) > 0.3 {
                    v
                } else {
                    f32::NAN
                }
            })
            .collect();
        assert!(mean(&inner) < 0.012, "{}", mean(&inner));
        // Without the centre, the median depth stays the start's.
        let d = depth_from_normals(
            &s.camera,
            48,
            48,
            &s.gt_normals(),
            None,
            &start,
            None,
            &params,
        )
        .unwrap();
        let mut v: Vec<f64> = d
            .iter()
            .filter(|x| x.is_finite())
            .map(|&x| x as f64)
            .collect();
        assert!((median(&mut v) - 6.0).abs() < 1e-5);
    }

    #[test]
    fn near_lights_are_estimated_where_distant_ones_are_not() {
        let (s, lights) = scene(24);
        let ward = Ward::new([0.2; 3], [0.5; 3], 0.1, 0.3);
        let mats: [&dyn Brdf; 1] = [&ward];
        let mut stack = Stack::zeros(24, 24, lights.len());
        for (i, l) in lights.iter().enumerate() {
            stack.set_image(i, &s.render(&mats, l));
        }
        let mask = s.mask();
        let error = |normals: &[f32]| {
            let mut sum = 0.0;
            let mut n = 0;
            for p in 0..mask.len() {
                let e = DVec3::from_array([0, 1, 2].map(|c| normals[3 * p + c] as f64));
                if mask[p] && e.is_finite() && s.normals[p].z > 0.5 {
                    sum += e.angle_between(s.normals[p]).to_degrees();
                    n += 1;
                }
            }
            sum / n as f64
        };
        // The distant answer: directions from the dome's centre.
        let dirs: Vec<DVec3> = lights
            .iter()
            .map(|l| l.position - s.balls[0].centre)
            .collect();
        let rig = Rig::new(&dirs, RigOptions::default()).unwrap();
        let far = crate::estimate_stack(
            &stack,
            &rig,
            Some(&mask),
            EstimatorParams::default(),
            &|_| {},
        )
        .unwrap();
        let params = NearParams {
            tile: 2,
            max_iterations: 3,
            ..NearParams::default()
        };
        let near = estimate_near_stack(
            &stack,
            Some(&mask),
            &s.camera,
            &lights,
            6.0,
            &params,
            &|_| {},
        )
        .unwrap();
        let (e_far, e_near) = (error(&far.normals), error(&near.maps.normals));
        assert!(
            e_near < 1.0 && e_near < e_far / 3.0,
            "near {e_near}, distant {e_far}"
        );
        assert!(near.iterations >= 2 && near.changes_deg.len() == near.iterations - 1);
        // Bad input is an error, never a panic.
        assert!(estimate_near_stack(
            &stack,
            Some(&mask),
            &s.camera,
            &lights[1..],
            6.0,
            &params,
            &|_| {}
        )
        .is_err());
        assert!(estimate_near_stack(
            &stack,
            Some(&mask),
            &s.camera,
            &lights,
            -1.0,
            &params,
            &|_| {}
        )
        .is_err());
    }
}
