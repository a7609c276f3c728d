//! The near-light calibration job (`symframe calibrate --K K.txt --sphere-radius R`): the
//! lights' positions from two or more chrome spheres seen by a pinhole camera, written as
//! `light_positions.txt` with a JSON record beside it. The geometry (each sphere placed by its
//! outline and radius, each light triangulated from its reflections) is the core crate's
//! ([`symframe::Pinhole::sphere_from_rim`], [`symframe::Triangulation::from_rays`]); the
//! highlights and the spheres' outlines too. With a matte sphere in the images, each light's
//! radiant intensity is measured on it with the light's falloff from its position
//! ([`symframe::CalibrationParams::near_sphere_intensity`]) and written as `light_intensities.txt`.
//! This module reads the images and writes the files.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use symframe::{
    CalibrationParams, Circle, Detection, Highlight, Pinhole, PointLight, Triangulation,
};
use symframe_io::DecodeOptions;

use crate::calibrate::{
    check_saturation, check_threshold, image_list, image_size, keep_rows, read_grey, DECODE_MEMORY,
};
use crate::{Control, Interrupted};

mod report;

pub use report::{LightRecord, MatteRecord, NearCalibrationReport, SphereRecord};

/// Rays toward a light less than this many degrees apart fix it poorly along them (a tenth of a
/// degree of error in a ray moves it by a twentieth of its distance and more): it is placed on
/// the sphere through the other lights instead.
pub const DOME_SPREAD_DEG: f64 = 5.0;

/// A light whose rays pass further from their meeting point than this many times the median of
/// all lights' (a highlight partly hidden by the other sphere, a reflection of something else)
/// is placed on the sphere through the other lights instead.
pub const OUTLIER_RESIDUAL: f64 = 20.0;

/// Everything a calibration of light positions needs.
#[derive(Debug, Clone, PartialEq)]
pub struct NearCalibrateConfig {
    /// A folder of images (sorted by name; `mask.*` left out), an `.lp` file (its images), or a
    /// list file of image paths (one per line, relative to it, e.g. a DiLiGenT
    /// `filenames.txt`): one image per light, in the order the positions are written.
    pub images: PathBuf,
    /// The camera's `K.txt` (OpenCV's 3 x 3 intrinsics).
    pub k_file: PathBuf,
    /// The chrome spheres' radius, in the length unit of the positions written.
    pub radius: f64,
    /// The spheres' circles in pixels (empty: detect them); at least two.
    pub spheres: Vec<Circle>,
    /// The `light_positions.txt` to write; `<stem>-calibration.json` is written beside it, and
    /// `K.txt` where the folder has none.
    pub output: PathBuf,
    /// A highlight is the pixels above this fraction of its peak (above the sphere's median).
    pub threshold: f64,
    /// Fail where a light is seen on fewer than two spheres, and triangulate every light seen
    /// on two (else a light seen once, or whose rays are less than [`DOME_SPREAD_DEG`] apart or
    /// far from meeting, is placed where they meet the sphere through the other lights, with a
    /// warning).
    pub strict: bool,
    /// A matte (diffuse, grey) sphere's circle in the same images: per light, its radiant
    /// intensity is measured there with the light's `1 / r^2` from the triangulated position
    /// and written as `light_intensities.txt` beside the positions, normalised to a mean of 1.
    pub matte_sphere: Option<Circle>,
    /// The matte sphere's radius (`None`: the chrome spheres' [`NearCalibrateConfig::radius`]).
    pub matte_radius: Option<f64>,
    /// How images are decoded.
    pub decode: DecodeOptions,
}

/// Checks the settings and the output's folder before any image is read: the output a `.txt`,
/// a `K.txt` beside it the same camera as the one given.
fn check(config: &NearCalibrateConfig, camera: &Pinhole) -> Result<()> {
    let txt = config
        .output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("txt"));
    if !txt {
        bail!(
            "{}: the light positions are written as a .txt file (light_positions.txt)",
            config.output.display()
        );
    }
    if !(config.radius.is_finite() && config.radius > 0.0) {
        bail!(
            "the chrome spheres' radius must be a positive number, got {}",
            config.radius
        );
    }
    check_threshold(config.threshold)?;
    check_saturation(config.decode.saturation)?;
    if let Some(r) = config.matte_radius {
        if !(r.is_finite() && r > 0.0) {
            bail!("the matte sphere's radius must be a positive number, got {r}");
        }
    }
    if config.spheres.len() == 1 {
        bail!("light positions need two or more chrome spheres: give --sphere once for each, or none to detect them");
    }
    let beside = out_dir(&config.output).join(symframe_io::near::INTRINSICS);
    if beside.symlink_metadata().is_ok() {
        let there = symframe_io::near::read_camera(&beside)?;
        if there != *camera {
            bail!(
                "{}: a different camera than {} is already there; write the positions to \
                 another folder",
                beside.display(),
                config.k_file.display()
            );
        }
    }
    Ok(())
}

/// The folder of the output file.
fn out_dir(output: &Path) -> PathBuf {
    output
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf()
}

/// Runs a calibration of light positions: finds the spheres (or takes their circles), places
/// each by its outline in the mean image, finds every image's highlight on each sphere and
/// triangulates its light; writes `light_positions.txt` (one row per image), the JSON report and
/// `K.txt` where the output's folder has none. Lights seen on one sphere only are told through
/// `ctl`'s warnings; its stop flag is polled between images.
pub fn calibrate_near(
    config: &NearCalibrateConfig,
    ctl: &Control,
) -> Result<NearCalibrationReport> {
    let camera = symframe_io::near::read_camera(&config.k_file)?;
    check(config, &camera)?;
    let images = image_list(&config.images)?;
    let out = outputs(config, &images)?;
    let cap = capture(config, &images)?;
    let (mean, brightest) = mean_and_brightest(&cap, ctl)?;
    let (circles, source) = chrome_circles(config, cap.size, &mean, &brightest)?;
    let spheres = place_spheres(config, &camera, (&mean, cap.size), (&circles, source), ctl)?;
    let found = find_highlights(config, &cap, &circles, ctl)?;
    let placed = place_lights(config, &camera, &images, (&spheres, &found), ctl)?;
    let positions: Vec<DVec3> = placed.iter().flatten().map(|(p, _, _)| *p).collect();
    let matte = match config.matte_sphere {
        Some(c) => Some(matte_intensities(
            config, &camera, &cap, &mean, c, &positions, ctl,
        )?),
        None => None,
    };
    let findings = Findings {
        spheres,
        found,
        placed,
        positions,
    };
    let (report, rows_out) = assemble(config, &camera, &images, findings, matte.as_ref())?;
    write_files(config, &camera, out, report, &rows_out, matte.as_ref())
}

/// The files a run writes beside the positions: their folder, the JSON report, `K.txt` and the
/// intensities.
struct Outputs {
    dir: PathBuf,
    json_path: PathBuf,
    k_path: PathBuf,
    intensities_path: PathBuf,
}

/// The output's folder and the files written beside it; refused where an output is one of the
/// inputs (the images or their list), which it would replace.
fn outputs(config: &NearCalibrateConfig, images: &[PathBuf]) -> Result<Outputs> {
    let dir = out_dir(&config.output);
    let stem = config
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "light_positions".into());
    let json_path = dir.join(format!("{stem}-calibration.json"));
    let k_path = dir.join(symframe_io::near::INTRINSICS);
    let intensities_path = dir.join(INTENSITIES);
    {
        let canon = |p: &Path| p.canonicalize().ok();
        let inputs: Vec<PathBuf> = std::iter::once(config.images.as_path())
            .chain(images.iter().map(PathBuf::as_path))
            .filter_map(canon)
            .collect();
        for o in [&config.output, &json_path, &intensities_path] {
            if canon(o).is_some_and(|c| inputs.contains(&c)) {
                bail!(
                    "{}: is an input of this run, and the output would replace it; write the \
                     positions elsewhere (-o)",
                    o.display()
                );
            }
        }
    }
    Ok(Outputs {
        dir,
        json_path,
        k_path,
        intensities_path,
    })
}

/// The images every stage decodes, with their size, how they are decoded and how many are
/// decoded at once (within [`DECODE_MEMORY`]).
struct Capture<'a> {
    images: &'a [PathBuf],
    size: (usize, usize),
    opts: DecodeOptions,
    at_once: usize,
}

/// The images' size (from the first image's header), every circle given checked to fit it, and
/// the batch size: before any image is decoded whole.
fn capture<'a>(config: &NearCalibrateConfig, images: &'a [PathBuf]) -> Result<Capture<'a>> {
    let opts = config.decode.clone();
    let (w, h) = image_size(&images[0], &opts)?;
    for (what, c) in config
        .spheres
        .iter()
        .map(|c| ("sphere", c))
        .chain(config.matte_sphere.iter().map(|c| ("matte sphere", c)))
    {
        if let Err(why) = c.check_fits(w, h) {
            bail!(
                "the {what}'s circle {},{},{} (CX,CY,R) does not fit the {w}x{h} image: {why}",
                c.cx,
                c.cy,
                c.r
            );
        }
    }
    let at_once = (DECODE_MEMORY / (4 * w * h)).max(1);
    Ok(Capture {
        images,
        size: (w, h),
        opts,
        at_once,
    })
}

/// The mean image and each image's brightest pixel, decoded in parallel batches with the stop
/// flag polled between them: the spheres are found, and their outlines fitted, in the mean.
fn mean_and_brightest(cap: &Capture, ctl: &Control) -> Result<(Vec<f32>, Vec<usize>)> {
    let (images, (w, h), opts) = (cap.images, cap.size, &cap.opts);
    let stopped = || ctl.stop.load(std::sync::atomic::Ordering::SeqCst);
    let mut mean = vec![0.0f32; w * h];
    let mut brightest = Vec::with_capacity(images.len());
    let key = |v: f32| if v.is_finite() { v } else { f32::INFINITY };
    for batch in images.chunks(cap.at_once) {
        if stopped() {
            return Err(Interrupted.into());
        }
        let greys = batch
            .par_iter()
            .map(|p| -> Result<(Vec<f32>, usize)> {
                let mut own = Vec::with_capacity(w * h);
                read_grey(p, opts, (w, h), &mut |_, g, _| own.extend_from_slice(g))?;
                let best = (0..own.len())
                    .max_by(|&a, &b| key(own[a]).total_cmp(&key(own[b])))
                    .unwrap_or(0);
                Ok((own, best))
            })
            .collect::<Result<Vec<_>>>()?;
        for (g, best) in greys {
            for (m, v) in mean.iter_mut().zip(&g) {
                // Saturated pixels stay saturated in the mean.
                *m += v / images.len() as f32;
            }
            brightest.push(best);
        }
    }
    Ok((mean, brightest))
}

/// The chrome spheres' circles and where they came from: `given`, or `detected` in the mean
/// image (two or more, the matte sphere left out, sorted left to right).
fn chrome_circles(
    config: &NearCalibrateConfig,
    (w, h): (usize, usize),
    mean: &[f32],
    brightest: &[usize],
) -> Result<(Vec<Circle>, &'static str)> {
    let (circles, source): (Vec<Circle>, &'static str) = if config.spheres.is_empty() {
        let found = Detection::find_all(w, h, mean, brightest, 0.05).map_err(|why| {
            anyhow::anyhow!(
                "{}: cannot find the chrome spheres: {why}; give each circle with --sphere \
                 CX,CY,R",
                config.images.display()
            )
        })?;
        if found.len() < 2 {
            let c = found[0].circle;
            bail!(
                "{}: found one chrome sphere (at {:.1}, {:.1}, radius {:.1} px), two or more \
                 are needed; give each circle with --sphere CX,CY,R",
                config.images.display(),
                c.cx,
                c.cy,
                c.r
            );
        }
        // A round region where the matte sphere was given is the matte sphere.
        let mut v: Vec<Circle> = found
            .iter()
            .map(|d| d.circle)
            .filter(|c| {
                config
                    .matte_sphere
                    .is_none_or(|m| (c.cx - m.cx).hypot(c.cy - m.cy) > m.r)
            })
            .collect();
        if v.len() < 2 {
            bail!(
                "{}: found {} chrome sphere(s) besides the matte sphere, two or more are \
                 needed; give each circle with --sphere CX,CY,R",
                config.images.display(),
                v.len()
            );
        }
        v.sort_by(|a, b| a.cx.total_cmp(&b.cx).then(a.cy.total_cmp(&b.cy)));
        (v, "detected")
    } else {
        (config.spheres.clone(), "given")
    };
    Ok((circles, source))
}

/// Each chrome sphere placed in the camera frame by its outline in the mean image (its circle's
/// rim, with a warning, where the image gives none) and the spheres' radius.
fn place_spheres(
    config: &NearCalibrateConfig,
    camera: &Pinhole,
    (mean, (w, h)): (&[f32], (usize, usize)),
    (circles, source): (&[Circle], &'static str),
    ctl: &Control,
) -> Result<Vec<SphereRecord>> {
    let mut spheres = Vec::with_capacity(circles.len());
    for c in circles {
        let (outline, rim) = match c.outline(w, h, mean) {
            Some((_, rim)) if rim.len() >= 16 => ("image", rim),
            _ => {
                ctl.warn(&format!(
                    "the sphere at ({:.1}, {:.1}): no outline found in the mean image; its \
                     circle's rim is taken",
                    c.cx, c.cy
                ));
                ("circle", c.rim(360))
            }
        };
        let centre = camera.sphere_from_rim(&rim, config.radius).map_err(|why| {
            anyhow::anyhow!(
                "the sphere at ({:.1}, {:.1}), radius {:.1} px: cannot place it: {why}",
                c.cx,
                c.cy,
                c.r
            )
        })?;
        spheres.push(SphereRecord {
            circle: *c,
            circle_source: source,
            outline,
            outline_points: rim.len(),
            centre: centre.to_array(),
        });
    }
    Ok(spheres)
}

/// A highlight's centre on one sphere in pixels, or why none was found there.
type Sighting = Result<[f64; 2], String>;

/// Each image's highlight on each sphere, from the spheres' rows alone (decoded in parallel
/// batches, the stop flag polled between them).
fn find_highlights(
    config: &NearCalibrateConfig,
    cap: &Capture,
    circles: &[Circle],
    ctl: &Control,
) -> Result<Vec<Vec<Sighting>>> {
    let (images, (w, h), opts) = (cap.images, cap.size, &cap.opts);
    let stopped = || ctl.stop.load(std::sync::atomic::Ordering::SeqCst);
    let rows = circles
        .iter()
        .map(|c| crate::calibrate::circle_rows(c, h))
        .fold(h..0, |a, r| a.start.min(r.start)..a.end.max(r.end));
    let rows = if rows.start < rows.end { rows } else { 0..0 };
    let params = CalibrationParams {
        highlight_fraction: config.threshold,
        ..CalibrationParams::default()
    };
    let mut found: Vec<Vec<Sighting>> = Vec::with_capacity(images.len());
    for batch in images.chunks(cap.at_once) {
        if stopped() {
            return Err(Interrupted.into());
        }
        let done = batch
            .par_iter()
            .map(|p| -> Result<Vec<Sighting>> {
                let mut g = vec![0.0f32; w * h];
                read_grey(p, opts, (w, h), &mut |y, band, _| {
                    keep_rows(band, y, w, &rows, &mut g[rows.start * w..rows.end * w]);
                })?;
                Ok(circles
                    .iter()
                    .map(|c| {
                        Highlight::find(w, h, &g, c, &params)
                            .map(|hl| [hl.x, hl.y])
                            .map_err(|e| e.to_string())
                    })
                    .collect())
            })
            .collect::<Result<Vec<_>>>()?;
        found.extend(done);
    }
    Ok(found)
}

/// A light's position, its triangulation (where its rays gave one) and how it was placed
/// (`triangulated` or `dome`).
type Placed = (DVec3, Option<Triangulation>, &'static str);

/// Each light placed from its highlights: triangulated where two or more rays fix it well; else
/// (not `strict`) where its rays meet the sphere through the others, with a warning. Every
/// entry is `Some` on return.
fn place_lights(
    config: &NearCalibrateConfig,
    camera: &Pinhole,
    images: &[PathBuf],
    (spheres, found): (&[SphereRecord], &[Vec<Sighting>]),
    ctl: &Control,
) -> Result<Vec<Option<Placed>>> {
    // Triangulated lights first; lights seen once, or whose rays fix them poorly, are then
    // placed on the sphere through the others.
    let centres: Vec<DVec3> = spheres.iter().map(|s| DVec3::from(s.centre)).collect();
    let mut placed: Vec<Option<Placed>> = Vec::with_capacity(images.len());
    let mut all_rays = Vec::with_capacity(images.len());
    for (path, hls) in images.iter().zip(found) {
        let rays: Vec<(DVec3, DVec3)> = hls
            .iter()
            .zip(&centres)
            .filter_map(|(hl, c)| {
                hl.as_ref()
                    .ok()
                    .map(|[x, y]| camera.reflected_ray(*c, config.radius, *x, *y))
            })
            .collect();
        let why = |e: &str| {
            let each: Vec<String> = hls
                .iter()
                .enumerate()
                .map(|(i, hl)| match hl {
                    Ok([x, y]) => format!("sphere {}: highlight at ({x:.1}, {y:.1})", i + 1),
                    Err(e) => format!("sphere {}: {e}", i + 1),
                })
                .collect();
            format!("{}: {e} ({})", path.display(), each.join("; "))
        };
        match rays.len() {
            0 => bail!("{}", why("the light is seen on no sphere")),
            1 if config.strict => bail!("{}", why("the light is seen on one sphere only")),
            1 => placed.push(None),
            _ => match Triangulation::from_rays(&rays) {
                Ok(t) => placed.push(Some((t.position, Some(t), "triangulated"))),
                Err(e) if config.strict => bail!("{}", why(&e)),
                Err(_) => placed.push(None),
            },
        }
        all_rays.push(rays);
    }
    // Rays that meet at a narrow angle, or far apart against the others, fix a light poorly
    // along them: such lights join those seen once.
    let mut residuals: Vec<f64> = placed
        .iter()
        .flatten()
        .filter_map(|(_, t, _)| t.map(|t| t.residual_rms))
        .collect();
    residuals.sort_by(f64::total_cmp);
    let median = residuals.get(residuals.len() / 2).copied().unwrap_or(0.0);
    if !config.strict {
        for p in placed.iter_mut() {
            if let Some((_, Some(t), _)) = p {
                if t.spread_deg < DOME_SPREAD_DEG || t.residual_rms > OUTLIER_RESIDUAL * median {
                    *p = None;
                }
            }
        }
    }
    let kept: Vec<DVec3> = placed.iter().flatten().map(|(p, _, _)| *p).collect();
    let pending: Vec<usize> = (0..placed.len()).filter(|&k| placed[k].is_none()).collect();
    if let Some(&first) = pending.first() {
        let Some((centre, radius)) = PointLight::fit_sphere(&kept) else {
            bail!(
                "{} lights are seen on one sphere only or fixed poorly by their rays, and the {} \
                 others do not lie on a sphere to place them on (e.g. {}); place the spheres so \
                 that every light is seen on two, far apart",
                pending.len(),
                kept.len(),
                images[first].display()
            );
        };
        for k in pending {
            // Each ray's far meeting with the dome's sphere (the rays leave from inside it),
            // averaged.
            let mut sum = DVec3::ZERO;
            for (o, d) in &all_rays[k] {
                let oc = *o - centre;
                let b = oc.dot(*d);
                let disc = b * b - (oc.length_squared() - radius * radius);
                if disc < 0.0 {
                    bail!(
                        "{}: the light is seen on one sphere only or fixed poorly by its rays, \
                         and a ray misses the sphere through the other lights",
                        images[k].display()
                    );
                }
                sum += *o + *d * (-b + disc.sqrt());
            }
            let p = sum / all_rays[k].len() as f64;
            ctl.warn(&format!(
                "{}: the light is seen on one sphere only or fixed poorly by its rays (rays {} \
                 degrees apart at most); placed where they meet the sphere through the other \
                 lights",
                images[k].display(),
                all_rays[k]
                    .iter()
                    .flat_map(|a| all_rays[k].iter().map(move |b| a.1.angle_between(b.1)))
                    .fold(0.0f64, f64::max)
                    .to_degrees()
                    .round()
            ));
            let t = Triangulation::from_rays(&all_rays[k]).ok();
            placed[k] = Some((p, t, "dome"));
        }
    }
    Ok(placed)
}

/// The matte sphere's record and each light's raw RGB intensity, in the images' order.
type Matte = (MatteRecord, Vec<[f64; 3]>);

/// What the stages found, for the report: the spheres, each image's highlights, each light
/// placed and the positions.
struct Findings {
    spheres: Vec<SphereRecord>,
    found: Vec<Vec<Sighting>>,
    placed: Vec<Option<Placed>>,
    positions: Vec<DVec3>,
}

/// The report (its `written` left empty) and the rows of `light_positions.txt`, one per image;
/// nothing is written yet.
fn assemble(
    config: &NearCalibrateConfig,
    camera: &Pinhole,
    images: &[PathBuf],
    findings: Findings,
    matte: Option<&Matte>,
) -> Result<(NearCalibrationReport, String)> {
    let Findings {
        spheres,
        found,
        placed,
        positions,
    } = findings;
    let mut records = Vec::with_capacity(images.len());
    let mut rows_out = String::new();
    let mut residuals = Vec::new();
    for ((path, hls), p) in images.iter().zip(found).zip(&placed) {
        let Some((pos, t, placed_by)) = p else {
            bail!("{}: the light was not placed", path.display());
        };
        rows_out.push_str(&format!("{:?} {:?} {:?}\n", pos.x, pos.y, pos.z));
        if let (Some(t), &"triangulated") = (t, placed_by) {
            residuals.push(t.residual_rms);
        }
        records.push(LightRecord {
            image: path.display().to_string(),
            position: pos.to_array(),
            placed_by,
            highlights: hls,
            residual_rms: t.map(|t| t.residual_rms),
            residual_max: t.map(|t| t.residual_max),
            spread_deg: t.map(|t| t.spread_deg),
            intensity: matte.map(|m| m.1[records.len()]),
        });
    }
    residuals.sort_by(f64::total_cmp);
    let report = NearCalibrationReport {
        version: env!("CARGO_PKG_VERSION"),
        k: camera.k(),
        sphere_radius: config.radius,
        spheres,
        images: images.len(),
        triangulated: residuals.len(),
        residual_rms_median: residuals.get(residuals.len() / 2).copied().unwrap_or(0.0),
        residual_rms_max: residuals.last().copied().unwrap_or(0.0),
        dome: PointLight::fit_sphere(&positions).map(|(c, r)| (c.to_array(), r)),
        matte: matte.map(|m| m.0.clone()),
        records,
        conventions: "pixels: x right, y down, centre of the top-left pixel (0.5, 0.5); \
                      positions: camera frame, x right, y up, z toward the camera, origin at \
                      the centre of projection, in the spheres' radius's unit",
        written: Vec::new(),
    };
    Ok((report, rows_out))
}

/// Writes `K.txt` (where the folder has none), the JSON report, the intensities (with a matte
/// sphere, normalised to a mean of 1) and the positions last; the report with what was written.
fn write_files(
    config: &NearCalibrateConfig,
    camera: &Pinhole,
    out: Outputs,
    report: NearCalibrationReport,
    rows_out: &str,
    matte: Option<&Matte>,
) -> Result<NearCalibrationReport> {
    let Outputs {
        dir,
        json_path,
        k_path,
        intensities_path,
    } = out;
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    let mut written = vec![config.output.clone(), json_path.clone()];
    if k_path.symlink_metadata().is_err() {
        let text = camera.k().iter().fold(String::new(), |mut t, r| {
            t.push_str(&format!("{:?} {:?} {:?}\n", r[0], r[1], r[2]));
            t
        });
        symframe_io::write_bytes(&k_path, text.as_bytes())?;
        written.push(k_path);
    }
    symframe_io::write_bytes(
        &json_path,
        (serde_json::to_string_pretty(&report)? + "\n").as_bytes(),
    )?;
    if let Some((record, raw)) = matte {
        let mean = record.intensity_mean_raw;
        let text: String = raw
            .iter()
            .map(|e| format!("{:?} {:?} {:?}\n", e[0] / mean, e[1] / mean, e[2] / mean))
            .collect();
        symframe_io::write_bytes(&intensities_path, text.as_bytes())?;
        written.push(intensities_path);
    }
    symframe_io::write_bytes(&config.output, rows_out.as_bytes())?;
    Ok(NearCalibrationReport { written, ..report })
}

/// The intensities' file name, beside the positions (the name a dataset's reader takes).
const INTENSITIES: &str = "light_intensities.txt";

/// The matte sphere placed by its outline in the mean image (or its circle's rim) and
/// `radius`, then each image's RGB rows of it read again and each light's intensity measured
/// with its falloff from `positions` ([`CalibrationParams::near_sphere_intensity`], isotropic
/// lights); the record (the mean over lights and channels, which must be positive) and the raw
/// intensities in the images' order. An image where too few of its pixels face the light is an
/// error naming it.
fn matte_intensities(
    config: &NearCalibrateConfig,
    camera: &Pinhole,
    cap: &Capture,
    mean: &[f32],
    circle: Circle,
    positions: &[DVec3],
    ctl: &Control,
) -> Result<Matte> {
    let (images, (w, h), at_once) = (cap.images, cap.size, cap.at_once);
    let radius = config.matte_radius.unwrap_or(config.radius);
    let (outline, rim) = match circle.outline(w, h, mean) {
        Some((_, rim)) if rim.len() >= 16 => ("image", rim),
        _ => {
            ctl.warn(&format!(
                "the matte sphere at ({:.1}, {:.1}): no outline found in the mean image; its \
                 circle's rim is taken",
                circle.cx, circle.cy
            ));
            ("circle", circle.rim(360))
        }
    };
    let centre = camera.sphere_from_rim(&rim, radius).map_err(|why| {
        anyhow::anyhow!(
            "the matte sphere at ({:.1}, {:.1}), radius {:.1} px: cannot place it: {why}",
            circle.cx,
            circle.cy,
            circle.r
        )
    })?;
    // Its rows alone, seen by the camera moved up by their first (K's convention: a row's
    // pixel centres keep their offsets from the principal point).
    let rows = crate::calibrate::circle_rows(&circle, h);
    let mut k = camera.k();
    k[1][2] -= rows.start as f64;
    let crop = Pinhole::from_k(k).map_err(anyhow::Error::msg)?;
    let opts = config.decode.clone();
    let params = CalibrationParams::default();
    let mut raw: Vec<[f64; 3]> = Vec::with_capacity(images.len());
    let at_once = at_once.max(1);
    for (b, batch) in images.chunks(at_once).enumerate() {
        if ctl.stop.load(std::sync::atomic::Ordering::SeqCst) {
            return Err(Interrupted.into());
        }
        let done = batch
            .par_iter()
            .enumerate()
            .map(|(i, p)| -> Result<[f64; 3]> {
                let mut rgb = vec![0.0f32; 3 * w * rows.len()];
                read_grey(p, &opts, (w, h), &mut |y, _, band_rgb| {
                    keep_rows(band_rgb, y, 3 * w, &rows, &mut rgb);
                })?;
                let light = PointLight::isotropic(positions[b * at_once + i]);
                params
                    .near_sphere_intensity(w, rows.len(), &rgb, &crop, centre, radius, &light)
                    .with_context(|| format!("{}: the matte sphere", p.display()))
            })
            .collect::<Result<Vec<_>>>()?;
        raw.extend(done);
    }
    let mean_raw = raw.iter().flatten().sum::<f64>() / (3 * raw.len().max(1)) as f64;
    if !(mean_raw.is_finite() && mean_raw > 0.0) {
        bail!(
            "{}: the matte sphere is black under every light (mean intensity {mean_raw})",
            config.images.display()
        );
    }
    Ok((
        MatteRecord {
            circle,
            radius,
            outline,
            centre: centre.to_array(),
            intensity_mean_raw: mean_raw,
        },
        raw,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{synth_near, NearSynthConfig};

    fn config(images: PathBuf, k_file: PathBuf, output: PathBuf) -> NearCalibrateConfig {
        NearCalibrateConfig {
            images,
            k_file,
            radius: 1.0,
            spheres: Vec::new(),
            output,
            threshold: 0.3,
            strict: false,
            matte_sphere: None,
            matte_radius: None,
            decode: DecodeOptions {
                saturation: 0.995,
                ..DecodeOptions::default()
            },
        }
    }

    /// `synth --near --chrome-sphere`'s calibration images give the lights' positions within
    /// 1% of the dome's radius (the spheres 139 pixels in radius); prints the errors.
    #[test]
    fn chrome_spheres_of_a_near_synth_give_the_light_positions() {
        let d = tempfile::tempdir().unwrap();
        let data = d.path().join("near");
        let synth = NearSynthConfig {
            size: 640,
            lights: 24,
            chrome_spheres: true,
            ..NearSynthConfig::new(&data)
        };
        synth_near(&synth, &Control::default()).unwrap();
        let out = d.path().join("cal").join("light_positions.txt");
        let cfg = config(
            data.join("chrome").join("filenames.txt"),
            data.join("K.txt"),
            out.clone(),
        );
        let report = calibrate_near(&cfg, &Control::default()).unwrap();
        assert_eq!(report.spheres.len(), 2);
        let truth = symframe_io::near::read_positions(&data.join("light_positions.txt")).unwrap();
        let got = symframe_io::near::read_positions(&out).unwrap();
        assert_eq!(got.len(), truth.len());
        let dome = synth.dome_ratio * crate::synth_near::PAIR_WIDTH;
        let errors: Vec<f64> = got
            .iter()
            .zip(&truth)
            .map(|(a, b)| (*a - *b).length() / dome)
            .collect();
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let max = errors.iter().copied().fold(0.0, f64::max);
        println!(
            "{} lights ({} triangulated): position error over the dome's radius: mean {:.3}%, \
             max {:.3}%; rms residual median {:.4}, max {:.4}",
            errors.len(),
            report.triangulated,
            100.0 * mean,
            100.0 * max,
            report.residual_rms_median,
            report.residual_rms_max
        );
        assert!(max < 0.01, "max {max}");
        // K.txt is copied beside the positions, and the folder reads as a near geometry.
        let k = symframe_io::near::read_camera(&out.with_file_name("K.txt")).unwrap();
        assert_eq!(k, synth.scene().camera);
        // A different K.txt there is refused before anything is read.
        let other = d.path().join("K2.txt");
        std::fs::write(&other, "500 0 320\n0 500 160\n0 0 1\n").unwrap();
        let e = calibrate_near(
            &NearCalibrateConfig {
                k_file: other,
                ..cfg.clone()
            },
            &Control::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("a different camera"), "{e}");
    }

    /// Lights of unequal intensities, a calibration capture of two chrome spheres with a matte
    /// one between them (640 px wide): `light_intensities.txt` is written beside the positions,
    /// within 1% of the truth (both normalised to a mean of 1), and an estimate of a near
    /// capture under those lights with it matches the one with the true intensities (the
    /// median pixel, and the mean error within 0.1 degree); without intensities the estimate
    /// is degrees worse. Prints the errors.
    #[test]
    fn a_matte_sphere_gives_the_near_lights_intensities() {
        use symframe::brdf::{parse_model, Brdf, Lambertian};
        use symframe::render::{dome_lights, Ball, NearMirrorBalls, NearScene};
        use symframe_io::{ImageFormat, NearFiles};

        let d = tempfile::tempdir().unwrap();
        let object = NearSynthConfig {
            size: 64,
            lights: 30,
            ..NearSynthConfig::new(d.path().join("data"))
        };
        let depth = object.camera_ratio * crate::synth_near::PAIR_WIDTH;
        let dome = object.dome_ratio * crate::synth_near::PAIR_WIDTH;
        let mut lights = dome_lights(object.lights, object.centre(), dome, 5.0, dome * dome);
        for (i, l) in lights.iter_mut().enumerate() {
            let f = |a: f64| (i as f64 * a).fract();
            let s = 0.6 + 0.8 * f(0.618_034);
            l.intensity = [s, s * (0.9 + 0.2 * f(0.377)), s * 1.1].map(|v| v * dome * dome);
        }
        let positions: Vec<DVec3> = lights.iter().map(|l| l.position).collect();
        let directions: Vec<DVec3> = positions
            .iter()
            .map(|p| (*p - object.centre()).normalize())
            .collect();
        let truth: Vec<[f64; 3]> = lights.iter().map(|l| l.intensity).collect();
        let truth_mean = truth.iter().flatten().sum::<f64>() / (3 * truth.len()) as f64;

        // The calibration capture: chrome, matte, chrome, radius 0.7, at the object's depth.
        let cal = NearSynthConfig {
            size: 640,
            ..object.clone()
        };
        let camera = cal.scene().camera;
        let (w, h) = (640, 320);
        let mirrors = NearMirrorBalls {
            lamp_radius: 0.05,
            ..NearMirrorBalls::new(
                w,
                h,
                camera,
                &[
                    (DVec3::new(-1.5, 0.0, -depth), 0.7),
                    (DVec3::new(1.5, 0.0, -depth), 0.7),
                ],
            )
        };
        let matte_ball = Ball {
            centre: DVec3::new(0.0, 0.0, -depth),
            radius: 0.7,
            material: 0,
        };
        let matte = NearScene::spheres(w, h, camera, &[matte_ball]);
        let grey = Lambertian::new([0.8; 3]);
        let images: Vec<Vec<f32>> = lights
            .par_iter()
            .map(|l| {
                let mut img: Vec<f32> = mirrors
                    .render(l.position)
                    .into_iter()
                    .flat_map(|v| [v; 3])
                    .collect();
                let lit = matte.render(&[&grey], l);
                for (p, seen) in matte.seen.iter().enumerate() {
                    if seen.is_some() {
                        img[3 * p..3 * p + 3].copy_from_slice(&lit[3 * p..3 * p + 3]);
                    }
                }
                img
            })
            .collect();
        let cal_dir = d.path().join("cal");
        let files = NearFiles {
            positions: &positions,
            directions: &directions,
            k: camera.k(),
            gt_depth: None,
        };
        symframe_io::write_near_dataset(
            &cal_dir,
            &files,
            &images,
            w,
            h,
            ImageFormat::Exr,
            None,
            None,
            None,
        )
        .unwrap();
        let (mcx, mcy) = camera.project(matte_ball.centre).unwrap();
        let out = d.path().join("out").join("light_positions.txt");
        let cfg = NearCalibrateConfig {
            radius: 0.7,
            matte_sphere: Some(Circle {
                cx: mcx + 0.5,
                cy: mcy + 0.5,
                r: 0.7 / depth * camera.fx,
            }),
            ..config(
                cal_dir.join("filenames.txt"),
                cal_dir.join("K.txt"),
                out.clone(),
            )
        };
        let report = calibrate_near(&cfg, &Control::default()).unwrap();
        assert_eq!(
            report.spheres.len(),
            2,
            "the matte sphere is not a chrome one"
        );
        let m = report
            .matte
            .as_ref()
            .expect("the matte sphere was measured");
        let centre_error = (DVec3::from(m.centre) - matte_ball.centre).length();
        let written = out.with_file_name("light_intensities.txt");
        assert!(report.written.contains(&written));
        let text = std::fs::read_to_string(&written).unwrap();
        let got: Vec<[f64; 3]> = text
            .lines()
            .map(|l| {
                let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        assert_eq!(got.len(), truth.len());
        let errors: Vec<f64> = got
            .iter()
            .zip(&truth)
            .flat_map(|(g, t)| (0..3).map(move |c| (g[c] / (t[c] / truth_mean) - 1.0).abs()))
            .collect();
        let max = errors.iter().copied().fold(0.0, f64::max);
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        println!(
            "matte sphere centre off by {centre_error:.4}; intensities over the truth (both \
             normalised): mean error {:.3}%, max {:.3}%",
            100.0 * mean,
            100.0 * max
        );
        assert!(max < 0.01, "max intensity error {max}");

        // The object under the same lights, estimated with the true intensities, the
        // calibrated ones and none.
        let scene = object.scene();
        let models: Vec<Box<dyn Brdf>> = object
            .models
            .iter()
            .map(|m| parse_model(m).unwrap())
            .collect();
        let materials: Vec<&dyn Brdf> = models.iter().map(|m| m.as_ref()).collect();
        let images: Vec<Vec<f32>> = lights
            .par_iter()
            .map(|l| scene.render(&materials, l))
            .collect();
        let data = d.path().join("data");
        symframe_io::write_near_dataset(
            &data,
            &NearFiles {
                k: scene.camera.k(),
                gt_depth: Some(&scene.depth()),
                ..files
            },
            &images,
            scene.width,
            scene.height,
            ImageFormat::Exr,
            Some(&scene.gt_normals()),
            Some(&scene.gt_tangents()),
            Some(&scene.mask()),
        )
        .unwrap();
        let run = |intensities: Option<String>, name: &str| {
            let file = data.join("light_intensities.txt");
            match intensities {
                Some(t) => std::fs::write(&file, t).unwrap(),
                None => {
                    let _ = std::fs::remove_file(&file);
                }
            }
            let mut config = crate::EstimateConfig::new(&data, d.path().join(name));
            config.near.max_iterations = 3;
            match crate::estimate(&config, &Control::default()).unwrap() {
                crate::EstimateOutcome::Maps(done) => done.maps.unwrap().normals,
                crate::EstimateOutcome::Shard(_) => unreachable!("not a shard"),
            }
        };
        let true_text: String = truth
            .iter()
            .map(|t| format!("{:?} {:?} {:?}\n", t[0], t[1], t[2]))
            .collect();
        let with_truth = run(Some(true_text), "truth");
        let with_calibrated = run(Some(text), "calibrated");
        let without = run(None, "none");
        let gt = scene.gt_normals();
        let angle = |a: &[f32], b: &[f32]| {
            let (mut sum, mut n) = (0.0, 0);
            for (x, y) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
                let dot: f32 = x.iter().zip(y).map(|(p, q)| p * q).sum();
                if dot.is_finite() {
                    sum += (dot.min(1.0) as f64).acos().to_degrees();
                    n += 1;
                }
            }
            sum / n.max(1) as f64
        };
        let (e_truth, e_cal, e_none) = (
            angle(&with_truth, &gt),
            angle(&with_calibrated, &gt),
            angle(&without, &gt),
        );
        // A few pixels' answers move by a search step under any change of the intensities
        // (a quarter of a percent moves the mean as much): the median pixel and the error are
        // held.
        let mut apart: Vec<f64> = with_truth
            .chunks_exact(3)
            .zip(with_calibrated.chunks_exact(3))
            .filter_map(|(x, y)| {
                let dot: f32 = x.iter().zip(y).map(|(p, q)| p * q).sum();
                dot.is_finite()
                    .then(|| (dot.min(1.0) as f64).acos().to_degrees())
            })
            .collect();
        apart.sort_by(f64::total_cmp);
        let median = apart[apart.len() / 2];
        println!(
            "normals' mean error: true intensities {e_truth:.3} deg, calibrated {e_cal:.3}, none \
             {e_none:.3}; calibrated from true: median {median:.4} deg"
        );
        assert!(median < 0.1, "median {median}");
        assert!((e_cal - e_truth).abs() < 0.1, "{e_cal} {e_truth}");
        assert!(e_none > e_truth + 2.0, "{e_none} {e_truth}");
    }

    #[test]
    fn bad_settings_name_what_is_wrong() {
        let d = tempfile::tempdir().unwrap();
        let k = d.path().join("K.txt");
        std::fs::write(&k, "500 0 320\n0 500 160\n0 0 1\n").unwrap();
        let base = config(
            d.path().to_path_buf(),
            k.clone(),
            d.path().join("o/pos.txt"),
        );
        let err = |c: &NearCalibrateConfig| {
            format!("{:#}", calibrate_near(c, &Control::default()).unwrap_err())
        };
        let e = err(&NearCalibrateConfig {
            output: d.path().join("o/lights.lp"),
            ..base.clone()
        });
        assert!(e.contains(".txt file"), "{e}");
        let e = err(&NearCalibrateConfig {
            radius: 0.0,
            ..base.clone()
        });
        assert!(e.contains("radius must be a positive number"), "{e}");
        let e = err(&NearCalibrateConfig {
            spheres: vec![Circle {
                cx: 10.0,
                cy: 10.0,
                r: 5.0,
            }],
            ..base.clone()
        });
        assert!(e.contains("two or more chrome spheres"), "{e}");
        std::fs::write(&k, "500 0 320\n0 500 160\n0 0\n").unwrap();
        let e = err(&base);
        assert!(e.contains("K.txt") && e.contains("3"), "{e}");
    }
}
