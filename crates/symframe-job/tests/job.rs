//! The job API on small rendered captures: the tiled fit (the default, automatic model) equals
//! the in-memory fit bit for bit, an interrupted fit resumes to the same maps, and an estimate's progress and stop flag work.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use symframe::brdf::Ward;
use symframe::render::{Scene, TangentField};
use symframe::{uniform_cone_lights, FitParams};
use symframe_io::{DecodeOptions, ImageFormat};
use symframe_job::{
    estimate, fit, Control, EstimateConfig, EstimateOutcome, FitConfig, Interrupted, Stage,
};

/// A 20 x 20 brushed-metal sphere under 300 lights as an `.lp` dataset in `dir`.
fn capture(dir: &Path) -> (Scene, PathBuf) {
    let scene = Scene::sphere(20, TangentField::Circular);
    let lights = uniform_cone_lights(300, 65.0);
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
    let lp = write_exr_capture(dir, &scene, &lights, &images);
    (scene, lp)
}

/// `images` of `scene` under `lights` as float EXR images of an `.lp` dataset in `dir`, with
/// the scene's mask.
fn write_exr_capture(
    dir: &Path,
    scene: &Scene,
    lights: &[glam::DVec3],
    images: &[Vec<f32>],
) -> PathBuf {
    let (w, h) = (scene.width, scene.height);
    symframe_io::write_lp_dataset(
        dir,
        lights,
        images,
        w,
        h,
        ImageFormat::Exr,
        None,
        None,
        Some(&scene.mask),
    )
    .unwrap()
}

#[test]
fn the_tiled_fit_equals_the_in_memory_fit_and_resumes_after_a_stop() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, lp) = capture(&tmp.path().join("data"));
    let frames = tmp.path().join("frames");
    let mut est = EstimateConfig::new(&lp, &frames);
    est.cache.options.tile = 8;
    let EstimateOutcome::Maps(done) = estimate(&est, &Control::default()).unwrap() else {
        panic!("a full run gives maps");
    };

    let mut config = FitConfig::new(&lp, &frames, tmp.path().join("fit"));
    config.holdout = 6;
    // Stopped after one tile: interrupted, the finished tile kept.
    let stopped = Control {
        stop_after_tiles: Some(1),
        ..Control::default()
    };
    let e = fit(&config, &stopped).unwrap_err();
    assert!(e.is::<Interrupted>(), "{e}");
    let resumed = fit(&config, &Control::default()).unwrap();
    // The automatic fit stopped in its first pass (each pixel's evidence for the choice of its
    // model): at least the one tile was kept (the other workers may have finished theirs too),
    // and the second pass (the fit) ran whole.
    let tiles = resumed
        .report
        .evidence_tiles
        .expect("an automatic fit gathers evidence");
    assert!(tiles.reused >= 1 && tiles.computed >= 1, "{tiles:?}");
    assert_eq!(tiles.reused + tiles.computed, 9);
    assert_eq!(resumed.report.tiles.computed, 9);
    // The estimate's cache was read again, not rebuilt.
    assert!(resumed.report.cache.info.hit);

    let ds = symframe_io::open_dataset(&lp).unwrap();
    let stack = symframe_io::load_stack(&ds, &DecodeOptions::default(), &|| {}).unwrap();
    // The default model, at the exposure the job chose by validation lights.
    let exposure = resumed
        .report
        .exposure
        .expect("the automatic fit has an exposure");
    assert!(resumed.report.exposure_choice.is_some());
    let params = FitParams {
        holdout: FitParams::holdout_lights(300, 6).unwrap(),
        exposure,
        ..FitParams::default()
    };
    let maps = done.maps.as_ref().expect("kept by default");
    let memory = params
        .fit_stack(
            &stack,
            &ds.lights,
            &maps.normals,
            &maps.tangents,
            Some(&scene.mask),
            &|_| {},
        )
        .unwrap();
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&resumed.maps.ward.kd), bits(&memory.ward.kd));
    assert_eq!(bits(&resumed.maps.ward.alpha_t), bits(&memory.ward.alpha_t));
    let (job_gltf, mem_gltf) = (resumed.maps.gltf.as_ref(), memory.gltf.as_ref());
    let (job_gltf, mem_gltf) = (job_gltf.expect("glTF maps"), mem_gltf.expect("glTF maps"));
    assert_eq!(bits(&job_gltf.base_color), bits(&mem_gltf.base_color));
    assert_eq!(bits(&job_gltf.roughness), bits(&mem_gltf.roughness));
    assert_eq!(resumed.maps.model, memory.model);
    assert_eq!(bits(&resumed.maps.residual), bits(&memory.residual));
    assert_eq!(resumed.maps.summary, memory.summary);
    assert!(memory.summary.anisotropic > 100, "{:?}", memory.summary);
    // A Ward material: the automatic choice keeps Ward at most pixels.
    let s = memory.summary;
    assert!(s.ward_pixels > s.gltf_pixels, "{s:?}");
}

#[test]
fn progress_is_reported_and_a_set_stop_flag_interrupts_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, lp) = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    let stop = AtomicBool::new(true);
    let ctl = Control {
        stop: &stop,
        ..Control::default()
    };
    let e = estimate(&EstimateConfig::new(&lp, &out), &ctl).unwrap_err();
    assert!(e.is::<Interrupted>(), "{e}");
    assert!(!out.join("normals.npy").exists());

    stop.store(false, Ordering::SeqCst);
    let (images, tiles) = (AtomicU64::new(0), AtomicU64::new(0));
    let progress = |p: symframe_job::Progress| {
        let counter = match p.stage {
            Stage::Decoding => &images,
            Stage::Tiles => &tiles,
            Stage::Merging | Stage::Rendering => unreachable!("no merge or rendering here"),
        };
        counter.fetch_max(p.done, Ordering::SeqCst);
        assert!(p.done <= p.total);
    };
    let ctl = Control {
        stop: &stop,
        progress: &progress,
        ..Control::default()
    };
    estimate(&EstimateConfig::new(&lp, &out), &ctl).unwrap();
    // The interrupted run decoded nothing; this one decoded every image and did the one tile.
    assert_eq!(images.into_inner(), 300);
    assert_eq!(tiles.into_inner(), 1);
    assert!(out.join("normals.npy").is_file());
}

#[test]
fn a_float_capture_that_clipped_is_told_and_its_clip_level_recorded() {
    // The sphere's float images clipped at the level 2% of its samples reach: the estimate
    // warns that the float images clip and records the level in report.json; the same images
    // unclipped give neither.
    let tmp = tempfile::tempdir().unwrap();
    let scene = Scene::sphere(20, TangentField::Circular);
    let lights = uniform_cone_lights(300, 65.0);
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
    let mut all: Vec<f32> = images
        .iter()
        .flatten()
        .copied()
        .filter(|&v| v > 0.0)
        .collect();
    all.sort_by(f32::total_cmp);
    let level = all[all.len() * 98 / 100];
    for (name, clip) in [("clipped", Some(level)), ("smooth", None)] {
        let stored: Vec<Vec<f32>> = images
            .iter()
            .map(|img| img.iter().map(|&v| clip.map_or(v, |c| v.min(c))).collect())
            .collect();
        let lp = write_exr_capture(&tmp.path().join(name), &scene, &lights, &stored);
        let warnings = std::sync::Mutex::new(Vec::new());
        let warn = |line: &str| warnings.lock().unwrap().push(line.to_string());
        let ctl = Control {
            warning: &warn,
            ..Control::default()
        };
        let out = tmp.path().join(format!("{name}-out"));
        estimate(&EstimateConfig::new(&lp, &out), &ctl).unwrap();
        let told = warnings
            .into_inner()
            .unwrap()
            .iter()
            .any(|w| w.contains("the float images clip"));
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        let recorded = &report["parameters"]["noise"]["clip_level"];
        match clip {
            Some(c) => {
                assert!(told, "no warning for a clipped float capture");
                assert_eq!(recorded.as_f64(), Some(c as f64), "{report}");
            }
            None => {
                assert!(!told, "a warning for an unclipped float capture");
                assert!(recorded.is_null(), "{report}");
            }
        }
    }
}
