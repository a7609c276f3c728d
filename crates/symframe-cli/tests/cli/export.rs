//! End-to-end tests of `symframe export gltf`: a fit and an estimate exported as `.gltf` and
//! `.glb`, quad and integrated mesh; the files are well formed (GLB chunks, buffer sizes,
//! accessors, the anisotropy extension), textures carry the maps, and the Khronos validator
//! (when `.ci/node_modules` has it: run `.ci/gltf-check.sh` once) reports no error.

use std::fs;
use std::path::Path;
use std::process::Command;

use crate::common::{assert_one_line_error, s, symframe};

fn run_ok(args: &[&str]) -> String {
    let o = symframe(args);
    assert!(
        o.status.success(),
        "symframe {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The JSON and BIN chunks of a GLB file, checked for layout.
fn glb_chunks(path: &Path) -> (serde_json::Value, Vec<u8>) {
    let g = fs::read(path).unwrap();
    assert_eq!(&g[..4], b"glTF");
    let u = |o: usize| u32::from_le_bytes(g[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(u(4), 2);
    assert_eq!(u(8), g.len());
    let jl = u(12);
    assert_eq!(&g[16..20], b"JSON");
    let json = serde_json::from_slice(&g[20..20 + jl]).unwrap();
    let bl = u(20 + jl);
    assert_eq!(&g[24 + jl..28 + jl], b"BIN\0");
    (json, g[28 + jl..28 + jl + bl].to_vec())
}

/// Checks buffer views and accessors against the buffer's length.
fn check_layout(doc: &serde_json::Value, bin_len: usize) {
    assert_eq!(doc["asset"]["version"], "2.0");
    assert_eq!(
        doc["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
        bin_len
    );
    for v in doc["bufferViews"].as_array().unwrap() {
        let end = v["byteOffset"].as_u64().unwrap() + v["byteLength"].as_u64().unwrap();
        assert!(end as usize <= bin_len);
        assert_eq!(v["byteOffset"].as_u64().unwrap() % 4, 0);
    }
    let m = &doc["materials"][0];
    assert!(m["extensions"]["KHR_materials_anisotropy"]["anisotropyTexture"].is_object());
    assert_eq!(doc["extensionsUsed"][0], "KHR_materials_anisotropy");
    // A fifth texture, the clear coat's, where some pixel has a clear-coat model.
    let coat = m["extensions"]["KHR_materials_clearcoat"].is_object();
    assert_eq!(
        doc["images"].as_array().unwrap().len(),
        if coat { 5 } else { 4 }
    );
}

/// Runs the Khronos validator on `files` when it is installed; returns whether it ran.
fn validate(files: &[&Path]) -> bool {
    let ci = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.ci");
    let installed = ci.join("node_modules/gltf-validator").is_dir();
    let node = Command::new("node").arg("--version").output().is_ok();
    if !(installed && node) {
        eprintln!("glTF validator not installed (run .ci/gltf-check.sh once): skipped");
        return false;
    }
    let mut cmd = Command::new("node");
    cmd.arg(ci.join("gltf-validate.js"));
    for f in files {
        cmd.arg(f);
    }
    let o = cmd.output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    eprintln!("{out}");
    assert!(o.status.success(), "validator: {out}");
    for f in files {
        assert!(out.contains(&format!("{}: 0 errors", f.display())), "{out}");
    }
    true
}

#[test]
fn fits_and_estimates_export_as_valid_gltf() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (data, est, fit, int) = (t.join("data"), t.join("est"), t.join("fit"), t.join("int"));
    run_ok(&["synth", "-o", s(&data), "--size", "32", "--rig", "cone:150"]);
    run_ok(&["estimate", s(&data), "-o", s(&est)]);
    run_ok(&["fit", s(&data), "--frames", s(&est), "-o", s(&fit)]);
    run_ok(&["integrate", s(&est), "-o", s(&int), "--solver", "poisson"]);

    // .gltf: JSON, .bin and four PNG textures beside it.
    let gltf = t.join("out/quad.gltf");
    let out = run_ok(&["export", "gltf", s(&fit), "-o", s(&gltf)]);
    assert!(out.contains("fitted"), "{out}");
    let doc: serde_json::Value = serde_json::from_str(&fs::read_to_string(&gltf).unwrap()).unwrap();
    let bin = fs::read(t.join("out/quad.bin")).unwrap();
    check_layout(&doc, bin.len());
    for name in ["basecolor", "metallicroughness", "normal", "anisotropy"] {
        let p = t.join(format!("out/quad_{name}.png"));
        let img = symframe_io::read_image(&p, &symframe_io::DecodeOptions::default()).unwrap();
        assert_eq!((img.width, img.height), (32, 32));
    }
    assert!(doc["materials"][0]["normalTexture"].is_object());
    assert_eq!(doc["accessors"][0]["count"], 4);

    // .glb of the fit, of the estimate, and of the integrated mesh.
    let glb = t.join("quad.glb");
    run_ok(&["export", "gltf", s(&fit), "-o", s(&glb)]);
    let (doc, bin) = glb_chunks(&glb);
    check_layout(&doc, bin.len());
    let est_glb = t.join("est.glb");
    let out = run_ok(&["export", "gltf", s(&est), "-o", s(&est_glb)]);
    assert!(out.contains("estimated-frames"), "{out}");
    let mesh_glb = t.join("mesh.glb");
    run_ok(&[
        "export",
        "gltf",
        s(&fit),
        "--mesh",
        "--depth",
        s(&int.join("depth.npy")),
        "-o",
        s(&mesh_glb),
    ]);
    let (doc, bin) = glb_chunks(&mesh_glb);
    check_layout(&doc, bin.len());
    assert!(doc["materials"][0]["normalTexture"].is_null());
    let vertices = doc["accessors"][0]["count"].as_u64().unwrap();
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(int.join("integrate.json")).unwrap()).unwrap();
    assert_eq!(vertices, report["vertices"].as_u64().unwrap());
    // No temporary folder is left beside the outputs.
    for e in fs::read_dir(t).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with(".symframe-export"), "{name}");
    }
    validate(&[&gltf, &glb, &est_glb, &mesh_glb]);

    // Errors name the file.
    let o = symframe(&["export", "gltf", s(&fit), "-o", s(&t.join("x.obj"))]);
    assert_one_line_error(&o, "x.obj");
    let o = symframe(&["export", "gltf", s(&data), "-o", s(&glb)]);
    assert_one_line_error(&o, "normals.npy");
    let o = symframe(&["export", "gltf", s(&fit), "--mesh", "-o", s(&glb)]);
    assert_one_line_error(&o, "depth.npy");
}

/// A clear-coat fit exports `KHR_materials_clearcoat` beside `KHR_materials_anisotropy` (its
/// factor and roughness in one texture, R and G), the relight job renders it, and a woven fit
/// (which glTF cannot carry as two lobes) exports without a coat; the validator, when
/// installed, accepts both.
#[test]
fn two_lobe_fits_export_the_clear_coat() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (data, est) = (t.join("data"), t.join("est"));
    run_ok(&["synth", "-o", s(&data), "--size", "24", "--rig", "cone:120"]);
    run_ok(&["estimate", s(&data), "-o", s(&est)]);
    let coat_fit = t.join("coat");
    run_ok(&[
        "fit",
        s(&data),
        "--frames",
        s(&est),
        "-o",
        s(&coat_fit),
        "--model",
        "clearcoat",
    ]);
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(coat_fit.join("fit.json")).unwrap()).unwrap();
    assert_eq!(report["model"], "clearcoat");
    assert!(report["fit"]["clearcoat_pixels"].as_u64().unwrap() > 0);
    for name in ["lobes_kd", "lobes_ka", "lobes_kb", "lobes_alpha_c", "model"] {
        assert!(coat_fit.join(format!("{name}.npy")).is_file(), "{name}");
    }
    assert!(!coat_fit.join("kd.npy").exists() && !coat_fit.join("base_color.npy").exists());

    let glb = t.join("coat.glb");
    run_ok(&["export", "gltf", s(&coat_fit), "-o", s(&glb)]);
    let (doc, bin) = glb_chunks(&glb);
    check_layout(&doc, bin.len());
    let coat = &doc["materials"][0]["extensions"]["KHR_materials_clearcoat"];
    assert_eq!(coat["clearcoatTexture"]["index"], 4, "{doc}");
    assert_eq!(coat["clearcoatRoughnessTexture"]["index"], 4, "{doc}");
    let used: Vec<&str> = doc["extensionsUsed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(
        used,
        ["KHR_materials_anisotropy", "KHR_materials_clearcoat"]
    );
    let gltf = t.join("out/coat.gltf");
    run_ok(&["export", "gltf", s(&coat_fit), "-o", s(&gltf)]);
    let img = symframe_io::read_image(
        &t.join("out/coat_clearcoat.png"),
        &symframe_io::DecodeOptions::default(),
    )
    .unwrap();
    assert_eq!((img.width, img.height), (24, 24));

    // The relight job renders the two-lobe pixels: the sphere is lit.
    let relit = t.join("relit");
    run_ok(&[
        "relight",
        s(&coat_fit),
        "-o",
        s(&relit),
        "--light",
        "0.2,0.1,1",
    ]);
    let exr = fs::read_dir(&relit)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "exr"))
        .unwrap();
    let lit = symframe_io::read_image(&exr, &symframe_io::DecodeOptions::default()).unwrap();
    assert!(lit.data.iter().any(|&v| v > 0.0));

    let woven_fit = t.join("woven");
    run_ok(&[
        "fit",
        s(&data),
        "--frames",
        s(&est),
        "-o",
        s(&woven_fit),
        "--model",
        "woven",
    ]);
    let woven_glb = t.join("woven.glb");
    run_ok(&["export", "gltf", s(&woven_fit), "-o", s(&woven_glb)]);
    let (doc, bin) = glb_chunks(&woven_glb);
    check_layout(&doc, bin.len());
    assert!(doc["materials"][0]["extensions"]["KHR_materials_clearcoat"].is_null());
    validate(&[&glb, &gltf, &woven_glb]);
}
