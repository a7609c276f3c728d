//! The calibration job (`symframe calibrate`): light directions from a mirror sphere in the
//! images, written as an `.lp` file, with a picture of the detected highlights and a JSON
//! record beside it. The per-image highlight and the sphere detection are the core crate's
//! ([`symframe::Highlight::find`], [`symframe::Detection::find_all`]); this module reads the images
//! and writes the files.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use symframe::{CalibrationError, CalibrationParams, Circle, Detection, Highlight};
use symframe_io::DecodeOptions;

use crate::{Control, Interrupted};

mod images;

pub(crate) use images::{
    circle_rows, image_list, image_size, keep_rows, read_grey, relative_to, DECODE_MEMORY,
};

/// Everything a calibration needs.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateConfig {
    /// A folder of images (every image file in it, sorted by name; `mask.*` left out), an
    /// `.lp` file (its images), or a list file of image paths (one per line, relative to it).
    pub images: PathBuf,
    /// The mirror sphere's circle in pixels (`None`: detect it).
    pub sphere: Option<Circle>,
    /// The `.lp` file to write (image paths relative to its folder); `<stem>-highlights.png`
    /// and `<stem>-calibration.json` are written beside it.
    pub output: PathBuf,
    /// A highlight is the pixels above this fraction of its peak (above the sphere's median).
    pub threshold: f64,
    /// Fail on the first image without a single clear highlight (else drop it with a warning).
    pub strict: bool,
    /// A diffuse (matte, grey) sphere's circle: per light, its RGB intensity is measured there
    /// ([`symframe::CalibrationParams::intensity`]) and written as `light_intensities.txt` beside
    /// the `.lp`, normalised to a mean of 1 over every light and channel.
    pub matte_sphere: Option<Circle>,
    /// How images are decoded.
    pub decode: DecodeOptions,
}

impl CalibrateConfig {
    /// Detect the sphere, threshold 0.3, drop unclear images, saturation at 0.995.
    pub fn new(images: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        Self {
            images: images.into(),
            sphere: None,
            output: output.into(),
            threshold: 0.3,
            strict: false,
            matte_sphere: None,
            decode: DecodeOptions {
                saturation: 0.995,
                ..DecodeOptions::default()
            },
        }
    }
}

/// How the sphere was found, when it was detected.
#[derive(Debug, Clone, Serialize)]
pub struct SphereDetection {
    /// Share of the images whose brightest spot is in the sphere.
    pub highlight_share: f64,
    /// Roundness of the detected outline.
    pub roundness: f64,
}

/// No sphere was given and none was found in the images.
#[derive(Debug, Clone)]
pub struct SphereNotFound {
    /// The images argument.
    pub images: PathBuf,
    /// What the detection found wrong.
    pub reason: String,
}

impl std::fmt::Display for SphereNotFound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: cannot find the mirror sphere: {}",
            self.images.display(),
            self.reason
        )
    }
}

impl std::error::Error for SphereNotFound {}

/// A given circle (the mirror sphere's or the matte sphere's) does not fit the images.
#[derive(Debug, Clone)]
pub struct CircleDoesNotFit {
    /// `mirror` or `matte`.
    pub sphere: &'static str,
    /// The circle.
    pub circle: Circle,
    /// The images' size.
    pub size: (usize, usize),
    /// Why not ([`Circle::check_fits`]).
    pub reason: String,
}

impl std::fmt::Display for CircleDoesNotFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.circle;
        write!(
            f,
            "the {} sphere's circle {},{},{} (CX,CY,R) does not fit the {}x{} image: {}",
            self.sphere, c.cx, c.cy, c.r, self.size.0, self.size.1, self.reason
        )
    }
}

impl std::error::Error for CircleDoesNotFit {}

/// One image's outcome in `<stem>-calibration.json`.
#[derive(Debug, Serialize)]
pub struct ImageRecord {
    /// The image path.
    pub image: String,
    /// Whether its light is in the `.lp` file.
    pub used: bool,
    /// Highlight centre `(x, y)`, pixels (x right, y down, top-left pixel centre (0.5, 0.5)).
    pub highlight: Option<[f64; 2]>,
    /// The light direction (x right, y up, z toward the camera; surface toward light).
    pub light: Option<[f64; 3]>,
    /// Pixels in the highlight spot.
    pub pixels: Option<usize>,
    /// Saturated pixels in it.
    pub saturated: Option<usize>,
    /// The light's RGB intensity from the matte sphere, before normalising (times the
    /// sphere's albedo).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intensity: Option<[f64; 3]>,
    /// Why it was dropped.
    pub error: Option<String>,
}

/// What `<stem>-calibration.json` holds.
#[derive(Debug, Serialize)]
pub struct CalibrationReport {
    /// symframe version.
    pub version: &'static str,
    /// The sphere's circle.
    pub sphere: Circle,
    /// `given` (--sphere) or `detected`.
    pub sphere_source: &'static str,
    /// Detection figures (share of images whose brightest spot is in the sphere, roundness).
    pub detection: Option<SphereDetection>,
    /// Images read.
    pub images: usize,
    /// Images whose light was written.
    pub used: usize,
    /// Per image.
    pub records: Vec<ImageRecord>,
    /// The conventions of the figures.
    pub conventions: &'static str,
    /// The matte sphere's circle, when intensities were measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matte_sphere: Option<Circle>,
    /// The mean of the raw intensities over lights and channels, by which they were divided
    /// (so that `light_intensities.txt` has a mean of 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intensity_mean_raw: Option<f64>,
    /// The files written: the `.lp`, the picture, this report.
    #[serde(skip)]
    pub written: [PathBuf; 3],
    /// `light_intensities.txt`, when intensities were measured.
    #[serde(skip)]
    pub intensities_file: Option<PathBuf>,
}

/// Draws the picture of the highlights: the brightest of all images around the sphere
/// (tone-mapped), the circle in yellow, found highlights as green crosses and the spots of
/// ambiguous images as red ones, enlarged to at least 384 pixels across.
fn picture(
    max_image: &[f32],
    width: usize,
    height: usize,
    circle: &Circle,
    found: &[(f64, f64)],
    bad: &[(f64, f64)],
) -> (usize, usize, Vec<u8>) {
    let margin = 4.0;
    let clip = |v: f64, n: usize| (v.max(0.0) as usize).min(n);
    let (c0, c1) = (
        clip((circle.cx - circle.r - margin).floor(), width),
        clip((circle.cx + circle.r + margin).ceil(), width),
    );
    let (r0, r1) = (
        clip((circle.cy - circle.r - margin).floor(), height),
        clip((circle.cy + circle.r + margin).ceil(), height),
    );
    let (cw, ch) = ((c1 - c0).max(1), (r1 - r0).max(1));
    let k = (384 / cw.max(ch)).max(1);
    let (ow, oh) = (cw * k, ch * k);
    let mut vals: Vec<f32> = max_image
        .iter()
        .filter(|v| v.is_finite())
        .cloned()
        .collect();
    vals.sort_by(f32::total_cmp);
    let white = vals
        .get(vals.len() * 99 / 100)
        .cloned()
        .unwrap_or(1.0)
        .max(1e-12);
    let mut rgb = vec![0u8; ow * oh * 3];
    for oy in 0..oh {
        for ox in 0..ow {
            let (col, row) = (c0 + ox / k, r0 + oy / k);
            let v = if col < width && row < height {
                max_image[row * width + col]
            } else {
                0.0
            };
            let g = if v.is_finite() {
                symframe_io::linear_to_srgb((v / white).clamp(0.0, 1.0))
            } else {
                1.0
            };
            let b = (g * 200.0).round() as u8;
            rgb[3 * (oy * ow + ox)..3 * (oy * ow + ox) + 3].copy_from_slice(&[b, b, b]);
        }
    }
    let mut put = |x: f64, y: f64, c: [u8; 3]| {
        if x >= 0.0 && y >= 0.0 && (x as usize) < ow && (y as usize) < oh {
            let i = 3 * (y as usize * ow + x as usize);
            rgb[i..i + 3].copy_from_slice(&c);
        }
    };
    // Image point to picture point.
    let to = |x: f64, y: f64| ((x - c0 as f64) * k as f64, (y - r0 as f64) * k as f64);
    let steps = (8.0 * circle.r * k as f64) as usize + 16;
    for s in 0..steps {
        let a = s as f64 / steps as f64 * std::f64::consts::TAU;
        let (x, y) = to(
            circle.cx + circle.r * a.cos(),
            circle.cy + circle.r * a.sin(),
        );
        put(x, y, [255, 220, 0]);
    }
    for (list, colour) in [(found, [0u8, 255, 0]), (bad, [255, 40, 40])] {
        for &(x, y) in list {
            let (px, py) = to(x, y);
            for d in -3i32..=3 {
                put(px + d as f64, py, colour);
                put(px, py + d as f64, colour);
            }
        }
    }
    (ow, oh, rgb)
}

/// Refuses a run whose `.lp`, highlights picture or JSON would replace one of its inputs (the
/// `.lp` or list it reads, an image), as `calibrate lights.lp -o lights.lp` would.
fn refuse_inputs_as_outputs(config: &CalibrateConfig, images: &[PathBuf]) -> Result<()> {
    let canon = |p: &Path| p.canonicalize().ok();
    let inputs: Vec<PathBuf> = std::iter::once(config.images.as_path())
        .chain(images.iter().map(PathBuf::as_path))
        .filter_map(canon)
        .collect();
    let stem = config
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let outputs = [
        config.output.clone(),
        config
            .output
            .with_file_name(format!("{stem}-highlights.png")),
        config
            .output
            .with_file_name(format!("{stem}-calibration.json")),
    ];
    for o in &outputs {
        if canon(o).is_some_and(|c| inputs.contains(&c)) {
            bail!(
                "{}: is an input of this run, and the output would replace it; write the .lp \
                 elsewhere (-o)",
                o.display()
            );
        }
    }
    Ok(())
}

/// Runs a calibration: finds the highlight of every image on the sphere and writes the `.lp`,
/// the picture and the JSON report; returns the report. Dropped images are told through
/// `ctl`'s warnings; its stop flag is polled between images.
pub fn calibrate(config: &CalibrateConfig, ctl: &Control) -> Result<CalibrationReport> {
    check_config(config)?;
    let images = image_list(&config.images)?;
    refuse_inputs_as_outputs(config, &images)?;
    let opts = config.decode.clone();
    let stopped = || ctl.stop.load(std::sync::atomic::Ordering::SeqCst);
    let (w, h) = image_size(&images[0], &opts)?;
    // Given circles, checked before anything is computed with them (a radius far beyond the
    // image would make the highlight search run without end).
    for (sphere, circle) in [("mirror", config.sphere), ("matte", config.matte_sphere)] {
        if let Some(c) = circle {
            c.check_fits(w, h).map_err(|reason| CircleDoesNotFit {
                sphere,
                circle: c,
                size: (w, h),
                reason,
            })?;
        }
    }

    // Images are read a band of rows at a time, as many at once as fit in DECODE_MEMORY
    // (their grey values, 4 bytes a pixel, and the matte sphere's rows in RGB); a large one
    // alone, keeping only what it needs.
    let matte_rows = config.matte_sphere.map_or(0..0, |c| circle_rows(&c, h));
    let at_once = (DECODE_MEMORY / (4 * w * h + 12 * w * matte_rows.len())).max(1);
    // The sphere: given, or found in the mean image.
    let (circle, source, detection) = match config.sphere {
        Some(c) => (c, "given", None),
        None => detect_sphere(config, &images, (w, h), at_once, &stopped)?,
    };
    let params = CalibrationParams {
        highlight_fraction: config.threshold,
        ..CalibrationParams::default()
    };
    // The brightest of all images (NaN where any was saturated), for the picture.
    let max_image = std::sync::Mutex::new(vec![0.0f32; w * h]);
    type Outcome = (
        Result<Highlight, CalibrationError>,
        Option<Result<[f64; 3], CalibrationError>>,
    );
    let sphere_rows = circle_rows(&circle, h);
    let mut results: Vec<Outcome> = Vec::with_capacity(images.len());
    for batch in images.chunks(at_once) {
        let done = batch
            .par_iter()
            .map(|p| -> Result<_> {
                if stopped() {
                    return Err(Interrupted.into());
                }
                // The image's grey values where the highlight is looked for, the sphere's
                // rows: the others are never written, so a large image's are never resident
                // (a zeroed allocation is mapped lazily).
                let mut g = vec![0.0f32; w * h];
                let mut rgb = vec![0.0f32; 3 * w * matte_rows.len()];
                read_grey(p, &opts, (w, h), &mut |y, band, band_rgb| {
                    let sphere = &mut g[sphere_rows.start * w..sphere_rows.end * w];
                    keep_rows(band, y, w, &sphere_rows, sphere);
                    keep_rows(band_rgb, y, 3 * w, &matte_rows, &mut rgb);
                    let mut m = max_image.lock().unwrap_or_else(|e| e.into_inner());
                    for (m, v) in m[y * w..].iter_mut().zip(band) {
                        if !v.is_finite() {
                            *m = f32::NAN;
                        } else if m.is_finite() {
                            *m = m.max(*v);
                        }
                    }
                })?;
                let res = Highlight::find(w, h, &g, &circle, &params);
                // The matte sphere from its rows alone: its circle moved up by their first
                // (a whole number of rows: every pixel's offset from the centre is the same).
                let matte = match (&res, &config.matte_sphere) {
                    (Ok(hl), Some(c)) => Some(CalibrationParams::default().intensity(
                        w,
                        matte_rows.len(),
                        &rgb,
                        &Circle {
                            cy: c.cy - matte_rows.start as f64,
                            ..*c
                        },
                        hl.light,
                    )),
                    _ => None,
                };
                Ok((res, matte))
            })
            .collect::<Result<Vec<_>>>()?;
        results.extend(done);
    }
    let max_image = max_image.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut records = Vec::with_capacity(images.len());
    let (mut found, mut bad) = (Vec::new(), Vec::new());
    let mut lp_lines = Vec::new();
    let lp_dir = config
        .output
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let mut intensities: Vec<[f64; 3]> = Vec::new();
    for (path, (res, matte)) in images.iter().zip(results) {
        // A light whose intensity cannot be measured is dropped as one without a highlight.
        let res = match (res, matte) {
            (Ok(_), Some(Err(e))) => Err(e.to_string()),
            (Ok(hl), Some(Ok(e))) => {
                intensities.push(e);
                Ok((hl, Some(e)))
            }
            (Ok(hl), None) => Ok((hl, None)),
            (Err(e), _) => {
                if let CalibrationError::Several { x1, y1, x2, y2, .. } = e {
                    bad.extend([(x1, y1), (x2, y2)]);
                }
                Err(e.to_string())
            }
        };
        match res {
            Ok((hl, intensity)) => {
                found.push((hl.x, hl.y));
                let rel = relative_to(path, &lp_dir);
                let name = rel.to_string_lossy().replace('\\', "/");
                if name.contains(char::is_whitespace) || name.contains('#') {
                    bail!(
                        "{}: .lp files cannot hold paths with spaces or '#'",
                        path.display()
                    );
                }
                lp_lines.push(format!(
                    "{name} {:.6} {:.6} {:.6}",
                    hl.light.x, hl.light.y, hl.light.z
                ));
                records.push(ImageRecord {
                    image: path.display().to_string(),
                    used: true,
                    highlight: Some([hl.x, hl.y]),
                    light: Some(hl.light.to_array()),
                    pixels: Some(hl.pixels),
                    saturated: Some(hl.saturated),
                    intensity,
                    error: None,
                });
            }
            Err(e) => {
                if config.strict {
                    bail!("{}: {e}", path.display());
                }
                ctl.warn(&format!("{}: dropped: {e}", path.display()));
                records.push(ImageRecord {
                    image: path.display().to_string(),
                    used: false,
                    highlight: None,
                    light: None,
                    pixels: None,
                    saturated: None,
                    intensity: None,
                    error: Some(e),
                });
            }
        }
    }
    if lp_lines.len() < 3 {
        bail!(
            "{}: only {} of {} images have a usable highlight on the sphere at ({:.1}, {:.1}), \
             radius {:.1}; at least 3 are needed",
            config.images.display(),
            lp_lines.len(),
            images.len(),
            circle.cx,
            circle.cy,
            circle.r
        );
    }
    // Write the three files (each atomically through a temporary name).
    let stem = config
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "lights".into());
    std::fs::create_dir_all(&lp_dir)
        .with_context(|| format!("{}: cannot create folder", lp_dir.display()))?;
    // Plain, as the other RTI tools read an `.lp` (RTIBuilder, RTIViewer, relight: a count,
    // then that many `name x y z` rows, nothing else); the sphere, the conventions and each
    // image's figures are in the JSON report beside it.
    let lp_text = format!("{}\n{}\n", lp_lines.len(), lp_lines.join("\n"));
    let (pw, ph, rgb) = picture(&max_image, w, h, &circle, &found, &bad);
    let pic = lp_dir.join(format!("{stem}-highlights.png"));
    symframe_io::write_png_rgb8(&pic, pw, ph, &rgb)?;
    let used = lp_lines.len();
    let mut intensity_mean_raw = None;
    let mut intensities_file = None;
    if config.matte_sphere.is_some() {
        let mean = intensities.iter().flatten().sum::<f64>() / (3 * intensities.len()) as f64;
        if !(mean.is_finite() && mean > 0.0) {
            bail!(
                "{}: the matte sphere is black under every light (mean intensity {mean})",
                config.images.display()
            );
        }
        let rows: Vec<String> = intensities
            .iter()
            .map(|e| format!("{:.6} {:.6} {:.6}", e[0] / mean, e[1] / mean, e[2] / mean))
            .collect();
        let path = lp_dir.join("light_intensities.txt");
        symframe_io::write_bytes(&path, (rows.join("\n") + "\n").as_bytes())?;
        intensity_mean_raw = Some(mean);
        intensities_file = Some(path);
    }
    let json_path = lp_dir.join(format!("{stem}-calibration.json"));
    let report = CalibrationReport {
        version: env!("CARGO_PKG_VERSION"),
        sphere: circle,
        sphere_source: source,
        detection,
        images: images.len(),
        used,
        records,
        conventions: "pixels: x right, y down, centre of the top-left pixel (0.5, 0.5); \
                      lights: x right, y up, z toward the camera, surface toward light",
        matte_sphere: config.matte_sphere,
        intensity_mean_raw,
        written: [config.output.clone(), pic, json_path.clone()],
        intensities_file,
    };
    // Each file atomically through a temporary file created anew (never written through a
    // link planted at its name), the `.lp` last.
    symframe_io::write_bytes(
        &json_path,
        (serde_json::to_string_pretty(&report)? + "\n").as_bytes(),
    )?;
    symframe_io::write_bytes(&config.output, lp_text.as_bytes())?;
    Ok(report)
}

/// Refuses a configuration calibrate cannot run: an output that is not an `.lp` file, a
/// saturation level outside (0, 1], a highlight threshold outside (0, 1).
fn check_config(config: &CalibrateConfig) -> Result<()> {
    let ext_ok = config
        .output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("lp"));
    if !ext_ok {
        bail!(
            "{}: the output must be an .lp file",
            config.output.display()
        );
    }
    check_saturation(config.decode.saturation)?;
    check_threshold(config.threshold)
}

/// Refuses a saturation level outside (0, 1] (calibrate and calibrate --K).
pub(crate) fn check_saturation(saturation: f32) -> Result<()> {
    if !(saturation > 0.0 && saturation <= 1.0) {
        bail!("the saturation level must be in (0, 1], got {saturation}");
    }
    Ok(())
}

/// Refuses a highlight threshold outside (0, 1) (calibrate and calibrate --K).
pub(crate) fn check_threshold(threshold: f64) -> Result<()> {
    if !(threshold > 0.0 && threshold < 1.0) {
        bail!("the highlight threshold must be in (0, 1), got {threshold}");
    }
    Ok(())
}

/// Finds the mirror sphere in the mean of the `images` (`w x h`, read `at_once` at a time, or
/// a band of rows at a time where one is read alone), helped by where each image is brightest:
/// its circle, how it was found (`detected`) and the detection's figures.
fn detect_sphere(
    config: &CalibrateConfig,
    images: &[PathBuf],
    (w, h): (usize, usize),
    at_once: usize,
    stopped: &(dyn Fn() -> bool + Sync),
) -> Result<(Circle, &'static str, Option<SphereDetection>)> {
    let opts = &config.decode;
    let key = |v: f32| if v.is_finite() { v } else { f32::INFINITY };
    // The index of the brightest of `g`'s values (starting at pixel `at`) if brighter than or
    // as bright as `best` (the last of equals, as `max_by` picks it).
    let brighter = |best: &mut Option<(usize, f32)>, at: usize, g: &[f32]| {
        for (k, &v) in g.iter().enumerate() {
            if best.is_none_or(|(_, b)| key(v).total_cmp(&key(b)) != std::cmp::Ordering::Less) {
                *best = Some((at + k, v));
            }
        }
    };

    // The images summed in order, each band as it is read when one is read at a
    // time, else each image's grey values once its batch is read.
    let mut sum = vec![0.0f32; w * h];
    let mut brightest = Vec::with_capacity(images.len());
    for batch in images.chunks(at_once) {
        if stopped() {
            return Err(Interrupted.into());
        }
        if let [p] = batch {
            let mut best = None;
            read_grey(p, opts, (w, h), &mut |y, g, _| {
                brighter(&mut best, y * w, g);
                for (s, v) in sum[y * w..].iter_mut().zip(g) {
                    *s += v;
                }
            })?;
            brightest.push(best.map_or(0, |b| b.0));
            continue;
        }
        let greys = batch
            .par_iter()
            .map(|p| -> Result<(Vec<f32>, usize)> {
                if stopped() {
                    return Err(Interrupted.into());
                }
                let mut best = None;
                let mut own = Vec::with_capacity(w * h);
                read_grey(p, opts, (w, h), &mut |y, g, _| {
                    brighter(&mut best, y * w, g);
                    own.extend_from_slice(g);
                })?;
                Ok((own, best.map_or(0, |b| b.0)))
            })
            .collect::<Result<Vec<_>>>()?;
        for (g, best) in greys {
            sum.iter_mut().zip(&g).for_each(|(x, y)| *x += y);
            brightest.push(best);
        }
    }
    let n = images.len() as f32;
    let mut mean = sum;
    mean.iter_mut().for_each(|v| *v /= n);
    let d = Detection::find(w, h, &mean, &brightest).map_err(|e| SphereNotFound {
        images: config.images.clone(),
        reason: e.to_string(),
    })?;
    Ok((
        d.circle,
        "detected",
        Some(SphereDetection {
            highlight_share: d.highlight_share,
            roundness: d.roundness,
        }),
    ))
}
