//! The near-light synthetic capture (`symframe synth --near`): two spheres side by side seen by
//! a pinhole camera, lit by isotropic point lights on a dome about them, written as a DiLiGenT
//! folder with `light_positions.txt`, `K.txt` and the truth (normals, tangents, depth).
//!
//! The scene, in the camera frame (x right, y up, z toward the viewer): two unit spheres with
//! centres 2.2 apart on the x axis at depth `camera_ratio * W` (W = 4.2, the pair's width), so
//! the gap between them is 0.2; `lights` lights spread evenly over the dome of radius
//! `dome_ratio * W` about the pair's centre, from 5 degrees above its equator (the plane through
//! the centres facing the camera) to its top; a camera of `size x size/2` pixels whose
//! horizontal field of view spans 1.1 W at the spheres' depth. The left sphere is made of the
//! first model, the right one of the second; the brushing tangents circle each sphere's axis
//! toward the camera. Every light has the intensity `(dome_ratio * W)^2` (radiance about 1 on a
//! white surface facing a light).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use serde_json::json;
use symframe::brdf::{parse_model, Brdf};
use symframe::render::{dome_lights, Ball, Degradation, NearMirrorBalls, NearScene, Noise};
use symframe::Pinhole;
use symframe_io::{ImageFormat, NearFiles};

use crate::outdir::Staging;
use crate::synth::{in_locked_target, synth_degradation, SynthOutcome};
use crate::{Control, Interrupted, Progress, Stage};

/// The pair of spheres' width (two unit spheres, centres 2.2 apart).
pub const PAIR_WIDTH: f64 = 4.2;

/// The folder of the chrome spheres' calibration images ([`NearSynthConfig::chrome_spheres`]).
pub const CHROME_FOLDER: &str = "chrome";

/// The radius of the lamps the chrome spheres reflect.
const CHROME_LAMP_RADIUS: f64 = 0.05;

/// Everything a near-light synthetic capture needs.
#[derive(Debug, Clone, PartialEq)]
pub struct NearSynthConfig {
    /// Output dataset folder (created; the dataset's files in it are replaced).
    pub output: PathBuf,
    /// Write into a non-empty folder that synth did not write.
    pub force: bool,
    /// Image width in pixels (16 to 2048); the height is half of it.
    pub size: usize,
    /// Reflectance model specs of the left and the right sphere
    /// ([`symframe::brdf::parse_model`]).
    pub models: [String; 2],
    /// Number of lights on the dome (4 to 10,000).
    pub lights: usize,
    /// Dome radius over the pair's width.
    pub dome_ratio: f64,
    /// Camera distance (to the spheres' centres) over the pair's width.
    pub camera_ratio: f64,
    /// Sensor noise spec ([`Noise::parse`]).
    pub noise: String,
    /// Image file format.
    pub format: ImageFormat,
    /// Scale applied to the rendered radiance before noise and quantisation (> 0).
    pub exposure: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Also render the calibration images of two chrome spheres where the object's spheres
    /// are (the object taken away), under the same lights and camera, into `chrome/`
    /// ([`symframe::render::NearMirrorBalls`]: a lamp of radius 0.05 and radiance 5000, a room
    /// of radiance 1), for `symframe calibrate --K`.
    pub chrome_spheres: bool,
}

impl NearSynthConfig {
    /// A 128-pixel-wide render of a GGX plastic and a brushed Ward sphere under 150 lights on a
    /// dome twice the pair's width in radius, the camera at three times its width, as EXR.
    pub fn new(output: impl Into<PathBuf>) -> Self {
        Self {
            output: output.into(),
            force: false,
            size: 128,
            models: [
                "ggx:kd=0.4,f0=0.04,ax=0.15,ay=0.15".into(),
                "ward:kd=0.1,ks=0.6,ax=0.08,ay=0.3".into(),
            ],
            lights: 150,
            dome_ratio: 2.0,
            camera_ratio: 3.0,
            noise: "none".into(),
            format: ImageFormat::Exr,
            exposure: 1.0,
            seed: 0,
            chrome_spheres: false,
        }
    }

    /// The scene's camera and spheres.
    pub fn scene(&self) -> NearScene {
        let depth = self.camera_ratio * PAIR_WIDTH;
        let half = 0.55 * PAIR_WIDTH;
        let fov = 2.0 * (half / depth).atan().to_degrees();
        let (w, h) = (self.size, self.size / 2);
        let camera = Pinhole::centred(w, h, fov);
        let balls = [-1.1, 1.1].map(|x| Ball {
            centre: DVec3::new(x, 0.0, -depth),
            radius: 1.0,
            material: (x > 0.0) as usize,
        });
        NearScene::spheres(w, h, camera, &balls)
    }

    /// The centre of the pair (and of the dome).
    pub fn centre(&self) -> DVec3 {
        DVec3::new(0.0, 0.0, -self.camera_ratio * PAIR_WIDTH)
    }
}

/// Renders a near-light capture and writes it as a DiLiGenT folder with ground truth and
/// `scene.json`; progress is told per rendered image ([`Stage::Rendering`]).
pub fn synth_near(config: &NearSynthConfig, ctl: &Control) -> Result<SynthOutcome> {
    if !(16..=2048).contains(&config.size) {
        bail!(
            "the image width must be between 16 and 2048, got {}",
            config.size
        );
    }
    if !(4..=10_000).contains(&config.lights) {
        bail!("the dome needs 4 to 10000 lights, got {}", config.lights);
    }
    for (what, v) in [
        ("dome radius", config.dome_ratio),
        ("camera distance", config.camera_ratio),
    ] {
        if !(v.is_finite() && (0.3..=1000.0).contains(&v)) {
            bail!("the {what} over the object's width must be in [0.3, 1000], got {v}");
        }
    }
    if config.camera_ratio * PAIR_WIDTH <= config.dome_ratio * PAIR_WIDTH * 0.2 + 1.0 {
        bail!("the camera must stand clear of the spheres and the lights");
    }
    if !(config.exposure.is_finite() && config.exposure > 0.0) {
        bail!(
            "the exposure must be a positive number, got {}",
            config.exposure
        );
    }
    in_locked_target(&config.output, config.force, ctl, |_| {
        render_and_write(config, ctl)
    })
}

/// One degraded image per light, rendered in parallel with progress and a stop check: the
/// object's pass and the chrome spheres' pass alike.
fn render_each<L: Sync>(
    lights: &[L],
    degradation: &Degradation,
    ctl: &Control,
    render: impl Fn(&L) -> Vec<f32> + Sync,
) -> Result<Vec<Vec<f32>>> {
    let n_lights = lights.len() as u64;
    let rendered = std::sync::atomic::AtomicU64::new(0);
    lights
        .par_iter()
        .enumerate()
        .map(|(i, light)| -> Result<Vec<f32>> {
            if ctl.stop.load(std::sync::atomic::Ordering::SeqCst) {
                return Err(Interrupted.into());
            }
            let mut img = render(light);
            degradation.apply(&mut img, i);
            let done = rendered.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            ctl.report(Progress::new(Stage::Rendering, done, n_lights));
            Ok(img)
        })
        .collect()
}

fn render_and_write(config: &NearSynthConfig, ctl: &Control) -> Result<SynthOutcome> {
    let models: Vec<Box<dyn Brdf>> = config
        .models
        .iter()
        .map(|m| parse_model(m).map_err(anyhow::Error::msg))
        .collect::<Result<_>>()?;
    let materials: Vec<&dyn Brdf> = models.iter().map(|m| m.as_ref()).collect();
    let noise = Noise::parse(&config.noise).map_err(anyhow::Error::msg)?;
    let scene = config.scene();
    let centre = config.centre();
    let radius = config.dome_ratio * PAIR_WIDTH;
    let lights = dome_lights(config.lights, centre, radius, 5.0, radius * radius);
    let degradation = synth_degradation(config.exposure, noise, config.seed);
    let images = render_each(&lights, &degradation, ctl, |light| {
        scene.render(&materials, light)
    })?;
    let positions: Vec<DVec3> = lights.iter().map(|l| l.position).collect();
    let directions: Vec<DVec3> = positions
        .iter()
        .map(|p| (*p - centre).normalize())
        .collect();
    let mask = scene.mask();
    let depth = scene.depth();
    let staging = Staging::new(&config.output)?;
    symframe_io::write_near_dataset(
        staging.dir(),
        &NearFiles {
            positions: &positions,
            directions: &directions,
            k: scene.camera.k(),
            gt_depth: Some(&depth),
        },
        &images,
        scene.width,
        scene.height,
        config.format,
        Some(&scene.gt_normals()),
        Some(&scene.gt_tangents()),
        Some(&mask),
    )
    .with_context(|| format!("{}: cannot write the dataset", config.output.display()))?;
    if config.chrome_spheres {
        let balls: Vec<(DVec3, f64)> = scene.balls.iter().map(|b| (b.centre, b.radius)).collect();
        let mirrors = NearMirrorBalls {
            lamp_radius: CHROME_LAMP_RADIUS,
            ..NearMirrorBalls::new(scene.width, scene.height, scene.camera, &balls)
        };
        let chrome = render_each(&lights, &degradation, ctl, |light| {
            mirrors
                .render(light.position)
                .into_iter()
                .flat_map(|v| [v; 3])
                .collect()
        })?;
        symframe_io::write_near_dataset(
            &staging.path(CHROME_FOLDER),
            &NearFiles {
                positions: &positions,
                directions: &directions,
                k: scene.camera.k(),
                gt_depth: None,
            },
            &chrome,
            scene.width,
            scene.height,
            config.format,
            None,
            None,
            None,
        )
        .with_context(|| {
            format!(
                "{}: cannot write the chrome spheres' images",
                config.output.display()
            )
        })?;
    }
    let description = json!({
        "version": env!("CARGO_PKG_VERSION"),
        "generator": "symframe synth --near",
        "models": models.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "model_specs": config.models,
        "spheres": scene.balls.iter().map(|b| json!({
            "centre": b.centre.to_array(), "radius": b.radius, "model": b.material,
        })).collect::<Vec<_>>(),
        "tangent_field": "circles about each sphere's axis toward the camera",
        "camera": { "K": scene.camera.k(), "width": scene.width, "height": scene.height },
        "dome": {
            "centre": centre.to_array(), "radius": radius, "lights": lights.len(),
            "min_elevation_deg": 5.0, "intensity": radius * radius,
        },
        "object_width": PAIR_WIDTH,
        "dome_ratio": config.dome_ratio,
        "camera_ratio": config.camera_ratio,
        "noise": noise.to_string(),
        "exposure": config.exposure,
        "format": match config.format {
            ImageFormat::Exr => "exr",
            ImageFormat::Png16 => "png16",
            ImageFormat::Png8 => "png8",
        },
        "seed": config.seed,
        "chrome_spheres": config.chrome_spheres.then(|| json!({
            "folder": CHROME_FOLDER,
            "centres": scene.balls.iter().map(|b| b.centre.to_array()).collect::<Vec<_>>(),
            "radius": 1.0,
            "lamp_radius": CHROME_LAMP_RADIUS,
        })),
        "mask_pixels": mask.iter().filter(|&&m| m).count(),
        "conventions": "camera frame x right, y up, z toward the camera, origin at the centre \
                        of projection; K in OpenCV's convention (u right, v down, top-left \
                        pixel centre at (0, 0)); gt_depth along the optical axis; gt maps NaN \
                        outside the mask",
    });
    let text = serde_json::to_string_pretty(&description)? + "\n";
    symframe_io::write_bytes(&staging.path("scene.json"), text.as_bytes())?;
    staging.commit()?;
    Ok(SynthOutcome {
        lp: config.output.clone(),
        lights: lights.len(),
        model: models
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>()
            .join(" + "),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_near_capture_reads_back_with_its_camera_and_lights() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("near");
        let config = NearSynthConfig {
            size: 32,
            lights: 12,
            ..NearSynthConfig::new(&out)
        };
        let done = synth_near(&config, &Control::default()).unwrap();
        assert_eq!(done.lights, 12);
        let ds = symframe_io::open_dataset(&out).unwrap();
        assert_eq!(ds.images.len(), 12);
        assert!(ds.warnings.is_empty(), "{:?}", ds.warnings);
        let g = symframe_io::open_near_geometry(&ds).unwrap().unwrap();
        assert_eq!(g.camera, config.scene().camera);
        assert!(g.warnings.is_empty(), "{:?}", g.warnings);
        let (centre, radius) = g.dome.unwrap();
        assert!((centre - config.centre()).length() < 1e-9);
        assert!((radius - 2.0 * PAIR_WIDTH).abs() < 1e-9);
        // The directions a distant-light reader gets are those from the dome's centre.
        for (l, p) in ds.lights.iter().zip(&g.lights) {
            assert!(l.angle_between(p.position - centre) < 1e-9);
        }
        let (shape, depth) = symframe_io::read_npy_f32(&out.join("gt_depth.npy")).unwrap();
        assert_eq!(shape, [16, 32]);
        let seen: Vec<f32> = depth.into_iter().filter(|d| d.is_finite()).collect();
        assert!(!seen.is_empty());
        let far = config.camera_ratio * PAIR_WIDTH;
        assert!(seen.iter().all(|&d| (far - 1.0..far).contains(&(d as f64))));
        // Bad settings are refused before anything is written.
        let bad = NearSynthConfig {
            lights: 2,
            ..NearSynthConfig::new(d.path().join("bad"))
        };
        let e = synth_near(&bad, &Control::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("4 to 10000 lights"), "{e}");
    }
}
