//! The estimation job's near-light rounds: where the dataset's folder holds
//! `light_positions.txt` and `K.txt`, each round runs the core's per-tile-rig method
//! ([`NearMethod`]) over the tile cache as the distant-light job runs its estimator, reads the
//! normals back, integrates them into a perspective depth map and goes again, until the normals
//! settle (docs/method.md, "Near lights and perspective cameras"). The last round's tile
//! results are the job's, written as any estimate's; `depth.npy` and report.json's `near`
//! section are added.

use std::path::Path;

use anyhow::{bail, Result};
use serde::Serialize;
use symframe::{EstimatorParams, NearMethod, NearParams, PixelRecord, RigOptions};
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{NearGeometry, TileCache};

use crate::tiles::{run_tiles, tile_path};
use crate::{Control, TileCounts};

/// Which light model the job uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LightModel {
    /// Near lights where the dataset gives `light_positions.txt` and `K.txt`, distant ones
    /// otherwise.
    #[default]
    Auto,
    /// Distant lights (the directions of `light_directions.txt` or the `.lp`), whatever else is
    /// there.
    Distant,
    /// Near lights: an error where the dataset gives no positions and camera.
    Near,
}

/// How the near-light rounds run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearOptions {
    /// The light model.
    pub model: LightModel,
    /// The object's distance from the camera along the optical axis (the depth of its centre),
    /// in the light positions' unit; `None`: the depth of the centre of the sphere through the
    /// lights.
    pub distance: Option<f64>,
    /// Side of a rig's tile, pixels.
    pub tile: usize,
    /// Rounds at most.
    pub max_iterations: usize,
    /// Stop once the normals change by less than this on average, degrees.
    pub tolerance_deg: f64,
}

impl Default for NearOptions {
    /// The defaults of [`NearParams`], the light model chosen by the dataset, no distance.
    fn default() -> Self {
        let p = NearParams::default();
        Self {
            model: LightModel::Auto,
            distance: None,
            tile: p.tile,
            max_iterations: p.max_iterations,
            tolerance_deg: p.tolerance_deg,
        }
    }
}

/// What report.json records of a near-light run.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct NearReport {
    /// `pinhole camera, point lights`.
    pub model: &'static str,
    /// The intrinsics, row-major, OpenCV's convention.
    #[serde(rename = "K")]
    pub k: [[f64; 3]; 3],
    /// The camera frame's convention.
    pub camera_frame: &'static str,
    /// Number of point lights.
    pub lights: usize,
    /// Whether the lights are LEDs with principal directions (cos^mu falloff).
    pub led_falloff: bool,
    /// The files read.
    pub files: Vec<String>,
    /// The centre and radius of the sphere through the lights, if they lie on one.
    pub dome: Option<([f64; 3], f64)>,
    /// The object's distance the rounds started from (depth of its centre).
    pub distance: f64,
    /// Where the distance came from: `given` or `the centre of the sphere through the lights`.
    pub distance_from: &'static str,
    /// Side of the largest rig tile, pixels.
    pub rig_tile: usize,
    /// Tiles are halved while a pixel's halfway vectors may be further than this from its
    /// rig's, degrees (`null`: fixed tiles).
    pub rig_bound_deg: Option<f64>,
    /// The largest such angle over the last round's tiles on the depth map written, degrees.
    pub rig_bound_measured_deg: f64,
    /// Tiles (rigs) of the last round.
    pub rig_tiles: usize,
    /// Rigs built over all rounds.
    pub rigs_built: usize,
    /// Rounds run, the last (every pixel) included.
    pub iterations: usize,
    /// Rounds before the last that estimated one pixel per tile.
    pub coarse_rounds: usize,
    /// Pixels estimated once more after the last round (their tile's rig moved too far on
    /// the last depth map).
    pub refined_pixels: usize,
    /// Mean change of the normals per round after the first, degrees (a coarse round's
    /// normals spread over every pixel).
    pub changes_deg: Vec<f64>,
    /// Whether the last change was under the tolerance.
    pub settled: bool,
    /// The depth map written (depth along the optical axis, metric, NaN outside the mask).
    pub depth: &'static str,
}

/// What the rounds leave for the job: the last round's counts and job fingerprint, the
/// report's section and the depth map.
pub(crate) struct NearRun {
    pub counts: TileCounts,
    pub job: u64,
    pub report: NearReport,
    pub depth: Vec<f32>,
}

/// Runs the rounds over `tiles` (every tile of the image) of `cache`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_near_rounds(
    cache: &TileCache,
    geometry: &NearGeometry,
    options: &NearOptions,
    rig: RigOptions,
    estimator: EstimatorParams,
    mask: Option<&[bool]>,
    base_job: u64,
    tiles: &[usize],
    dir: &Path,
    ctl: &Control,
) -> Result<NearRun> {
    let grid = *cache.grid();
    let (w, h) = (grid.width, grid.height);
    let (distance, distance_from) = match (options.distance, geometry.dome) {
        (Some(d), _) => (d, "given"),
        (None, Some((c, _))) => (-c.z, "the centre of the sphere through the lights"),
        (None, None) => bail!(
            "the light positions lie on no sphere, so the object's distance cannot be told from \
             them: give it (--distance, the depth of the object's centre along the optical axis \
             in the positions' unit)"
        ),
    };
    if !(distance.is_finite() && distance > 0.0) {
        bail!(
            "the object's distance must be in front of the camera (a positive depth), got \
             {distance}"
        );
    }
    let params = NearParams {
        rig,
        estimator,
        tile: options.tile,
        max_iterations: options.max_iterations.max(1),
        tolerance_deg: options.tolerance_deg,
        ..NearParams::default()
    };
    let mut last = None;
    let outcome = params.rounds(
        &geometry.camera,
        &geometry.lights,
        w,
        h,
        mask,
        distance,
        &mut |method: &NearMethod<'_>,
              round: usize,
              stage: &'static str|
         -> Result<Vec<PixelRecord>> {
            // Each round's results depend on its depths and what it estimates: its own
            // fingerprint.
            let mut f = Fingerprint::new();
            f.u64(base_job)
                .str("near rounds")
                .str(stage)
                .u64(params.tile as u64)
                .u64(round as u64);
            for d in method.depth() {
                f.bytes(&d.to_le_bytes());
            }
            let job = f.finish();
            let counts = run_tiles(cache, method, mask, job, tiles, dir, ctl)?;
            let mut records = vec![PixelRecord::MASKED; w * h];
            for &t in tiles {
                let got =
                    symframe_io::read_tile_result(&tile_path(dir, t), job, t, grid.tile_pixels(t))?;
                for (p, r) in grid.pixels(t).zip(got) {
                    records[p] = r;
                }
            }
            last = Some((counts, job));
            Ok(records)
        },
    )?;
    let (counts, job) = last.ok_or_else(|| anyhow::anyhow!("no estimation round ran"))?;
    let report = NearReport {
        model: "pinhole camera, point lights",
        k: geometry.camera.k(),
        camera_frame: "x right, y up, z toward the viewer, origin at the centre of \
                       projection; normals and tangents in this frame",
        lights: geometry.lights.len(),
        led_falloff: geometry.lights.iter().any(|l| l.principal.is_some()),
        files: geometry
            .files
            .iter()
            .map(|p| p.display().to_string())
            .collect(),
        dome: geometry.dome.map(|(c, r)| (c.to_array(), r)),
        distance,
        distance_from,
        rig_tile: params.tile,
        rig_bound_deg: params.rig_bound_deg,
        rig_bound_measured_deg: outcome.rig_bound_deg,
        rig_tiles: outcome.tiles,
        rigs_built: outcome.rigs_built,
        iterations: outcome.iterations,
        coarse_rounds: outcome.coarse_rounds,
        refined_pixels: outcome.refined_pixels,
        settled: outcome.settled,
        changes_deg: outcome.changes_deg,
        depth: "depth.npy",
    };
    Ok(NearRun {
        counts,
        job,
        report,
        depth: outcome.depth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{estimate, synth_near, EstimateConfig, EstimateOutcome, NearSynthConfig};

    #[test]
    fn a_near_capture_is_estimated_with_its_lights_and_camera() {
        let d = tempfile::tempdir().unwrap();
        let data = d.path().join("data");
        let capture = NearSynthConfig {
            size: 48,
            lights: 60,
            ..NearSynthConfig::new(&data)
        };
        synth_near(&capture, &Control::default()).unwrap();
        let run = |model: LightModel, out: &str| {
            let mut config = EstimateConfig::new(&data, d.path().join(out));
            config.near.model = model;
            config.near.max_iterations = 3;
            match estimate(&config, &Control::default()).unwrap() {
                EstimateOutcome::Maps(done) => *done,
                EstimateOutcome::Shard(_) => unreachable!("not a shard"),
            }
        };
        let (truth_shape, truth) = symframe_io::read_npy_f32(&data.join("gt_normals.npy")).unwrap();
        assert_eq!(truth_shape, [24, 48, 3]);
        let error = |normals: &[f32]| {
            let (mut sum, mut n) = (0.0, 0);
            for (a, b) in normals.chunks_exact(3).zip(truth.chunks_exact(3)) {
                let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
                if dot.is_finite() && b[2] > 0.5 {
                    sum += (dot.min(1.0) as f64).acos().to_degrees();
                    n += 1;
                }
            }
            sum / n as f64
        };
        let near = run(LightModel::Auto, "near");
        let report = near.report.near.clone().expect("near lights were used");
        assert_eq!(report.lights, 60);
        assert_eq!(report.k, capture.scene().camera.k());
        assert!(report.iterations >= 2 && report.coarse_rounds == report.iterations - 1);
        assert_eq!(report.changes_deg.len(), report.coarse_rounds - 1);
        assert!(d.path().join("near/depth.npy").is_file());
        let json = std::fs::read_to_string(d.path().join("near/report.json")).unwrap();
        assert!(json.contains("\"near\"") && json.contains("\"K\""));
        let far = run(LightModel::Distant, "far");
        assert!(far.report.near.is_none());
        let json = std::fs::read_to_string(d.path().join("far/report.json")).unwrap();
        assert!(!json.contains("\"near\""));
        let (e_near, e_far) = (
            error(&near.maps.unwrap().normals),
            error(&far.maps.unwrap().normals),
        );
        assert!(
            e_near < 1.5 && e_near < e_far / 3.0,
            "near {e_near}, distant {e_far}"
        );
    }

    /// An `.lp` whose rows are the lights' positions in hundredths (far from unit length),
    /// with K.txt beside it, is estimated with near lights as light_positions.txt is.
    #[test]
    fn an_lp_of_positions_beside_k_is_estimated_with_near_lights() {
        let d = tempfile::tempdir().unwrap();
        let data = d.path().join("data");
        let capture = NearSynthConfig {
            size: 48,
            lights: 60,
            ..NearSynthConfig::new(&data)
        };
        synth_near(&capture, &Control::default()).unwrap();
        let positions =
            symframe_io::near::read_positions(&data.join("light_positions.txt")).unwrap();
        let names = std::fs::read_to_string(data.join("filenames.txt")).unwrap();
        let lp_dir = d.path().join("lp");
        std::fs::create_dir(&lp_dir).unwrap();
        let mut lp = format!("{}\n", positions.len());
        for (name, p) in names.lines().zip(&positions) {
            let q = *p * 100.0;
            lp += &format!("../data/{name} {:?} {:?} {:?}\n", q.x, q.y, q.z);
        }
        std::fs::write(lp_dir.join("lights.lp"), lp).unwrap();
        std::fs::copy(data.join("K.txt"), lp_dir.join("K.txt")).unwrap();
        std::fs::copy(data.join("mask.png"), lp_dir.join("mask.png")).unwrap();
        let mut config = EstimateConfig::new(lp_dir.join("lights.lp"), d.path().join("out"));
        config.near.max_iterations = 3;
        let done = match estimate(&config, &Control::default()).unwrap() {
            EstimateOutcome::Maps(done) => *done,
            EstimateOutcome::Shard(_) => unreachable!("not a shard"),
        };
        let report = done.report.near.clone().expect("near lights were used");
        assert_eq!(report.lights, 60);
        let (_, truth) = symframe_io::read_npy_f32(&data.join("gt_normals.npy")).unwrap();
        let normals = done.maps.unwrap().normals;
        let (mut sum, mut n) = (0.0, 0);
        for (a, b) in normals.chunks_exact(3).zip(truth.chunks_exact(3)) {
            let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
            if dot.is_finite() && b[2] > 0.5 {
                sum += (dot.min(1.0) as f64).acos().to_degrees();
                n += 1;
            }
        }
        let mean = sum / n as f64;
        assert!(mean < 1.5, "mean normal error {mean} degrees");
        // The depths are in the .lp's unit: a hundred times the scene's.
        let (_, depth) = symframe_io::read_npy_f32(&d.path().join("out/depth.npy")).unwrap();
        let far = capture.camera_ratio * crate::synth_near::PAIR_WIDTH * 100.0;
        let seen: Vec<f32> = depth.into_iter().filter(|v| v.is_finite()).collect();
        let median = {
            let mut v = seen.clone();
            v.sort_by(f32::total_cmp);
            v[v.len() / 2] as f64
        };
        assert!(
            (median / far - 1.0).abs() < 0.1,
            "median depth {median}, object at {far}"
        );
    }
}
