//! `symframe relight`: the folder of `symframe fit` in, images under new lights out (linear EXR
//! and a tone-mapped PNG per light), with optional appearance edits.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use glam::DVec3;
use serde::Serialize;
use symframe::relight::{tone_map, Edits, Relighter};
use symframe::WardMaps;

use crate::cli::RelightArgs;
use crate::outdir::Staging;

/// What `relight.json` records about a run.
#[derive(Debug, Serialize)]
struct RelightReport<'a> {
    version: &'static str,
    fit_dir: &'a Path,
    /// Unit light directions, one per image, in file order.
    lights: Vec<[f64; 3]>,
    /// Image file names (without extension), one per light.
    images: Vec<String>,
    diffuse_scale: f64,
    specular_scale: f64,
    roughness_scale: f64,
    rotate_tangents_deg: Option<f64>,
    region: Option<&'a Path>,
    exposure_stops: f64,
}

/// Reads one map of the fit folder; `expect` is the shape it must have (`None`: any
/// `H x W x channels`, which then sets the size).
fn read_map(dir: &Path, name: &str, expect: &[usize]) -> Result<Vec<f32>> {
    let path = dir.join(format!("{name}.npy"));
    if !path.is_file() {
        bail!(
            "{}: missing (the folder must be an output folder of symframe fit)",
            path.display()
        );
    }
    let (shape, data) = symframe_io::read_npy_f32(&path)?;
    if shape != expect {
        bail!(
            "{}: shape {shape:?} does not match kd.npy ({expect:?} expected)",
            path.display()
        );
    }
    Ok(data)
}

/// Reads the fitted maps of `dir`, checking that every map has kd.npy's size.
pub fn read_ward_maps(dir: &Path) -> Result<WardMaps> {
    let kd_path = dir.join("kd.npy");
    if !kd_path.is_file() {
        bail!(
            "{}: missing (the folder must be an output folder of symframe fit)",
            kd_path.display()
        );
    }
    let (shape, kd) = symframe_io::read_npy_f32(&kd_path)?;
    let [h, w, 3] = shape[..] else {
        bail!(
            "{}: shape {shape:?} is not an H x W x 3 map",
            kd_path.display()
        );
    };
    Ok(WardMaps {
        width: w,
        height: h,
        ks: read_map(dir, "ks", &[h, w, 3])?,
        alpha_t: read_map(dir, "alpha_t", &[h, w])?,
        alpha_b: read_map(dir, "alpha_b", &[h, w])?,
        normals: read_map(dir, "normals", &[h, w, 3])?,
        tangents: read_map(dir, "tangents", &[h, w, 3])?,
        kd,
    })
}

/// Checks the flags that clap cannot.
fn validate(args: &RelightArgs) -> Result<()> {
    for (flag, v) in [
        ("--specular-scale", args.specular_scale),
        ("--diffuse-scale", args.diffuse_scale),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            bail!("{flag} must be finite and >= 0, got {v}");
        }
    }
    if !(args.roughness_scale > 0.0 && args.roughness_scale.is_finite()) {
        bail!(
            "--roughness-scale must be finite and > 0, got {}",
            args.roughness_scale
        );
    }
    if !args.exposure.is_finite() {
        bail!("--exposure must be finite, got {}", args.exposure);
    }
    if args.rotate_tangents.is_some_and(|d| !d.is_finite()) {
        bail!("--rotate-tangents must be finite");
    }
    Ok(())
}

/// Runs the command; returns the paths of the PNG pictures written (in light order).
pub fn run(args: &RelightArgs) -> Result<Vec<PathBuf>> {
    validate(args)?;
    let maps = read_ward_maps(&args.fit_dir)?;
    let (w, h) = (maps.width, maps.height);
    let mut lights: Vec<DVec3> = args.light.iter().map(|&l| DVec3::from_array(l)).collect();
    if let Some(p) = &args.lights {
        lights.extend(symframe_io::read_light_directions(p)?);
    }
    let lights: Vec<DVec3> = lights.into_iter().map(|l| l.normalize()).collect();
    let region = match &args.region {
        Some(p) => Some(symframe_io::read_mask(p, w, h)?),
        None => None,
    };
    let edits = Edits {
        diffuse_scale: args.diffuse_scale,
        specular_scale: args.specular_scale,
        roughness_scale: args.roughness_scale,
        tangent_rotation_deg: args.rotate_tangents.unwrap_or(0.0),
        region,
    };
    let relighter =
        Relighter::new(&maps, &edits).with_context(|| args.fit_dir.display().to_string())?;

    let staging = Staging::new(&args.output)?;
    let mut names = Vec::with_capacity(lights.len());
    for (i, &l) in lights.iter().enumerate() {
        let name = format!("relit_{i:03}");
        let img = relighter.render(l);
        symframe_io::write_exr_rgb(&staging.path(&format!("{name}.exr")), w, h, &img)?;
        symframe_io::write_png8_rgb(
            &staging.path(&format!("{name}.png")),
            w,
            h,
            &tone_map(&img, args.exposure),
            true,
        )?;
        names.push(name);
    }
    if args.rotate_tangents.is_some() {
        symframe_io::write_png_rgb8(
            &staging.path("tangents_edited.png"),
            w,
            h,
            &symframe_io::tangent_map_rgb8(&relighter.tangents()),
        )?;
    }
    let report = RelightReport {
        version: env!("CARGO_PKG_VERSION"),
        fit_dir: &args.fit_dir,
        lights: lights.iter().map(|l| l.to_array()).collect(),
        images: names.clone(),
        diffuse_scale: args.diffuse_scale,
        specular_scale: args.specular_scale,
        roughness_scale: args.roughness_scale,
        rotate_tangents_deg: args.rotate_tangents,
        region: args.region.as_deref(),
        exposure_stops: args.exposure,
    };
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(staging.path("relight.json"), json + "\n")
        .context("cannot write relight.json")?;
    staging.commit()?;
    Ok(names
        .iter()
        .map(|n| args.output.join(format!("{n}.png")))
        .collect())
}
