//! The rounds of a near-light estimate ([`NearParams::rounds`]): one pixel per tile and a
//! depth map until the normals settle, then every pixel, then the tiles the last depth map moved
//! (docs/method.md, "Near lights and perspective cameras").

use std::collections::HashMap;
use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::integrate::IntegrateParams;
use crate::maps::{EstimateMaps, PixelRecord};
use crate::method::run_stack;
use crate::near::solve::{
    check_method_inputs, tile_rig, tile_rigs, NearMethod, NearParams, TileRig,
};
use crate::near::tiling::{halfway_change_deg, tile_image, Tiling, NO_TILE};
use crate::near::{Pinhole, PointLight};
use crate::regions::{label_regions, OUTSIDE};
use crate::stack::Stack;

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
