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
use crate::maps::{PixelRecord, PixelStatus};
use crate::method::PixelMethod;
use crate::near::tiling::{halfway_change_deg, tile_image, Tile, Tiling, NO_TILE};
use crate::near::{rotation_to_z, Pinhole, PointLight};

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
pub(super) struct TileRig {
    rig: Rig,
    /// The surface point the rig was built for.
    pub(super) point: DVec3,
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
    pub(super) selected: Option<Vec<bool>>,
    /// What the pixels not selected give (`None`: no data).
    pub(super) kept: Option<Vec<PixelRecord>>,
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
pub(super) fn tile_rigs(
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

    pub(super) fn with_rigs(
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

pub(super) fn check_method_inputs(
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
pub(super) fn tile_rig(
    lights: &[PointLight],
    point: DVec3,
    options: RigOptions,
) -> Option<TileRig> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{Brdf, Ward};
    use crate::integrate::IntegrateParams;
    use crate::near::depth::median;
    use crate::render::perspective::{dome_lights, Ball, NearScene};
    use crate::stack::Stack;

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
