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
    assert_eq!(doc["images"].as_array().unwrap().len(), 4);
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
