//! Accuracy of the baselines (Woodham photometric stereo, its robust variant, max-reflectance)
//! on synthetic sphere renders with known normals, over pixels whose normal is within 60
//! degrees of the view. Each baseline is exact at its own end of the range of materials and
//! off at the other (the paper's Figure 4).

use glam::DVec3;
use symframe::brdf::{parse_model, Brdf, Lambertian};
use symframe::render::{Scene, TangentField};
use symframe::{evaluate, uniform_cone_lights, Baseline, BaselineParams, Evaluation, PixelStatus};

/// Lights spread uniformly over the paper's cone: up to 130 degrees from the view.
fn rig(n: usize) -> Vec<DVec3> {
    uniform_cone_lights(n, 65.0)
}

fn run_with(
    scene: &Scene,
    brdf: &dyn Brdf,
    lights: &[DVec3],
    method: Baseline,
    params: BaselineParams,
) -> Evaluation {
    let stack = scene.render_stack(brdf, lights);
    let maps = method
        .estimate_stack(&stack, lights, Some(&scene.mask), params, &|_| {})
        .unwrap();
    let e = evaluate(
        &maps.normals,
        &maps.tangents,
        &scene.gt_normals(),
        None,
        Some(&scene.mask),
        60.0,
        None,
    );
    eprintln!(
        "{method} on {} ({} lights, shadow fraction {}): mean {:.4} median {:.4} p90 {:.4} max {:.4} deg, coverage {:.3}",
        brdf.name(),
        lights.len(),
        params.shadow_fraction,
        e.normal_error.mean,
        e.normal_error.median,
        e.normal_error.p90,
        e.normal_error.max,
        e.coverage
    );
    e
}

fn run(scene: &Scene, brdf: &dyn Brdf, lights: &[DVec3], method: Baseline) -> Evaluation {
    run_with(scene, brdf, lights, method, BaselineParams::default())
}

#[test]
fn woodham_and_robust_woodham_are_exact_on_a_lambertian_sphere() {
    let scene = Scene::sphere(40, TangentField::Circular);
    let brdf = Lambertian::new([0.7, 0.6, 0.5]);
    let lights = rig(500);
    for m in [Baseline::Woodham, Baseline::WoodhamRobust] {
        let e = run(&scene, &brdf, &lights, m);
        assert!(e.normal_error.max < 0.01, "{m}: {e:?}");
        assert_eq!(e.coverage, 1.0, "{m}: {e:?}");
    }
}

#[test]
fn excluding_shadowed_samples_matters_with_lights_far_from_the_view() {
    // Lights up to 130 degrees from the view: tilted normals see many lights below their
    // horizon, whose zero samples pull a plain least-squares fit off.
    let scene = Scene::sphere(40, TangentField::Circular);
    let brdf = Lambertian::new([0.8; 3]);
    let lights = rig(500);
    let plain = run_with(
        &scene,
        &brdf,
        &lights,
        Baseline::Woodham,
        BaselineParams {
            shadow_fraction: 0.0,
            ..BaselineParams::default()
        },
    );
    let with_threshold = run(&scene, &brdf, &lights, Baseline::Woodham);
    assert!(
        plain.normal_error.mean > 3.0,
        "plain least squares should be several degrees off: {plain:?}"
    );
    assert!(
        with_threshold.normal_error.mean < 0.05,
        "{with_threshold:?}"
    );
}

#[test]
fn robust_woodham_beats_woodham_on_a_glossy_material() {
    let scene = Scene::sphere(40, TangentField::Circular);
    let brdf = parse_model("ward:kd=0.5,ks=0.5,alpha=0.1").unwrap();
    let lights = rig(500);
    let plain = run(&scene, brdf.as_ref(), &lights, Baseline::Woodham);
    let robust = run(&scene, brdf.as_ref(), &lights, Baseline::WoodhamRobust);
    // The shadow threshold's reference is a high quantile, not the maximum: relative to the
    // highlight's peak every diffuse sample would count as shadowed.
    let from_max = run_with(
        &scene,
        brdf.as_ref(),
        &lights,
        Baseline::WoodhamRobust,
        BaselineParams {
            shadow_reference_quantile: 1.0,
            ..BaselineParams::default()
        },
    );
    assert!(
        from_max.normal_error.mean > 2.0 * robust.normal_error.mean,
        "{from_max:?}"
    );
    assert!(
        robust.normal_error.mean < 0.7 * plain.normal_error.mean,
        "robust {:?} vs plain {:?}",
        robust.normal_error,
        plain.normal_error
    );
}

/// Mean angle from each light's halfway vector to its nearest neighbour's (degrees).
fn halfway_spacing_deg(lights: &[DVec3]) -> f64 {
    let h: Vec<DVec3> = lights.iter().map(|&l| (l + DVec3::Z).normalize()).collect();
    let total: f64 = h
        .iter()
        .enumerate()
        .map(|(i, a)| {
            h.iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, b)| a.dot(*b).clamp(-1.0, 1.0).acos())
                .fold(f64::INFINITY, f64::min)
        })
        .sum();
    (total / h.len() as f64).to_degrees()
}

#[test]
fn max_reflectance_is_within_the_light_spacing_on_a_specular_sphere() {
    // A pure Torrance-Sparrow highlight (no diffuse term, no Fresnel): its radiance peaks
    // where the halfway vector is the normal.
    let scene = Scene::sphere(40, TangentField::Circular);
    let brdf = parse_model("torrance-sparrow:kd=0,ks=1,sigma=0.1").unwrap();
    let lights = rig(500);
    let spacing = halfway_spacing_deg(&lights);
    let e = run(&scene, brdf.as_ref(), &lights, Baseline::MaxReflectance);
    eprintln!("halfway spacing {spacing:.3} deg");
    assert!(
        e.normal_error.mean < 0.25 * spacing,
        "mean {} vs spacing {spacing}",
        e.normal_error.mean
    );
    assert!(e.normal_error.max < spacing, "{e:?}");
    assert_eq!(e.coverage, 1.0);
}

#[test]
fn max_reflectance_is_off_by_half_the_tilt_on_a_lambertian_sphere() {
    // The paper's Figure 4: the specularity method fails at the diffuse end. The brightest
    // light is along the normal, so its halfway vector is halfway between normal and view.
    let scene = Scene::sphere(40, TangentField::Circular);
    let lights = rig(1000);
    let e = run(
        &scene,
        &Lambertian::new([0.8; 3]),
        &lights,
        Baseline::MaxReflectance,
    );
    assert!(e.normal_error.mean > 8.0, "{e:?}");
}

#[test]
fn stack_driver_matches_the_per_pixel_results_and_counts() {
    let scene = Scene::sphere(16, TangentField::Circular);
    let lights = rig(120);
    let stack = scene.render_stack(&Lambertian::new([0.5; 3]), &lights);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let maps = Baseline::WoodhamRobust
        .estimate_stack(&stack, &lights, None, BaselineParams::default(), &|k| {
            done.fetch_add(k, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
    assert_eq!(done.into_inner(), 16 * 16);
    let inside = scene.mask.iter().filter(|&&m| m).count();
    // Outside the sphere the renders are black: no data.
    assert_eq!(maps.counts.estimated, inside);
    assert_eq!(maps.counts.no_data, 16 * 16 - inside);
    for p in 0..16 * 16 {
        let est = maps.status[p] == PixelStatus::Estimated;
        assert_eq!(est, scene.mask[p]);
        assert_eq!(maps.normals[p * 3].is_nan(), !est);
        assert_eq!(maps.confidence[p].is_nan(), !est);
    }
}
