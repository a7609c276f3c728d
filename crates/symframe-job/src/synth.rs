//! The synthetic-capture job (`symframe synth`): renders a capture (shape, reflectance model,
//! tangent field, light rig, sensor degradations) and writes it as an `.lp` dataset folder with
//! ground truth and a `scene.json` describing what was rendered.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use serde_json::{json, Value};
use symframe::brdf::{parse_model, Brdf, TangentAxis};
use symframe::render::{diligent_lights, BumpParams, Degradation, Noise, Scene, TangentField};
use symframe::uniform_cone_lights;
use symframe_io::ImageFormat;

use crate::outdir::{OutputDir, Staging};
use crate::{Checkpoint, Control, Interrupted, Progress, Stage};

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
                        format!("rig {spec}: N must be a whole number in 1..=100000")
                    })?;
                let theta_d_max_deg = match parts.next() {
                    None => 65.0,
                    Some(t) => t
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|t| *t > 0.0 && *t < 90.0)
                        .with_context(|| {
                            format!("rig {spec}: THETA_D must be in (0, 90) degrees")
                        })?,
                };
                if parts.next().is_some() {
                    bail!("rig {spec}: expected cone:N or cone:N:THETA_D");
                }
                Ok(RigSpec::Cone { n, theta_d_max_deg })
            }
            ("diligent", None) => Ok(RigSpec::Diligent),
            ("lp", Some(path)) if !path.trim().is_empty() => {
                Ok(RigSpec::Lp(PathBuf::from(path.trim())))
            }
            _ => bail!("rig {spec}: expected cone:N[:THETA_D], diligent or lp:PATH"),
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

    /// The files the rig is read from (none for the built-in rigs): the light file, or every
    /// file of the dataset folder it names.
    pub fn input_files(&self) -> Vec<PathBuf> {
        match self {
            RigSpec::Lp(path) if path.is_dir() => std::fs::read_dir(path)
                .map(|d| d.flatten().map(|e| e.path()).collect())
                .unwrap_or_default(),
            RigSpec::Lp(path) => vec![path.clone()],
            _ => Vec::new(),
        }
    }

    /// What `scene.json` records about the rig.
    pub fn describe(&self, n_lights: usize) -> Value {
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

/// The rendered surface of a synthetic capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SynthShape {
    /// A sphere filling the frame (head-on).
    Sphere,
    /// A cylinder with its axis along image y, filling the frame.
    Cylinder,
    /// A flat patch (see [`SynthConfig::normal_angle`] and the fields after it).
    Plane,
    /// Seeded random Gaussian bumps on flat ground, with cast shadows.
    Bumps,
}

/// Everything a synthetic capture needs.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthConfig {
    /// Output dataset folder (created; the dataset's files in it are replaced).
    pub output: PathBuf,
    /// Write into a non-empty folder that synth did not write.
    pub force: bool,
    /// The rendered surface.
    pub shape: SynthShape,
    /// Image width and height in pixels (8 to 2048).
    pub size: usize,
    /// Reflectance model spec ([`symframe::brdf::parse_model`]).
    pub model: String,
    /// Tangent field spec ([`TangentField::parse`]; `None`: circular, or the plane's angle).
    pub tangent_field: Option<String>,
    /// The light rig.
    pub rig: RigSpec,
    /// Plane only: angle between the normal and the view, degrees (`None`: 0).
    pub normal_angle: Option<f64>,
    /// Plane only: image-plane direction the normal tilts toward, degrees (`None`: 0).
    pub normal_azimuth: Option<f64>,
    /// Plane only: tangent angle about the normal, degrees (`None`: 0).
    pub tangent_angle: Option<f64>,
    /// Bumps only: number of bumps (`None`: the default of [`BumpParams`]).
    pub bumps: Option<usize>,
    /// Bumps only: height scale (`None`: the default of [`BumpParams`]).
    pub relief: Option<f64>,
    /// Sensor noise spec ([`Noise::parse`]).
    pub noise: String,
    /// Image file format.
    pub format: ImageFormat,
    /// Scale applied to the rendered radiance before noise and quantisation (> 0).
    pub exposure: f64,
    /// Seed of the noise and of the bump layout.
    pub seed: u64,
    /// Put a mirror (chrome) sphere beside the object (the images become twice as wide).
    pub chrome_sphere: bool,
    /// With `chrome_sphere`: a matte (Lambertian, grey albedo 0.5) sphere to its right too, for
    /// intensity calibration (the images become three times as wide).
    pub matte_sphere: bool,
    /// Per-light RGB intensities drawn uniformly from `[1 - s, 1 + s]` (seeded by `seed`),
    /// applied to the whole image before noise; 0: every light of intensity 1. The truth is
    /// written as `gt_light_intensities.txt` (not `light_intensities.txt`, which the loader
    /// would apply).
    pub intensity_spread: f64,
}

impl SynthConfig {
    /// A 64-pixel Ward sphere under 1,000 lights over the 65-degree cone, as EXR.
    pub fn new(output: impl Into<PathBuf>) -> Self {
        Self {
            output: output.into(),
            force: false,
            shape: SynthShape::Sphere,
            size: 64,
            model: "ward".into(),
            tangent_field: None,
            rig: RigSpec::Cone {
                n: 1000,
                theta_d_max_deg: 65.0,
            },
            normal_angle: None,
            normal_azimuth: None,
            tangent_angle: None,
            bumps: None,
            relief: None,
            noise: "none".into(),
            format: ImageFormat::Exr,
            exposure: 1.0,
            seed: 0,
            chrome_sphere: false,
            matte_sphere: false,
            intensity_spread: 0.0,
        }
    }
}

/// What a synthetic capture wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOutcome {
    /// The dataset's `lights.lp`.
    pub lp: PathBuf,
    /// Number of lights (images).
    pub lights: usize,
    /// The reflectance model's name.
    pub model: String,
}

/// The scene for the flags, and what `scene.json` records about its shape.
fn build_scene(args: &SynthConfig, field: Option<TangentField>) -> (Scene, Value) {
    let size = args.size;
    let f = field.unwrap_or(TangentField::Circular);
    match args.shape {
        SynthShape::Sphere => (
            Scene::sphere(size, f),
            json!({ "kind": "sphere", "size": size }),
        ),
        SynthShape::Cylinder => (
            Scene::cylinder(size, f),
            json!({ "kind": "cylinder", "size": size, "axis": "image y" }),
        ),
        SynthShape::Plane => {
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
        SynthShape::Bumps => {
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

/// The name `scene.json` records for a format.
fn format_name(f: ImageFormat) -> &'static str {
    match f {
        ImageFormat::Exr => "exr",
        ImageFormat::Png16 => "png16",
        ImageFormat::Png8 => "png8",
    }
}

/// Renders a synthetic capture and writes it as an `.lp` dataset folder with ground truth and
/// `scene.json`; progress is told per rendered image ([`Stage::Rendering`]).
pub fn synth(config: &SynthConfig, ctl: &Control) -> Result<SynthOutcome> {
    if !(8..=2048).contains(&config.size) {
        bail!(
            "the image size must be between 8 and 2048, got {}",
            config.size
        );
    }
    if !(config.exposure.is_finite() && config.exposure > 0.0) {
        bail!(
            "the exposure must be a positive number, got {}",
            config.exposure
        );
    }
    if config.matte_sphere && !config.chrome_sphere {
        bail!("the matte sphere goes beside the chrome sphere: ask for both");
    }
    if !(0.0..1.0).contains(&config.intensity_spread) {
        bail!(
            "the intensity spread must be in [0, 1), got {}",
            config.intensity_spread
        );
    }
    in_locked_target(&config.output, config.force, ctl, |out| {
        render_and_write(config, out, ctl)
    })
}

/// Runs `write` into the synthetic dataset's folder `output` under its lock, as estimate and
/// fit take it: a second synth (or any job) into the folder is refused while this one writes.
/// The folder is checked as a target ([`symframe_io::check_synth_target`]) before and again
/// under the lock; on an error what this run left unfinished is discarded.
pub(crate) fn in_locked_target(
    output: &Path,
    force: bool,
    ctl: &Control,
    write: impl FnOnce(&OutputDir) -> Result<SynthOutcome>,
) -> Result<SynthOutcome> {
    symframe_io::check_synth_target(output, force)?;
    let out = OutputDir::lock(output)?;
    (ctl.checkpoint)(Checkpoint::OutputLocked);
    let result = symframe_io::check_synth_target(output, force)
        .map_err(anyhow::Error::from)
        .and_then(|()| write(&out));
    if result.is_err() {
        out.discard_unfinished();
    }
    result
}

/// The sensor degradation of `synth` and `synth --near`: exposure, noise and seed, the rest off.
pub(crate) fn synth_degradation(exposure: f64, noise: Noise, seed: u64) -> Degradation {
    Degradation {
        exposure: exposure as f32,
        noise,
        seed,
        ..Degradation::default()
    }
}

/// Renders the dataset and writes it into the (locked) output folder.
fn render_and_write(config: &SynthConfig, out: &OutputDir, ctl: &Control) -> Result<SynthOutcome> {
    let brdf: Box<dyn Brdf> = parse_model(&config.model).map_err(anyhow::Error::msg)?;
    let field = config
        .tangent_field
        .as_deref()
        .map(TangentField::parse)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    let noise = Noise::parse(&config.noise).map_err(anyhow::Error::msg)?;
    let rig = &config.rig;
    let lights = rig.lights()?;
    let squares = 1 + config.chrome_sphere as usize + config.matte_sphere as usize;
    let n = config.size * config.size * squares;
    let bytes = (lights.len() * n * 3 * 4) as f64;
    if bytes > MAX_STACK_BYTES {
        bail!(
            "{} lights of {}x{} images need {:.1} GiB in memory; use fewer lights or a smaller size",
            lights.len(),
            config.size * squares,
            config.size,
            bytes / (1u64 << 30) as f64
        );
    }
    let (scene, shape_json) = build_scene(config, field);
    let degradation = synth_degradation(config.exposure, noise, config.seed);
    let n_lights = lights.len() as u64;
    let rendered = std::sync::atomic::AtomicU64::new(0);
    let stop = || ctl.stop.load(std::sync::atomic::Ordering::SeqCst);
    let chrome = config
        .chrome_sphere
        .then(|| ChromeSphere::new(config.size, config.matte_sphere));
    let intensities = light_intensities(lights.len(), config.intensity_spread, config.seed);
    let images: Vec<Vec<f32>> = lights
        .par_iter()
        .enumerate()
        .map(|(i, &l)| -> Result<Vec<f32>> {
            if stop() {
                return Err(Interrupted.into());
            }
            let img = match &chrome {
                None if intensities.is_none() => {
                    scene.render_degraded(brdf.as_ref(), l, i, &degradation)
                }
                None => {
                    let mut img = scene.render(brdf.as_ref(), l);
                    if let Some(e) = &intensities {
                        scale(&mut img, e[i]);
                    }
                    degradation.apply(&mut img, i);
                    img
                }
                Some(c) => {
                    let mut img = c.beside(&scene.render(brdf.as_ref(), l), l);
                    if let Some(e) = &intensities {
                        scale(&mut img, e[i]);
                    }
                    degradation.apply(&mut img, i);
                    img
                }
            };
            let done = rendered.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            ctl.report(Progress::new(Stage::Rendering, done, n_lights));
            Ok(img)
        })
        .collect::<Result<_>>()?;

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

    let (format, format_name) = (config.format, format_name(config.format));
    let staging = Staging::new(&config.output)?;
    let widen = |v: Vec<f32>, fill: f32| match &chrome {
        None => v,
        Some(c) => c.widen(&v, 3, fill),
    };
    let mask = match &chrome {
        None => scene.mask.clone(),
        Some(c) => c.widen_mask(&scene.mask),
    };
    let width = scene.width * squares;
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
    .with_context(|| format!("{}: cannot write the dataset", config.output.display()))?;
    drop(images);

    let description = json!({
        "version": env!("CARGO_PKG_VERSION"),
        "generator": "symframe synth",
        "model": brdf.name(),
        "model_spec": config.model,
        "tangent_axis": match brdf.tangent_axis() {
            TangentAxis::X => "x",
            TangentAxis::Y => "y",
            TangentAxis::None => "none",
        },
        "shape": shape_json,
        "tangent_field": match (config.shape, field) {
            (SynthShape::Plane, None) => Value::Null,
            (_, f) => json!(f.unwrap_or(TangentField::Circular).to_string()),
        },
        "rig": rig.describe(lights.len()),
        "noise": noise.to_string(),
        "noise_units": "full scale = 1 (the integer formats' white level)",
        "exposure": config.exposure,
        "format": format_name,
        "seed": config.seed,
        "cast_shadows": scene.heights.is_some(),
        "chrome_sphere": chrome.as_ref().map(|c| c.describe()),
        "matte_sphere": chrome.as_ref().and_then(|c| c.describe_matte()),
        "intensity_spread": config.intensity_spread,
        "width": width,
        "height": scene.height,
        "mask_pixels": scene.mask.iter().filter(|&&m| m).count(),
        "clipped_share": clipped as f64 / in_mask_samples.max(1) as f64,
        "conventions": "camera frame x right, y up, z toward the camera; row 0 at the top; \
                        lights point from the surface to the light; gt maps NaN outside the mask",
    });
    if let Some(e) = &intensities {
        let rows: Vec<String> = e
            .iter()
            .map(|c| format!("{:.6} {:.6} {:.6}", c[0], c[1], c[2]))
            .collect();
        let path = staging.path("gt_light_intensities.txt");
        symframe_io::write_bytes(&path, (rows.join("\n") + "\n").as_bytes())?;
    }
    write_json(&staging.path("scene.json"), &description)?;
    // The rig's own light file (or its dataset's files) is an input: never replaced.
    let staged: Vec<String> = std::fs::read_dir(staging.dir())?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    out.guard_inputs(
        rig.input_files(),
        "scene.json",
        &|n| staged.iter().any(|s| s == n),
        &|_| true,
    )?;
    staging.commit()?;
    Ok(SynthOutcome {
        lp: config.output.join("lights.lp"),
        lights: lights.len(),
        model: brdf.name().to_string(),
    })
}

/// A mirror sphere rendered beside the object (`--chrome-sphere`): in a square as large as the
/// object's frame, to its right, with a black margin of `size / 16` (at least 2) pixels; and
/// optionally a matte sphere in a third square to the right of it.
struct ChromeSphere {
    size: usize,
    margin: usize,
    scene: Scene,
    ball: symframe::render::MirrorBall,
    matte: Option<symframe::brdf::Lambertian>,
}

impl ChromeSphere {
    fn new(size: usize, matte: bool) -> Self {
        let margin = (size / 16).max(2);
        Self {
            size,
            margin,
            scene: Scene::sphere(size - 2 * margin, TangentField::Circular),
            // A chrome ball as a camera sees it: a lamp of half a degree, a dim room, the rim
            // and the lamp's reflection anti-aliased and blurred by the lens; the lamp clips in
            // integer formats, the room stays well below the white level.
            ball: symframe::render::MirrorBall {
                lamp: 1000.0,
                room: 0.3,
                ..symframe::render::MirrorBall::new(
                    (size - 2 * margin) as f64 / 2.0,
                    (size - 2 * margin) as f64 / 2.0,
                    (size - 2 * margin) as f64 / 2.0,
                )
            },
            matte: matte.then(|| symframe::brdf::Lambertian::new([0.5; 3])),
        }
    }

    /// Squares to the right of the object's.
    fn extra(&self) -> usize {
        1 + self.matte.is_some() as usize
    }

    /// The object's image (`size x size x 3`) with the sphere(s) under light `l` to its right.
    fn beside(&self, object: &[f32], l: DVec3) -> Vec<f32> {
        let d = self.scene.width;
        let grey = self.ball.render(d, d, l);
        let mut spheres = vec![grey.iter().flat_map(|&v| [v; 3]).collect::<Vec<f32>>()];
        if let Some(m) = &self.matte {
            spheres.push(self.scene.render(m, l));
        }
        let (m, d) = (self.margin, self.scene.width);
        let row = 3 * self.size;
        let mut out = Vec::with_capacity((1 + spheres.len()) * object.len());
        for (r, a) in object.chunks_exact(row).enumerate() {
            out.extend_from_slice(a);
            for sphere in &spheres {
                let start = out.len();
                out.resize(start + row, 0.0);
                if (m..m + d).contains(&r) {
                    let src = &sphere[3 * (r - m) * d..3 * (r - m + 1) * d];
                    out[start + 3 * m..start + 3 * (m + d)].copy_from_slice(src);
                }
            }
        }
        out
    }

    /// A map of `channels` per pixel widened with `fill` on the spheres' side.
    fn widen(&self, v: &[f32], channels: usize, fill: f32) -> Vec<f32> {
        let row = channels * self.size;
        v.chunks_exact(row)
            .flat_map(|a| {
                a.iter()
                    .copied()
                    .chain(std::iter::repeat_n(fill, row * self.extra()))
            })
            .collect()
    }

    fn widen_mask(&self, m: &[bool]) -> Vec<bool> {
        m.chunks_exact(self.size)
            .flat_map(|a| {
                a.iter()
                    .copied()
                    .chain(std::iter::repeat_n(false, self.size * self.extra()))
            })
            .collect()
    }

    /// What `scene.json` records about the matte sphere: its circle.
    fn describe_matte(&self) -> Option<Value> {
        let lambertian = self.matte.as_ref()?;
        let r = self.scene.width as f64 / 2.0;
        let (cx, cy) = (
            (2 * self.size + self.margin) as f64 + r,
            self.margin as f64 + r,
        );
        Some(json!({
            "cx": cx, "cy": cy, "r": r,
            "model": lambertian.name(),
            "albedo": lambertian.albedo,
            "sphere_arg": format!("{cx},{cy},{r}"),
        }))
    }

    fn describe(&self) -> Value {
        let r = self.scene.width as f64 / 2.0;
        let (cx, cy) = ((self.size + self.margin) as f64 + r, self.margin as f64 + r);
        json!({
            "cx": cx, "cy": cy, "r": r,
            "circle_convention": "pixels, x right, y down, centre of the top-left pixel (0.5, 0.5)",
            "model": format!(
                "mirror ball: lamp {:.2} degrees radius, radiance {}, room {}, reflectance {}, lens blur {} px",
                self.ball.lamp_radius.to_degrees(),
                self.ball.lamp,
                self.ball.room,
                self.ball.reflectance,
                self.ball.blur
            ),
            "sphere_arg": format!("{cx},{cy},{r}"),
        })
    }
}

/// Per-light RGB intensities uniform in `[1 - spread, 1 + spread)`, one stream per light under
/// `seed`; `None` for no spread.
fn light_intensities(n: usize, spread: f64, seed: u64) -> Option<Vec<[f32; 3]>> {
    (spread > 0.0).then(|| {
        (0..n)
            .map(|i| {
                let mut rng = symframe::render::Rng::for_image(seed ^ 0x1a7e_5ca1e, i as u64);
                [0; 3].map(|_| rng.range(1.0 - spread, 1.0 + spread) as f32)
            })
            .collect()
    })
}

/// Multiplies an RGB image by a light's intensity.
fn scale(img: &mut [f32], e: [f32; 3]) {
    for px in img.chunks_exact_mut(3) {
        for (v, k) in px.iter_mut().zip(e) {
            *v *= k;
        }
    }
}

fn write_json(path: &Path, v: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v)? + "\n";
    Ok(symframe_io::write_bytes(path, text.as_bytes())?)
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
            assert!(e.starts_with("rig ") && !e.contains('\n'), "{bad}: {e}");
        }
    }
}
