//! The glTF export job (`symframe export gltf`): a fit's (or an estimate's) maps as a glTF 2.0 asset: a quad, or the
//! integrated mesh, with a metallic-roughness material, a tangent-space normal texture and
//! `KHR_materials_anisotropy`.
//!
//! Frames: the quad lies in the x-y plane facing +z (x right, y up: the camera frame), one image
//! width across; its vertex tangent is +x and bitangent +y, so a camera-frame normal *is* its
//! tangent-space normal (glTF's +Y-up normal-map convention). For `--mesh` the vertex normals and
//! tangents come from the maps at each pixel (one vertex per pixel), so the shading detail is in
//! the geometry and no normal texture is written.
//!
//! Material, from a `symframe fit --model gltf` folder: exactly the fitted base colour,
//! metallic, roughness and anisotropy strength (direction = the fit's tangent), quantised to
//! the 8-bit textures; the light intensity the fit assumed is recorded in the material's
//! `extras.symframe.lightIntensity` (a renderer lighting the asset with lights of that
//! intensity reproduces the photographs). From a Ward fit (a conversion, not a fit of the glTF
//! model): `metallic = ks / (kd + ks)` (luminances), `baseColor = kd + metallic (ks - kd)`; the
//! narrow roughness `alpha_narrow = min(alpha_t, alpha_b)` gives `roughness = sqrt(alpha_narrow)`
//! (glTF's `alpha = roughness^2`), and the anisotropy strength `s` solves
//! `alpha_wide = alpha_narrow + s^2 (1 - alpha_narrow)` (the extension's stretch), its direction
//! the axis of the wider highlight. From an automatic fit (`--model auto`, both models' maps):
//! the glTF parameters where the glTF model was chosen, the Ward pixels converted as above
//! after dividing their albedos by the fit's light intensity (one glTF material needs one
//! model; the conversion is approximate where Ward was chosen). From an estimate folder: grey base colour, roughness 0.5,
//! metallic 0, and anisotropy strength = the estimate's anisotropy where it has a tangent.
//!
//! Two-lobe pixels (`--model clearcoat`, `woven`, or chosen by `auto`) are converted the same
//! way, their GGX roughnesses taken as glTF's `alpha` directly. A clear-coat pixel's base
//! (`lobes_kd`, `lobes_ka`, `lobes_alpha_t`, `lobes_alpha_b`) becomes the metallic-roughness
//! material with its anisotropy, and its coat `KHR_materials_clearcoat`: factor
//! `kc / 0.04` (the coat's reflectance over that of glTF's index-1.5 coat, clamped to 1) and
//! roughness `sqrt(alpha_c)`, in one texture (R factor, G roughness) written only when some
//! pixel has a coat. glTF has no second anisotropic lobe: a woven pixel becomes one lobe with
//! both lobes' reflectance, stretched along the stronger lobe's wide axis (approximate).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::Value;

mod asset;
mod maps;
mod targets;

pub use asset::{
    clearcoat_texture, document, from_camera_mesh, from_mesh, glb, gltf_anisotropy_rgb8, quad,
    textures, Geometry,
};
pub use maps::{read_maps, Maps};
use targets::{check_own_files, check_targets, input_files};

/// Everything a glTF export needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportConfig {
    /// Output folder of [`crate::fit`] (kd, ks, alpha_t, alpha_b, normals, tangents `.npy`) or
    /// of [`crate::estimate`] (normals, tangents, anisotropy `.npy`).
    pub input: PathBuf,
    /// The file to write: `.gltf` (textures and `.bin` beside it) or `.glb` (all in one).
    pub output: PathBuf,
    /// Export the integrated mesh (one vertex per pixel) instead of a flat quad.
    pub mesh: bool,
    /// With `mesh`: the height map of [`crate::integrate`] (`None`: `INPUT/depth.npy`).
    pub depth: Option<PathBuf>,
    /// With `mesh`: leave out triangles across depth jumps (as the integrate job's `max_jump`).
    pub max_jump: f64,
    /// With `mesh`: the depth map is a perspective one through this camera (`K.txt`), the mesh
    /// metric in the camera frame. `None`: the camera recorded beside the depth map
    /// ([`crate::recorded_camera`]), else the depth map is a height map.
    pub camera: Option<PathBuf>,
}

impl ExportConfig {
    /// A quad, no mesh, the integrate job's default jump limit.
    pub fn new(input: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        Self {
            input: input.into(),
            output: output.into(),
            mesh: false,
            depth: None,
            max_jump: 2.0,
            camera: None,
        }
    }
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOutcome {
    /// The files written, the asset first.
    pub written: Vec<PathBuf>,
    /// Whether the material comes from a fit (else from an estimate's frames).
    pub fitted: bool,
    /// Vertices of the geometry.
    pub vertices: usize,
    /// Triangles of the geometry.
    pub triangles: usize,
}

/// Whether `dir` holds the record of an orthographic integration (an `integrate.json` with no
/// camera), whose `depth.npy` is a height map in pixel units.
fn is_height_map(dir: &Path) -> Result<bool> {
    let path = dir.join("integrate.json");
    if !path.is_file() {
        return Ok(false);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let json: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    Ok(json.get("camera").is_none_or(Value::is_null))
}

/// Runs a glTF export; returns the files written and what they hold.
pub fn export_gltf(config: &ExportConfig) -> Result<ExportOutcome> {
    let ext = config
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let embed = match ext.as_deref() {
        Some("glb") => true,
        Some("gltf") => false,
        _ => bail!(
            "{}: the output must end in .gltf or .glb",
            config.output.display()
        ),
    };
    let maps = read_maps(&config.input)?;
    let (w, h) = (maps.w, maps.h);
    let geometry = if config.mesh {
        let depth_path = config
            .depth
            .clone()
            .unwrap_or_else(|| config.input.join("depth.npy"));
        let (shape, depth) = symframe_io::read_npy_f32(&depth_path).with_context(|| {
            format!(
                "a mesh needs a height map: the depth.npy of symframe integrate ({} missing or \
                 unreadable)",
                depth_path.display()
            )
        })?;
        if shape != [h, w] {
            bail!(
                "{}: shape {shape:?} does not match the maps ({h} x {w})",
                depth_path.display()
            );
        }
        let beside = depth_path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let camera = crate::integrate::camera_for(config.camera.as_deref(), beside)?;
        if camera.is_some() && is_height_map(beside)? {
            bail!(
                "{}: a height map of an orthographic integration (its integrate.json records no \
                 camera); integrate with --K for a perspective depth map",
                depth_path.display()
            );
        }
        if let Some((cam, _)) = camera {
            let mesh = cam.mesh(w, h, &depth, &maps.normals, config.max_jump);
            if mesh.triangles.is_empty() {
                bail!("{}: the mesh has no triangles", depth_path.display());
            }
            from_camera_mesh(&mesh, w, h)
        } else {
            let dm = symframe::DepthMap {
                width: w,
                height: h,
                depth,
                cg_iterations: 0,
                reweight_iterations: 0,
                energy: 0.0,
                regions: 0,
                pixels: 0,
            };
            let mesh = dm.mesh(&maps.normals, config.max_jump);
            if mesh.triangles.is_empty() {
                bail!("{}: the mesh has no triangles", depth_path.display());
            }
            from_mesh(&mesh, w, h)
        }
    } else {
        quad(w, h)
    };
    let out_dir = config
        .output
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let stem = config
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "asset".into());
    let coat = clearcoat_texture(&maps);
    let names: &[&str] = if coat.is_some() {
        &[
            "basecolor",
            "metallicroughness",
            "normal",
            "anisotropy",
            "clearcoat",
        ]
    } else {
        &["basecolor", "metallicroughness", "normal", "anisotropy"]
    };
    let bin_name = format!("{stem}.bin");
    // The asset's files, the .gltf or .glb last (the textures and buffer it names go in first).
    let mut targets: Vec<PathBuf> = Vec::new();
    if !embed {
        targets.extend(
            names
                .iter()
                .map(|n| out_dir.join(format!("{stem}_{n}.png"))),
        );
        targets.push(out_dir.join(&bin_name));
    }
    targets.push(config.output.clone());
    let mut inputs = input_files(&config.input)?;
    if config.mesh {
        inputs.push(
            config
                .depth
                .clone()
                .unwrap_or_else(|| config.input.join("depth.npy")),
        );
    }
    check_targets(&targets, &inputs)?;
    check_own_files(&targets, &config.output)?;
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("{}: cannot create folder", out_dir.display()))?;

    // Every file is written into a staging folder first, then moved in (see [`switch_in`]);
    // the folder goes in any case.
    let staging = Staging::new(&out_dir)?;
    let [base, mr, normal, aniso] = textures(&maps, !config.mesh);
    let mut images = Vec::new();
    for (name, bytes) in names
        .iter()
        .zip([&base, &mr, &normal, &aniso].into_iter().chain(&coat))
    {
        let p = staging.0.join(format!("{stem}_{name}.png"));
        symframe_io::write_png_rgb8(&p, w, h, bytes)?;
        images.push((*name, p));
    }
    let refs: Vec<(&str, &Path)> = images.iter().map(|(n, p)| (*n, p.as_path())).collect();
    let (doc, bin) = document(
        &geometry,
        &refs,
        !config.mesh,
        embed,
        (!embed).then_some(&bin_name),
        maps.light_intensity,
    )?;
    let asset = staging
        .0
        .join(config.output.file_name().unwrap_or_default());
    let mut staged: Vec<PathBuf> = Vec::new();
    if embed {
        std::fs::write(&asset, glb(&doc, &bin))
            .with_context(|| format!("{}: cannot write", asset.display()))?;
    } else {
        staged.extend(images.iter().map(|(_, p)| p.clone()));
        let bp = staging.0.join(&bin_name);
        std::fs::write(&bp, &bin).with_context(|| format!("{}: cannot write", bp.display()))?;
        staged.push(bp);
        std::fs::write(&asset, serde_json::to_string_pretty(&doc)? + "\n")
            .with_context(|| format!("{}: cannot write", asset.display()))?;
    }
    staged.push(asset);
    let moves: Vec<(PathBuf, PathBuf)> = staged.into_iter().zip(targets.iter().cloned()).collect();
    switch_in(&moves, &staging.0)?;
    drop(staging);
    // The asset first, then the buffer and the textures.
    let mut written = targets;
    written.rotate_right(1);
    if !embed {
        written[1..].rotate_right(1);
    }
    Ok(ExportOutcome {
        written,
        fitted: maps.fitted,
        vertices: geometry.positions.len(),
        triangles: geometry.indices.len() / 3,
    })
}

/// The export's staging folder (`.symframe-export-PID-TOKEN` in the output's folder, a fresh
/// name: a folder already there is never touched), removed when dropped: on success and on
/// any error.
struct Staging(PathBuf);

impl Staging {
    fn new(dir: &Path) -> Result<Self> {
        let p = dir.join(format!(
            ".symframe-export-{}-{:016x}",
            std::process::id(),
            crate::outdir::new_token()
        ));
        std::fs::create_dir(&p).with_context(|| format!("{}: cannot create", p.display()))?;
        Ok(Self(p))
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// Moves each staged file onto its target, in order, keeping a link to (or, where links are not
/// supported, the moved) old file in `backup_dir`; if a move fails, the files moved so far are
/// taken out again and the old ones put back, so the targets hold either all the old files (an
/// error is returned) or all the new ones.
fn switch_in(moves: &[(PathBuf, PathBuf)], backup_dir: &Path) -> Result<()> {
    // (target, its old file's backup)
    let mut done: Vec<(&Path, Option<PathBuf>)> = Vec::new();
    let mut result = Ok(());
    for (i, (from, to)) in moves.iter().enumerate() {
        let backup = backup_dir.join(format!(".old-{i}"));
        let old = match std::fs::symlink_metadata(to) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => {
                result = Err(e).with_context(|| format!("{}: cannot read", to.display()));
                break;
            }
            Ok(m) if m.is_dir() => {
                result = Err(anyhow::anyhow!(
                    "{}: a folder is in the way of the exported file",
                    to.display()
                ));
                break;
            }
            Ok(_) => {
                match std::fs::hard_link(to, &backup).or_else(|_| std::fs::rename(to, &backup)) {
                    Ok(()) => Some(backup),
                    Err(e) => {
                        result = Err(e).with_context(|| format!("{}: cannot keep", to.display()));
                        break;
                    }
                }
            }
        };
        if let Err(e) = std::fs::rename(from, to) {
            result = Err(e).with_context(|| format!("{}: cannot replace", to.display()));
            if let Some(b) = &old {
                if std::fs::symlink_metadata(to).is_err() {
                    std::fs::rename(b, to).ok();
                }
            }
            break;
        }
        done.push((to, old));
    }
    if result.is_err() {
        for (to, old) in done.into_iter().rev() {
            match old {
                Some(b) => {
                    std::fs::rename(&b, to).ok();
                }
                None => {
                    std::fs::remove_file(to).ok();
                }
            }
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_switch_puts_every_old_file_back() {
        let d = tempfile::tempdir().unwrap();
        let (out, stage) = (d.path().join("out"), d.path().join("stage"));
        std::fs::create_dir_all(&out).unwrap();
        std::fs::create_dir_all(&stage).unwrap();
        let names = ["a.png", "b.bin", "c.gltf"];
        let moves: Vec<(PathBuf, PathBuf)> =
            names.iter().map(|n| (stage.join(n), out.join(n))).collect();
        let stage_new = || {
            for (from, _) in &moves {
                std::fs::write(from, "new").unwrap();
            }
        };
        // The old asset: a and b (c is new); a folder in the way of the last move.
        std::fs::write(out.join("a.png"), "old a").unwrap();
        std::fs::write(out.join("b.bin"), "old b").unwrap();
        std::fs::create_dir_all(out.join("c.gltf/x")).unwrap();
        stage_new();
        assert!(switch_in(&moves, &stage).is_err());
        assert_eq!(std::fs::read_to_string(out.join("a.png")).unwrap(), "old a");
        assert_eq!(std::fs::read_to_string(out.join("b.bin")).unwrap(), "old b");
        assert!(out.join("c.gltf/x").is_dir());
        // Cleared: every new file in.
        std::fs::remove_dir_all(out.join("c.gltf")).unwrap();
        stage_new();
        switch_in(&moves, &stage).unwrap();
        for n in names {
            assert_eq!(std::fs::read_to_string(out.join(n)).unwrap(), "new");
        }
    }
}
