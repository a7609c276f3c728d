//! Hostile jobs: commands pointed at folders they did not write, forged shard manifests,
//! circles that do not fit the image, exports that fail half-way or would replace their own
//! inputs, and `--quiet` on every subcommand.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use crate::common::{
    assert_one_line_error, ok, run_measuring_rss, run_with_timeout, s, stderr, symframe,
    ward_sphere,
};

/// `demo -o DIR` writes `DIR/dataset`, `DIR/estimate`, `DIR/fit`, `DIR/relit*` and
/// `DIR/region.png`: a non-empty one of them that an earlier demo did not write is refused
/// (a user's `DIR/dataset/lights.lp` is not replaced), unless `--force`; a folder the demo
/// wrote is written again.
#[test]
fn demo_refuses_folders_it_did_not_write() {
    let tmp = tempfile::tempdir().unwrap();
    let small = ["--size", "16", "--lights", "16", "--quiet"];
    let demo = |dir: &Path, extra: &[&str]| {
        symframe(&[&["demo", "-o", s(dir)], &small[..], extra].concat())
    };
    // A user's dataset folder.
    let dir = tmp.path().join("a");
    fs::create_dir_all(dir.join("dataset")).unwrap();
    fs::write(dir.join("dataset/lights.lp"), "1\nmine.png 0 0 1\n").unwrap();
    let o = demo(&dir, &[]);
    assert_one_line_error(&o, "dataset");
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
    assert_eq!(
        fs::read_to_string(dir.join("dataset/lights.lp")).unwrap(),
        "1\nmine.png 0 0 1\n"
    );
    assert!(!dir.join("estimate").exists() && !dir.join("region.png").exists());
    // A user's estimate folder, and a user's region.png.
    let dir = tmp.path().join("b");
    fs::create_dir_all(dir.join("estimate")).unwrap();
    fs::write(dir.join("estimate/notes.txt"), "mine").unwrap();
    assert_one_line_error(&demo(&dir, &[]), "estimate");
    assert!(!dir.join("dataset").exists());
    let dir = tmp.path().join("c");
    fs::create_dir_all(&dir).unwrap();
    fs::write(dir.join("region.png"), "mine").unwrap();
    assert_one_line_error(&demo(&dir, &[]), "region.png");
    assert_eq!(fs::read_to_string(dir.join("region.png")).unwrap(), "mine");
    // --force writes anyway.
    ok(&demo(&tmp.path().join("a"), &["--force"]));
    assert!(fs::read_to_string(tmp.path().join("a/dataset/lights.lp"))
        .unwrap()
        .starts_with("16\n"));
    // A fresh folder, then the same folder again: the demo's own.
    let dir = tmp.path().join("d");
    ok(&demo(&dir, &[]));
    ok(&demo(&dir, &[]));
    assert!(dir.join("estimate/normals.npy").is_file());
}

/// A forged `shard.json` of a few bytes declaring a huge image (65536 x 2048 pixels in
/// one-pixel tiles, or one tile of all of it beside a tiny tile file) is refused before
/// anything the size of the declared image is allocated: the merge fails with a one-line
/// error and its peak memory stays under 600 MB.
#[test]
#[cfg(target_os = "linux")]
fn merge_refuses_a_forged_manifest_before_allocating_its_size() {
    let tmp = tempfile::tempdir().unwrap();
    let forge = |name: &str, tile_size: usize, tiles: &[usize]| {
        let dir = tmp.path().join(name);
        fs::create_dir_all(dir.join(".symframe-tiles")).unwrap();
        let (w, h) = (65536usize, 2048usize);
        let n = w.div_ceil(tile_size) * h.div_ceil(tile_size);
        let m = serde_json::json!({
            "format": "symframe-shard", "version": 1, "job": "00000000deadbeef",
            "shard": 1, "of": 1, "width": w, "height": h, "tile_size": tile_size,
            "n_tiles": n, "tiles": tiles, "report": {},
        });
        fs::write(dir.join("shard.json"), m.to_string()).unwrap();
        for &t in tiles {
            fs::write(
                dir.join(format!(".symframe-tiles/tile-{t:06}.bin")),
                [0u8; 88],
            )
            .unwrap();
        }
        assert!(fs::metadata(dir.join("shard.json")).unwrap().len() < 4096);
        dir
    };
    let cases = [
        (forge("pixels", 1, &[0, 1, 2]), "missing tiles 3, 4, 5"),
        (forge("one_tile", 65536, &[0]), "tile-000000.bin"),
    ];
    for (shard, needle) in cases {
        let out = tmp.path().join("merged");
        let (o, kib) = run_measuring_rss(&["merge", s(&shard), "-o", s(&out)]);
        assert_one_line_error(&o, needle);
        assert!(!out.exists());
        assert!(
            kib < 600 * 1024,
            "merge of {shard:?} peaked at {} MB",
            kib / 1024
        );
    }
}

/// `--sphere` and `--matte-sphere` circles are checked against the image before anything is
/// computed with them: a radius beyond the image's diagonal (1e12 would run without end), a
/// centre outside the image, a sphere mostly outside the frame are one-line errors naming the
/// circle and the image size.
#[test]
fn calibrate_refuses_circles_that_do_not_fit_the_image() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    crate::common::chrome_sphere_capture(&data, true);
    let images = data.join("images");
    let lp = tmp.path().join("cal.lp");
    // The image is 96 x 32 (object, chrome and matte sphere side by side).
    let good = "48,16,12";
    for (flag, circle) in [
        ("--sphere", "8,8,1e12"),
        ("--sphere", "-40,16,10"),
        ("--sphere", "48,100,10"),
        ("--sphere", "0,0,20"),
        ("--sphere", "8,8,120"),
        ("--matte-sphere", "8,8,1e12"),
        ("--matte-sphere", "200,16,10"),
    ] {
        let mut args = vec!["calibrate", s(&images), "-o", s(&lp)];
        if flag == "--matte-sphere" {
            args.extend(["--sphere", good]);
        }
        args.extend([flag, circle]);
        let o = run_with_timeout(&args, 60);
        assert_one_line_error(&o, "96x32");
        let e = stderr(&o);
        assert!(e.contains(flag), "{flag} {circle}: {e}");
        assert!(!lp.exists());
    }
}

/// Every entry directly in `dir`: its name and a hash of its bytes (`None` for a folder).
fn snapshot(dir: &Path) -> BTreeMap<String, Option<u64>> {
    use std::hash::{Hash, Hasher};
    fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            let hash = p.is_file().then(|| {
                let mut h = std::collections::hash_map::DefaultHasher::new();
                fs::read(&p).unwrap().hash(&mut h);
                h.finish()
            });
            (name, hash)
        })
        .collect()
}

/// A failed `export gltf` leaves the earlier asset as it was (no new textures beside the old
/// `.gltf`) and no `.symframe-export-*` folder; a successful one replaces the whole asset.
#[test]
fn failed_export_keeps_the_old_asset_and_leaves_no_staging_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let est_a = tmp.path().join("est_a");
    let est_b = tmp.path().join("est_b");
    ok(&crate::common::estimate(
        &ward_sphere(&tmp.path().join("a"), 16, 40),
        &est_a,
        &["--quiet"],
    ));
    ok(&crate::common::estimate(
        &ward_sphere(&tmp.path().join("b"), 20, 40),
        &est_b,
        &["--quiet"],
    ));
    let asset = tmp.path().join("asset");
    let gltf = asset.join("x.gltf");
    ok(&symframe(&["export", "gltf", s(&est_a), "-o", s(&gltf)]));
    // A folder where the new export's anisotropy texture goes.
    let tex = asset.join("x_anisotropy.png");
    fs::remove_file(&tex).unwrap();
    fs::create_dir(&tex).unwrap();
    fs::write(tex.join("keep"), "mine").unwrap();
    let before = snapshot(&asset);
    let o = symframe(&["export", "gltf", s(&est_b), "-o", s(&gltf)]);
    assert_one_line_error(&o, "x_anisotropy.png");
    assert_eq!(
        snapshot(&asset),
        before,
        "the old asset must be kept as it was"
    );
    assert_eq!(fs::read_to_string(tex.join("keep")).unwrap(), "mine");
    // The same for a .glb: the old one kept when the export fails (a folder at the .glb).
    let glb = asset.join("y.glb");
    fs::create_dir(&glb).unwrap();
    let o = symframe(&["export", "gltf", s(&est_b), "-o", s(&glb)]);
    assert_one_line_error(&o, "y.glb");
    fs::remove_dir(&glb).unwrap();
    assert_eq!(snapshot(&asset), before);
    // Once the way is clear the new asset replaces the old one as a whole.
    fs::remove_dir_all(&tex).unwrap();
    ok(&symframe(&["export", "gltf", s(&est_b), "-o", s(&gltf)]));
    let after = snapshot(&asset);
    // (The quad's buffer and document are those of any square image.)
    for name in ["x_basecolor.png", "x_metallicroughness.png", "x_normal.png"] {
        assert_ne!(
            after.get(name),
            before.get(name),
            "{name} should be the new one"
        );
    }
    let doc: serde_json::Value = serde_json::from_str(&fs::read_to_string(&gltf).unwrap()).unwrap();
    for img in doc["images"].as_array().unwrap() {
        assert!(asset.join(img["uri"].as_str().unwrap()).is_file());
    }
    assert!(after.keys().all(|n| !n.starts_with(".symframe-export")));
}

/// `export gltf` refuses an output that would replace one of its own inputs: a `.bin` that is
/// the `--depth` file it reads, a texture that is a link to one of the maps it reads.
#[test]
fn export_refuses_to_replace_its_own_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let est = tmp.path().join("est");
    ok(&crate::common::estimate(
        &ward_sphere(&tmp.path().join("a"), 16, 40),
        &est,
        &["--quiet"],
    ));
    let shape = tmp.path().join("shape");
    ok(&symframe(&[
        "integrate",
        s(&est),
        "-o",
        s(&shape),
        "--quiet",
    ]));
    // The height map copied to where the asset's buffer goes.
    let asset = tmp.path().join("asset");
    fs::create_dir_all(&asset).unwrap();
    let depth = asset.join("m.bin");
    fs::copy(shape.join("depth.npy"), &depth).unwrap();
    let depth_bytes = fs::read(&depth).unwrap();
    let o = symframe(&[
        "export",
        "gltf",
        s(&est),
        "--mesh",
        "--depth",
        s(&depth),
        "-o",
        s(&asset.join("m.gltf")),
    ]);
    assert_one_line_error(&o, "m.bin");
    assert!(stderr(&o).contains("input"), "{}", stderr(&o));
    assert_eq!(fs::read(&depth).unwrap(), depth_bytes);
    assert!(!asset.join("m.gltf").exists());
    // A texture name that is a link to the estimate's normals.
    #[cfg(unix)]
    {
        let normals = fs::read(est.join("normals.npy")).unwrap();
        std::os::unix::fs::symlink(est.join("normals.npy"), asset.join("q_normal.png")).unwrap();
        let o = symframe(&["export", "gltf", s(&est), "-o", s(&asset.join("q.gltf"))]);
        assert_one_line_error(&o, "normals.npy");
        assert_eq!(fs::read(est.join("normals.npy")).unwrap(), normals);
        assert!(!asset.join("q.gltf").exists());
    }
}

/// `--quiet` leaves nothing on stdout or stderr of any subcommand run on good inputs (only
/// errors and warnings are printed with it, and these inputs give none).
#[test]
fn quiet_silences_every_subcommand() {
    let tmp = tempfile::tempdir().unwrap();
    let t = |p: &str| tmp.path().join(p).to_str().unwrap().to_string();
    let data = t("data");
    let lp = format!("{data}/lights.lp");
    let cap = t("cap");
    // Each subcommand, after the ones whose outputs it reads.
    let runs: Vec<Vec<String>> = [
        vec!["synth", "-o", &data, "--size", "24", "--rig", "cone:60"],
        vec!["estimate", &lp, "-o", &t("est")],
        vec![
            "estimate",
            &lp,
            "-o",
            &t("s1"),
            "--tiles",
            "1/2",
            "--tile-size",
            "8",
        ],
        vec![
            "estimate",
            &lp,
            "-o",
            &t("s2"),
            "--tiles",
            "2/2",
            "--tile-size",
            "8",
        ],
        vec!["merge", &t("s1"), &t("s2"), "-o", &t("merged")],
        vec!["fit", &lp, "--frames", &t("est"), "-o", &t("fit")],
        vec![
            "relight",
            &t("fit"),
            "--light",
            "0.3,0.2,1",
            "-o",
            &t("relit"),
        ],
        vec!["view", &t("fit")],
        vec!["eval", &data, &t("est")],
        vec!["integrate", &t("est"), "-o", &t("shape")],
        vec!["export", "gltf", &t("fit"), "-o", &t("asset/a.glb")],
        vec![
            "synth",
            "-o",
            &cap,
            "--size",
            "48",
            "--rig",
            "cone:30",
            "--chrome-sphere",
        ],
        vec![
            "calibrate",
            &format!("{cap}/images"),
            "-o",
            &format!("{cap}/cal.lp"),
        ],
        vec!["demo", "-o", &t("demo"), "--size", "16", "--lights", "16"],
    ]
    .iter()
    .map(|v| v.iter().map(|a| a.to_string()).collect())
    .collect();
    let mut seen = std::collections::BTreeSet::new();
    for args in &runs {
        let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
        a.push("--quiet");
        let o = symframe(&a);
        assert!(o.status.success(), "{a:?}: {}", stderr(&o));
        assert_eq!(
            (
                String::from_utf8_lossy(&o.stdout).as_ref(),
                stderr(&o).as_str()
            ),
            ("", ""),
            "{a:?} --quiet printed something"
        );
        seen.insert(a[0]);
    }
    for cmd in [
        "estimate",
        "merge",
        "fit",
        "relight",
        "view",
        "synth",
        "eval",
        "calibrate",
        "integrate",
        "export",
        "demo",
    ] {
        assert!(seen.contains(cmd), "{cmd} not run");
    }
}

/// A forged `shard.json` claiming 2^64 - 1 shards is not merged without a word, even where its
/// tiles cover the grid; `estimate --tiles K/N` with more shards than tiles makes no empty
/// shards.
#[test]
fn shard_counts_beyond_the_tile_count_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = crate::common::ward_sphere(&tmp.path().join("data"), 16, 30);
    let out = tmp.path().join("sh");
    let o = crate::common::estimate(
        &lp,
        &out,
        &["--method", "woodham", "--tiles", "1/9", "--tile-size", "8"],
    );
    crate::common::assert_one_line_error(&o, "--tiles 1/9: the image has 4 tiles of 8 px");
}

/// A texture name of the asset that is a hard link to a map the export reads (the same file
/// under another name) is not replaced through the switch's backup link: refused with a
/// one-line error naming the map, the map untouched.
#[cfg(unix)]
#[test]
fn export_refuses_a_texture_name_hard_linked_to_a_map() {
    let tmp = tempfile::tempdir().unwrap();
    let est = tmp.path().join("est");
    ok(&crate::common::estimate(
        &ward_sphere(&tmp.path().join("a"), 16, 30),
        &est,
        &["--method", "woodham", "--quiet"],
    ));
    let asset = tmp.path().join("asset");
    fs::create_dir_all(&asset).unwrap();
    let normals = fs::read(est.join("normals.npy")).unwrap();
    fs::hard_link(est.join("normals.npy"), asset.join("h_normal.png")).unwrap();
    let gltf = asset.join("h.gltf");
    let o = symframe(&["export", "gltf", s(&est), "-o", s(&gltf)]);
    assert_one_line_error(&o, "normals.npy");
    assert!(stderr(&o).contains("h_normal.png"), "{}", stderr(&o));
    assert_eq!(fs::read(est.join("normals.npy")).unwrap(), normals);
    assert!(!gltf.exists());
    assert!(fs::read_dir(&asset).unwrap().all(|e| !e
        .unwrap()
        .file_name()
        .to_string_lossy()
        .starts_with(".symframe")));
}

/// `export gltf -o FILE` never replaces a user's `scene.gltf`, nor a user's `scene.bin` beside
/// a new asset, without a word. It replaces only an asset symframe wrote (its
/// `asset.generator`) and the files that asset names; anything else is refused before a file
/// is written.
#[test]
fn export_never_replaces_files_it_did_not_write() {
    let tmp = tempfile::tempdir().unwrap();
    let est = tmp.path().join("est");
    ok(&crate::common::estimate(
        &ward_sphere(&tmp.path().join("a"), 16, 40),
        &est,
        &["--quiet"],
    ));
    let out = tmp.path().join("out");
    fs::create_dir_all(&out).unwrap();
    let export = |name: &str| symframe(&["export", "gltf", s(&est), "-o", s(&out.join(name))]);
    // Its own asset, written and written again.
    ok(&export("own.gltf"));
    ok(&export("own.gltf"));
    ok(&export("own.glb"));
    ok(&export("own.glb"));
    let before = snapshot(&out);
    // A user's glTF and GLB files at the output's name.
    let user = r#"{"asset": {"version": "2.0", "generator": "Blender 4.2"}}"#;
    fs::write(out.join("scene.gltf"), user).unwrap();
    fs::write(out.join("scene.glb"), b"glTF\x02\0\0\0junk").unwrap();
    fs::write(out.join("notes.gltf"), "my notes").unwrap();
    for name in ["scene.gltf", "scene.glb", "notes.gltf"] {
        let o = export(name);
        assert_one_line_error(&o, name);
        assert!(
            stderr(&o).contains("is not a glTF asset written by symframe export"),
            "{}",
            stderr(&o)
        );
    }
    assert_eq!(fs::read_to_string(out.join("scene.gltf")).unwrap(), user);
    // A user's buffer where a new asset's would go: nothing of the asset is written.
    fs::write(out.join("new.bin"), "my buffer").unwrap();
    let o = export("new.gltf");
    assert_one_line_error(&o, "new.bin");
    assert!(
        stderr(&o).contains("is not a file of a glTF asset symframe export wrote"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        fs::read_to_string(out.join("new.bin")).unwrap(),
        "my buffer"
    );
    assert!(!out.join("new.gltf").exists() && !out.join("new_basecolor.png").exists());
    let after = snapshot(&out);
    for (name, hash) in &before {
        assert_eq!(after.get(name), Some(hash), "{name}");
    }
}

/// `calibrate` does not decode each image whole (three HDR files of 96 KB declaring 8000 x 8000
/// pixels would cost gigabytes: docs/performance.md, "Memory model"). It reads them a band at a
/// time as grey values, keeping the sum or the brightest of all images and each image's
/// spheres' rows, and refuses images of more than 8192 x 8192 pixels from their header.
#[cfg(target_os = "linux")]
#[test]
fn calibrate_reads_large_declared_images_in_bounded_memory() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("big");
    fs::create_dir_all(&d).unwrap();
    for i in 0..3 {
        crate::forged::hdr_zeros(&d.join(format!("{i}.hdr")), 8000, 8000);
    }
    let lp = tmp.path().join("cal/lights.lp");
    let args = [
        "calibrate",
        s(&d),
        "-o",
        s(&lp),
        "--sphere",
        "4000,4000,1000",
        "--quiet",
    ];
    let (o, peak_kib) = run_measuring_rss(&args);
    // Each image dropped with a warning (black), then the error.
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("big: only 0 of 3 images have a usable highlight"),
        "{}",
        stderr(&o)
    );
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
    // The sphere looked for in the mean image: the sum of the images, a band at a time.
    let (o, peak_kib) = run_measuring_rss(&["calibrate", s(&d), "-o", s(&lp), "--quiet"]);
    assert_one_line_error(&o, "big");
    assert!(
        stderr(&o).contains("nothing in the images is brighter than their border"),
        "{}",
        stderr(&o)
    );
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
    // Larger than 8192 x 8192: refused from the header.
    let huge = tmp.path().join("huge");
    fs::create_dir_all(&huge).unwrap();
    for i in 0..3 {
        crate::forged::hdr_zeros(&huge.join(format!("{i}.hdr")), 16384, 8192);
    }
    let (o, peak_kib) = run_measuring_rss(&[
        "calibrate",
        s(&huge),
        "-o",
        s(&lp),
        "--sphere",
        "8000,4000,1000",
    ]);
    assert_one_line_error(&o, "0.hdr");
    assert!(
        stderr(&o).contains("16384x8192 pixels, more than the 67108864 (8192 x 8192)"),
        "{}",
        stderr(&o)
    );
    assert!(peak_kib < 100 << 10, "peak {peak_kib} KiB");
    assert!(!lp.exists());
}
