//! End-to-end tests of `symframe fit` and `symframe relight`: a rendered capture in, Ward maps
//! and relit pictures out, and bad input refused with a one-line error naming the file, leaving
//! no output folder behind.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{
    assert_fails_keeping_cache, assert_fails_naming, estimate, ok, report, s, sphere_dataset,
    stderr, symframe, Truth,
};

use glam::DVec3;
use symframe::brdf::Ward;
use symframe::render::Scene;
use symframe::uniform_cone_lights;
use symframe_io::{read_npy_f32, write_npy_f32, DecodeOptions, ImageFormat};

fn material() -> Ward {
    Ward::new([0.4, 0.3, 0.2], [0.3, 0.45, 0.6], 0.1, 0.35)
}

/// A rendered sphere in `.lp` form (EXR images, mask.png beside); returns the scene, the lights
/// and the .lp path.
fn dataset(dir: &Path, size: usize, n_lights: usize) -> (Scene, Vec<DVec3>, PathBuf) {
    let truth = Truth {
        normals: true,
        tangents: true,
    };
    let (scene, lp) = sphere_dataset(
        dir,
        size,
        n_lights,
        &material(),
        ImageFormat::Exr,
        1.0,
        truth,
    );
    (scene, uniform_cone_lights(n_lights, 65.0), lp)
}

/// A frames folder holding the true normals and tangents.
fn true_frames(dir: &Path, scene: &Scene) -> PathBuf {
    let n = scene.width;
    fs::create_dir_all(dir).unwrap();
    write_npy_f32(&dir.join("normals.npy"), &[n, n, 3], &scene.gt_normals()).unwrap();
    write_npy_f32(&dir.join("tangents.npy"), &[n, n, 3], &scene.gt_tangents()).unwrap();
    dir.to_path_buf()
}

fn read_exr(path: &Path) -> Vec<f32> {
    symframe_io::read_image(path, &DecodeOptions::default())
        .unwrap()
        .into_rgb()
}

#[test]
fn estimate_fit_relight_end_to_end() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, lights, lp) = dataset(&tmp.path().join("data"), 24, 400);
    let est = tmp.path().join("est");
    let o = symframe(&["estimate", s(&lp), "-o", s(&est)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let fit = tmp.path().join("fit");
    let o = fit_with(&lp, &est, &fit, &["--holdout", "10", "--model", "ward"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "kd.npy",
        "ks.npy",
        "alpha_t.npy",
        "alpha_b.npy",
        "residual.npy",
        "holdout_residual.npy",
        "normals.npy",
        "tangents.npy",
        "kd.exr",
        "ks.exr",
        "alpha_t.exr",
        "alpha_b.exr",
        "residual.exr",
        "kd.png",
        "fit.json",
    ] {
        assert!(fit.join(f).is_file(), "missing {f}");
    }
    let (shape, kd) = read_npy_f32(&fit.join("kd.npy")).unwrap();
    assert_eq!(shape, vec![24, 24, 3]);
    let (shape, at) = read_npy_f32(&fit.join("alpha_t.npy")).unwrap();
    assert_eq!(shape, vec![24, 24]);
    let (_, ab) = read_npy_f32(&fit.join("alpha_b.npy")).unwrap();
    // The centre pixels are close to the truth (estimated frames).
    let w = material();
    let mut kd_err = vec![];
    let mut wide_err = vec![];
    for p in 0..24 * 24 {
        if scene.mask[p] && scene.normals_in_camera[p].z > 0.5 && !at[p].is_nan() {
            kd_err.push((kd[p * 3] as f64 / w.kd[0] - 1.0).abs());
            wide_err.push((at[p].max(ab[p]) as f64 / 0.35 - 1.0).abs());
        }
    }
    kd_err.sort_by(f64::total_cmp);
    wide_err.sort_by(f64::total_cmp);
    assert!(kd_err.len() > 200);
    assert!(kd_err[kd_err.len() / 2] < 0.03, "{kd_err:?}");
    assert!(wide_err[wide_err.len() / 2] < 0.05, "{wide_err:?}");
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(fit.join("fit.json")).unwrap()).unwrap();
    assert_eq!(report["lights"]["held_out"], 10);
    assert_eq!(report["lights"]["fitted"], 390);
    assert_eq!(report["parameters"]["holdout"][0], 20);
    let psnr = report["fit"]["holdout_psnr_db"].as_f64().unwrap();
    assert!(psnr > 30.0, "{report}");

    // Relight under two held-out lights, one given on the command line and one in a file.
    let held: Vec<usize> = report["parameters"]["holdout"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let (l0, l1) = (lights[held[3]], lights[held[6]]);
    let lfile = tmp.path().join("new.lp");
    fs::write(&lfile, format!("1\nnew {} {} {}\n", l1.x, l1.y, l1.z)).unwrap();
    let relit = tmp.path().join("relit");
    let o = symframe(&[
        "relight",
        s(&fit),
        "-o",
        s(&relit),
        "--light",
        &format!("{},{},{}", l0.x, l0.y, l0.z),
        "--lights",
        s(&lfile),
        "--exposure",
        "-0.5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut inside = scene.mask.clone();
    for (p, m) in inside.iter_mut().enumerate() {
        *m &= scene.normals_in_camera[p].z > 0.5;
    }
    for (i, l) in [l0, l1].into_iter().enumerate() {
        assert!(relit.join(format!("relit_{i:03}.png")).is_file());
        let img = read_exr(&relit.join(format!("relit_{i:03}.exr")));
        let psnr = symframe::Relighter::image_psnr(&img, &scene.render(&w, l), Some(&inside));
        assert!(psnr > 35.0, "light {i}: {psnr} dB");
    }
    assert!(relit.join("relight.json").is_file());

    // Edit: tangents turned inside the left half only.
    let region: Vec<f32> = (0..24 * 24)
        .flat_map(|p| [((p % 24) < 12) as u8 as f32; 3])
        .collect();
    let region_png = tmp.path().join("region.png");
    symframe_io::write_png8_rgb(&region_png, 24, 24, &region, false).unwrap();
    let edited = tmp.path().join("edited");
    let o = symframe(&[
        "relight",
        s(&fit),
        "-o",
        s(&edited),
        "--light",
        &format!("{},{},{}", l0.x, l0.y, l0.z),
        "--rotate-tangents",
        "90",
        "--region",
        s(&region_png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(edited.join("tangents_edited.png").is_file());
    let (a, b) = (
        read_exr(&relit.join("relit_000.exr")),
        read_exr(&edited.join("relit_000.exr")),
    );
    let mut changed = 0;
    for p in 0..24 * 24 {
        let same = a[p * 3..p * 3 + 3] == b[p * 3..p * 3 + 3];
        if p % 24 >= 12 {
            assert!(same, "pixel {p} outside the region changed");
        } else if !same {
            changed += 1;
        }
    }
    assert!(changed > 50, "{changed}");

    // From the samples themselves, with no model: at a photographed light, the photograph;
    // between the lights, the true render. Edits are refused (no parameters to edit).
    let between = (l0 + 0.05 * DVec3::X).normalize();
    let samples = tmp.path().join("samples");
    let light = |l: DVec3| format!("{},{},{}", l.x, l.y, l.z);
    let o = symframe(&[
        "relight",
        s(&fit),
        "-o",
        s(&samples),
        "--from-samples",
        s(&lp),
        "--light",
        &light(l0),
        "--light",
        &light(between),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let photo = symframe::Relighter::image_psnr(
        &read_exr(&samples.join("relit_000.exr")),
        &scene.render(&w, l0),
        Some(&inside),
    );
    assert!(photo > 60.0, "at a photographed light: {photo} dB");
    let psnr = symframe::Relighter::image_psnr(
        &read_exr(&samples.join("relit_001.exr")),
        &scene.render(&w, between),
        Some(&inside),
    );
    assert!(psnr > 30.0, "between the lights: {psnr} dB");
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(samples.join("relight.json")).unwrap()).unwrap();
    assert_eq!(report["from_samples"], s(&lp));
    let o = symframe(&[
        "relight",
        s(&fit),
        "-o",
        s(&tmp.path().join("refused")),
        "--from-samples",
        s(&lp),
        "--light",
        &light(l0),
        "--rotate-tangents",
        "90",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--from-samples"), "{}", stderr(&o));
    assert!(!tmp.path().join("refused").join("relight.json").exists());
    // The viewer's view `samples` holds at most 254 lights: this capture's 400 are refused
    // in one line naming it, and no page is written.
    let page = tmp.path().join("v.html");
    let o = symframe(&["view", s(&fit), "-o", s(&page), "--from-samples", s(&lp)]);
    crate::common::assert_one_line_error(&o, "400 lights");
    assert!(!page.exists());
}

#[test]
fn fit_refuses_mismatched_or_missing_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, _, lp) = dataset(&tmp.path().join("data"), 12, 60);
    let frames = true_frames(&tmp.path().join("frames"), &scene);
    let out = tmp.path().join("out");
    // Normals of another size.
    write_npy_f32(&frames.join("normals.npy"), &[10, 12, 3], &vec![0.0; 360]).unwrap();
    let o = fit_with(&lp, &frames, &out, &[]);
    assert_fails_keeping_cache(&o, "normals.npy", &out);
    // Tangents missing.
    true_frames(&frames, &scene);
    fs::remove_file(frames.join("tangents.npy")).unwrap();
    let o = fit_with(&lp, &frames, &out, &[]);
    assert_fails_keeping_cache(&o, "tangents.npy", &out);
    // Tangents not an array file.
    fs::write(frames.join("tangents.npy"), b"not npy").unwrap();
    let o = fit_with(&lp, &frames, &out, &[]);
    assert_fails_keeping_cache(&o, "tangents.npy", &out);
    // Too many lights held out; a missing dataset.
    true_frames(&frames, &scene);
    let o = fit_with(&lp, &frames, &out, &["--holdout", "40"]);
    assert_fails_keeping_cache(&o, "--holdout", &out);
    let o = symframe(&[
        "fit",
        "/no/such/data.lp",
        "--frames",
        s(&frames),
        "-o",
        s(&out),
    ]);
    assert_fails_keeping_cache(&o, "/no/such/data.lp", &out);
    // A wrong-size mask.
    let small = tmp.path().join("small.png");
    symframe_io::write_png8_rgb(&small, 5, 5, &[1.0; 75], false).unwrap();
    let o = fit_with(&lp, &frames, &out, &["--mask", s(&small)]);
    assert_fails_keeping_cache(&o, "small.png: mask is 5x5 but the images are 12x12", &out);
    // And the good case works with true frames.
    let o = fit_with(&lp, &frames, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("holdout_residual.npy").exists());
}

/// Copies the files of a dataset folder (one level of subfolders, as `synth` writes).
fn copy_dataset(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for e in fs::read_dir(from).unwrap().flatten() {
        let dest = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dataset(&e.path(), &dest);
        } else {
            fs::copy(e.path(), dest).unwrap();
        }
    }
}

/// `fit --frames` from another capture of the same size is refused (it would give wrong Ward
/// maps, exit 0): the estimate's report.json records the capture's fingerprint and fit checks
/// it before decoding anything. A copy of the capture elsewhere is the same capture.
#[test]
fn fit_refuses_frames_of_another_capture() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, _, lp_a) = dataset(&tmp.path().join("a"), 12, 60);
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    // Another capture of the same size and lights: the same sphere, brighter.
    let lp_b = sphere_dataset(
        &tmp.path().join("b"),
        12,
        60,
        &material(),
        ImageFormat::Exr,
        1.5,
        truth,
    )
    .1;
    let est = tmp.path().join("est-a");
    ok(&estimate(&lp_a, &est, &["--quiet"]));
    let recorded = report(&est)["inputs"].clone();
    assert_eq!(recorded["images_by"], "content", "{recorded}");
    assert_eq!(recorded["fingerprint"].as_str().unwrap().len(), 16);
    let cache = est.join(".symframe-cache");
    let listing = |d: &Path| {
        let mut v: Vec<String> = fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    let cached = listing(&cache);

    let out = tmp.path().join("fit");
    let o = fit_with(&lp_b, &est, &out, &[]);
    assert_fails_naming(
        &o,
        &format!(
            "{}: frames estimated from another capture than {}",
            est.display(),
            lp_b.display()
        ),
        &out,
    );
    assert_eq!(
        listing(&cache),
        cached,
        "nothing of b decoded into a's cache"
    );

    // A copy of capture a is a: accepted, and fit.json records the same fingerprint.
    copy_dataset(&tmp.path().join("a"), &tmp.path().join("a-copy"));
    let lp_copy = tmp.path().join("a-copy").join(lp_a.file_name().unwrap());
    let o = symframe(&[
        "fit",
        "--quiet",
        s(&lp_copy),
        "--frames",
        s(&est),
        "-o",
        s(&out),
    ]);
    ok(&o);
    let fit: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
    assert_eq!(fit["inputs"], recorded);

    // A report without the record (an older symframe): fitted, with a warning.
    let rp = est.join("report.json");
    let mut r = report(&est);
    r.as_object_mut().unwrap().remove("inputs");
    fs::write(&rp, serde_json::to_string(&r).unwrap()).unwrap();
    let o = symframe(&[
        "fit",
        "--quiet",
        s(&lp_b),
        "--frames",
        s(&est),
        "-o",
        s(&out),
    ]);
    ok(&o);
    assert!(
        stderr(&o).contains("records no input fingerprint"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn relight_refuses_bad_fit_folders_regions_and_light_files() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, _, lp) = dataset(&tmp.path().join("data"), 12, 60);
    let frames = true_frames(&tmp.path().join("frames"), &scene);
    let fit = tmp.path().join("fit");
    let o = fit_with(&lp, &frames, &fit, &["--model", "ward"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = tmp.path().join("out");
    let relight = |extra: &[&str]| {
        let mut a = vec!["relight", s(&fit), "-o", s(&out)];
        a.extend_from_slice(extra);
        symframe(&a)
    };
    // Region of the wrong size.
    let small = tmp.path().join("logo.png");
    symframe_io::write_png8_rgb(&small, 5, 5, &[1.0; 75], false).unwrap();
    let o = relight(&[
        "--light",
        "0,0,1",
        "--rotate-tangents",
        "90",
        "--region",
        s(&small),
    ]);
    assert_fails_naming(&o, "logo.png", &out);
    // A bad light file.
    let lfile = tmp.path().join("bad.lp");
    fs::write(&lfile, "2\na 0 0 1\n").unwrap();
    let o = relight(&["--lights", s(&lfile)]);
    assert_fails_naming(&o, "bad.lp", &out);
    let o = relight(&["--lights", "/no/such/lights.lp"]);
    assert_fails_naming(&o, "/no/such/lights.lp", &out);
    // Bad flag values.
    let o = relight(&["--light", "0,0,1", "--roughness-scale", "0"]);
    assert_fails_naming(&o, "--roughness-scale", &out);
    // A roughness map of another size than the albedos.
    write_npy_f32(&fit.join("alpha_t.npy"), &[12, 11], &[0.1; 132]).unwrap();
    let o = relight(&["--light", "0,0,1"]);
    assert_fails_naming(&o, "alpha_t.npy", &out);
    // Frames of another size than the fit.
    write_npy_f32(&fit.join("alpha_t.npy"), &[12, 12], &[0.1; 144]).unwrap();
    write_npy_f32(&fit.join("normals.npy"), &[12, 13, 3], &[0.0; 468]).unwrap();
    let o = relight(&["--light", "0,0,1"]);
    assert_fails_keeping_cache(&o, "normals.npy", &out);
    // A missing map, and a folder that is not a fit.
    fs::remove_file(fit.join("kd.npy")).unwrap();
    let o = relight(&["--light", "0,0,1"]);
    assert_fails_naming(&o, "kd.npy", &out);
    let o = symframe(&["relight", "/no/such/fit", "-o", s(&out), "--light", "0,0,1"]);
    assert_fails_naming(&o, "/no/such/fit", &out);
}

/// PSNR (dB) of the `relit_NNN.exr` of `dir` against the dataset's images of `lights`, over
/// every pixel of every image where both are defined (the fit leaves a few pixels NaN; a light
/// below the ground's horizon gives a black image, so a per-image PSNR is not defined).
fn relit_psnr(dir: &Path, data: &Path, lights: &[usize]) -> f64 {
    let exact = DecodeOptions {
        saturation: f32::INFINITY,
        ..DecodeOptions::default()
    };
    let (mut relit, mut truth) = (Vec::new(), Vec::new());
    for (k, &i) in lights.iter().enumerate() {
        let r = symframe_io::read_image(&dir.join(format!("relit_{k:03}.exr")), &exact);
        let t =
            symframe_io::read_image(&data.join("images").join(format!("img_{i:04}.exr")), &exact);
        relit.extend(r.unwrap().into_rgb());
        truth.extend(t.unwrap().into_rgb());
    }
    let both: Vec<bool> = relit
        .chunks_exact(3)
        .zip(truth.chunks_exact(3))
        .map(|(a, b)| a.iter().chain(b).all(|v| v.is_finite()))
        .collect();
    symframe::Relighter::image_psnr(&relit, &truth, Some(&both))
}

#[test]
fn cast_shadows_from_the_integrated_relief_raise_held_out_psnr_on_bumps() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n);
    let run = |args: &[&str]| {
        let o = symframe(args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    };
    let (n_lights, k) = (200, 20);
    run(&[
        "-q",
        "synth",
        "-o",
        s(&p("d")),
        "--shape",
        "bumps",
        "--size",
        "32",
        "--relief",
        "1.5",
        "--rig",
        "cone:200",
        "--model",
        "ward:kd=0.5,ks=0.2,ax=0.2,ay=0.2",
    ]);
    run(&["-q", "estimate", s(&p("d")), "-o", s(&p("est"))]);
    run(&[
        "-q",
        "fit",
        s(&p("d")),
        "--frames",
        s(&p("est")),
        "-o",
        s(&p("fit")),
        "--holdout",
        "20",
    ]);
    run(&[
        "-q",
        "integrate",
        s(&p("est")),
        "-o",
        s(&p("shape")),
        "--solver",
        "poisson",
    ]);
    let held = symframe::FitParams::holdout_lights(n_lights, k).unwrap();
    let all = symframe_io::open_dataset(&p("d")).unwrap().lights;
    let rows: Vec<String> = held
        .iter()
        .map(|&i| format!("{} {} {}", all[i].x, all[i].y, all[i].z))
        .collect();
    fs::write(p("held.txt"), rows.join("\n") + "\n").unwrap();
    let relight = |out: &str, extra: &[&str]| {
        run(&[
            &[
                "-q",
                "relight",
                s(&p("fit")),
                "-o",
                s(&p(out)),
                "--lights",
                s(&p("held.txt")),
            ],
            extra,
        ]
        .concat());
        relit_psnr(&p(out), &p("d"), &held)
    };
    let plain = relight("plain", &[]);
    let shadowed = relight(
        "shadowed",
        &["--shadows", "--depth", s(&p("shape/depth.npy"))],
    );
    println!(
        "bumps (32 px, relief 1.5, 200 lights, 20 held out): held-out relit PSNR {plain:.2} dB \
         without cast shadows, {shadowed:.2} dB with them"
    );
    assert!(shadowed > plain + 0.5, "{plain} -> {shadowed}");
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(p("shadowed/relight.json")).unwrap()).unwrap();
    assert!(report["shadows"].as_str().unwrap().ends_with("depth.npy"));
}

#[test]
fn gltf_fit_relight_and_export_reproduce_a_brushed_gltf_metal_at_any_exposure() {
    use symframe::brdf::GltfPbr;
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n);
    let truth = GltfPbr::new([0.9, 0.7, 0.5], 1.0, 0.35, 0.6);
    let flags = Truth {
        normals: true,
        tangents: true,
    };
    // Photographs three times brighter than unit lights: the exposure is chosen from them.
    let (scene, lp) = sphere_dataset(&p("data"), 24, 300, &truth, ImageFormat::Exr, 3.0, flags);
    let frames = true_frames(&p("frames"), &scene);
    let fit = p("fit");
    let o = fit_with(&lp, &frames, &fit, &["--model", "gltf", "--holdout", "10"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "base_color.npy",
        "metallic.npy",
        "roughness.npy",
        "anisotropy_strength.npy",
        "normals.npy",
        "tangents.npy",
        "base_color.png",
        "holdout_residual.npy",
    ] {
        assert!(fit.join(f).is_file(), "missing {f}");
    }
    assert!(!fit.join("kd.npy").exists());
    let report = report_of(&fit);
    assert_eq!(report["model"], "gltf");
    assert_eq!(report["exposure_chosen"], true);
    // A metal's scale is set by its brightest base colour (0.9 here): 3 x 0.9 / 1.
    let e = report["exposure"].as_f64().unwrap();
    assert!((e / 2.7 - 1.0).abs() < 0.02, "{e}");
    let psnr = report["fit"]["holdout_psnr_db"].as_f64().unwrap();
    assert!(psnr > 40.0, "{report}");
    // The parameters (with the base colour relative to the brightest channel).
    let (shape, base) = read_npy_f32(&fit.join("base_color.npy")).unwrap();
    assert_eq!(shape, vec![24, 24, 3]);
    let (_, metallic) = read_npy_f32(&fit.join("metallic.npy")).unwrap();
    let (_, rough) = read_npy_f32(&fit.join("roughness.npy")).unwrap();
    let (_, strength) = read_npy_f32(&fit.join("anisotropy_strength.npy")).unwrap();
    let centre = (12 * 24 + 12) as usize;
    assert!((base[centre * 3 + 1] as f64 / 0.7 * 0.9 - 1.0).abs() < 0.02);
    assert!(metallic[centre] > 0.97, "{}", metallic[centre]);
    assert!(
        (rough[centre] as f64 - 0.35).abs() < 0.01,
        "{}",
        rough[centre]
    );
    assert!(
        (strength[centre] as f64 - 0.6).abs() < 0.02,
        "{}",
        strength[centre]
    );

    // Relit under the held-out lights, the photographs come back (exposure included).
    let held: Vec<usize> = report["parameters"]["holdout"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let all = symframe_io::open_dataset(&lp).unwrap().lights;
    let mut args = vec![
        "relight".to_string(),
        s(&fit).into(),
        "-o".into(),
        s(&p("relit")).into(),
    ];
    for &i in &held {
        args.push("--light".into());
        args.push(format!("{},{},{}", all[i].x, all[i].y, all[i].z));
    }
    let o = symframe(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let relit = relit_psnr(&p("relit"), &p("data"), &held);
    assert!(relit > 40.0, "{relit}");
    // A glTF fit has no specular albedo to scale.
    let o = symframe(&[
        "relight",
        s(&fit),
        "-o",
        s(&p("bad")),
        "--light",
        "0,0,1",
        "--specular-scale",
        "2",
    ]);
    assert_fails_naming(&o, "specular scale", &p("bad"));

    // The export carries the fitted values and the light intensity.
    let gltf = p("out/asset.gltf");
    let o = symframe(&["export", "gltf", s(&fit), "-o", s(&gltf)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_str(&fs::read_to_string(&gltf).unwrap()).unwrap();
    let m = &doc["materials"][0];
    let li = m["extras"]["symframe"]["lightIntensity"].as_f64().unwrap();
    assert!((li - e).abs() < 1e-12);
    let linear = DecodeOptions {
        gamma: symframe_io::Gamma::Linear,
        saturation: f32::INFINITY,
        ..DecodeOptions::default()
    };
    let mr = symframe_io::read_image(&p("out/asset_metallicroughness.png"), &linear)
        .unwrap()
        .into_rgb();
    // Linear 8-bit, rounded: green roughness, blue metallic.
    assert!((mr[centre * 3 + 1] as f64 - rough[centre] as f64).abs() < 0.51 / 255.0);
    assert!((mr[centre * 3 + 2] as f64 - metallic[centre] as f64).abs() < 0.51 / 255.0);
}

#[test]
fn fit_refuses_bad_model_flags() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, _, lp) = dataset(&tmp.path().join("data"), 12, 60);
    let frames = true_frames(&tmp.path().join("frames"), &scene);
    let out = tmp.path().join("out");
    for (flag, value, needle) in [
        ("--model", "phong", "--model"),
        ("--exposure", "0", "--exposure"),
        ("--exposure", "bright", "--exposure"),
        ("--roughness-min", "0", "--roughness-min"),
        ("--roughness-min", "1.5", "--roughness-min"),
        ("--choice-radius", "many", "--choice-radius"),
    ] {
        let o = fit_with(&lp, &frames, &out, &[flag, value]);
        assert!(!o.status.success(), "{flag} {value}");
        assert!(
            stderr(&o).contains(needle),
            "{flag} {value}: {}",
            stderr(&o)
        );
        assert!(!out.exists(), "{flag} {value}");
    }
    // An explicit exposure is used as given and recorded.
    let o = fit_with(
        &lp,
        &frames,
        &out,
        &["--model", "gltf", "--exposure", "2.5"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report_of(&out);
    assert_eq!(
        (r["exposure"].as_f64(), r["exposure_chosen"].as_bool()),
        (Some(2.5), Some(false))
    );
    assert_eq!(r["parameters"]["model"], "gltf");
    assert!(
        r.get("evidence_tiles").is_none(),
        "a forced model chooses nothing"
    );
    // The automatic choice's neighbourhood is recorded, and its first pass is counted.
    let auto = tmp.path().join("auto");
    let o = fit_with(&lp, &frames, &auto, &["--choice-radius", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report_of(&auto);
    assert_eq!(r["parameters"]["model"], "auto");
    assert_eq!(r["parameters"]["choice_radius"], 1);
    assert_eq!(
        r["evidence_tiles"], r["tiles"],
        "one pass each over the same tiles"
    );
    assert!(!auto.join(".symframe-evidence-tiles").exists());
}

/// Runs `symframe fit LP --frames FRAMES -o OUT` with `extra` flags.
fn fit_with(lp: &Path, frames: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    symframe(&[&["fit", s(lp), "--frames", s(frames), "-o", s(out)], extra].concat())
}

/// The `fit.json` of a fit folder.
fn report_of(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap()
}
