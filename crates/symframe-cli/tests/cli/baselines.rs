//! End-to-end tests of `symframe estimate --method`: each method on small synthetic datasets
//! written as `.lp` files, the same outputs as the symmetry method, accuracy checked against
//! ground truth (directly and through `symframe eval`).

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{sphere_dataset, stderr, symframe, Truth};

use symframe::brdf::{parse_model, Brdf, Lambertian};
use symframe::render::Scene;
use symframe::{evaluate, Evaluation};
use symframe_io::{read_npy_f32, ImageFormat};

/// A float EXR sphere dataset of `brdf` under `n_lights` lights up to 130 degrees from the
/// view; returns the scene and the `.lp` path.
fn dataset(dir: &Path, brdf: &dyn Brdf, n_lights: usize) -> (Scene, PathBuf) {
    let truth = Truth {
        normals: true,
        tangents: false,
    };
    sphere_dataset(dir, 24, n_lights, brdf, ImageFormat::Exr, 1.0, truth)
}

/// Runs `estimate --method <method>` into `out`; checks the outputs and the report; returns the
/// evaluation of the normals against the scene.
fn estimate(lp: &Path, out: &Path, method: &str, scene: &Scene, n_lights: u64) -> Evaluation {
    let o = symframe(&[
        "estimate",
        lp.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--method",
        method,
    ]);
    assert!(o.status.success(), "{method}: {}", stderr(&o));
    for f in [
        "normals.npy",
        "tangents.npy",
        "confidence.npy",
        "anisotropy.npy",
        "normals.exr",
        "tangents.exr",
        "normals.png",
        "tangents.png",
        "confidence.png",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{method}: missing {f}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["method"], method);
    let (_, normals) = read_npy_f32(&out.join("normals.npy")).unwrap();
    let (_, tangents) = read_npy_f32(&out.join("tangents.npy")).unwrap();
    let (_, confidence) = read_npy_f32(&out.join("confidence.npy")).unwrap();
    if method != "symmetry" {
        // Every light is used; normals only; a goodness of fit in [0, 1].
        assert_eq!(report["lights"]["used"], n_lights, "{report}");
        assert_eq!(report["lights"]["dropped"], 0, "{report}");
        assert!(
            report["parameters"]["shadow_fraction"].is_number(),
            "{report}"
        );
        assert!(tangents.iter().all(|v| v.is_nan()));
        assert_eq!(report["pixels"]["with_tangent"], 0);
        assert!(confidence
            .iter()
            .all(|c| c.is_nan() || (0.0..=1.0).contains(c)));
    }
    // Every pixel with a normal carries the method's source code, every other one none. The
    // symmetry estimator's own are symmetry or, on this diffuse sphere, the Lambertian centre
    // of a diffuse slice and the fallbacks beyond the reach (codes 1-3).
    let codes: &[u8] = match method {
        "symmetry" => &[1, 2, 3],
        "max-reflectance" | "highlight-centroid" => &[3],
        _ => &[2],
    };
    let source: ndarray::Array2<u8> = ndarray_npy::read_npy(out.join("source.npy")).unwrap();
    for (&c, n) in source.iter().zip(normals.chunks_exact(3)) {
        if n[0].is_nan() {
            assert_eq!(c, 0, "{method}");
        } else {
            assert!(codes.contains(&c), "{method}: source {c}");
        }
    }
    let counted: u64 = codes
        .iter()
        .map(|&c| report["sources"][c as usize]["pixels"].as_u64().unwrap())
        .sum();
    assert_eq!(
        Some(counted),
        report["pixels"]["estimated"].as_u64(),
        "{report}"
    );
    let e = evaluate(
        &normals,
        &tangents,
        &scene.gt_normals(),
        None,
        Some(&scene.mask),
        60.0,
        None,
    );
    eprintln!(
        "{method}: mean {:.4} median {:.4} max {:.4} deg, coverage {:.3}",
        e.normal_error.mean, e.normal_error.median, e.normal_error.max, e.coverage
    );
    e
}

/// `symframe eval` on an estimate folder: its eval.json's normal figures.
fn eval_json(lp: &Path, out: &Path) -> serde_json::Value {
    let o = symframe(&["eval", lp.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&fs::read_to_string(out.join("eval.json")).unwrap()).unwrap()
}

#[test]
fn every_method_on_a_lambertian_sphere() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, lp) = dataset(
        &tmp.path().join("data"),
        &Lambertian::new([0.7, 0.6, 0.5]),
        300,
    );
    for (method, bound) in [
        ("symmetry", 1.0),
        ("woodham", 0.01),
        ("woodham-robust", 0.01),
    ] {
        let out = tmp.path().join(method);
        let e = estimate(&lp, &out, method, &scene, 300);
        assert!(e.normal_error.mean < bound, "{method}: {e:?}");
        assert!(e.coverage > 0.95, "{method}: {e:?}");
        // symframe eval agrees with the library's figures.
        let j = eval_json(&lp, &out);
        assert_eq!(j["method"], method);
        let mean = j["normal_error"]["mean"].as_f64().unwrap();
        assert!((mean - e.normal_error.mean).abs() < 1e-9, "{j}");
    }
    // The specularity method is wrong on a diffuse surface (half the normal's tilt).
    let out = tmp.path().join("max-reflectance");
    let e = estimate(&lp, &out, "max-reflectance", &scene, 300);
    assert!(e.normal_error.mean > 8.0, "{e:?}");
}

#[test]
fn max_reflectance_on_a_specular_sphere() {
    let tmp = tempfile::tempdir().unwrap();
    let brdf = parse_model("torrance-sparrow:kd=0,ks=1,sigma=0.1").unwrap();
    let (scene, lp) = dataset(&tmp.path().join("data"), brdf.as_ref(), 300);
    let out = tmp.path().join("out");
    let e = estimate(&lp, &out, "max-reflectance", &scene, 300);
    // 300 lights over the 130-degree cone are about 6 degrees apart in halfway space.
    assert!(e.normal_error.mean < 0.5, "{e:?}");
    assert!(e.coverage > 0.95, "{e:?}");
    // Lambertian photometric stereo is far off on it.
    let out = tmp.path().join("woodham");
    let w = estimate(&lp, &out, "woodham", &scene, 300);
    assert!(w.normal_error.mean > 5.0 * e.normal_error.mean, "{w:?}");
}

#[test]
fn an_unknown_method_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = symframe(&[
        "estimate",
        "whatever.lp",
        "-o",
        out.to_str().unwrap(),
        "--method",
        "magic",
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("woodham-robust") && err.contains("max-reflectance"),
        "{err}"
    );
    assert!(!out.exists());
}
