//! Normals and tangents under near lights and a pinhole camera, with the estimator of distant
//! lights ([`Estimator`]) and per-tile rigs.
//!
//! A pixel's lights are exact for its own surface point `p`: their directions `l_i =
//! normalize(L_i - p)`, their irradiances `E_i(p)` ([`PointLight::at`]) and the view `v =
//! normalize(-p)`. The estimator assumes one set of light directions for every pixel and the
//! view along +z, so each tile of pixels gets its own rig: the lights as seen from the tile's
//! mean surface point, turned by the rotation that takes the tile's view to +z. A pixel's
//! samples are divided by its own irradiances (`1/r^2`, the LED's `cos^mu`), the pixel is
//! estimated in the tile's frame, and its normal and tangent are turned back into the camera
//! frame. Within a tile the directions are those of the tile's point, not the pixel's: tiles
//! are halved until the pixels' halfway vectors are within a bound of their rig's
//! ([`NearParams::rig_bound_deg`]; `tiling`), so the error a tile leaves is bounded in angle
//! whatever the image's resolution (docs/method.md, "Near lights and perspective cameras").
//!
//! The surface points need depths, which are unknown: [`NearParams::rounds`] starts from a plane at
//! the object's distance and goes in rounds. Each round but the last estimates one pixel per
//! tile (the depth needs no more), spreads those normals over their neighbours and integrates
//! them into a perspective depth map ([`Pinhole::integrate`]); once those normals settle, the
//! last round estimates every pixel. A tile keeps the rig of the round before while its point
//! has moved too little to matter ([`NearParams::rig_reuse_deg`]); the tiles whose point the
//! last round's own depth map moves by more are estimated once more.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::frames::estimator::{Estimator, EstimatorParams, PixelScratch};
use crate::frames::rig::{Rig, RigOptions};
use crate::integrate::{DepthMap, IntegrateParams};
use crate::maps::{EstimateMaps, PixelRecord, PixelStatus};
use crate::method::{run_stack, PixelMethod};
use crate::near::tiling::{halfway_change_deg, tile_image, Tile, Tiling, NO_TILE};
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
    /// Side of the largest rig tile, pixels (1: one rig per pixel, exact).
    pub tile: usize,
    /// Tiles are halved while a pixel's halfway vectors may be further than this from its
    /// rig's, degrees (`None`: every tile of side `tile`).
    pub rig_bound_deg: Option<f64>,
    /// A tile keeps its rig from the round before while the halfway vectors at its point have
    /// moved by at most this, degrees (0: every round builds its rigs).
    pub rig_reuse_deg: f64,
    /// Whether the rounds before the last estimate one pixel per tile (else every pixel).
    pub coarse: bool,
    /// Estimation rounds at most, the last included (each but the last followed by a depth
    /// update).
    pub max_iterations: usize,
    /// The rounds stop once the mean change of the normals is below this, degrees.
    pub tolerance_deg: f64,
}

impl Default for NearParams {
    /// The default cone and estimator; tiles of up to 16 pixels halved to a halfway bound of
    /// 0.5 degrees, rigs kept while their point moves by under 0.1 degrees; coarse rounds, at
    /// most 5 rounds, 0.05 degrees.
    fn default() -> Self {
        Self {
            rig: RigOptions::default(),
            estimator: EstimatorParams::default(),
            tile: 8,
            rig_bound_deg: Some(1.0),
            rig_reuse_deg: 0.1,
            coarse: true,
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
    /// The surface point the rig was built for.
    point: DVec3,
    /// Camera frame to the tile's frame.
    to_tile: DMat3,
    /// `1 / mean_i E_i` at the tile's point: the samples divided by a pixel's irradiances are
    /// multiplied by it, so that they keep about their size.
    scale: f64,
}

/// The per-pixel method of one round: per-tile rigs at the current depths, every pixel or a
/// selection of them.
#[derive(Debug, Clone)]
pub struct NearMethod<'a> {
    camera: Pinhole,
    lights: &'a [PointLight],
    width: usize,
    depth: &'a [f32],
    tile_of: Vec<u32>,
    rigs: Vec<Option<Arc<TileRig>>>,
    /// The pixels estimated (`None`: every pixel).
    selected: Option<Vec<bool>>,
    /// What the pixels not selected give (`None`: no data).
    kept: Option<Vec<PixelRecord>>,
    params: EstimatorParams,
    /// The rig with the most lights (sizes the per-thread buffers).
    largest: Option<usize>,
}

/// Per-thread buffers of [`NearMethod`]: the estimator's, sized for the largest rig (none where
/// no tile has a rig), and one pixel's samples divided by its irradiances.
pub(crate) type NearScratch = (Option<PixelScratch>, Vec<f32>);

/// The rigs of a tiling, those of `cache` kept where their point is within `reuse_deg` of the
/// tile's (in halfway terms); the cache then holds this tiling's rigs. Returns the rigs and
/// which were built.
fn tile_rigs(
    lights: &[PointLight],
    tiling: &Tiling,
    options: RigOptions,
    reuse_deg: f64,
    cache: &mut HashMap<[usize; 4], Option<Arc<TileRig>>>,
) -> (Vec<Option<Arc<TileRig>>>, Vec<bool>) {
    let key = |t: &Tile| [t.x0, t.y0, t.w, t.h];
    let kept: Vec<Option<Option<Arc<TileRig>>>> = tiling
        .tiles
        .par_iter()
        .map(|t| match cache.get(&key(t)) {
            Some(Some(r)) if halfway_change_deg(lights, r.point, t.point) <= reuse_deg => {
                Some(Some(r.clone()))
            }
            _ => None,
        })
        .collect();
    let built: Vec<bool> = kept.iter().map(|k| k.is_none()).collect();
    let rigs: Vec<Option<Arc<TileRig>>> = tiling
        .tiles
        .par_iter()
        .zip(kept)
        .map(|(t, k)| k.unwrap_or_else(|| tile_rig(lights, t.point, options).map(Arc::new)))
        .collect();
    cache.clear();
    cache.extend(tiling.tiles.iter().map(key).zip(rigs.iter().cloned()));
    (rigs, built)
}

impl<'a> NearMethod<'a> {
    /// The rigs of every tile (of `params.tile`, halved to `params.rig_bound_deg`) that holds a
    /// pixel inside `mask` with a finite depth (`depth`: per pixel, along the optical axis). A
    /// tile whose rig cannot be built (fewer than three lights in its cone) leaves its pixels
    /// without data.
    pub fn new(
        camera: Pinhole,
        lights: &'a [PointLight],
        width: usize,
        height: usize,
        depth: &'a [f32],
        mask: Option<&[bool]>,
        params: &NearParams,
    ) -> Result<Self> {
        check_method_inputs(lights, width, height, depth, mask, params)?;
        let tiling = tile_image(
            &camera,
            lights,
            width,
            height,
            depth,
            mask,
            params.tile,
            params.rig_bound_deg,
        );
        let (rigs, _) = tile_rigs(lights, &tiling, params.rig, 0.0, &mut HashMap::new());
        Ok(Self::with_rigs(
            camera,
            lights,
            width,
            depth,
            tiling.tile_of,
            rigs,
            params.estimator,
        ))
    }

    fn with_rigs(
        camera: Pinhole,
        lights: &'a [PointLight],
        width: usize,
        depth: &'a [f32],
        tile_of: Vec<u32>,
        rigs: Vec<Option<Arc<TileRig>>>,
        params: EstimatorParams,
    ) -> Self {
        let largest = (0..rigs.len())
            .filter(|&t| rigs[t].is_some())
            .max_by_key(|&t| rigs[t].as_ref().map_or(0, |r| r.rig.n_used()));
        Self {
            camera,
            lights,
            width,
            depth,
            tile_of,
            rigs,
            selected: None,
            kept: None,
            params,
            largest,
        }
    }

    /// Tiles with a rig.
    pub fn n_rigs(&self) -> usize {
        self.rigs.iter().filter(|r| r.is_some()).count()
    }

    /// The depths the round's rigs and irradiances are computed at.
    pub fn depth(&self) -> &[f32] {
        self.depth
    }

    /// Whether the round estimates pixel `p` (a round before the last estimates one pixel per
    /// tile).
    pub fn selects(&self, p: usize) -> bool {
        self.selected.as_ref().is_none_or(|s| s[p])
    }
}

fn check_method_inputs(
    lights: &[PointLight],
    width: usize,
    height: usize,
    depth: &[f32],
    mask: Option<&[bool]>,
    params: &NearParams,
) -> Result<()> {
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
    let angle_ok = |a: f64| a.is_finite() && a >= 0.0;
    if params.rig_bound_deg.is_some_and(|b| !angle_ok(b)) || !angle_ok(params.rig_reuse_deg) {
        return Err(Error::BadParameter(
            "the rig's bound and reuse angles must be at least 0 degrees".into(),
        ));
    }
    Ok(())
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
        point,
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
        (
            largest.map(|r| PixelScratch::new(&r.rig)),
            Vec::with_capacity(largest.map_or(0, |r| r.rig.n_used() * 3)),
        )
    }

    fn pixel(&self, p: usize, samples: &[f32], scratch: &mut NearScratch) -> PixelRecord {
        if !self.selects(p) {
            return self.kept.as_ref().map_or(NO_DATA, |k| k[p]);
        }
        let t = self.tile_of[p];
        let tr = (t != NO_TILE)
            .then(|| self.rigs[t as usize].as_deref())
            .flatten();
        let (Some(tr), Some(pixel_scratch)) = (tr, scratch.0.as_mut()) else {
            return NO_DATA;
        };
        let depth = self.depth[p] as f64;
        if !(depth.is_finite() && depth > 0.0) {
            return NO_DATA;
        }
        let (col, row) = (p % self.width, p / self.width);
        let point = self.camera.point(col as f64, row as f64, depth);
        let view = (-point).normalize_or_zero();
        let buf = &mut scratch.1;
        buf.clear();
        // The rotation that best takes the rig's halfway vectors to the pixel's own (both in
        // the tile's frame), to first order: `R a_i ~ b_i` with `R = I + [w]x` gives
        // `sum (I - a_i a_i^T) w = sum a_i x b_i`. The part of the tile's error that turns
        // every halfway vector alike (the view's, mostly) so leaves the pixel's answer.
        let (mut m, mut c) = (DMat3::ZERO, DVec3::ZERO);
        for (&i, &a) in tr.rig.input_index().iter().zip(tr.rig.halfway_in_camera()) {
            let s = &samples[3 * i..3 * i + 3];
            let k = match self.lights[i].at(point) {
                Some((l, e)) if e > 0.0 => {
                    if let Some(b) = (tr.to_tile * (l + view)).try_normalize() {
                        m += DMat3::IDENTITY - DMat3::from_cols(a * a.x, a * a.y, a * a.z);
                        c += a.cross(b);
                    }
                    (tr.scale / e) as f32
                }
                _ => f32::NAN,
            };
            buf.extend(s.iter().map(|&v| v * k));
        }
        let est = Estimator::new(&tr.rig, self.params).estimate_pixel_with(buf, pixel_scratch);
        let turn = (m.determinant().abs() > 1e-12)
            .then(|| m.inverse() * c)
            .and_then(|w| Some(DMat3::from_axis_angle(w.try_normalize()?, w.length())))
            .unwrap_or(DMat3::IDENTITY);
        let back = tr.to_tile.transpose() * turn;
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

/// A coarse tile's largest side, in tiles of the last round's.
const COARSE_SIDE: usize = 2;

/// A coarse tiling's halfway bound, in the last round's.
const COARSE_BOUND: f64 = 2.0;

/// A tile of the last round is estimated again where its bound on the last depth map exceeds
/// this many times the tiling's bound and `rig_reuse_deg`.
const REFINE_BOUND: f64 = 2.0;

/// The conjugate gradients' tolerance of a coarse round's depth map.
const COARSE_CG_TOLERANCE: f64 = 1e-4;

/// The coarse rounds stop once no more than one sample in this many has moved (its rig's
/// point by more than the coarse reuse angle).
const SETTLED_SHARE: usize = 50;

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

fn median(v: &mut [f64]) -> f64 {
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// What [`NearParams::rounds`] found.
#[derive(Debug, Clone)]
pub struct NearOutcome {
    /// The last round's maps (normals and tangents in the camera frame).
    pub maps: EstimateMaps,
    /// Depth along the optical axis integrated from the last round's normals (NaN outside the
    /// mask).
    pub depth: Vec<f32>,
    /// Rounds run, the last (every pixel) included.
    pub iterations: usize,
    /// Mean change of the normals from the round before, degrees, per round after the first.
    pub changes_deg: Vec<f64>,
    /// Rounds that estimated one pixel per tile.
    pub coarse_rounds: usize,
    /// Tiles of the last round with a rig.
    pub tiles: usize,
    /// Rigs built over all rounds.
    pub rigs_built: usize,
    /// The largest halfway bound over the last round's tiles: the angle between the halfway
    /// vectors of a tile's rig and those of its pixel farthest from the rig's point, on the
    /// depth map written, degrees.
    pub rig_bound_deg: f64,
    /// Pixels estimated once more after the last round: those of the tiles whose bound the last
    /// round's own depth map took past the tiling's bound and `rig_reuse_deg`.
    pub refined_pixels: usize,
    /// Whether the rounds settled before their limit: the normals changed by less than the
    /// tolerance, or no coarse sample's rig moved by more than `rig_reuse_deg`.
    pub settled: bool,
}

/// What a round of [`NearParams::rounds`] estimates: one pixel per tile, for the depth map.
const STAGE_COARSE: &str = "coarse";
/// What a round of [`NearParams::rounds`] estimates: every pixel.
const STAGE_FULL: &str = "full";
/// What a round of [`NearParams::rounds`] estimates: the pixels of the tiles the last depth map
/// moved, the others kept.
const STAGE_REFINE: &str = "refine";

/// One round of [`NearParams::rounds`]: the method's result at every pixel, given the round's
/// number and what it estimates (`coarse`, `full` or `refine`).
pub(crate) type RoundFn<'r, E> = dyn FnMut(&NearMethod<'_>, usize, &'static str) -> std::result::Result<Vec<PixelRecord>, E>
    + 'r;

/// Mean angle (degrees) between two normal maps over the pixels where both have a normal.
pub(crate) fn mean_change_deg(a: &[f32], b: &[f32]) -> f64 {
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

/// The normals of every pixel with a tile from those of the tiles' centres (a coarse round's):
/// a tent-weighted mean of the centres within the side of the pixel's tile, in the pixel's
/// connected region; NaN where there is none.
fn spread_normals(
    width: usize,
    height: usize,
    records: &[PixelRecord],
    tiling: &Tiling,
    labels: &[u32],
) -> Vec<f32> {
    let mut sample = vec![None; width * height];
    for t in &tiling.tiles {
        let n = DVec3::from_array(records[t.centre].normal.map(|v| v as f64));
        if n.is_finite() {
            sample[t.centre] = Some(n);
        }
    }
    let spread: Vec<[f32; 3]> = (0..width * height)
        .into_par_iter()
        .map(|p| {
            let t = tiling.tile_of[p];
            if t == NO_TILE || labels[p] == OUTSIDE {
                return [f32::NAN; 3];
            }
            let tile = &tiling.tiles[t as usize];
            let r = tile.w.max(tile.h);
            let (col, row) = (p % width, p / width);
            let mut sum = DVec3::ZERO;
            for y in row.saturating_sub(r)..(row + r + 1).min(height) {
                for x in col.saturating_sub(r)..(col + r + 1).min(width) {
                    let q = y * width + x;
                    if let (Some(n), true) = (sample[q], labels[q] == labels[p]) {
                        let d = ((x as f64 - col as f64).powi(2) + (y as f64 - row as f64).powi(2))
                            .sqrt();
                        sum += n * (1.0 - d / (r as f64 + 1.0)).max(0.0);
                    }
                }
            }
            sum.try_normalize()
                .map_or([f32::NAN; 3], |n| n.as_vec3().to_array())
        })
        .collect();
    spread.into_iter().flatten().collect()
}

impl NearParams {
    /// Estimates every pixel (inside `mask`) of a `width x height` image under `lights` seen by
    /// `camera`, the object's surface started as the plane at `distance` along the optical axis.
    /// `run` estimates one round: the method's result at every pixel of the image (as
    /// [`Stack::run`] gives them), told the round's number and what it estimates. Rounds of one
    /// pixel per tile (`params.coarse`) and [`Pinhole::integrate`] go on until their normals
    /// change by less than `params.tolerance_deg` on average; a round of every pixel follows
    /// (`params.max_iterations` rounds at most, that one included), and the tiles its own depth
    /// map moves are estimated once more.
    #[allow(clippy::too_many_arguments)]
    pub fn rounds<E: From<Error>>(
        &self,
        camera: &Pinhole,
        lights: &[PointLight],
        width: usize,
        height: usize,
        mask: Option<&[bool]>,
        distance: f64,
        run: &mut RoundFn<'_, E>,
    ) -> std::result::Result<NearOutcome, E> {
        let params = self;
        if !(distance.is_finite() && distance > 0.0) {
            return Err(Error::BadParameter(format!(
                "the object's distance must be a positive number, got {distance}"
            ))
            .into());
        }
        let n = width * height;
        let inside = |p: usize| mask.is_none_or(|m| m[p]);
        let mut depth: Vec<f32> = (0..n)
            .map(|p| if inside(p) { distance as f32 } else { f32::NAN })
            .collect();
        check_method_inputs(lights, width, height, &depth, mask, params)?;
        let (labels, _) = label_regions(width, height, inside).ok_or_else(|| {
            Error::BadParameter(format!("a {width}x{height} image is too large to estimate"))
        })?;
        let integrate_params = IntegrateParams::default();
        // A coarse round's depth map needs less: its normals are a sample.
        let coarse_integrate = IntegrateParams {
            cg_tolerance: COARSE_CG_TOLERANCE,
            ..integrate_params
        };
        let tiles_of = |depth: &[f32], coarse: bool| {
            let (side, bound) = if coarse {
                (
                    COARSE_SIDE * params.tile,
                    params.rig_bound_deg.map(|b| COARSE_BOUND * b),
                )
            } else {
                (params.tile, params.rig_bound_deg)
            };
            let mut tiling = tile_image(camera, lights, width, height, depth, mask, side, bound);
            if coarse {
                // The one pixel a coarse tile estimates gets the rig of its own point.
                for t in &mut tiling.tiles {
                    let p = t.centre;
                    t.point = camera.point((p % width) as f64, (p / width) as f64, depth[p] as f64);
                }
            }
            tiling
        };
        let mut cache = HashMap::new();
        let mut rigs_built = 0;
        let mut changes = Vec::new();
        let mut previous: Option<Vec<f32>> = None;
        let mut coarse_records: Option<Vec<PixelRecord>> = None;
        let rounds = params.max_iterations.max(1);
        let mut coarse = params.coarse;
        let mut converged = false;
        let mut round = 0;
        loop {
            round += 1;
            let mut stage = if coarse && round < rounds {
                STAGE_COARSE
            } else {
                STAGE_FULL
            };
            let mut tiling = tiles_of(&depth, stage == STAGE_COARSE);
            let reuse = if stage == STAGE_COARSE {
                COARSE_BOUND * params.rig_reuse_deg
            } else {
                params.rig_reuse_deg
            };
            let (mut rigs, mut built) = tile_rigs(lights, &tiling, params.rig, reuse, &mut cache);
            let mut n_coarse_built = usize::MAX;
            let n_moved = built.iter().filter(|&&b| b).count();
            if stage == STAGE_COARSE && round > 1 && n_moved * SETTLED_SHARE <= built.len() {
                n_coarse_built = 0;
                // (Almost) every sample's geometry is where it was: the depth has settled.
                stage = STAGE_FULL;
                tiling = tiles_of(&depth, false);
                (rigs, built) = tile_rigs(
                    lights,
                    &tiling,
                    params.rig,
                    params.rig_reuse_deg,
                    &mut cache,
                );
            }
            let n_built = built.iter().filter(|&&b| b).count();
            rigs_built += n_built;
            let mut method = NearMethod::with_rigs(
                *camera,
                lights,
                width,
                &depth,
                tiling.tile_of.clone(),
                rigs.clone(),
                params.estimator,
            );
            if stage == STAGE_COARSE {
                // A sample whose rig is kept keeps its normal: only the others are estimated.
                let mut selected = vec![false; n];
                for (t, _) in tiling.tiles.iter().zip(&built).filter(|(_, &b)| b) {
                    selected[t.centre] = true;
                }
                method.selected = Some(selected);
                method.kept = coarse_records.take();
            }
            let records = run(&method, round, stage)?;
            drop(method);
            if records.len() != n {
                return Err(Error::BadParameter(format!(
                    "a round gave {} results for {n} pixels",
                    records.len()
                ))
                .into());
            }
            let normals = match stage {
                STAGE_COARSE => spread_normals(width, height, &records, &tiling, &labels),
                _ => records.iter().flat_map(|r| r.normal).collect(),
            };
            // The last round after coarse ones is compared with nothing: a coarse round's
            // normals are its samples', spread.
            let change = previous
                .as_ref()
                .filter(|_| stage == STAGE_COARSE || !params.coarse)
                .map(|prev| mean_change_deg(prev, &normals));
            changes.extend(change);
            let settled = change.is_some_and(|c| c < params.tolerance_deg);
            if stage == STAGE_FULL && params.coarse {
                converged = converged || n_coarse_built == 0;
            } else {
                converged = settled;
            }
            let confidence: Option<Vec<f32>> =
                (stage == STAGE_FULL).then(|| records.iter().map(|r| r.confidence).collect());
            let next = camera
                .integrate(
                    width,
                    height,
                    &normals,
                    confidence.as_deref(),
                    &depth,
                    Some(distance),
                    if stage == STAGE_COARSE {
                        &coarse_integrate
                    } else {
                        &integrate_params
                    },
                )
                .map(|d| d.depth)?;
            if stage == STAGE_COARSE {
                coarse = !settled;
                depth = next;
                previous = Some(normals);
                coarse_records = Some(records);
                continue;
            }
            if !(settled || round == rounds || params.coarse) {
                depth = next;
                previous = Some(normals);
                continue;
            }
            // The last round: its tiles' bounds on its own depth map, and the tiles it moved
            // estimated again with rigs at their new points.
            let (records, next, bound, refined) = refine(
                camera,
                lights,
                width,
                params,
                &tiling,
                &rigs,
                records,
                next,
                &mut |method| run(method, round + 1, STAGE_REFINE),
                &mut |normals, confidence, previous| {
                    camera
                        .integrate(
                            width,
                            height,
                            normals,
                            Some(confidence),
                            previous,
                            Some(distance),
                            &integrate_params,
                        )
                        .map(|d| d.depth)
                        .map_err(E::from)
                },
            )?;
            rigs_built += refined.1;
            let depth = next
                .iter()
                .enumerate()
                .map(|(p, &d)| if inside(p) { d } else { f32::NAN })
                .collect();
            return Ok(NearOutcome {
                maps: EstimateMaps::from_records(width, height, &records),
                depth,
                iterations: round,
                changes_deg: changes,
                coarse_rounds: if params.coarse { round - 1 } else { 0 },
                tiles: rigs.iter().filter(|r| r.is_some()).count(),
                rigs_built,
                rig_bound_deg: bound,
                refined_pixels: refined.0,
                settled: converged,
            });
        }
    }
}

/// The last round's tiles measured on the depth map its normals give (`next`): each tile's
/// bound is the halfway change at its pixel farthest from its rig's point. A tile past its
/// tiling bound plus `rig_reuse_deg` gets a rig at its new point and its pixels are estimated
/// again (`run`, the others' records kept), and the depth map is integrated once more
/// (`integrate`). Returns the records, the depth map, the largest bound and (pixels estimated
/// again, rigs built).
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn refine<E: From<Error>>(
    camera: &Pinhole,
    lights: &[PointLight],
    width: usize,
    params: &NearParams,
    tiling: &Tiling,
    rigs: &[Option<Arc<TileRig>>],
    records: Vec<PixelRecord>,
    next: Vec<f32>,
    run: &mut dyn FnMut(&NearMethod<'_>) -> std::result::Result<Vec<PixelRecord>, E>,
    integrate: &mut dyn FnMut(&[f32], &[f32], &[f32]) -> std::result::Result<Vec<f32>, E>,
) -> std::result::Result<(Vec<PixelRecord>, Vec<f32>, f64, (usize, usize)), E> {
    // Each tile's pixels' points on the new depth map.
    let n = next.len();
    let mut members: Vec<Vec<DVec3>> = vec![Vec::new(); tiling.tiles.len()];
    for (p, (&t, &d)) in tiling.tile_of.iter().zip(&next).enumerate() {
        let d = d as f64;
        if t != NO_TILE && d.is_finite() && d > 0.0 {
            let q = camera.point((p % width) as f64, (p / width) as f64, d);
            members[t as usize].push(q);
        }
    }
    let far_bound = |points: &[DVec3], from: DVec3| {
        points
            .iter()
            .copied()
            .max_by(|a, b| {
                a.distance_squared(from)
                    .total_cmp(&b.distance_squared(from))
            })
            .map_or(0.0, |q| halfway_change_deg(lights, q, from))
    };
    let measured: Vec<(f64, Option<DVec3>)> = (0..tiling.tiles.len())
        .into_par_iter()
        .map(|t| {
            let Some(rig) = rigs[t].as_ref() else {
                return (0.0, None);
            };
            let points = &members[t];
            let bound = far_bound(points, rig.point);
            let allowed = REFINE_BOUND
                * (params.rig_bound_deg.unwrap_or(tiling.tiles[t].bound_deg)
                    + params.rig_reuse_deg);
            if bound <= allowed || points.is_empty() {
                return (bound, None);
            }
            let point = points.iter().copied().sum::<DVec3>() / points.len() as f64;
            (far_bound(points, point), Some(point))
        })
        .collect();
    let moved: Vec<usize> = (0..tiling.tiles.len())
        .filter(|&t| measured[t].1.is_some())
        .collect();
    let largest = measured.iter().map(|m| m.0).fold(0.0, f64::max);
    if moved.is_empty() {
        return Ok((records, next, largest, (0, 0)));
    }
    let mut new_rigs = rigs.to_vec();
    let built: Vec<(usize, Option<Arc<TileRig>>)> = moved
        .par_iter()
        .map(|&t| {
            let point = measured[t].1.unwrap_or(DVec3::ZERO);
            (t, tile_rig(lights, point, params.rig).map(Arc::new))
        })
        .collect();
    for (t, r) in built {
        new_rigs[t] = r;
    }
    let mut selected = vec![false; n];
    let mut count = 0;
    for (p, &t) in tiling.tile_of.iter().enumerate() {
        if t != NO_TILE && measured[t as usize].1.is_some() {
            selected[p] = true;
            count += 1;
        }
    }
    let mut method = NearMethod::with_rigs(
        *camera,
        lights,
        width,
        &next,
        tiling.tile_of.clone(),
        new_rigs,
        params.estimator,
    );
    method.selected = Some(selected);
    method.kept = Some(records);
    let records = run(&method)?;
    drop(method);
    let normals: Vec<f32> = records.iter().flat_map(|r| r.normal).collect();
    let confidence: Vec<f32> = records.iter().map(|r| r.confidence).collect();
    let depth = integrate(&normals, &confidence, &next)?;
    Ok((records, depth, largest, (count, moved.len())))
}

impl NearParams {
    /// Estimates every pixel of `stack` (inside `mask`) under `lights` (one per image) seen by
    /// `camera`, the object's surface started as the plane at `distance` along the optical axis:
    /// the rounds of [`NearParams::rounds`] over the stack. `progress` is told the pixels
    /// finished, round after round.
    pub fn estimate_stack(
        &self,
        stack: &Stack,
        mask: Option<&[bool]>,
        camera: &Pinhole,
        lights: &[PointLight],
        distance: f64,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<NearOutcome> {
        Stack::check_inputs(
            stack.width,
            stack.height,
            stack.n_lights,
            lights.len(),
            mask,
        )?;
        self.rounds(
            camera,
            lights,
            stack.width,
            stack.height,
            mask,
            distance,
            &mut |method, _, _| Ok::<_, Error>(run_stack(method, stack, mask, progress)),
        )
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
        let d = s
            .camera
            .integrate(48, 48, &s.gt_normals(), None, &start, Some(6.0), &params)
            .map(|d| d.depth)
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
        let d = s
            .camera
            .integrate(48, 48, &s.gt_normals(), None, &start, None, &params)
            .map(|d| d.depth)
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
        let near = params
            .estimate_stack(&stack, Some(&mask), &s.camera, &lights, 6.0, &|_| {})
            .unwrap();
        let (e_far, e_near) = (error(&far.normals), error(&near.maps.normals));
        assert!(
            e_near < 1.0 && e_near < e_far / 3.0,
            "near {e_near}, distant {e_far}"
        );
        // Coarse rounds, then one of every pixel: each coarse round after the first has its
        // change.
        assert!(near.iterations >= 2 && near.coarse_rounds == near.iterations - 1);
        assert_eq!(near.changes_deg.len(), near.coarse_rounds - 1);
        assert!(near.tiles > 0 && near.rigs_built >= near.tiles);
        assert!(near.rig_bound_deg.is_finite() && near.rig_bound_deg >= 0.0);
        // Bad input is an error, never a panic.
        assert!(params
            .estimate_stack(&stack, Some(&mask), &s.camera, &lights[1..], 6.0, &|_| {})
            .is_err());
        assert!(params
            .estimate_stack(&stack, Some(&mask), &s.camera, &lights, -1.0, &|_| {})
            .is_err());
    }
}
