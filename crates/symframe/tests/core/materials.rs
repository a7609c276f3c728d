//! Accuracy across materials and rigs with the default settings: the per-pixel default measure
//! (diffuse to near-mirror), the search against sharp highlights, fallbacks beyond a narrow
//! rig's reach, and tangents only on anisotropic materials. Mean and 99th-percentile normal
//! errors over pixels within 60 degrees of the view; thresholds sit just above what the
//! estimator measures on these scenes (figures in the comments, `-- --nocapture` prints them).

use glam::DVec3;
use symframe::baselines::{estimate_stack_baseline, Baseline};
use symframe::brdf::{Brdf, Ggx, Lambertian};
use symframe::frames::estimator::Fallback;
use symframe::frames::rig::uniform_cone_lights;
use symframe::frames::slice::gather_pixel;
use symframe::maps::PixelSource;
use symframe::render::{rigs, Scene, TangentField};
use symframe::{estimate_stack, EstimateMaps, Estimator, EstimatorParams, Rig, RigOptions};

/// Normal error figures over the pixels within 60 degrees of the view.
#[derive(Debug)]
struct Figures {
    mean: f64,
    p99: f64,
    coverage: f64,
    tangent_share: f64,
}

fn figures(scene: &Scene, maps: &EstimateMaps) -> Figures {
    let mut errors = Vec::new();
    let (mut pixels, mut tangents) = (0usize, 0usize);
    for p in 0..scene.n_pixels() {
        let g = scene.normals_in_camera[p];
        if !scene.mask[p] || g.z < 0.5 {
            continue;
        }
        pixels += 1;
        let n = &maps.normals[p * 3..p * 3 + 3];
        if n[0].is_finite() {
            let n = DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64);
            errors.push(n.angle_between(g).to_degrees());
            if maps.tangents[p * 3].is_finite() {
                tangents += 1;
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let k = errors.len();
    Figures {
        mean: errors.iter().sum::<f64>() / k.max(1) as f64,
        p99: errors
            .get((0.99 * (k.max(1) - 1) as f64).round() as usize)
            .copied()
            .unwrap_or(f64::NAN),
        coverage: k as f64 / pixels.max(1) as f64,
        tangent_share: tangents as f64 / k.max(1) as f64,
    }
}

fn dense() -> Vec<DVec3> {
    uniform_cone_lights(1000, 65.0)
}

fn estimate(scene: &Scene, brdf: &dyn Brdf, lights: &[DVec3], params: EstimatorParams) -> Figures {
    let stack = scene.render_stack(brdf, lights);
    let rig = Rig::new(lights, RigOptions::default()).unwrap();
    let maps = estimate_stack(&stack, &rig, Some(&scene.mask), params, &|_| {}).unwrap();
    let f = figures(scene, &maps);
    eprintln!("{}: {f:?}", brdf.name());
    f
}

fn baseline(scene: &Scene, brdf: &dyn Brdf, lights: &[DVec3], method: Baseline) -> Figures {
    let stack = scene.render_stack(brdf, lights);
    let maps = estimate_stack_baseline(&stack, lights, Some(&scene.mask), method, &|_| {}).unwrap();
    let f = figures(scene, &maps);
    eprintln!("{} {method}: {f:?}", brdf.name());
    f
}

fn ggx(kd: f64, f0: f64, ax: f64, ay: f64) -> Ggx {
    Ggx::new([kd; 3], [f0; 3], ax, ay)
}

#[test]
fn near_mirror_highlights_do_not_derail_the_search() {
    // Lights ~3.5 degrees apart in halfway space; the lobes are 1-3 degrees wide. Measured:
    // alpha 0.02: mean 0.80, p99 1.9; 0.03: 0.65, 1.6; 0.05: 0.5, 1.2 (before the full-level
    // judge: 3.1 mean, 18% of pixels over 5 degrees).
    let scene = Scene::sphere(40, TangentField::Circular);
    for alpha in [0.02, 0.03, 0.05] {
        let f = estimate(
            &scene,
            &ggx(0.0, 0.95, alpha, alpha),
            &dense(),
            EstimatorParams::default(),
        );
        assert!(f.mean <= 0.85 && f.p99 <= 3.0, "alpha {alpha}: {f:?}");
        assert!(f.coverage >= 0.99, "alpha {alpha}: {f:?}");
    }
}

#[test]
fn the_default_measure_is_right_from_diffuse_to_metal() {
    let scene = Scene::sphere(40, TangentField::Circular);
    let lambert = estimate(
        &scene,
        &Lambertian::new([0.8; 3]),
        &dense(),
        EstimatorParams::default(),
    );
    // Measured 0.04 (the paper's form is exact for diffuse surfaces).
    assert!(lambert.mean <= 0.1, "{lambert:?}");
    // Diffuse fraction from mostly diffuse to metal, roughness 0.05-0.2. Measured mean
    // 0.17-0.55, p99 up to 3.75 on the rough plastic (kd 0.7, alpha 0.2, whose weak wide lobe
    // the paper's form alone tilts by 1.7 degrees on average).
    for (kd, f0, alpha) in [
        (0.5, 0.04, 0.1),
        (0.7, 0.04, 0.2),
        (0.2, 0.5, 0.05),
        (0.0, 0.9, 0.1),
    ] {
        let f = estimate(
            &scene,
            &ggx(kd, f0, alpha, alpha),
            &dense(),
            EstimatorParams::default(),
        );
        assert!(
            f.mean <= 0.6 && f.p99 <= 4.0,
            "kd {kd} f0 {f0} alpha {alpha}: {f:?}"
        );
    }
}

#[test]
fn brushed_metal_along_the_tilt_plane_is_not_biased() {
    // The paper's form tilts these normals by 2 degrees on average (the wide axis lies in the
    // plane of tilt); the default measure removes the bias. Measured: 0.47 mean.
    let scene = Scene::sphere(40, TangentField::Axial(DVec3::X));
    let f = estimate(
        &scene,
        &ggx(0.02, 0.9, 0.3, 0.06),
        &dense(),
        EstimatorParams::default(),
    );
    assert!(f.mean <= 0.7, "{f:?}");
    assert!(f.tangent_share >= 0.95, "{f:?}");
}

#[test]
fn the_estimator_beats_the_highlight_centroid_on_glossy_materials() {
    let scene = Scene::sphere(40, TangentField::Circular);
    for brdf in [ggx(0.5, 0.04, 0.1, 0.1), ggx(0.0, 0.95, 0.03, 0.03)] {
        let ours = estimate(&scene, &brdf, &dense(), EstimatorParams::default());
        let centroid = baseline(&scene, &brdf, &dense(), Baseline::HighlightCentroid);
        assert!(ours.mean < centroid.mean, "{ours:?} vs {centroid:?}");
    }
}

#[test]
fn narrow_rigs_fill_every_pixel_and_say_where_from() {
    // A DiLiGenT-like grid within 45 degrees reaches normals within ~22 degrees of the view.
    let scene = Scene::sphere(40, TangentField::Circular);
    let lights = rigs::diligent_lights();
    let brdf = Lambertian::new([0.8; 3]);
    let filled = estimate(&scene, &brdf, &lights, EstimatorParams::default());
    // Measured: coverage 100%, mean 0.08 degrees (the Lambertian fallback is exact here).
    assert!(filled.coverage >= 0.99 && filled.mean <= 0.1, "{filled:?}");
    let bare = estimate(
        &scene,
        &brdf,
        &lights,
        EstimatorParams {
            fallback: Fallback::None,
            ..EstimatorParams::default()
        },
    );
    assert!(bare.coverage < 0.3, "{bare:?}");

    // Per pixel: inside the reach the symmetry estimator answers, beyond it the fallback, with
    // a lower confidence.
    // A glossy plastic, whose centre is not diffuse (a Lambertian sphere's is the fit's).
    let plastic = ggx(0.5, 0.04, 0.1, 0.1);
    let stack = scene.render_stack(&plastic, &lights);
    let rig = Rig::new(&lights, RigOptions::default()).unwrap();
    let estimator = Estimator::new(&rig, EstimatorParams::default());
    let mut slice = vec![0.0; rig.n_used() * 3];
    let (mut centre, mut rim) = (None, None);
    for p in 0..scene.n_pixels() {
        if !scene.mask[p] {
            continue;
        }
        let angle = scene.normals_in_camera[p].z.acos().to_degrees();
        gather_pixel(&rig, stack.pixel(p), &mut slice);
        if angle < 5.0 && centre.is_none() {
            centre = Some(estimator.estimate_pixel(&slice));
        } else if (40.0..50.0).contains(&angle) && rim.is_none() {
            rim = Some(estimator.estimate_pixel(&slice));
        }
    }
    let (centre, rim) = (centre.unwrap(), rim.unwrap());
    assert_eq!(centre.source, PixelSource::Symmetry);
    assert_eq!(rim.source, PixelSource::Lambertian);
    assert!(rim.confidence <= 0.5 && rim.confidence < centre.confidence.max(0.5) + 1e-6);
}

#[test]
fn isotropic_materials_get_no_tangents() {
    // Measured tangent shares: dense and narrow at most 1.1%; sparse (200 lights) up to 6.5%
    // on plastic, where a highlight of three or four samples can look elongated.
    let scene = Scene::sphere(40, TangentField::Circular);
    let rigs: [(&str, Vec<DVec3>, f64); 3] = [
        ("dense", dense(), 0.02),
        ("sparse", uniform_cone_lights(200, 65.0), 0.08),
        ("narrow", rigs::diligent_lights(), 0.02),
    ];
    let materials: [Box<dyn Brdf>; 3] = [
        Box::new(Lambertian::new([0.8; 3])),
        Box::new(ggx(0.5, 0.04, 0.1, 0.1)),
        Box::new(ggx(0.0, 0.95, 0.03, 0.03)),
    ];
    for (name, lights, limit) in &rigs {
        for brdf in &materials {
            let f = estimate(&scene, brdf.as_ref(), lights, EstimatorParams::default());
            assert!(f.tangent_share <= *limit, "{name} {}: {f:?}", brdf.name());
        }
    }
}
