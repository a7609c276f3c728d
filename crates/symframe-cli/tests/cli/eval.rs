//! End-to-end tests of `symframe eval` on constructed maps with known errors: the estimate is
//! the ground truth rotated by known angles, so every figure of eval.json is known; and bad
//! input refused with a one-line error naming the file.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::{assert_one_line_error, stderr, symframe};

use glam::{DQuat, DVec3};
use symframe_io::{read_image, write_npy_f32, write_png8_rgb, DecodeOptions};

const W: usize = 8;
const H: usize = 6;

/// Ground truth on a W x H grid: normals tilted up to 45 degrees, except the bottom row at 70
/// degrees (outside the default 60-degree evaluation); tangents perpendicular to them.
fn truth() -> (Vec<DVec3>, Vec<DVec3>) {
    let mut n = Vec::new();
    let mut t = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let phi = (x as f64 * 45.0 + y as f64 * 10.0).to_radians();
            let tilt = if y == H - 1 {
                70f64
            } else {
                5.0 * (x + y) as f64
            }
            .to_radians();
            let normal = DVec3::new(tilt.sin() * phi.cos(), tilt.sin() * phi.sin(), tilt.cos());
            let tangent = DVec3::new(-phi.sin(), phi.cos(), 0.0);
            n.push(normal);
            t.push(tangent);
        }
    }
    (n, t)
}

fn flat(v: &[DVec3]) -> Vec<f32> {
    v.iter().flat_map(|d| d.as_vec3().to_array()).collect()
}

/// A dataset folder with gt normals and tangents and a mask excluding pixel (1, 0).
fn write_dataset(dir: &Path, n: &[DVec3], t: &[DVec3]) {
    fs::create_dir_all(dir).unwrap();
    write_npy_f32(&dir.join("gt_normals.npy"), &[H, W, 3], &flat(n)).unwrap();
    write_npy_f32(&dir.join("gt_tangents.npy"), &[H, W, 3], &flat(t)).unwrap();
    let mask: Vec<f32> = (0..W * H)
        .flat_map(|p| [if p == 1 { 0.0 } else { 1.0 }; 3])
        .collect();
    write_png8_rgb(&dir.join("mask.png"), W, H, &mask, false).unwrap();
    fs::write(dir.join("lights.lp"), "0\n").unwrap();
}

/// An estimate folder: normals off by 3 degrees on even pixels and 7 on odd ones (the frame
/// turned about the true tangent), pixel 2 without an estimate; tangents 20 degrees off about
/// the new normal, except pixel 3 where t is the turned binormal (a swap).
fn write_estimate(dir: &Path, n: &[DVec3], t: &[DVec3]) {
    fs::create_dir_all(dir).unwrap();
    let mut en = Vec::new();
    let mut et = Vec::new();
    for p in 0..W * H {
        // Rotating the whole frame about an axis in the tangent plane keeps t and n orthogonal;
        // then the tangent is turned about the new normal.
        let axis = t[p];
        let q = DQuat::from_axis_angle(axis, if p % 2 == 0 { 3f64 } else { 7f64 }.to_radians());
        let nn = q * n[p];
        let tt = if p == 3 {
            nn.cross(t[p]).normalize()
        } else {
            DQuat::from_axis_angle(nn, 20f64.to_radians()) * t[p]
        };
        if p == 2 {
            en.push(DVec3::NAN);
            et.push(DVec3::NAN);
        } else {
            en.push(nn);
            et.push(tt);
        }
    }
    write_npy_f32(&dir.join("normals.npy"), &[H, W, 3], &flat(&en)).unwrap();
    write_npy_f32(&dir.join("tangents.npy"), &[H, W, 3], &flat(&et)).unwrap();
    fs::write(dir.join("report.json"), "{\"method\": \"woodham\"}\n").unwrap();
}

fn setup(tmp: &Path) -> (PathBuf, PathBuf) {
    let (n, t) = truth();
    let data = tmp.join("data");
    let est = tmp.join("est");
    write_dataset(&data, &n, &t);
    write_estimate(&est, &n, &t);
    (data, est)
}

fn close(a: &serde_json::Value, b: f64, tol: f64) -> bool {
    a.as_f64().is_some_and(|a| (a - b).abs() < tol)
}

#[test]
fn known_errors_come_out_in_eval_json() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, est) = setup(tmp.path());
    let o = symframe(&[
        "eval",
        data.join("lights.lp").to_str().unwrap(),
        est.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("normal") && stdout.contains("tangent axis"),
        "{stdout}"
    );
    let j: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(est.join("eval.json")).unwrap()).unwrap();
    // 48 pixels: the mask drops pixel 1, the 70-degree bottom row (8) is outside 60 degrees.
    assert_eq!(j["pixels"], 39, "{j}");
    assert_eq!(j["method"], "woodham");
    // Pixel 2 has no estimate: 38 of 39. Errors: 3 degrees at even pixels, 7 at odd.
    assert!(close(&j["coverage"], 38.0 / 39.0, 1e-12), "{j}");
    let ne = &j["normal_error"];
    assert_eq!(ne["count"], 38);
    // Evaluated pixels: rows 0-4 minus pixels 1 and 2 -> even: 19 (row 0: 0,4,6; rows 1-4: 4 each),
    // odd: 19 (row 0: 3,5,7; rows 1-4: 4 each).
    assert!(
        close(&ne["mean"], (19.0 * 3.0 + 19.0 * 7.0) / 38.0, 1e-3),
        "{ne}"
    );
    assert!(close(&ne["max"], 7.0, 1e-3), "{ne}");
    assert!(close(&ne["p90"], 7.0, 1e-3), "{ne}");
    // Tangents: 20 degrees off except the swapped pixel: 90 off, and with t/b free as far as
    // the frame was turned (7 degrees: pixel 3 is odd).
    let te = &j["tangent_error"];
    assert_eq!(te["count"], 38);
    assert!(
        close(&te["mean"], (37.0 * 20.0 + 90.0) / 38.0, 1e-3),
        "{te}"
    );
    assert!(close(&te["median"], 20.0, 1e-3), "{te}");
    let free = &j["tangent_error_swap_free"];
    assert!(
        close(&free["mean"], (37.0 * 20.0 + 7.0) / 38.0, 1e-3),
        "{free}"
    );
    assert!(close(&j["swapped_share"], 1.0 / 38.0, 1e-12), "{j}");
    assert!(close(&j["tangent_coverage"], 1.0, 1e-12), "{j}");
    // The pictures: the map enlarged (8x6 by 32) beside a colour bar.
    for f in ["normal_error.png", "tangent_error.png"] {
        let img = read_image(&est.join(f), &DecodeOptions::default()).unwrap();
        assert!(img.width > W * 32 && img.height > H * 32, "{f}");
    }
}

#[test]
fn max_angle_and_scale_flags() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, est) = setup(tmp.path());
    let o = symframe(&[
        "eval",
        data.to_str().unwrap(),
        est.to_str().unwrap(),
        "--max-angle",
        "80",
        "--scale-max",
        "10",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(est.join("eval.json")).unwrap()).unwrap();
    assert_eq!(j["pixels"], 47, "{j}");
    assert_eq!(j["max_normal_angle_deg"], 80.0);
    assert_eq!(j["normal_scale_max_deg"], 10.0);
    // Without gt tangents: no tangent picture, tangent figures empty.
    fs::remove_file(data.join("gt_tangents.npy")).unwrap();
    fs::remove_file(est.join("tangent_error.png")).unwrap();
    let o = symframe(&["eval", data.to_str().unwrap(), est.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!est.join("tangent_error.png").exists());
    let j: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(est.join("eval.json")).unwrap()).unwrap();
    assert_eq!(j["tangent_error"]["count"], 0);
    assert!(j["tangent_scale_max_deg"].is_null());
}

fn assert_fails_naming(o: &Output, needle: &str, est: &Path) {
    assert_one_line_error(o, needle);
    assert!(!est.join("eval.json").exists(), "no eval.json on failure");
    assert!(!est.join("normal_error.png").exists());
}

#[test]
fn bad_input_is_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, est) = setup(tmp.path());
    let run = |d: &Path, e: &Path| symframe(&["eval", d.to_str().unwrap(), e.to_str().unwrap()]);

    // Missing ground truth.
    fs::rename(data.join("gt_normals.npy"), data.join("gt.bak")).unwrap();
    assert_fails_naming(&run(&data, &est), "gt_normals.npy", &est);
    fs::rename(data.join("gt.bak"), data.join("gt_normals.npy")).unwrap();

    // An estimate of another size.
    let small = tmp.path().join("small");
    fs::create_dir_all(&small).unwrap();
    write_npy_f32(
        &small.join("normals.npy"),
        &[H, W - 1, 3],
        &vec![0.0; H * (W - 1) * 3],
    )
    .unwrap();
    assert_fails_naming(&run(&data, &small), "normals.npy", &small);
    assert!(stderr(&run(&data, &small)).contains("gt_normals.npy"));

    // Ground truth that is not an H x W x 3 array.
    let bad = tmp.path().join("bad");
    fs::create_dir_all(&bad).unwrap();
    write_npy_f32(&bad.join("gt_normals.npy"), &[H, W], &[0.0; H * W]).unwrap();
    assert_fails_naming(&run(&bad, &est), "gt_normals.npy", &est);

    // gt tangents of another size, a mask of another size.
    write_npy_f32(&data.join("gt_tangents.npy"), &[2, 2, 3], &[0.0; 12]).unwrap();
    assert_fails_naming(&run(&data, &est), "gt_tangents.npy", &est);
    fs::remove_file(data.join("gt_tangents.npy")).unwrap();
    write_png8_rgb(&data.join("mask.png"), 3, 3, &[1.0; 27], false).unwrap();
    assert_fails_naming(&run(&data, &est), "mask.png", &est);
    fs::remove_file(data.join("mask.png")).unwrap();

    // No such folders; a missing estimate map; a corrupt one.
    let nowhere = tmp.path().join("nowhere");
    assert_fails_naming(&run(&nowhere, &est), "nowhere", &est);
    assert_fails_naming(&run(&data, &nowhere), "nowhere", &nowhere);
    let empty = tmp.path().join("empty");
    fs::create_dir_all(&empty).unwrap();
    assert_fails_naming(&run(&data, &empty), "normals.npy", &empty);
    fs::write(empty.join("normals.npy"), b"\x93NUMPY garbage").unwrap();
    assert_fails_naming(&run(&data, &empty), "normals.npy", &empty);

    // A bad flag.
    let o = symframe(&[
        "eval",
        data.to_str().unwrap(),
        est.to_str().unwrap(),
        "--max-angle",
        "0",
    ]);
    assert_fails_naming(&o, "--max-angle", &est);
}
