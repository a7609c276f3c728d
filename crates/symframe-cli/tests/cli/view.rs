//! End-to-end tests of `symframe view`: a fit folder (written here, no fit run) in, one HTML
//! page out with the maps embedded; the estimate's maps found through `fit.json` or
//! `--frames`; bad folders refused with a one-line error naming the file. The page itself is
//! rendered in a browser by `.ci/viewer-test.sh`.

use std::fs;
use std::path::Path;

use crate::common::{assert_one_line_error, ok, s, stderr, symframe};
use symframe::render::{Scene, TangentField};
use symframe_io::{write_npy_f32, write_npy_u8};

const SIZE: usize = 12;

/// A fit folder of a `SIZE` sphere (one Ward material, the scene's frames) in `dir/fit`, with
/// a `fit.json` naming the estimate folder `est` as given (relative, as a fit run from `dir`
/// records it), and that estimate folder with confidence, anisotropy and source maps.
pub fn fit_folder(dir: &Path) -> Scene {
    let scene = Scene::sphere(SIZE, TangentField::Circular);
    let (fit, est) = (dir.join("fit"), dir.join("est"));
    fs::create_dir_all(&fit).unwrap();
    fs::create_dir_all(&est).unwrap();
    let n = SIZE * SIZE;
    let inside = |p: usize, v: f32| if scene.mask[p] { v } else { f32::NAN };
    let rgb = |v: [f32; 3]| -> Vec<f32> { (0..n).flat_map(|p| v.map(|c| inside(p, c))).collect() };
    let grey = |v: f32| -> Vec<f32> { (0..n).map(|p| inside(p, v)).collect() };
    let hw3 = [SIZE, SIZE, 3];
    write_npy_f32(&fit.join("kd.npy"), &hw3, &rgb([0.4, 0.3, 0.2])).unwrap();
    write_npy_f32(&fit.join("ks.npy"), &hw3, &rgb([0.3, 0.45, 0.6])).unwrap();
    write_npy_f32(&fit.join("alpha_t.npy"), &[SIZE, SIZE], &grey(0.35)).unwrap();
    write_npy_f32(&fit.join("alpha_b.npy"), &[SIZE, SIZE], &grey(0.1)).unwrap();
    write_npy_f32(&fit.join("normals.npy"), &hw3, &scene.gt_normals()).unwrap();
    write_npy_f32(&fit.join("tangents.npy"), &hw3, &scene.gt_tangents()).unwrap();
    fs::write(fit.join("fit.json"), r#"{"frames": "est"}"#).unwrap();
    write_npy_f32(&est.join("confidence.npy"), &[SIZE, SIZE], &grey(0.9)).unwrap();
    let aniso: Vec<f32> = (0..n).map(|p| inside(p, p as f32 / n as f32)).collect();
    write_npy_f32(&est.join("anisotropy.npy"), &[SIZE, SIZE], &aniso).unwrap();
    let source: Vec<u8> = scene.mask.iter().map(|&m| u8::from(m)).collect();
    write_npy_u8(&est.join("source.npy"), &[SIZE, SIZE], &source).unwrap();
    scene
}

/// The JSON data block of a viewer page.
fn page_data(page: &str) -> serde_json::Value {
    let open = r#"<script id="symframe-data" type="application/json">"#;
    let start = page.find(open).expect("data block") + open.len();
    let len = page[start..].find("</script>").unwrap();
    serde_json::from_str(&page[start..start + len]).unwrap()
}

#[test]
fn writes_one_page_with_every_map() {
    let dir = tempfile::tempdir().unwrap();
    fit_folder(dir.path());
    // Run from the folder the fit was "run" from, so fit.json's relative `est` is found.
    let o = std::process::Command::new(crate::common::bin())
        .current_dir(dir.path())
        .args(["view", "fit"])
        .output()
        .unwrap();
    ok(&o);
    assert!(stderr(&o)
        .contains("views: relit, normal, tangent, kd, ks, confidence, anisotropy, source"));
    let page = fs::read_to_string(dir.path().join("fit/viewer.html")).unwrap();
    // Self-contained: no URL of anything to load.
    for needle in ["http://", "https://", "src=", "href="] {
        assert!(!page.contains(needle), "the page refers to {needle}");
    }
    assert!(page.contains("#version 300 es") && page.contains("symframeReady"));
    let data = page_data(&page);
    assert_eq!(data["width"], SIZE);
    assert_eq!(data["height"], SIZE);
    assert_eq!(data["sources"][1], "symmetry");
    for t in ["geom", "frame", "kd", "ks", "est"] {
        let b64 = data["textures"][t].as_str().unwrap();
        // A zlib stream starts with 0x78 (base64 "e").
        assert!(b64.len() > 20 && b64.starts_with('e'), "{t}: {b64:.20}");
    }
}

#[test]
fn frames_flag_and_missing_estimate() {
    let dir = tempfile::tempdir().unwrap();
    fit_folder(dir.path());
    let fit = dir.path().join("fit");
    // fit.json names `est` relative to the fit folder's parent: found from anywhere.
    let out = dir.path().join("a/b/v.html");
    ok(&symframe(&["view", s(&fit), "-o", s(&out)]));
    assert_eq!(
        page_data(&fs::read_to_string(&out).unwrap())["views"][7],
        "source"
    );
    // Without the estimate: a warning, and the views of the fit only.
    fs::rename(dir.path().join("est"), dir.path().join("moved")).unwrap();
    let o = symframe(&["view", s(&fit), "-o", s(&out)]);
    ok(&o);
    assert!(stderr(&o).contains("warning:") && stderr(&o).contains("--frames"));
    let views = page_data(&fs::read_to_string(&out).unwrap())["views"].clone();
    assert_eq!(views.as_array().unwrap().len(), 5, "{views}");
    // ... and with --frames.
    let moved = dir.path().join("moved");
    ok(&symframe(&[
        "view",
        s(&fit),
        "-o",
        s(&out),
        "--frames",
        s(&moved),
    ]));
    assert_eq!(
        page_data(&fs::read_to_string(&out).unwrap())["views"]
            .as_array()
            .unwrap()
            .len(),
        8
    );
    let o = symframe(&["view", s(&fit), "--frames", s(&dir.path().join("nope"))]);
    assert_one_line_error(&o, "nope");
    // An estimate folder without any of the maps: a warning naming it.
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    let o = symframe(&["view", s(&fit), "-o", s(&out), "--frames", s(&empty)]);
    ok(&o);
    assert!(stderr(&o).contains("warning:") && stderr(&o).contains("empty"));
    let data = page_data(&fs::read_to_string(&out).unwrap());
    assert_eq!(data["views"].as_array().unwrap().len(), 5);
    assert!(data["textures"]["est"].is_null());
}

#[test]
fn bad_folders_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    fit_folder(dir.path());
    let fit = dir.path().join("fit");
    let out = dir.path().join("v.html");
    // An estimate map of another size.
    write_npy_f32(&dir.path().join("est/confidence.npy"), &[3, 4], &[0.0; 12]).unwrap();
    let o = symframe(&[
        "view",
        s(&fit),
        "-o",
        s(&out),
        "--frames",
        s(&dir.path().join("est")),
    ]);
    assert_one_line_error(&o, "confidence.npy");
    assert!(!out.exists());
    // A fit map missing.
    fs::remove_file(fit.join("alpha_b.npy")).unwrap();
    let o = symframe(&["view", s(&fit), "-o", s(&out)]);
    assert_one_line_error(&o, "alpha_b.npy");
    assert!(!out.exists());
    // Not a fit folder at all.
    let o = symframe(&["view", s(dir.path()), "-o", s(&out)]);
    assert_one_line_error(&o, "kd.npy");
    assert!(!out.exists());
    // Nothing half-written beside the output.
    for e in fs::read_dir(dir.path()).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.contains(".partial"), "{name}");
    }
}

#[test]
fn a_new_fit_removes_the_old_fits_page() {
    use crate::common::ward_sphere;
    let dir = tempfile::tempdir().unwrap();
    let lp = ward_sphere(&dir.path().join("data"), 16, 60);
    let (est, fit) = (dir.path().join("est"), dir.path().join("fit"));
    ok(&symframe(&["estimate", s(&lp), "-o", s(&est)]));
    ok(&symframe(&[
        "fit",
        s(&lp),
        "--frames",
        s(&est),
        "-o",
        s(&fit),
        "--model",
        "ward",
    ]));
    ok(&symframe(&["view", s(&fit)]));
    assert!(fit.join("viewer.html").is_file());
    // The page shows the maps it was written from: a new fit into the folder removes it.
    ok(&symframe(&[
        "fit",
        s(&lp),
        "--frames",
        s(&est),
        "-o",
        s(&fit),
    ]));
    // The default model's maps replace the Ward fit's.
    assert!(fit.join("base_color.npy").is_file() && !fit.join("viewer.html").exists());
    assert!(!fit.join("kd.npy").exists());
}
