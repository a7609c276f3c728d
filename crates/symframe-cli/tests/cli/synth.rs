//! End-to-end tests of `symframe synth`: datasets written with ground truth and a scene
//! description, read back by `symframe estimate`, deterministic in the seed, and bad flags
//! refused with a one-line error and no output folder.

use std::fs;
use std::path::Path;

use crate::common::{s, symframe};

use glam::DVec3;
use symframe::evaluate;
use symframe_io::read_npy_f32;

fn run_ok(args: &[&str]) {
    let o = symframe(args);
    assert!(
        o.status.success(),
        "symframe {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn scene_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("scene.json")).unwrap()).unwrap()
}

#[test]
fn a_synthetic_lambertian_sphere_round_trips_through_estimate_within_1_degree() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    run_ok(&[
        "synth",
        "-o",
        s(&data),
        "--model",
        "lambertian",
        "--size",
        "24",
        "--rig",
        "cone:300",
        "--seed",
        "1",
    ]);
    for f in [
        "lights.lp",
        "gt_normals.npy",
        "gt_tangents.npy",
        "mask.png",
        "scene.json",
        "images/img_0299.exr",
    ] {
        assert!(data.join(f).is_file(), "missing {f}");
    }
    let j = scene_json(&data);
    assert!(
        j["model"].as_str().unwrap().starts_with("lambertian"),
        "{j}"
    );
    assert_eq!(j["shape"]["kind"], "sphere");
    assert_eq!(j["rig"]["kind"], "cone");
    assert_eq!(j["rig"]["lights"], 300);
    assert_eq!(j["noise"], "none");
    assert_eq!(j["seed"], 1);
    assert_eq!(j["format"], "exr");
    assert_eq!(j["cast_shadows"], false);

    let out = tmp.path().join("est");
    run_ok(&["estimate", s(&data), "-o", s(&out)]);
    let (shape, normals) = read_npy_f32(&out.join("normals.npy")).unwrap();
    assert_eq!(shape, vec![24, 24, 3]);
    let (_, tangents) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let (_, gt) = read_npy_f32(&data.join("gt_normals.npy")).unwrap();
    let e = evaluate(&normals, &tangents, &gt, None, None, 60.0, None);
    assert!(e.pixels > 200 && e.coverage > 0.95, "{e:?}");
    assert!(e.normal_error.mean < 1.0, "{e:?}");
}

#[test]
fn bumps_with_noise_are_deterministic_in_the_seed_and_read_back() {
    let tmp = tempfile::tempdir().unwrap();
    let synth = |name: &str, seed: &str| {
        let dir = tmp.path().join(name);
        run_ok(&[
            "synth",
            "-o",
            s(&dir),
            "--shape",
            "bumps",
            "--bumps",
            "5",
            "--relief",
            "1.5",
            "--size",
            "24",
            "--rig",
            "diligent",
            "--format",
            "png16",
            "--noise",
            "gaussian:0.01",
            "--tangent-field",
            "radial",
            "--seed",
            seed,
        ]);
        dir
    };
    let a = synth("a", "5");
    let b = synth("b", "5");
    let c = synth("c", "6");
    let img = "images/img_0007.png";
    assert_eq!(
        fs::read(a.join(img)).unwrap(),
        fs::read(b.join(img)).unwrap()
    );
    assert_ne!(
        fs::read(a.join(img)).unwrap(),
        fs::read(c.join(img)).unwrap()
    );
    let j = scene_json(&a);
    assert_eq!(j["shape"]["kind"], "bumps");
    assert_eq!(j["shape"]["bumps"].as_array().unwrap().len(), 5);
    assert_eq!(j["cast_shadows"], true);
    assert_eq!(j["rig"]["lights"], 96);
    assert_eq!(j["noise"], "gaussian:0.01");
    assert_eq!(j["tangent_field"], "radial");
    // The whole frame is surface.
    assert_eq!(j["mask_pixels"], 24 * 24);
    let out = tmp.path().join("est");
    run_ok(&["estimate", s(&a), "-o", s(&out), "--no-tangents"]);
    assert!(out.join("normals.npy").is_file());
    // Re-running into the same folder replaces the dataset.
    run_ok(&[
        "synth",
        "-o",
        s(&a),
        "--size",
        "8",
        "--rig",
        "cone:20",
        "--format",
        "png8",
    ]);
    assert!(!a.join("images/img_0020.png").exists());
    assert_eq!(scene_json(&a)["shape"]["kind"], "sphere");
}

#[test]
fn plane_and_cylinder_ground_truth_is_what_was_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let plane = tmp.path().join("plane");
    run_ok(&[
        "synth",
        "-o",
        s(&plane),
        "--shape",
        "plane",
        "--size",
        "8",
        "--normal-angle",
        "30",
        "--tangent-angle",
        "25",
        "--rig",
        "cone:40",
        "--format",
        "png8",
        "--exposure",
        "0.5",
    ]);
    let (n_exp, t_exp) = symframe::render::Scene::plane_frame(30.0, 0.0, 25.0);
    let (_, n) = read_npy_f32(&plane.join("gt_normals.npy")).unwrap();
    let (_, t) = read_npy_f32(&plane.join("gt_tangents.npy")).unwrap();
    for p in 0..64 {
        let np = DVec3::new(n[3 * p] as f64, n[3 * p + 1] as f64, n[3 * p + 2] as f64);
        let tp = DVec3::new(t[3 * p] as f64, t[3 * p + 1] as f64, t[3 * p + 2] as f64);
        assert!((np - n_exp).length() < 1e-6 && (tp - t_exp).length() < 1e-6);
    }
    let j = scene_json(&plane);
    assert_eq!(j["shape"]["normal_angle_deg"], 30.0);
    assert_eq!(j["shape"]["tangent_angle_deg"], 25.0);
    assert_eq!(j["exposure"], 0.5);

    let cyl = tmp.path().join("cyl");
    run_ok(&[
        "synth",
        "-o",
        s(&cyl),
        "--shape",
        "cylinder",
        "--size",
        "10",
        "--rig",
        "cone:30:40",
        "--tangent-field",
        "axial:90",
        "--model",
        "ward:ax=0.5,ay=0.1",
    ]);
    let (_, n) = read_npy_f32(&cyl.join("gt_normals.npy")).unwrap();
    let (_, t) = read_npy_f32(&cyl.join("gt_tangents.npy")).unwrap();
    assert!(n.iter().all(|v| v.is_finite()));
    assert!(n.chunks(3).all(|c| c[1] == 0.0));
    assert!(t.chunks(3).all(|c| (c[1] - 1.0).abs() < 1e-6));
    assert_eq!(scene_json(&cyl)["rig"]["theta_d_max_deg"], 40.0);
}

#[test]
fn bad_synth_flags_fail_with_one_line_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let missing = tmp.path().join("nowhere.lp");
    let rig_missing = format!("lp:{}", missing.display());
    let cases: &[(&[&str], &str)] = &[
        (&["--rig", "cone:0"], "--rig"),
        (&["--rig", "grid"], "--rig"),
        (&["--rig", &rig_missing], "nowhere.lp"),
        (&["--noise", "gauss:1"], "noise"),
        (&["--noise", "shot:0"], "PHOTONS"),
        (&["--model", "velvet"], "velvet"),
        (&["--tangent-field", "spiral"], "spiral"),
        (&["--normal-angle", "30"], "--shape plane"),
        (
            &["--shape", "plane", "--normal-angle", "95"],
            "--normal-angle",
        ),
        (
            &[
                "--shape",
                "plane",
                "--tangent-angle",
                "5",
                "--tangent-field",
                "radial",
            ],
            "exclusive",
        ),
        (&["--relief", "2"], "--shape bumps"),
        (&["--shape", "bumps", "--bumps", "0"], "--bumps"),
        (&["--size", "4"], "--size"),
        (&["--exposure", "0"], "--exposure"),
    ];
    for (extra, needle) in cases {
        let mut args = vec!["synth", "-o", s(&out)];
        if !extra.contains(&"--rig") {
            args.extend(["--rig", "cone:10"]);
        }
        args.extend_from_slice(extra);
        let o = symframe(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{extra:?} should fail");
        assert!(
            err.contains(needle),
            "{extra:?}: error should name {needle:?}: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "{extra:?}: one line: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{extra:?}: no output may be written");
    }
    let leftovers: Vec<_> = fs::read_dir(tmp.path()).unwrap().collect();
    assert!(leftovers.is_empty(), "nothing left behind: {leftovers:?}");
}
