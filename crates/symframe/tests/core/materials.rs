//! Accuracy across materials and rigs with the default settings: the per-pixel default measure
//! (diffuse to near-mirror), the search against sharp highlights, fallbacks beyond a narrow
//! rig's reach, and tangents only on anisotropic materials. Mean and 99th-percentile normal
//! errors over pixels within 60 degrees of the view; thresholds sit just above what the
//! estimator measures on these scenes (figures in the comments, `-- --nocapture` prints them).

use glam::DVec3;
use symframe::brdf::{Brdf, Ggx, Lambertian};
use symframe::render::{diligent_lights, BumpParams, Scene, TangentField};
use symframe::{
    estimate_stack, uniform_cone_lights, Baseline, BaselineParams, EstimateMaps, Estimator,
    EstimatorParams, Fallback, PixelSource, Rig, RigOptions,
};

/// Normal error figures over the pixels within 60 degrees of the view.
#[derive(Debug)]
struct Figures {
    mean: f64,
    p99: f64,
    coverage: f64,
    tangent_share: f64,
    /// Share of the estimated pixels more than 5 degrees off.
    over_5: f64,
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
        over_5: errors.iter().filter(|&&e| e > 5.0).count() as f64 / k.max(1) as f64,
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
    let maps = method
        .estimate_stack(
            &stack,
            lights,
            Some(&scene.mask),
            BaselineParams::default(),
            &|_| {},
        )
        .unwrap();
    let f = figures(scene, &maps);
    eprintln!("{} {method}: {f:?}", brdf.name());
    f
}

/// Bumps with cast shadows (48 x 48, ten bumps of relief 1, tangents swirling at 30 degrees).
fn shadowed_bumps(seed: u64) -> Scene {
    Scene::bumps(
        48,
        &BumpParams {
            count: 10,
            relief: 1.0,
            seed,
        },
        TangentField::Swirl(30.0),
    )
}

fn ggx(kd: f64, f0: f64, ax: f64, ay: f64) -> Ggx {
    Ggx::new([kd; 3], [f0; 3], ax, ay)
}

#[test]
fn near_mirror_highlights_do_not_derail_the_search() {
    // Lights ~3.6 degrees apart in halfway space; the lobes are 1-3 degrees wide. The lobe fit
    // answers; the search alone does worse, without the full-level judge far worse (measured:
    // docs/method.md, "What the tests measured").
    let scene = Scene::sphere(40, TangentField::Circular);
    for alpha in [0.02, 0.03, 0.05] {
        let f = estimate(
            &scene,
            &ggx(0.0, 0.95, alpha, alpha),
            &dense(),
            EstimatorParams::default(),
        );
        assert!(f.mean <= 0.2 && f.p99 <= 1.0, "alpha {alpha}: {f:?}");
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
    // The robust Lambertian fit is the centre of a diffuse slice.
    assert!(lambert.mean <= 0.1, "{lambert:?}");
    // Diffuse fraction from mostly diffuse to metal, roughness 0.05-0.2: the lobe fit answers;
    // the search would tilt the rough plastic's weak wide lobe in the paper's form (measured:
    // docs/method.md, "What the tests measured").
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
            f.mean <= 0.1 && f.p99 <= 0.5,
            "kd {kd} f0 {f0} alpha {alpha}: {f:?}"
        );
    }
}

#[test]
fn brushed_metal_along_the_tilt_plane_is_not_biased() {
    // The paper's form tilts these normals by 2 degrees on average (the wide axis lies in the
    // plane of tilt); the default measure removes the bias (measured, and with the search and
    // the compensated measure alone: docs/method.md, "What the tests measured").
    let scene = Scene::sphere(40, TangentField::Axial(DVec3::X));
    let f = estimate(
        &scene,
        &ggx(0.02, 0.9, 0.3, 0.06),
        &dense(),
        EstimatorParams::default(),
    );
    assert!(f.mean <= 0.3, "{f:?}");
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
    let lights = diligent_lights();
    let brdf = Lambertian::new([0.8; 3]);
    let filled = estimate(&scene, &brdf, &lights, EstimatorParams::default());
    // The Lambertian fallback is exact here (measured: docs/method.md, "What the tests measured").
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
    let (mut centre, mut rim) = (None, None);
    for p in 0..scene.n_pixels() {
        if !scene.mask[p] {
            continue;
        }
        let angle = scene.normals_in_camera[p].z.acos().to_degrees();
        // The pixel's samples in rig order.
        let all = stack.pixel(p);
        let slice: Vec<f32> = rig
            .input_index()
            .iter()
            .flat_map(|&i| all[3 * i..3 * i + 3].iter().copied())
            .collect();
        if angle < 5.0 && centre.is_none() {
            centre = Some(estimator.estimate_pixel(&slice));
        } else if (40.0..50.0).contains(&angle) && rim.is_none() {
            rim = Some(estimator.estimate_pixel(&slice));
        }
    }
    let (centre, rim) = (centre.unwrap(), rim.unwrap());
    // Within reach the lobe fit answers at full confidence; beyond it, the lobe extrapolated
    // from the part the rig sees, as a fallback.
    assert_eq!(centre.source, PixelSource::Lobe);
    assert_eq!(rim.status, symframe::PixelStatus::Estimated);
    assert!(
        matches!(rim.source, PixelSource::Lobe | PixelSource::Lambertian),
        "{rim:?}"
    );
    assert!(rim.confidence <= 0.5 && rim.confidence < centre.confidence.max(0.5) + 1e-6);
}

#[test]
fn isotropic_materials_get_no_tangents() {
    // Under 200 lights a highlight of three or four samples can look elongated; the lobe fit
    // does not read it so (measured tangent shares: docs/method.md, "What the tests measured").
    let scene = Scene::sphere(40, TangentField::Circular);
    let rigs: [(&str, Vec<DVec3>, f64); 3] = [
        ("dense", dense(), 0.02),
        ("sparse", uniform_cone_lights(200, 65.0), 0.02),
        ("narrow", diligent_lights(), 0.02),
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

/// Brushed metals under a 200-light rig (halfway vectors ~4 degrees apart, the lobe 3 degrees
/// wide across the grooves): the piecewise-linear slice is not symmetric about the true planes
/// there; the lobe fit reconstructs it smoothly (docs/method.md, "Lobe fit").
#[test]
fn sparse_rigs_keep_brushed_frames() {
    let lights = uniform_cone_lights(200, 65.0);
    let rig = Rig::new(&lights, RigOptions::default()).unwrap();
    let brdf = ggx(0.02, 0.9, 0.3, 0.06);
    for field in [TangentField::Circular, TangentField::Axial(DVec3::X)] {
        let scene = Scene::sphere(40, field);
        let stack = scene.render_stack(&brdf, &lights);
        let maps = estimate_stack(
            &stack,
            &rig,
            Some(&scene.mask),
            EstimatorParams::default(),
            &|_| {},
        )
        .unwrap();
        let f = figures(&scene, &maps);
        let e = scene.evaluate(&maps.normals, &maps.tangents);
        eprintln!(
            "{field:?}: {f:?}, tangent mean {:.2} swapped {:.3} coverage {:.3}",
            e.tangent_error.mean, e.swapped_share, e.tangent_coverage
        );
        // Measured figures: docs/method.md, "What the tests measured".
        assert!(f.mean <= 0.5 && f.coverage >= 0.99, "{field:?}: {f:?}");
        assert!(e.tangent_error.mean <= 1.0, "{field:?}: {e:?}");
        assert!(e.swapped_share < 0.02, "{field:?}: {e:?}");
        assert!(e.tangent_coverage >= 0.95, "{field:?}: {e:?}");
    }
}

/// Lobes of other families than the fit's microfacet one, and broad ones: Ward's (its
/// foreshortening is fitted), a rough metal (Fresnel and masking matter over its width).
#[test]
fn lobes_outside_the_microfacet_family_and_broad_lobes() {
    let scene = Scene::sphere(40, TangentField::Axial(DVec3::X));
    let ward = symframe::brdf::Ward::new([0.3; 3], [0.5; 3], 0.1, 0.4);
    let rough_metal = ggx(0.0, 0.9, 0.5, 0.5);
    for (brdf, limit) in [(&ward as &dyn Brdf, 0.5), (&rough_metal, 0.5)] {
        for lights in [dense(), uniform_cone_lights(200, 65.0)] {
            // Measured figures: docs/method.md, "What the tests measured".
            let f = estimate(&scene, brdf, &lights, EstimatorParams::default());
            assert!(
                f.mean <= limit && f.coverage >= 0.99,
                "{}: {f:?}",
                brdf.name()
            );
        }
    }
}

#[test]
fn beyond_reach_a_lobe_outside_the_family_beats_the_biased_lambertian_fit() {
    // Ashikhmin-Shirley (not a member of the lobe fit's family) under 200 lights: normals 45-60
    // degrees from the view have their highlight beyond the rig. The lobe fit leaves 0.6-0.7%
    // unexplained there (more than the 0.2% that makes it the answer) but much less than a
    // diffuse term, and is a few degrees off where the Lambertian fallback, biased by the
    // highlight's tails, is several times further (measured: docs/method.md, "What the tests
    // measured").
    let scene = Scene::sphere(48, TangentField::Circular);
    let brdf = symframe::brdf::AshikhminShirley::new([0.4; 3], [0.1; 3], 100.0, 10.0);
    let f = estimate(
        &scene,
        &brdf,
        &uniform_cone_lights(200, 65.0),
        EstimatorParams::default(),
    );
    assert!(
        f.over_5 <= 0.012 && f.mean <= 0.85 && f.coverage >= 0.99,
        "{f:?}"
    );
}

#[test]
fn a_lobe_that_barely_improves_on_the_diffuse_term_does_not_answer() {
    // Satin bumps with cast shadows and interreflections under the dense rig: on the steep
    // sides of the bumps a broad lobe with no diffuse part can stand in for the diffuse light,
    // centred far from the normal at high confidence, where the robust Lambertian fit (R^2 0.999)
    // is close; such a lobe does not answer (measured: docs/method.md, "What the tests measured").
    let scene = shadowed_bumps(5);
    let f = estimate(
        &scene,
        &ggx(0.3, 0.2, 0.4, 0.12),
        &dense(),
        EstimatorParams::default(),
    );
    assert!(
        f.over_5 <= 0.001 && f.mean <= 0.30 && f.coverage >= 0.99,
        "{f:?}"
    );
}

#[test]
fn a_doubtful_search_gives_way_to_a_plausible_lobe() {
    // Ward on shadowed bumps under 500 lights: cast shadows break the slices' symmetry, and
    // where the search's own confidence is under 0.1 a lobe fit leaving under 0.5% answers
    // (measured, and the search alone: docs/method.md, "What the tests measured").
    let scene = shadowed_bumps(7);
    let ward = symframe::brdf::Ward::new([0.3; 3], [0.5; 3], 0.1, 0.4);
    let f = estimate(
        &scene,
        &ward,
        &uniform_cone_lights(500, 65.0),
        EstimatorParams::default(),
    );
    assert!(
        f.mean <= 0.85 && f.over_5 <= 0.045 && f.coverage >= 0.99,
        "{f:?}"
    );
}

#[test]
fn a_spike_the_rig_undersamples_does_not_mislead_the_search() {
    // Sharp GGX plastic (alpha 0.02) on shadowed bumps under 200 lights: the spike falls on a
    // few lights or none; the robust Lambertian fit explains every other sample (R^2 > 0.999)
    // and its normal answers, where the search would go far off on the spike's few samples
    // (measured: docs/method.md, "What the tests measured").
    let scene = shadowed_bumps(7);
    let f = estimate(
        &scene,
        &ggx(0.5, 0.04, 0.02, 0.02),
        &uniform_cone_lights(200, 65.0),
        EstimatorParams::default(),
    );
    assert!(
        f.mean <= 0.4 && f.over_5 <= 0.002 && f.coverage >= 0.99,
        "{f:?}"
    );
}
