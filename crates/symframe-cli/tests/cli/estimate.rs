//! End-to-end tests of `symframe estimate` and `symframe demo`: real files in, maps out, and
//! bad input refused with a one-line error naming the file, leaving no output folder behind.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{
    assert_fails_keeping_cache, assert_fails_naming, estimate, ok, report, report_warnings, s,
    sphere_dataset, stderr, symframe, ward_sphere, Truth,
};

use glam::DVec3;
use symframe::brdf::Ward;
use symframe::render::{Scene, TangentField};
use symframe::{evaluate, uniform_cone_lights};
use symframe_io::{read_npy_f32, ImageFormat};

/// A small anisotropic Ward sphere dataset in `.lp` form with ground truth, exposure 0.5
/// (keeps 16-bit data below saturation); returns the scene and the .lp path.
fn small_dataset(
    dir: &Path,
    size: usize,
    n_lights: usize,
    format: ImageFormat,
) -> (Scene, PathBuf) {
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let truth = Truth {
        normals: true,
        tangents: true,
    };
    sphere_dataset(dir, size, n_lights, &brdf, format, 0.5, truth)
}

#[test]
fn estimate_on_an_lp_dataset_writes_every_output_and_is_accurate() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, lp) = small_dataset(&tmp.path().join("data"), 28, 600, ImageFormat::Png16);
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "normals.npy",
        "tangents.npy",
        "confidence.npy",
        "anisotropy.npy",
        "tangent_confidence.npy",
        "normals.exr",
        "tangents.exr",
        "normals.png",
        "tangents.png",
        "tangents_gltf.png",
        "confidence.png",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    // tangent_confidence.npy: in [0, 1] where there is a tangent, 0 where a normal has none,
    // NaN where there is no normal; most of the tangents of this brushed sphere stand out.
    let (shape, tc) = read_npy_f32(&out.join("tangent_confidence.npy")).unwrap();
    assert_eq!(shape, vec![28, 28]);
    let (_, normals) = read_npy_f32(&out.join("normals.npy")).unwrap();
    let (_, tangents) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let (mut with, mut sure) = (0, 0);
    for (p, c) in tc.iter().enumerate() {
        match (normals[3 * p].is_finite(), tangents[3 * p].is_finite()) {
            (false, _) => assert!(c.is_nan(), "pixel {p}: {c} without a normal"),
            (true, false) => assert_eq!(*c, 0.0, "pixel {p}: no tangent"),
            (true, true) => {
                assert!((0.0..=1.0).contains(c), "pixel {p}: {c}");
                with += 1;
                sure += (*c >= 0.5) as usize;
            }
        }
    }
    assert!(
        with > 100 && sure * 10 >= with * 8,
        "{sure} of {with} tangents >= 0.5"
    );
    // tangents_gltf.png: red/green the tangent's image-plane direction as (d + 1) / 2, blue
    // the anisotropy, at every pixel with a tangent.
    let (_, tan) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let (_, aniso) = read_npy_f32(&out.join("anisotropy.npy")).unwrap();
    let exact = symframe_io::DecodeOptions {
        gamma: symframe_io::Gamma::Linear,
        saturation: f32::INFINITY,
        ..Default::default()
    };
    let png = symframe_io::read_image(&out.join("tangents_gltf.png"), &exact).unwrap();
    let mut checked = 0;
    for (p, t) in tan.chunks_exact(3).enumerate() {
        if !t[0].is_finite() {
            continue;
        }
        let l = t[0].hypot(t[1]);
        let want = [
            (t[0] / l + 1.0) / 2.0,
            (t[1] / l + 1.0) / 2.0,
            aniso[p].clamp(0.0, 1.0),
        ];
        for (got, want) in png.data[3 * p..3 * p + 3].iter().zip(want) {
            assert!((got - want).abs() <= 0.5 / 255.0 + 1e-6, "pixel {p}");
        }
        checked += 1;
    }
    assert!(checked > 200, "{checked} pixels with a tangent");
    let (shape, normals) = read_npy_f32(&out.join("normals.npy")).unwrap();
    assert_eq!(shape, vec![28, 28, 3]);
    let (_, tangents) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let e = scene.evaluate(&normals, &tangents);
    assert!(e.normal_error.mean < 1.0, "{e:?}");
    assert!(e.tangent_error_swap_free.mean < 2.0, "{e:?}");
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["lights"]["input"], 600);
    assert_eq!(report["lights"]["used"], 600);
    assert_eq!(report["width"], 28);
    let estimated = report["pixels"]["estimated"].as_u64().unwrap();
    assert!(estimated > 400, "{report}");
    // Outside the sphere (mask.png beside the .lp): NaN.
    assert!(normals[0].is_nan());
    // The source map: a source wherever a normal was estimated (the lobe fit on most pixels),
    // none elsewhere; the report's legend counts the same pixels.
    let source: ndarray::Array2<u8> = ndarray_npy::read_npy(out.join("source.npy")).unwrap();
    assert_eq!(source.dim(), (28, 28));
    for (&code, n) in source.iter().zip(normals.chunks_exact(3)) {
        if n[0].is_nan() {
            assert_eq!(code, 0);
        } else {
            assert!((1..=4).contains(&code), "source {code}");
        }
    }
    assert_eq!(report["sources"][1]["name"], "symmetry");
    assert_eq!(report["sources"][4]["name"], "lobe");
    let lobe = report["sources"][4]["pixels"].as_u64().unwrap();
    let counted: u64 = (1..=4)
        .map(|c| report["sources"][c]["pixels"].as_u64().unwrap())
        .sum();
    assert_eq!(counted, estimated);
    // Most pixels of this Ward sphere are explained by the lobe fit (the rest: the symmetry
    // search, fallbacks at the rim).
    assert!(lobe * 4 >= estimated * 3, "{report}");
    assert!(out.join("source.png").is_file());
    assert_eq!(report["parameters"]["interpolation"], "fast");

    // The reference path on the same data: recorded in the report, and the default fast path
    // agrees with it.
    let reference = tmp.path().join("reference");
    let o = estimate(&lp, &reference, &["--reference"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(reference.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["parameters"]["interpolation"], "exact");
    let (_, exact) = read_npy_f32(&reference.join("normals.npy")).unwrap();
    let e = evaluate(
        &normals,
        &tangents,
        &exact,
        None,
        Some(&scene.mask),
        60.0,
        None,
    );
    assert!(e.normal_error.median < 0.1, "fast vs reference {e:?}");
}

#[test]
fn estimate_on_a_diligent_folder_divides_by_light_intensities() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("obj");
    fs::create_dir_all(&dir).unwrap();
    let size = 24;
    let scene = Scene::sphere(size, TangentField::Axial(DVec3::Y));
    let lights = uniform_cone_lights(400, 65.0);
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let (mut names, mut dirs, mut ints) = (String::new(), String::new(), String::new());
    for (i, &l) in lights.iter().enumerate() {
        // Each light has its own colour; the images carry it and the tool must divide it out.
        let k = [0.5 + 0.001 * i as f32, 0.8, 1.2 - 0.0005 * i as f32];
        let img: Vec<f32> = scene
            .render(&brdf, l)
            .chunks_exact(3)
            .flat_map(|p| [p[0] * k[0], p[1] * k[1], p[2] * k[2]])
            .collect();
        let name = format!("{i:03}.exr");
        symframe_io::write_exr_rgb(&dir.join(&name), size, size, &img).unwrap();
        names += &format!("{name}\n");
        dirs += &format!("{} {} {}\n", l.x, l.y, l.z);
        ints += &format!("{} {} {}\n", k[0], k[1], k[2]);
    }
    fs::write(dir.join("filenames.txt"), names).unwrap();
    fs::write(dir.join("light_directions.txt"), dirs).unwrap();
    fs::write(dir.join("light_intensities.txt"), ints).unwrap();
    let mask: Vec<f32> = scene
        .mask
        .iter()
        .flat_map(|&m| [m as u8 as f32; 3])
        .collect();
    symframe_io::write_png8_rgb(&dir.join("mask.png"), size, size, &mask, false).unwrap();
    let out = tmp.path().join("out");
    // An axial field puts the wide highlight in the plane of tilt: the compensated measure
    // avoids the paper form's bias there (see the accuracy tests).
    let o = estimate(&dir, &out, &["--cosine", "compensated"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, normals) = read_npy_f32(&out.join("normals.npy")).unwrap();
    let (_, tangents) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let e = scene.evaluate(&normals, &tangents);
    assert!(e.normal_error.mean < 1.0, "{e:?}");
    assert!(e.coverage > 0.9, "{e:?}");
}

/// A valid small `.lp` dataset to break in the bad-input tests.
fn breakable(tmp: &Path) -> PathBuf {
    small_dataset(&tmp.join("data"), 12, 60, ImageFormat::Exr).1
}

#[test]
fn mismatched_image_sizes_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let img = lp.parent().unwrap().join("images/img_0007.exr");
    symframe_io::write_exr_rgb(&img, 10, 12, &vec![0.1; 10 * 12 * 3]).unwrap();
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "img_0007.exr", &out);
    // Found from the headers before anything is decoded: an undecodable image before it
    // (whose header says nothing) is not reached.
    fs::write(
        lp.parent().unwrap().join("images/img_0002.exr"),
        b"not an image",
    )
    .unwrap();
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "img_0007.exr", &out);
}

#[test]
fn missing_and_unreadable_images_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let images = lp.parent().unwrap().join("images");
    fs::write(images.join("img_0003.exr"), b"this is not an exr file").unwrap();
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "img_0003.exr", &out);
    fs::remove_file(images.join("img_0003.exr")).unwrap();
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "img_0003.exr", &out);
}

#[test]
fn bad_light_files_are_refused_with_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let text = fs::read_to_string(&lp).unwrap();
    let out = tmp.path().join("out");
    // Wrong count.
    let wrong_count = text.replacen("60\n", "61\n", 1);
    fs::write(&lp, &wrong_count).unwrap();
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "lights.lp", &out);
    // A non-finite light on the third entry (line 4).
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let first = lines[3].split_whitespace().next().unwrap().to_string();
    lines[3] = format!("{first} nan 0 1");
    fs::write(&lp, lines.join("\n") + "\n").unwrap();
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "lights.lp:4", &out);
}

#[test]
fn all_lights_outside_the_cone_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let out = tmp.path().join("out");
    // A 10-degree cone: the rig's lights reach 130 degrees, but a handful stay inside, so
    // flip every light behind the object instead.
    let text = fs::read_to_string(&lp).unwrap();
    let flipped: Vec<String> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            if f.len() == 4 {
                let z: f64 = f[3].parse().unwrap();
                format!("{} {} {} {}", f[0], f[1], f[2], -z.abs() - 0.9)
            } else {
                l.to_string()
            }
        })
        .collect();
    fs::write(&lp, flipped.join("\n") + "\n").unwrap();
    let o = estimate(&lp, &out, &[]);
    assert_fails_naming(&o, "lights.lp", &out);
    let err = stderr(&o);
    assert!(err.contains("outside the light cone"), "{err}");
    // The command line names its flag; the library's message does not.
    assert!(err.contains("(--theta-d-max sets the cone)"), "{err}");
}

#[test]
fn empty_and_wrong_size_masks_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let out = tmp.path().join("out");
    let empty = tmp.path().join("empty.png");
    symframe_io::write_png8_rgb(&empty, 12, 12, &vec![0.0; 12 * 12 * 3], false).unwrap();
    let o = estimate(&lp, &out, &["--mask", empty.to_str().unwrap()]);
    assert_fails_keeping_cache(&o, "empty.png", &out);
    assert!(stderr(&o).contains("empty"), "{}", stderr(&o));
    let small = tmp.path().join("small.png");
    symframe_io::write_png8_rgb(&small, 5, 5, &vec![1.0; 5 * 5 * 3], false).unwrap();
    let o = estimate(&lp, &out, &["--mask", small.to_str().unwrap()]);
    assert_fails_keeping_cache(&o, "small.png", &out);
}

#[test]
fn a_light_error_lowers_the_confidence_and_barely_moves_the_normals() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, lp) = small_dataset(&tmp.path().join("data"), 20, 300, ImageFormat::Png16);
    let (exact, off) = (tmp.path().join("exact"), tmp.path().join("off"));
    ok(&estimate(&lp, &exact, &[]));
    ok(&estimate(&lp, &off, &["--light-error", "2"]));
    // Recorded beside the noise estimated from the images, which it does not replace.
    let noise = &report(&off)["parameters"]["noise"];
    assert_eq!(noise["light_error_deg"], 2.0, "{noise}");
    assert_eq!(
        noise["quantisation"],
        report(&exact)["parameters"]["noise"]["quantisation"]
    );
    let read = |dir: &Path, name: &str| read_npy_f32(&dir.join(name)).unwrap().1;
    // The lobe's acceptance reads the light error (a lobe may answer where the lights' error
    // explains what it leaves), so a normal may move, but by little.
    let (n0, n1) = (read(&exact, "normals.npy"), read(&off, "normals.npy"));
    for (a, b) in n0.chunks_exact(3).zip(n1.chunks_exact(3)) {
        assert_eq!(a[0].is_nan(), b[0].is_nan());
        if a[0].is_finite() {
            let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
            assert!(dot.min(1.0).acos().to_degrees() < 1.0, "{a:?} {b:?}");
        }
    }
    let (c0, c1) = (read(&exact, "confidence.npy"), read(&off, "confidence.npy"));
    let mean = |c: &[f32]| {
        let v: Vec<f64> = c
            .iter()
            .filter(|v| v.is_finite())
            .map(|&v| v as f64)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    // NaN where nothing was estimated, in both.
    assert!(c0.iter().zip(&c1).all(|(a, b)| a.is_nan() == b.is_nan()));
    assert!(mean(&c1) < mean(&c0), "{} {}", mean(&c1), mean(&c0));
}

#[test]
fn bad_flags_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = breakable(tmp.path());
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &["--theta-d-max", "120"]);
    assert_fails_naming(&o, "--theta-d-max", &out);
    let o = estimate(&lp, &out, &["--light-error=-1"]);
    assert_fails_naming(&o, "--light-error", &out);
    let o = estimate(Path::new("/no/such/dataset.lp"), &out, &[]);
    assert_fails_naming(&o, "/no/such/dataset.lp", &out);
}

#[test]
fn demo_runs_end_to_end_and_reports_small_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let o = symframe(&[
        "demo",
        "-o",
        out.to_str().unwrap(),
        "--size",
        "24",
        "--lights",
        "500",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("normals.png"), "{stdout}");
    assert!(out.join("estimate/normals.png").is_file());
    // Section 5.1: the Ward fit, a relit and an edited picture.
    assert!(stdout.contains("relit/relit_000.png"), "{stdout}");
    assert!(stdout.contains("relit-edited/relit_000.png"), "{stdout}");
    assert!(out.join("relit/relit_000.png").is_file());
    assert!(out.join("relit-edited/relit_000.png").is_file());
    assert!(out.join("fit/fit.json").is_file());
    assert!(stdout.contains("fit/viewer.html"), "{stdout}");
    assert!(out.join("fit/viewer.html").is_file());
    let eval: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("estimate/eval.json")).unwrap()).unwrap();
    let mean = eval["normal_error"]["mean"].as_f64().unwrap();
    assert!(mean < 1.5, "{eval}");
}

/// An 8-bit sRGB capture whose highlights clip: `report.json` records the capture's noise
/// model (quantisation, clip level, shot noise), and the clipped samples, read as censored at
/// the clip level, keep the brushed metal's tangents.
#[test]
fn a_clipped_8_bit_capture_records_its_noise_model_and_keeps_its_tangents() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    ok(&symframe(&[
        "synth",
        "-o",
        s(&cap),
        "--size",
        "24",
        "--rig",
        "cone:300",
        "--model",
        "ggx:kd=0.02,f0=0.91,ax=0.3,ay=0.08",
        "--format",
        "png8",
        "--exposure",
        "1.0",
        "--noise",
        "shot:4000",
        "-q",
    ]));
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cap.join("scene.json")).unwrap()).unwrap();
    assert!(scene["clipped_share"].as_f64().unwrap() > 0.005, "{scene}");
    let out = tmp.path().join("est");
    ok(&symframe(&[
        "estimate",
        s(&cap.join("lights.lp")),
        "-o",
        s(&out),
        "-q",
    ]));
    let noise = &report(&out)["parameters"]["noise"];
    assert_eq!(noise["quantisation"]["kind"], "srgb", "{noise}");
    assert_eq!(noise["quantisation"]["bits"], 8, "{noise}");
    let clip = noise["clip_level"].as_f64().unwrap();
    assert!((clip - 0.9911).abs() < 1e-3, "{noise}");
    assert!(noise["shot"].as_f64().unwrap() > 0.0, "{noise}");
    let o = symframe(&["eval", s(&cap), s(&out), "-q"]);
    ok(&o);
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    // Measured figures: docs/method.md, "What the tests measured".
    assert!(e["normal_error"]["mean"].as_f64().unwrap() < 0.3, "{e}");
    assert!(e["tangent_coverage"].as_f64().unwrap() > 0.95, "{e}");
}

#[test]
fn lights_read_in_a_reflected_convention_are_warned_about() {
    // The same sphere with its light file as written and with the y column negated (rows
    // counted down): each pixel is consistent either way, the map as a whole is not.
    let tmp = tempfile::tempdir().unwrap();
    let lp = ward_sphere(&tmp.path().join("data"), 32, 150);
    let text = fs::read_to_string(&lp).unwrap();
    let flipped: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, line)| {
            let f: Vec<&str> = line.split_whitespace().collect();
            if i == 0 || f.len() < 4 {
                return line.to_string();
            }
            let y: f64 = f[f.len() - 2].parse().unwrap();
            let mut f: Vec<String> = f.iter().map(|s| s.to_string()).collect();
            let k = f.len() - 2;
            f[k] = format!("{}", -y);
            f.join(" ")
        })
        .collect();
    let lp_flipped = lp.with_file_name("flipped.lp");
    fs::write(&lp_flipped, flipped.join("\n") + "\n").unwrap();
    let (good, bad) = (tmp.path().join("good"), tmp.path().join("bad"));
    let o = estimate(&lp, &good, &[]);
    ok(&o);
    assert!(!stderr(&o).contains("convention"), "{}", stderr(&o));
    assert!(report_warnings(&good)
        .iter()
        .all(|w| !w.contains("convention")));
    let o = estimate(&lp_flipped, &bad, &[]);
    ok(&o);
    let needle = "(x, y, z) -> (x, -y, z)";
    assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    assert!(
        report_warnings(&bad).iter().any(|w| w.contains(needle)),
        "{:?}",
        report_warnings(&bad)
    );
}
