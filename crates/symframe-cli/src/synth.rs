//! `symframe synth`: renders a synthetic capture (shape, reflectance model, tangent field, light
//! rig, sensor degradations) and writes it as an `.lp` dataset folder with ground truth and a
//! `scene.json` describing what was rendered. `symframe estimate DIR` reads it back.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use serde_json::{json, Value};
use symframe::brdf::{parse_model, Brdf, TangentAxis};
use symframe::render::rigs::{diligent_lights, uniform_cone_lights};
use symframe::render::{BumpParams, Degradation, Noise, Scene, TangentField};
use symframe_io::ImageFormat;

use crate::cli::{FormatArg, ShapeArg, SynthArgs};
use crate::progress;
use symframe_job::Staging;

/// Largest image stack `synth` holds in memory, in bytes.
const MAX_STACK_BYTES: f64 = 16.0 * (1u64 << 30) as f64;

/// A light rig as given by `--rig`.
#[derive(Debug, Clone, PartialEq)]
pub enum RigSpec {
    /// `cone:N[:THETA_D]`: N lights uniform over the halfway-angle cone of THETA_D degrees.
    Cone {
        /// Number of lights.
        n: usize,
        /// Cone half-angle in halfway space, degrees.
        theta_d_max_deg: f64,
    },
    /// `diligent`: the 96-light grid within 45 degrees of the view.
    Diligent,
    /// `lp:PATH`: the lights of an existing `.lp` file or dataset.
    Lp(PathBuf),
}

impl RigSpec {
    /// Parses `cone:N[:THETA_D]`, `diligent` or `lp:PATH`.
    pub fn parse(spec: &str) -> Result<Self> {
        let spec = spec.trim();
        let (kind, rest) = match spec.split_once(':') {
            Some((k, r)) => (k.trim().to_ascii_lowercase(), Some(r)),
            None => (spec.to_ascii_lowercase(), None),
        };
        match (kind.as_str(), rest) {
            ("cone", Some(rest)) => {
                let mut parts = rest.split(':');
                let n_text = parts.next().unwrap_or("").trim();
                let n: usize = n_text
                    .parse()
                    .ok()
                    .filter(|n| (1..=100_000).contains(n))
                    .with_context(|| {
                        format!("--rig {spec}: N must be a whole number in 1..=100000")
                    })?;
                let theta_d_max_deg = match parts.next() {
                    None => 65.0,
                    Some(t) => t
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|t| *t > 0.0 && *t < 90.0)
                        .with_context(|| {
                            format!("--rig {spec}: THETA_D must be in (0, 90) degrees")
                        })?,
                };
                if parts.next().is_some() {
                    bail!("--rig {spec}: expected cone:N or cone:N:THETA_D");
                }
                Ok(RigSpec::Cone { n, theta_d_max_deg })
            }
            ("diligent", None) => Ok(RigSpec::Diligent),
            ("lp", Some(path)) if !path.trim().is_empty() => {
                Ok(RigSpec::Lp(PathBuf::from(path.trim())))
            }
            _ => bail!("--rig {spec}: expected cone:N[:THETA_D], diligent or lp:PATH"),
        }
    }

    /// The unit light directions (camera frame, surface toward light).
    pub fn lights(&self) -> Result<Vec<DVec3>> {
        Ok(match self {
            RigSpec::Cone { n, theta_d_max_deg } => uniform_cone_lights(*n, *theta_d_max_deg),
            RigSpec::Diligent => diligent_lights(),
            RigSpec::Lp(path) => symframe_io::open_dataset(path)?.lights,
        })
    }

    /// What `scene.json` records about the rig.
    fn describe(&self, n_lights: usize) -> Value {
        match self {
            RigSpec::Cone { n, theta_d_max_deg } => json!({
                "kind": "cone", "lights": n, "theta_d_max_deg": theta_d_max_deg,
            }),
            RigSpec::Diligent => json!({
                "kind": "diligent", "lights": n_lights, "grid": [12, 8], "max_angle_deg": 45.0,
            }),
            RigSpec::Lp(path) => json!({
                "kind": "lp", "lights": n_lights, "source": path,
                "note": "directions only; rendered with unit intensities",
            }),
        }
    }
}

/// Checks the flags that clap cannot, and that shape-specific flags go with their shape.
fn validate(args: &SynthArgs) -> Result<()> {
    if !(8..=2048).contains(&args.size) {
        bail!("--size must be between 8 and 2048, got {}", args.size);
    }
    if !(args.exposure.is_finite() && args.exposure > 0.0) {
        bail!(
            "--exposure must be a positive number, got {}",
            args.exposure
        );
    }
    let plane_only = [
        ("--normal-angle", args.normal_angle),
        ("--normal-azimuth", args.normal_azimuth),
        ("--tangent-angle", args.tangent_angle),
    ];
    for (flag, value) in plane_only {
        if let Some(v) = value {
            if args.shape != ShapeArg::Plane {
                bail!("{flag} applies to --shape plane only");
            }
            if !v.is_finite() {
                bail!("{flag} must be a finite number of degrees, got {v}");
            }
        }
    }
    if let Some(a) = args.normal_angle {
        if !(0.0..90.0).contains(&a) {
            bail!("--normal-angle must be in [0, 90) degrees, got {a}");
        }
    }
    if args.tangent_angle.is_some() && args.tangent_field.is_some() {
        bail!("--tangent-angle and --tangent-field are exclusive: give one");
    }
    if args.shape != ShapeArg::Bumps && (args.bumps.is_some() || args.relief.is_some()) {
        bail!("--bumps and --relief apply to --shape bumps only");
    }
    if let Some(n) = args.bumps {
        if !(1..=1000).contains(&n) {
            bail!("--bumps must be between 1 and 1000, got {n}");
        }
    }
    if let Some(r) = args.relief {
        if !(r.is_finite() && r > 0.0) {
            bail!("--relief must be a positive number, got {r}");
        }
    }
    Ok(())
}

/// The scene for the flags, and what `scene.json` records about its shape.
fn build_scene(args: &SynthArgs, field: Option<TangentField>) -> (Scene, Value) {
    let size = args.size;
    let f = field.unwrap_or(TangentField::Circular);
    match args.shape {
        ShapeArg::Sphere => (
            Scene::sphere(size, f),
            json!({ "kind": "sphere", "size": size }),
        ),
        ShapeArg::Cylinder => (
            Scene::cylinder(size, f),
            json!({ "kind": "cylinder", "size": size, "axis": "image y" }),
        ),
        ShapeArg::Plane => {
            let theta = args.normal_angle.unwrap_or(0.0);
            let phi = args.normal_azimuth.unwrap_or(0.0);
            let tangent = args.tangent_angle.unwrap_or(0.0);
            let mut scene = Scene::tilted_plane(size, size, theta, phi, tangent);
            if let Some(field) = field {
                scene.set_tangent_field(field);
            }
            let n = scene.normals_in_camera[0];
            let t = scene.tangents_in_camera[0];
            (
                scene,
                json!({
                    "kind": "plane", "size": size,
                    "normal_angle_deg": theta, "normal_azimuth_deg": phi,
                    "tangent_angle_deg": if field.is_none() { json!(tangent) } else { Value::Null },
                    "normal": n.to_array(), "tangent": t.to_array(),
                }),
            )
        }
        ShapeArg::Bumps => {
            let params = BumpParams {
                count: args.bumps.unwrap_or(BumpParams::default().count),
                relief: args.relief.unwrap_or(BumpParams::default().relief),
                seed: args.seed,
            };
            let bumps = params.bumps(size);
            let list: Vec<Value> = bumps
                .iter()
                .map(|b| {
                    json!({ "col": b.col, "row": b.row, "sigma": b.sigma, "amplitude": b.amplitude })
                })
                .collect();
            (
                Scene::from_bumps(size, &bumps, f),
                json!({
                    "kind": "bumps", "size": size, "count": params.count,
                    "relief": params.relief, "seed": params.seed,
                    "height_units": "pixels", "bumps": list,
                }),
            )
        }
    }
}

fn image_format(f: FormatArg) -> (ImageFormat, &'static str) {
    match f {
        FormatArg::Exr => (ImageFormat::Exr, "exr"),
        FormatArg::Png16 => (ImageFormat::Png16, "png16"),
        FormatArg::Png8 => (ImageFormat::Png8, "png8"),
    }
}

/// Runs the command; returns the path of the written `lights.lp`.
pub fn run(args: &SynthArgs) -> Result<PathBuf> {
    validate(args)?;
    symframe_io::check_synth_target(&args.output, args.force)?;
    // The output folder's lock, as estimate and fit take it: a second synth (or any job) into
    // the folder is refused while this one writes. Checked again under the lock.
    let out = symframe_job::OutputDir::lock(&args.output)?;
    crate::test_checkpoint(symframe_job::Checkpoint::OutputLocked);
    let result = symframe_io::check_synth_target(&args.output, args.force)
        .map_err(anyhow::Error::from)
        .and_then(|()| render_and_write(args));
    if result.is_err() {
        out.discard_unfinished();
    }
    result
}

/// Renders the dataset and writes it into the (locked) output folder.
fn render_and_write(args: &SynthArgs) -> Result<PathBuf> {
    let t0 = Instant::now();
    let brdf: Box<dyn Brdf> = parse_model(&args.model).map_err(anyhow::Error::msg)?;
    let field = args
        .tangent_field
        .as_deref()
        .map(TangentField::parse)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    let noise = Noise::parse(&args.noise).map_err(anyhow::Error::msg)?;
    let rig = RigSpec::parse(&args.rig)?;
    let lights = rig.lights()?;
    let n = args.size * args.size * if args.chrome_sphere { 2 } else { 1 };
    let bytes = (lights.len() * n * 3 * 4) as f64;
    if bytes > MAX_STACK_BYTES {
        bail!(
            "{} lights of {0}x{0} images need {:.1} GiB in memory; use fewer lights or a smaller --size",
            lights.len(),
            bytes / (1u64 << 30) as f64
        );
    }
    let (scene, shape_json) = build_scene(args, field);
    let degradation = Degradation {
        exposure: args.exposure as f32,
        noise,
        clip: None,
        quantise_bits: None,
        seed: args.seed,
    };
    if progress::chatty() {
        eprintln!(
            "symframe synth: rendering a {0}x{0} {1:?} of {2} under {3} lights",
            args.size,
            args.shape,
            brdf.name(),
            lights.len()
        );
    }
    let bar = progress::bar(lights.len() as u64, "rendering");
    let chrome = args.chrome_sphere.then(|| ChromeSphere::new(args.size));
    let images: Vec<Vec<f32>> = lights
        .par_iter()
        .enumerate()
        .map(|(i, &l)| {
            let img = match &chrome {
                None => scene.render_degraded(brdf.as_ref(), l, i, &degradation),
                Some(c) => {
                    let img = c.beside(&scene.render(brdf.as_ref(), l), l);
                    let mut img = img;
                    degradation.apply(&mut img, i);
                    img
                }
            };
            bar.inc(1);
            img
        })
        .collect();
    bar.finish_and_clear();

    // Pixel-samples inside the mask that an integer format clips (any channel >= 1).
    let in_mask_samples = scene.mask.iter().filter(|&&m| m).count() * lights.len();
    let clipped: usize = images
        .par_iter()
        .map(|img| {
            img.chunks_exact(3)
                .zip(&scene.mask)
                .filter(|(px, &m)| m && px.iter().any(|&v| v >= 1.0))
                .count()
        })
        .sum();

    let (format, format_name) = image_format(args.format);
    let staging = Staging::new(&args.output)?;
    let widen = |v: Vec<f32>, fill: f32| match &chrome {
        None => v,
        Some(c) => c.widen(&v, 3, fill),
    };
    let mask = match &chrome {
        None => scene.mask.clone(),
        Some(c) => c.widen_mask(&scene.mask),
    };
    let width = scene.width * if chrome.is_some() { 2 } else { 1 };
    symframe_io::write_lp_dataset(
        staging.dir(),
        &lights,
        &images,
        width,
        scene.height,
        format,
        Some(&widen(scene.gt_normals(), f32::NAN)),
        Some(&widen(scene.gt_tangents(), f32::NAN)),
        Some(&mask),
    )
    .with_context(|| format!("{}: cannot write the dataset", args.output.display()))?;
    drop(images);

    let description = json!({
        "version": env!("CARGO_PKG_VERSION"),
        "generator": "symframe synth",
        "model": brdf.name(),
        "model_spec": args.model,
        "tangent_axis": match brdf.tangent_axis() {
            TangentAxis::X => "x",
            TangentAxis::Y => "y",
            TangentAxis::None => "none",
        },
        "shape": shape_json,
        "tangent_field": match (args.shape, field) {
            (ShapeArg::Plane, None) => Value::Null,
            (_, f) => json!(f.unwrap_or(TangentField::Circular).to_string()),
        },
        "rig": rig.describe(lights.len()),
        "noise": noise.to_string(),
        "noise_units": "full scale = 1 (the integer formats' white level)",
        "exposure": args.exposure,
        "format": format_name,
        "seed": args.seed,
        "cast_shadows": scene.heights.is_some(),
        "chrome_sphere": chrome.as_ref().map(|c| c.describe()),
        "width": width,
        "height": scene.height,
        "mask_pixels": scene.mask.iter().filter(|&&m| m).count(),
        "clipped_share": clipped as f64 / in_mask_samples.max(1) as f64,
        "conventions": "camera frame x right, y up, z toward the camera; row 0 at the top; \
                        lights point from the surface to the light; gt maps NaN outside the mask",
    });
    write_json(&staging.path("scene.json"), &description)?;
    staging.commit()?;
    let lp = args.output.join("lights.lp");
    if progress::chatty() {
        eprintln!(
            "symframe synth: wrote {} images to {} in {:.1} s",
            lights.len(),
            args.output.display(),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(lp)
}

/// A mirror sphere rendered beside the object (`--chrome-sphere`): in a square as large as the
/// object's frame, to its right, with a black margin of `size / 16` (at least 2) pixels.
struct ChromeSphere {
    size: usize,
    margin: usize,
    scene: Scene,
    brdf: symframe::brdf::Ggx,
}

impl ChromeSphere {
    fn new(size: usize) -> Self {
        let margin = (size / 16).max(2);
        Self {
            size,
            margin,
            scene: Scene::sphere(size - 2 * margin, TangentField::Circular),
            brdf: symframe::brdf::Ggx::new([0.02; 3], [0.9; 3], 0.05, 0.05),
        }
    }

    /// The object's image (`size x size x 3`) with the sphere under light `l` to its right.
    fn beside(&self, object: &[f32], l: DVec3) -> Vec<f32> {
        let sphere = self.scene.render(&self.brdf, l);
        let (m, d) = (self.margin, self.scene.width);
        let row = 3 * self.size;
        let mut out = Vec::with_capacity(2 * object.len());
        for (r, a) in object.chunks_exact(row).enumerate() {
            out.extend_from_slice(a);
            let start = out.len();
            out.resize(start + row, 0.0);
            if (m..m + d).contains(&r) {
                let src = &sphere[3 * (r - m) * d..3 * (r - m + 1) * d];
                out[start + 3 * m..start + 3 * (m + d)].copy_from_slice(src);
            }
        }
        out
    }

    /// A map of `channels` per pixel widened with `fill` on the sphere's side.
    fn widen(&self, v: &[f32], channels: usize, fill: f32) -> Vec<f32> {
        let row = channels * self.size;
        v.chunks_exact(row)
            .flat_map(|a| a.iter().copied().chain(std::iter::repeat_n(fill, row)))
            .collect()
    }

    fn widen_mask(&self, m: &[bool]) -> Vec<bool> {
        m.chunks_exact(self.size)
            .flat_map(|a| {
                a.iter()
                    .copied()
                    .chain(std::iter::repeat_n(false, self.size))
            })
            .collect()
    }

    fn describe(&self) -> Value {
        let r = self.scene.width as f64 / 2.0;
        let (cx, cy) = ((self.size + self.margin) as f64 + r, self.margin as f64 + r);
        json!({
            "cx": cx, "cy": cy, "r": r,
            "circle_convention": "pixels, x right, y down, centre of the top-left pixel (0.5, 0.5)",
            "model": self.brdf.name(),
            "sphere_arg": format!("{cx},{cy},{r}"),
        })
    }
}

fn write_json(path: &Path, v: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v)? + "\n";
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_specs_parse() {
        assert_eq!(
            RigSpec::parse("cone:200").unwrap(),
            RigSpec::Cone {
                n: 200,
                theta_d_max_deg: 65.0
            }
        );
        assert_eq!(
            RigSpec::parse("CONE:50:40").unwrap(),
            RigSpec::Cone {
                n: 50,
                theta_d_max_deg: 40.0
            }
        );
        assert_eq!(RigSpec::parse("diligent").unwrap(), RigSpec::Diligent);
        assert_eq!(
            RigSpec::parse("lp:a/b c.lp").unwrap(),
            RigSpec::Lp(PathBuf::from("a/b c.lp"))
        );
        assert_eq!(RigSpec::Diligent.lights().unwrap().len(), 96);
        for bad in [
            "cone",
            "cone:0",
            "cone:x",
            "cone:10:95",
            "cone:10:40:1",
            "diligent:3",
            "lp:",
            "grid",
        ] {
            let e = RigSpec::parse(bad).unwrap_err().to_string();
            assert!(e.contains("--rig") && !e.contains('\n'), "{bad}: {e}");
        }
    }
}
