//! End-to-end tests of `symframe integrate`: a rendered sphere's *estimated* normals integrate
//! to the sphere within 1% of its radius (RMS within 60 degrees of the view) with both solvers;
//! rendered bumps integrate to their heights; the outputs are complete and well formed; bad
//! input fails with a one-line error naming the file.

use std::fs;
use std::path::Path;

use crate::common::{assert_fails_naming, s, symframe};
use symframe::render::{BumpParams, Scene, TangentField};
use symframe_io::read_npy_f32;

fn run_ok(args: &[&str]) -> String {
    let o = symframe(args);
    assert!(
        o.status.success(),
        "symframe {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// RMS of `depth - truth` after removing the mean difference, over the pixels where `keep`
/// holds and both are finite; and how many pixels that was.
fn rms_after_offset(depth: &[f32], truth: &[f64], keep: impl Fn(usize) -> bool) -> (f64, usize) {
    let idx: Vec<usize> = (0..truth.len())
        .filter(|&i| keep(i) && depth[i].is_finite() && truth[i].is_finite())
        .collect();
    let mean = idx.iter().map(|&i| depth[i] as f64 - truth[i]).sum::<f64>() / idx.len() as f64;
    let ss: f64 = idx
        .iter()
        .map(|&i| (depth[i] as f64 - truth[i] - mean).powi(2))
        .sum();
    ((ss / idx.len() as f64).sqrt(), idx.len())
}

/// Parses a binary PLY header: (vertices, faces, header length).
fn ply_counts(path: &Path) -> (usize, usize, usize) {
    let bytes = fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("PLY header")
        + 11;
    let header = String::from_utf8_lossy(&bytes[..end]).into_owned();
    assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
    let count = |what: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {what} ")))
            .unwrap()
            .parse()
            .unwrap()
    };
    let (v, f) = (count("vertex"), count("face"));
    assert_eq!(bytes.len(), end + v * 24 + f * 13, "PLY body size");
    (v, f, end)
}

#[test]
fn an_estimated_sphere_integrates_within_1_percent_of_its_radius() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, est) = (tmp.path().join("data"), tmp.path().join("est"));
    let size = 96;
    run_ok(&[
        "synth",
        "-o",
        s(&data),
        "--size",
        &size.to_string(),
        "--rig",
        "cone:300",
    ]);
    run_ok(&["estimate", s(&data), "-o", s(&est)]);
    // The true heights: a sphere of radius size/2 pixels.
    let r = size as f64 / 2.0;
    let scene = Scene::sphere(size, TangentField::Circular);
    let truth: Vec<f64> = scene
        .normals_in_camera
        .iter()
        .zip(&scene.mask)
        .map(|(n, &m)| if m { r * n.z } else { f64::NAN })
        .collect();
    let within_60 = |i: usize| scene.mask[i] && scene.normals_in_camera[i].z >= 0.5;
    let in_view = (0..size * size).filter(|&i| within_60(i)).count();
    for solver in ["poisson", "bilateral"] {
        let out = tmp.path().join(solver);
        let stdout = run_ok(&["integrate", s(&est), "-o", s(&out), "--solver", solver]);
        assert!(stdout.contains(solver), "{stdout}");
        for f in [
            "depth.npy",
            "depth.exr",
            "depth.png",
            "mesh.ply",
            "integrate.json",
        ] {
            assert!(out.join(f).is_file(), "{solver}: {f} missing");
        }
        let (shape, depth) = read_npy_f32(&out.join("depth.npy")).unwrap();
        assert_eq!(shape, vec![size, size]);
        let (rms, n) = rms_after_offset(&depth, &truth, within_60);
        eprintln!(
            "{solver}: sphere of radius {r} px from estimated normals: height RMS {rms:.3} px \
             = {:.2}% of the radius over {n} of {in_view} pixels within 60 degrees",
            100.0 * rms / r
        );
        assert!(
            n as f64 > 0.95 * in_view as f64,
            "{solver}: {n} of {in_view}"
        );
        assert!(rms < 0.01 * r, "{solver}: RMS {rms} px");
        // Outside the sphere: NaN.
        for (i, &m) in scene.mask.iter().enumerate() {
            if !m {
                assert!(depth[i].is_nan());
            }
        }
        let report: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(out.join("integrate.json")).unwrap()).unwrap();
        assert_eq!(report["solver"], solver);
        assert_eq!(report["confidence_weighted"], true);
        let (v, f, _) = ply_counts(&out.join("mesh.ply"));
        assert_eq!(v as u64, report["vertices"].as_u64().unwrap());
        assert_eq!(f as u64, report["triangles"].as_u64().unwrap());
        assert_eq!(v, depth.iter().filter(|d| d.is_finite()).count());
        assert!(f > v, "{f} triangles for {v} vertices");
    }
}

#[test]
fn rendered_bumps_integrate_to_their_heights() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, est, out) = (
        tmp.path().join("data"),
        tmp.path().join("est"),
        tmp.path().join("out"),
    );
    let size = 64;
    run_ok(&[
        "synth",
        "-o",
        s(&data),
        "--shape",
        "bumps",
        "--model",
        "lambertian",
        "--size",
        &size.to_string(),
        "--rig",
        "cone:200",
    ]);
    run_ok(&["estimate", s(&data), "-o", s(&est)]);
    // The true normals as an estimate folder: what integration alone reaches.
    let gt = tmp.path().join("gt");
    fs::create_dir(&gt).unwrap();
    fs::copy(data.join("gt_normals.npy"), gt.join("normals.npy")).unwrap();
    let bumps = BumpParams::default().bumps(size);
    let scene = Scene::from_bumps(size, &bumps, TangentField::Circular);
    let truth = scene.heights.clone().unwrap();
    let relief = truth.iter().cloned().fold(f64::MIN, f64::max)
        - truth.iter().cloned().fold(f64::MAX, f64::min);
    // (normals, solver, RMS bound in pixels)
    for (input, solver, bound) in [
        (&gt, "poisson", 0.01 * relief),
        (&gt, "bilateral", 0.01 * relief),
        (&est, "poisson", 0.12 * relief),
        (&est, "bilateral", 0.12 * relief),
    ] {
        run_ok(&["integrate", s(input), "-o", s(&out), "--solver", solver]);
        let (_, depth) = read_npy_f32(&out.join("depth.npy")).unwrap();
        let (rms, n) = rms_after_offset(&depth, &truth, |_| true);
        let which = input.file_name().unwrap().to_string_lossy();
        eprintln!(
            "bumps, {which} normals, {solver}: relief {relief:.2} px, height RMS {rms:.3} px \
             ({:.1}% of the relief) over {n} pixels",
            100.0 * rms / relief
        );
        assert_eq!(n, size * size);
        assert!(
            rms < bound,
            "{which} {solver}: RMS {rms} of relief {relief}"
        );
    }
}

#[test]
fn bad_input_fails_with_one_line_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let est = tmp.path().join("est");
    fs::create_dir(&est).unwrap();
    let out = tmp.path().join("out");
    let o = symframe(&["integrate", s(&est), "-o", s(&out)]);
    assert_fails_naming(&o, "normals.npy", &out);
    fs::write(est.join("normals.npy"), b"not an npy").unwrap();
    let o = symframe(&["integrate", s(&est), "-o", s(&out)]);
    assert_fails_naming(&o, "normals.npy", &out);
    symframe_io::write_npy_f32(&est.join("normals.npy"), &[2, 2], &[0.0; 4]).unwrap();
    let o = symframe(&["integrate", s(&est), "-o", s(&out)]);
    assert_fails_naming(&o, "normals.npy", &out);
    symframe_io::write_npy_f32(&est.join("normals.npy"), &[2, 2, 3], &[f32::NAN; 12]).unwrap();
    let o = symframe(&["integrate", s(&est), "-o", s(&out)]);
    assert_fails_naming(&o, "no valid normal", &out);
    let n = [0.0f32, 0.0, 1.0].repeat(4);
    symframe_io::write_npy_f32(&est.join("normals.npy"), &[2, 2, 3], &n).unwrap();
    symframe_io::write_npy_f32(&est.join("confidence.npy"), &[3, 2], &[1.0; 6]).unwrap();
    let o = symframe(&["integrate", s(&est), "-o", s(&out)]);
    assert_fails_naming(&o, "confidence.npy", &out);
    let o = symframe(&["integrate", s(&est), "-o", s(&out), "--max-jump", "0"]);
    assert_fails_naming(&o, "--max-jump", &out);
    // A flat 2 x 2 map: a flat mesh of two triangles, and --no-confidence ignores the bad map.
    run_ok(&["integrate", s(&est), "-o", s(&out), "--no-confidence"]);
    let (v, f, _) = ply_counts(&out.join("mesh.ply"));
    assert_eq!((v, f), (4, 2));
    let (_, d) = read_npy_f32(&out.join("depth.npy")).unwrap();
    assert!(d.iter().all(|&z| z.abs() < 1e-6), "{d:?}");
}
