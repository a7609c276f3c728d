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

/// `--from-samples`: the view `samples`, the capture's slices and the rig's triangles in the
/// page (its relighting is checked in a browser against `symframe relight --from-samples` by
/// `.ci/viewer-test.sh`).
#[test]
fn from_samples_adds_the_capture_s_own_relighting() {
    let dir = tempfile::tempdir().unwrap();
    let scene = fit_folder(dir.path());
    let lights = symframe::uniform_cone_lights(40, 65.0);
    let brdf = symframe::brdf::Ward::new([0.4, 0.3, 0.2], [0.3, 0.45, 0.6], 0.35, 0.1);
    let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
    let lp = symframe_io::write_lp_dataset(
        &dir.path().join("data"),
        &lights,
        &images,
        SIZE,
        SIZE,
        symframe_io::ImageFormat::Exr,
        None,
        None,
        Some(&scene.mask),
    )
    .unwrap();
    let (fit, out) = (dir.path().join("fit"), dir.path().join("v.html"));
    let o = symframe(&["view", s(&fit), "-o", s(&out), "--from-samples", s(&lp)]);
    ok(&o);
    assert!(stderr(&o).contains(", samples)"), "{}", stderr(&o));
    let data = page_data(&fs::read_to_string(&out).unwrap());
    assert_eq!(data["views"].as_array().unwrap().last().unwrap(), "samples");
    assert_eq!(data["samples"]["lights"], 40);
    let triangles = data["samples"]["triangles"].as_array().unwrap();
    assert!(triangles.len() > 40, "{}", triangles.len());
    assert!(data["samples"]["layers"].as_str().unwrap().starts_with('e'));
    // Without it, no samples in the page.
    ok(&symframe(&["view", s(&fit), "-o", s(&out)]));
    assert!(page_data(&fs::read_to_string(&out).unwrap())["samples"].is_null());
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
    // Neither a fit nor an estimate folder: what was expected.
    let o = symframe(&["view", s(dir.path()), "-o", s(&out)]);
    assert_one_line_error(&o, "no maps to show");
    assert!(stderr(&o).contains("normals.npy") && stderr(&o).contains("base_color.npy"));
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
    // The default (automatic) fit's maps replace the Ward fit's: both models' maps and the
    // choice per pixel.
    assert!(fit.join("base_color.npy").is_file() && !fit.join("viewer.html").exists());
    assert!(fit.join("model.npy").is_file() && fit.join("kd.npy").is_file());
}

/// An estimate folder `dir/name` of a `size` x `size` sphere as `symframe estimate` writes it
/// (normals, tangents, confidence, anisotropy, source).
fn estimate_folder(dir: &Path, name: &str, size: usize) -> std::path::PathBuf {
    let scene = Scene::sphere(size, TangentField::Circular);
    let est = dir.join(name);
    fs::create_dir_all(&est).unwrap();
    let n = size * size;
    let hw3 = [size, size, 3];
    write_npy_f32(&est.join("normals.npy"), &hw3, &scene.gt_normals()).unwrap();
    write_npy_f32(&est.join("tangents.npy"), &hw3, &scene.gt_tangents()).unwrap();
    let grey: Vec<f32> = (0..n)
        .map(|p| if scene.mask[p] { 0.8 } else { f32::NAN })
        .collect();
    write_npy_f32(&est.join("confidence.npy"), &[size, size], &grey).unwrap();
    write_npy_f32(&est.join("anisotropy.npy"), &[size, size], &grey).unwrap();
    let source: Vec<u8> = scene.mask.iter().map(|&m| 3 * u8::from(m)).collect();
    write_npy_u8(&est.join("source.npy"), &[size, size], &source).unwrap();
    est
}

/// The tile scripts of a pyramid folder by level: `(level, file names)`, sorted.
fn tiles_by_level(dir: &Path) -> Vec<(usize, Vec<String>)> {
    let mut levels: Vec<(usize, Vec<String>)> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_dir())
        .map(|e| {
            let mut names: Vec<String> = fs::read_dir(e.path())
                .unwrap()
                .map(|t| t.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            (e.file_name().to_string_lossy().parse().unwrap(), names)
        })
        .collect();
    levels.sort();
    levels
}

#[test]
fn an_estimate_folder_opens() {
    let dir = tempfile::tempdir().unwrap();
    let est = estimate_folder(dir.path(), "est", SIZE);
    let o = symframe(&["view", s(&est)]);
    ok(&o);
    assert!(
        stderr(&o).contains("views: relit, normal, tangent, confidence, anisotropy, source"),
        "{}",
        stderr(&o)
    );
    let page = fs::read_to_string(est.join("viewer.html")).unwrap();
    let data = page_data(&page);
    assert_eq!(data["model"], "estimate");
    assert_eq!(
        (data["width"].clone(), data["height"].clone()),
        (SIZE.into(), SIZE.into())
    );
    // Frames and the estimate's maps; no fitted material.
    for t in ["geom", "frame", "est"] {
        assert!(
            data["textures"][t].as_str().unwrap().starts_with('e'),
            "{t}"
        );
    }
    assert!(data["textures"]["kd"].is_null() && data["textures"]["ks"].is_null());
    assert!(data["pyramid"].is_null());
    assert!(!est.join("viewer_files").exists());
    // Without the optional maps: the views of what is there.
    for f in [
        "tangents.npy",
        "confidence.npy",
        "anisotropy.npy",
        "source.npy",
    ] {
        fs::remove_file(est.join(f)).unwrap();
    }
    ok(&symframe(&["view", s(&est)]));
    let data = page_data(&fs::read_to_string(est.join("viewer.html")).unwrap());
    assert_eq!(data["views"], serde_json::json!(["relit", "normal"]));
    assert!(data["textures"]["est"].is_null());
}

#[test]
fn a_large_map_is_written_as_a_pyramid() {
    let dir = tempfile::tempdir().unwrap();
    let est = estimate_folder(dir.path(), "est", 40);
    let out = dir.path().join("big.html");
    let args = |extra: &[&str]| -> Vec<String> {
        ["view", s(&est), "-o", s(&out)]
            .iter()
            .chain(extra)
            .map(|a| a.to_string())
            .collect()
    };
    let run = |extra: &[&str]| {
        let a = args(extra);
        symframe(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let o = run(&["--pyramid-above", "32", "--tile-size", "8"]);
    ok(&o);
    assert!(
        stderr(&o).contains("4 levels of 8 px tiles, 38 tiles"),
        "{}",
        stderr(&o)
    );
    // 40 px: levels of 40, 20, 10 and 5 px; the last (one tile) in the page, the others in
    // 8 px tiles beside it: 5 x 5, 3 x 3 and 2 x 2.
    let tiles = dir.path().join("big_files");
    let levels = tiles_by_level(&tiles);
    let counts: Vec<(usize, usize)> = levels.iter().map(|(k, n)| (*k, n.len())).collect();
    assert_eq!(counts, [(0, 25), (1, 9), (2, 4)]);
    assert!(levels[1].1.contains(&"2_2.js".to_string()));
    // A tile is a script handing its textures to the page: level 1, tile (2, 0) is the last
    // column, 20 - 16 = 4 texels wide.
    let script = fs::read_to_string(tiles.join("1/2_0.js")).unwrap();
    assert!(
        script.starts_with("symframeTile(1,2,0,4,8,{\"geom\":\"e"),
        "{script:.40}"
    );
    assert!(script.contains("\"frame\":\"e") && script.contains("\"est\":\"e"));
    assert!(!script.contains("\"kd\""));
    let marker = fs::read_to_string(tiles.join("pyramid.json")).unwrap();
    assert!(marker.contains("\"levels\":4"), "{marker}");
    let data = page_data(&fs::read_to_string(&out).unwrap());
    assert_eq!(
        data["pyramid"],
        serde_json::json!({"dir": "big_files", "tile": 8, "levels": 4})
    );
    // The page itself holds the 5 x 5 level only (compared below with the 40 x 40 maps).
    let coarse = data["textures"]["geom"].as_str().unwrap().len();

    // Again with larger tiles: the folder is replaced, nothing of the old one is left.
    ok(&run(&["--pyramid-above", "32", "--tile-size", "16"]));
    let counts: Vec<(usize, usize)> = tiles_by_level(&tiles)
        .iter()
        .map(|(k, n)| (*k, n.len()))
        .collect();
    assert_eq!(counts, [(0, 9), (1, 4)]);
    // Below the threshold the page holds the maps, and its old tile folder goes.
    ok(&run(&[]));
    assert!(!tiles.exists());
    let whole = page_data(&fs::read_to_string(&out).unwrap());
    assert!(whole["pyramid"].is_null());
    let full = whole["textures"]["geom"].as_str().unwrap().len();
    assert!(coarse * 8 < full, "{coarse} {full}");
    // Nothing half-written or set aside is left beside the page.
    for e in fs::read_dir(dir.path()).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "{name}");
    }
}

#[test]
fn a_tile_folder_symframe_did_not_write_is_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let est = estimate_folder(dir.path(), "est", 20);
    // A folder of the user's where the tiles would go.
    let theirs = dir.path().join("page_files");
    fs::create_dir(&theirs).unwrap();
    fs::write(theirs.join("notes.txt"), "mine").unwrap();
    let out = dir.path().join("page.html");
    let o = symframe(&["view", s(&est), "-o", s(&out), "--pyramid-above", "0"]);
    assert_one_line_error(&o, "page_files");
    assert_eq!(
        fs::read_to_string(theirs.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!out.exists());
    // Even one that looks like ours but holds something else.
    ok(&symframe(&[
        "view",
        s(&est),
        "-o",
        s(&dir.path().join("x.html")),
        "--pyramid-above",
        "8",
        "--tile-size",
        "8",
    ]));
    let ours = dir.path().join("x_files");
    fs::write(ours.join("0/extra.txt"), "mine").unwrap();
    let o = symframe(&[
        "view",
        s(&est),
        "-o",
        s(&dir.path().join("x.html")),
        "--pyramid-above",
        "8",
        "--tile-size",
        "8",
    ]);
    assert_one_line_error(&o, "x_files");
    assert!(ours.join("0/extra.txt").is_file());
    // Without a pyramid, a folder of the user's is left alone.
    ok(&symframe(&["view", s(&est), "-o", s(&out)]));
    assert!(theirs.join("notes.txt").is_file());
    // A link is refused, and what it points to left alone.
    #[cfg(unix)]
    {
        let link = dir.path().join("linked_files");
        std::os::unix::fs::symlink(&theirs, &link).unwrap();
        let o = symframe(&[
            "view",
            s(&est),
            "-o",
            s(&dir.path().join("linked.html")),
            "--pyramid-above",
            "0",
        ]);
        assert_one_line_error(&o, "linked_files");
        assert_eq!(fs::read_dir(&theirs).unwrap().count(), 1);
    }
}

#[test]
fn bad_estimate_folders_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let est = estimate_folder(dir.path(), "est", SIZE);
    let out = dir.path().join("v.html");
    // A map of another size.
    write_npy_f32(&est.join("anisotropy.npy"), &[3, 4], &[0.0; 12]).unwrap();
    let o = symframe(&["view", s(&est), "-o", s(&out)]);
    assert_one_line_error(&o, "anisotropy.npy");
    fs::remove_file(est.join("anisotropy.npy")).unwrap();
    // Source codes of the wrong type.
    write_npy_f32(&est.join("source.npy"), &[SIZE, SIZE], &[0.0; SIZE * SIZE]).unwrap();
    let o = symframe(&["view", s(&est), "-o", s(&out)]);
    assert_one_line_error(&o, "source.npy");
    fs::remove_file(est.join("source.npy")).unwrap();
    // Normals cut short.
    let normals = est.join("normals.npy");
    let bytes = fs::read(&normals).unwrap();
    fs::write(&normals, &bytes[..bytes.len() / 2]).unwrap();
    let o = symframe(&["view", s(&est), "-o", s(&out)]);
    assert_one_line_error(&o, "normals.npy");
    // Not a .npy file at all.
    fs::write(&normals, "hello").unwrap();
    let o = symframe(&["view", s(&est), "-o", s(&out)]);
    assert_one_line_error(&o, "normals.npy");
    assert!(!out.exists());
    // Tiles too small.
    fs::write(&normals, &bytes).unwrap();
    let o = symframe(&["view", s(&est), "-o", s(&out), "--tile-size", "2"]);
    assert_one_line_error(&o, "tile size 2");
    assert!(!out.exists());
}
