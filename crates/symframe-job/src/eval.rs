//! The evaluation job (`symframe eval`): compares an estimate (`normals.npy`, `tangents.npy`)
//! with a synthetic dataset's ground truth (`gt_normals.npy`, optional `gt_tangents.npy` and
//! `mask.png`); writes `eval.json` and error pictures with colour bars into the estimate folder.
//! Only pixels whose true normal is within `max_angle` of the view count: of each pixel's own
//! view where the dataset has a pinhole camera (`K.txt`), else of +z.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use glam::DVec3;
use serde::Serialize;
use symframe::{evaluate, Evaluation};

use crate::colorbar::{error_picture, Cell, Scale};

/// Everything an evaluation needs.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalConfig {
    /// Synthetic dataset folder (or its `.lp` file) holding `gt_normals.npy`, optionally
    /// `gt_tangents.npy` and `mask.png`.
    pub dataset: PathBuf,
    /// Output folder of [`crate::estimate`]; `eval.json`, `normal_error.png` and
    /// `tangent_error.png` are written into it.
    pub estimate: PathBuf,
    /// Only pixels whose true normal is within this many degrees of the view are evaluated.
    pub max_angle: f64,
    /// Top of the error pictures' colour scale, degrees (`None`: a round number near the 95th
    /// percentile of each map).
    pub scale_max: Option<f64>,
}

impl EvalConfig {
    /// Pixels within 60 degrees of the view, scales from the errors.
    pub fn new(dataset: impl Into<PathBuf>, estimate: impl Into<PathBuf>) -> Self {
        Self {
            dataset: dataset.into(),
            estimate: estimate.into(),
            max_angle: 60.0,
            scale_max: None,
        }
    }
}

/// What `eval.json` holds: where the figures come from, and the figures.
#[derive(Debug, Serialize)]
pub struct EvalReport {
    /// symframe version.
    pub version: &'static str,
    /// The dataset folder the ground truth was read from.
    pub dataset: PathBuf,
    /// The estimate folder.
    pub estimate: PathBuf,
    /// The estimate's method, from its `report.json` when there is one.
    pub method: Option<String>,
    /// Top of the normal-error picture's colour scale, degrees.
    pub normal_scale_max_deg: f64,
    /// Top of the tangent-error picture's colour scale, degrees (none without tangent truth).
    pub tangent_scale_max_deg: Option<f64>,
    /// The view the angle limit is measured from: `+z`, or each pixel's own through the
    /// dataset's `K.txt`.
    pub view: &'static str,
    /// The error figures.
    #[serde(flatten)]
    pub evaluation: Evaluation,
}

/// The dataset folder of a dataset argument: the folder itself, or the folder of a file in it
/// (its `.lp`).
fn dataset_dir(p: &Path) -> Result<PathBuf> {
    if p.is_dir() {
        Ok(p.to_path_buf())
    } else if p.is_file() {
        Ok(p.parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf())
    } else {
        bail!("{}: no such dataset folder or file", p.display())
    }
}

/// Reads an `H x W x 3` float32 map as `((H, W), values)`; `expect` is the `(H, W)` it must
/// have, with the file it must agree with.
fn read_vectors(
    path: &Path,
    expect: Option<((usize, usize), &Path)>,
) -> Result<((usize, usize), Vec<f32>)> {
    let (shape, data) = symframe_io::read_npy_f32(path)?;
    if shape.len() != 3 || shape[2] != 3 {
        bail!(
            "{}: expected an H x W x 3 array, got shape {shape:?}",
            path.display()
        );
    }
    if let Some(((h, w), other)) = expect {
        if (shape[0], shape[1]) != (h, w) {
            bail!(
                "{}: map is {}x{} but {} is {w}x{h}",
                path.display(),
                shape[1],
                shape[0],
                other.display()
            );
        }
    }
    Ok(((shape[0], shape[1]), data))
}

/// The 95th percentile of the finite values at the pixels where `keep` is true (the default
/// top of a colour scale); `None` if there are none.
fn p95(values: &[f32], keep: &[bool]) -> Option<f64> {
    let mut v: Vec<f64> = values
        .iter()
        .zip(keep)
        .filter(|(x, &k)| k && x.is_finite())
        .map(|(&x, _)| x as f64)
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[((0.95 * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)])
}

/// Whether pixel `p` is inside the mask (every pixel is without one).
fn inside(mask: Option<&[bool]>, p: usize) -> bool {
    match mask {
        Some(m) => m[p],
        None => true,
    }
}

/// The evaluated pixels: inside the mask, with a true normal within `max_angle_deg` of the
/// pixel's view (as [`evaluate`] counts them).
fn evaluated(
    gt_normals: &[f32],
    mask: Option<&[bool]>,
    max_angle_deg: f64,
    view: &dyn Fn(usize) -> DVec3,
) -> Vec<bool> {
    let cos_max = max_angle_deg.to_radians().cos();
    gt_normals
        .chunks_exact(3)
        .enumerate()
        .map(|(p, n)| {
            let n = DVec3::from_array([0, 1, 2].map(|c| n[c] as f64));
            let len = n.length();
            inside(mask, p) && len > 0.0 && n.dot(view(p)) / len >= cos_max
        })
        .collect()
}

/// Pixels of an error map: an error where both sides exist, "no estimate" where only the
/// reference does (inside the mask), "no reference" elsewhere.
fn cells(errors: &[f32], reference: &[f32], mask: Option<&[bool]>) -> Vec<Cell> {
    errors
        .iter()
        .enumerate()
        .map(|(p, &e)| {
            let has_ref =
                reference[p * 3..p * 3 + 3].iter().all(|v| v.is_finite()) && inside(mask, p);
            match (has_ref, e.is_finite()) {
                (false, _) => Cell::NoReference,
                (true, true) => Cell::Error(e),
                (true, false) => Cell::NoEstimate,
            }
        })
        .collect()
}

/// Writes a small text file by a temporary sibling created anew and a rename (never
/// half-written, never written through a link planted at either name).
fn write_text(path: &Path, text: &str) -> Result<()> {
    Ok(symframe_io::write_bytes(path, text.as_bytes())?)
}

/// Runs an evaluation: compares the estimate with the dataset's ground truth, writes
/// `eval.json` and the error pictures into the estimate folder (holding its lock; `ctl` is told
/// when it is taken); returns what `eval.json` holds.
pub fn evaluate_job(config: &EvalConfig, ctl: &crate::Control) -> Result<EvalReport> {
    if !(config.max_angle > 0.0 && config.max_angle <= 90.0) {
        bail!(
            "the largest normal angle must be in (0, 90] degrees, got {}",
            config.max_angle
        );
    }
    if let Some(s) = config.scale_max {
        if !(s > 0.0 && s.is_finite()) {
            bail!("the colour scale's top must be a positive number of degrees, got {s}");
        }
    }
    let dir = dataset_dir(&config.dataset)?;
    let gt_n_path = dir.join("gt_normals.npy");
    if !gt_n_path.is_file() {
        bail!(
            "{}: missing: the dataset has no ground-truth normals",
            gt_n_path.display()
        );
    }
    let ((h, w), gt_normals) = read_vectors(&gt_n_path, None)?;
    let size = Some(((h, w), gt_n_path.as_path()));
    let gt_t_path = dir.join("gt_tangents.npy");
    let gt_tangents = if gt_t_path.is_file() {
        Some(read_vectors(&gt_t_path, size)?.1)
    } else {
        None
    };
    let mask_path = dir.join("mask.png");
    let mask = if mask_path.is_file() {
        Some(symframe_io::read_mask(&mask_path, w, h)?)
    } else {
        None
    };

    let est = &config.estimate;
    if !est.is_dir() {
        bail!("{}: no such estimate folder", est.display());
    }
    // The estimate folder's lock, held while its maps are read and eval's files written: no
    // estimate, fit or other eval into the folder runs meanwhile.
    let _lock = crate::OutputDir::lock(est)?;
    (ctl.checkpoint)(crate::Checkpoint::OutputLocked);
    let n_path = est.join("normals.npy");
    if !n_path.is_file() {
        bail!(
            "{}: missing: not an output folder of symframe estimate",
            n_path.display()
        );
    }
    let normals = read_vectors(&n_path, size)?.1;
    let t_path = est.join("tangents.npy");
    let tangents = if t_path.is_file() {
        read_vectors(&t_path, size)?.1
    } else {
        vec![f32::NAN; normals.len()]
    };
    let method = symframe_io::read_text_bounded(
        &est.join("report.json"),
        "a report",
        symframe_io::limits::MAX_TEXT_FILE_BYTES,
    )
    .ok()
    .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
    .and_then(|v| v["method"].as_str().map(String::from));

    // A perspective dataset (K.txt beside it): each pixel's own view; else the view is +z.
    let k_path = dir.join("K.txt");
    let camera = if k_path.is_file() {
        Some(symframe_io::near::read_camera(&k_path)?)
    } else {
        None
    };
    let view = |p: usize| match &camera {
        Some(c) => c.view((p % w) as f64, (p / w) as f64),
        None => DVec3::Z,
    };
    let evaluation = evaluate(
        &normals,
        &tangents,
        &gt_normals,
        gt_tangents.as_deref(),
        mask.as_deref(),
        config.max_angle,
        Some(&view),
    );
    // Colour scales: the user's top, or a round number near the 95th percentile of the
    // evaluated pixels' errors (those outside still show, clipped to the top colour).
    let keep = evaluated(&gt_normals, mask.as_deref(), config.max_angle, &view);
    let scale_for = |errors: &[f32], cap: f64| match config.scale_max {
        Some(s) => Scale::fixed(s),
        None => Scale::rounded(p95(errors, &keep).unwrap_or(cap)).capped(cap),
    };

    // Everything is computed before anything is written.
    let n_err = Evaluation::normal_error_map(&normals, &gt_normals);
    let n_scale = scale_for(&n_err, 180.0);
    let n_pic = error_picture(
        "normal error (degrees)",
        &cells(&n_err, &gt_normals, mask.as_deref()),
        w,
        h,
        &n_scale,
    )?;
    let t_pic = match &gt_tangents {
        Some(gt_t) => {
            let t_err = Evaluation::tangent_error_map(&tangents, gt_t);
            let t_scale = scale_for(&t_err, 90.0);
            let pic = error_picture(
                "tangent axis error (degrees)",
                &cells(&t_err, gt_t, mask.as_deref()),
                w,
                h,
                &t_scale,
            )?;
            Some((pic, t_scale.max))
        }
        None => None,
    };
    let report = EvalReport {
        version: env!("CARGO_PKG_VERSION"),
        dataset: dir,
        estimate: est.clone(),
        method,
        normal_scale_max_deg: n_scale.max,
        tangent_scale_max_deg: t_pic.as_ref().map(|t| t.1),
        view: if camera.is_some() {
            "each pixel's own, through the dataset's K.txt"
        } else {
            "+z"
        },
        evaluation,
    };

    let (rgb, pw, ph) = &n_pic;
    symframe_io::write_png_rgb8(&est.join("normal_error.png"), *pw, *ph, rgb)?;
    if let Some(((rgb, pw, ph), _)) = &t_pic {
        symframe_io::write_png_rgb8(&est.join("tangent_error.png"), *pw, *ph, rgb)?;
    }
    write_text(
        &est.join("eval.json"),
        &(serde_json::to_string_pretty(&report)? + "\n"),
    )?;

    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{synth_near, Control, NearSynthConfig};

    /// On a perspective dataset the 60-degree limit is taken from each pixel's own view: the
    /// pixels counted are those whose true normal is within 60 degrees of the ray back to the
    /// camera, not of +z.
    #[test]
    fn a_perspective_dataset_is_evaluated_in_each_pixels_view() {
        let d = tempfile::tempdir().unwrap();
        let data = d.path().join("data");
        let capture = NearSynthConfig {
            size: 64,
            lights: 8,
            ..NearSynthConfig::new(&data)
        };
        synth_near(&capture, &Control::default()).unwrap();
        let est = d.path().join("est");
        std::fs::create_dir(&est).unwrap();
        std::fs::copy(data.join("gt_normals.npy"), est.join("normals.npy")).unwrap();
        let report = evaluate_job(&EvalConfig::new(&data, &est), &Control::default()).unwrap();
        assert!(report.view.contains("K.txt"));
        let camera = capture.scene().camera;
        let (_, gt) = symframe_io::read_npy_f32(&data.join("gt_normals.npy")).unwrap();
        let count = |view: &dyn Fn(usize) -> DVec3| {
            (0..gt.len() / 3)
                .filter(|&p| {
                    let n = DVec3::from_array([0, 1, 2].map(|c| gt[3 * p + c] as f64));
                    n.is_finite() && n.dot(view(p)) >= 0.5
                })
                .count()
        };
        let own = count(&|p| camera.view((p % 64) as f64, (p / 64) as f64));
        let along_z = count(&|_| DVec3::Z);
        assert_eq!(report.evaluation.pixels, own);
        assert_ne!(own, along_z);
        assert!(report.evaluation.normal_error.mean < 1e-3);
        // Without K.txt the view is +z, as for every distant-light dataset.
        std::fs::remove_file(data.join("K.txt")).unwrap();
        let report = evaluate_job(&EvalConfig::new(&data, &est), &Control::default()).unwrap();
        assert_eq!((report.view, report.evaluation.pixels), ("+z", along_z));
    }
}
