//! Near lights and a pinhole camera beside a dataset: `light_positions.txt` and `K.txt`, with
//! the optional `light_principal_directions.txt` and `light_mu.txt` of LED domes (as LUCES and
//! Quéau et al.'s data give them), read from the dataset's folder.
//!
//! Conventions (docs/method.md, "Near lights and perspective cameras"): positions are in the
//! camera frame (x = image right, y = image up, z = toward the viewer, origin at the centre of
//! projection, so the object has z < 0), in any length unit; `K.txt` is OpenCV's 3 x 3
//! intrinsics (u right, v down, the centre of the top-left pixel at (0, 0)). Rows are in the
//! dataset's image order. Intensities stay where they were: `light_intensities.txt` divides the
//! images as it does for distant lights.

use std::path::{Path, PathBuf};

use glam::DVec3;
use symframe::{Pinhole, PointLight};

use super::Dataset;
use crate::error::{Error, Result, Warning};
use crate::lights;

/// The light positions' file name.
pub const POSITIONS: &str = "light_positions.txt";
/// The intrinsics' file name.
pub const INTRINSICS: &str = "K.txt";
/// The LED principal directions' file name.
pub const PRINCIPAL: &str = "light_principal_directions.txt";
/// The LED falloff exponents' file name.
pub const MU: &str = "light_mu.txt";

/// Median angle (degrees) between a dataset's light directions and those of its light positions
/// seen from the lights' sphere centre above which the two files are said to disagree.
const DISAGREE_DEG: f64 = 2.0;

/// The near-light geometry of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct NearGeometry {
    /// The camera.
    pub camera: Pinhole,
    /// One light per image, in the dataset's order; unit intensities (the images are divided
    /// by `light_intensities.txt` when they are read).
    pub lights: Vec<PointLight>,
    /// The sphere through the light positions (centre, radius), when they lie on one: where the
    /// object is taken to be when its distance is not given.
    pub dome: Option<(DVec3, f64)>,
    /// The files read.
    pub files: Vec<PathBuf>,
    /// What the user should know (light directions that disagree with the positions).
    pub warnings: Vec<Warning>,
}

/// Reads a `K.txt` (OpenCV's 3 x 3 pinhole intrinsics) as a camera; errors name the file (and
/// the line).
pub fn read_camera(path: &Path) -> Result<Pinhole> {
    Pinhole::from_k(lights::parse_k(path)?).map_err(|why| Error::invalid(path, why))
}

/// Reads a `light_positions.txt` (one `x y z` row per light, camera frame); errors name the file
/// and the line.
pub fn read_positions(path: &Path) -> Result<Vec<DVec3>> {
    lights::parse_positions(path)
}

/// The folder a dataset's side files are in: the folder it was opened as, or its file's folder.
fn folder(ds: &Dataset) -> PathBuf {
    if ds.source.is_dir() {
        ds.source.clone()
    } else {
        ds.source
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    }
}

/// Whether `path` exists (a broken link counts: reading it then names it).
fn present(path: &Path) -> bool {
    path.symlink_metadata().is_ok()
}

/// Reads the near-light geometry beside `ds`: `None` where its folder holds neither
/// `light_positions.txt` nor `K.txt`; an error naming the file (and line) where one is there
/// without the other, a row count differs from the dataset's images, or a row is bad.
pub fn open_near_geometry(ds: &Dataset) -> Result<Option<NearGeometry>> {
    let dir = folder(ds);
    let [pos, k, principal, mu] = [POSITIONS, INTRINSICS, PRINCIPAL, MU].map(|n| dir.join(n));
    let (has_pos, has_k) = (present(&pos), present(&k));
    if !has_pos && !has_k {
        for extra in [&principal, &mu] {
            if present(extra) {
                return Err(Error::invalid(
                    extra,
                    format!("LED data need the lights' positions: {POSITIONS} and {INTRINSICS} beside it"),
                ));
            }
        }
        return Ok(None);
    }
    // An .lp whose rows are positions stands for light_positions.txt.
    let lp_rows = if has_k && !has_pos && ds.source.is_file() {
        let lp = ds
            .source
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("lp"));
        if lp {
            super::lp_positions(&ds.source)?
        } else {
            None
        }
    } else {
        None
    };
    if !has_k {
        return Err(Error::invalid(
            &pos,
            format!(
                "near lights need the camera too: {} is missing (the 3 x 3 pinhole intrinsics, \
                 OpenCV's convention)",
                k.display()
            ),
        ));
    }
    if !has_pos && lp_rows.is_none() {
        return Err(Error::invalid(
            &k,
            format!(
                "a perspective camera is read with near lights only: {} is missing (one `x y z` \
                 row per image, camera frame; or an .lp whose rows are the positions, most of \
                 them far from unit length)",
                pos.display()
            ),
        ));
    }
    let n = ds.images.len();
    let (pos, positions) = match lp_rows {
        Some(rows) => (ds.source.clone(), rows),
        None => (pos.clone(), lights::parse_positions(&pos)?),
    };
    let count = |path: &Path, got: usize, what: &str| -> Result<()> {
        if got == n {
            return Ok(());
        }
        Err(Error::invalid(
            path,
            format!(
                "{got} {what} but the dataset ({}) has {n} images",
                ds.source.display()
            ),
        ))
    };
    count(&pos, positions.len(), "light positions")?;
    let camera = Pinhole::from_k(lights::parse_k(&k)?).map_err(|why| Error::invalid(&k, why))?;
    let mut files = vec![pos.clone(), k];
    let principals = if present(&principal) {
        let v = lights::parse_principal_directions(&principal)?;
        count(&principal, v.len(), "principal directions")?;
        files.push(principal.clone());
        Some(v)
    } else {
        None
    };
    let mus = if present(&mu) {
        if principals.is_none() {
            return Err(Error::invalid(
                &mu,
                format!(
                    "falloff exponents need the LEDs' principal directions: {PRINCIPAL} beside it"
                ),
            ));
        }
        let v = lights::parse_mu(&mu)?;
        if v.len() != 1 {
            count(&mu, v.len(), "falloff exponents (or one for every light)")?;
        }
        files.push(mu.clone());
        Some(v)
    } else {
        None
    };
    let lights: Vec<PointLight> = positions
        .iter()
        .enumerate()
        .map(|(i, &position)| PointLight {
            principal: principals.as_ref().map(|p| p[i]),
            mu: mus
                .as_ref()
                .map_or(0.0, |m| m[if m.len() == 1 { 0 } else { i }]),
            ..PointLight::isotropic(position)
        })
        .collect();
    let dome = PointLight::fit_sphere(&positions);
    let warnings = disagreement(ds, &pos, &positions, dome)
        .into_iter()
        .collect();
    Ok(Some(NearGeometry {
        camera,
        lights,
        dome,
        files,
        warnings,
    }))
}

/// The unit directions from the centre of the sphere through `positions` (read from `path`) to
/// each light: a dataset's distant lights when it gives positions alone. An error where the
/// positions lie on no sphere (on a plane, or fewer than four), since where the object is cannot
/// then be told from them.
pub(crate) fn directions_from_positions(path: &Path, positions: &[DVec3]) -> Result<Vec<DVec3>> {
    let Some((centre, _)) = PointLight::fit_sphere(positions) else {
        return Err(Error::invalid(
            path,
            "the light positions lie on no sphere (fewer than 4, or on a plane), so where the \
             object is cannot be told from them: give light_directions.txt (the directions at \
             the object) beside them",
        ));
    };
    positions
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            (p - centre).try_normalize().ok_or_else(|| {
                Error::invalid(
                    path,
                    format!("light {} is at the lights' sphere centre", i + 1),
                )
            })
        })
        .collect()
}

/// A warning where the dataset's light directions are not those of its light positions seen
/// from the lights' sphere centre (median angle over [`DISAGREE_DEG`]): the positions are used.
fn disagreement(
    ds: &Dataset,
    pos: &Path,
    positions: &[DVec3],
    dome: Option<(DVec3, f64)>,
) -> Option<Warning> {
    let (centre, _) = dome?;
    let mut angles: Vec<f64> = ds
        .lights
        .iter()
        .zip(positions)
        .filter_map(|(d, p)| Some(d.angle_between((*p - centre).try_normalize()?).to_degrees()))
        .collect();
    if angles.is_empty() {
        return None;
    }
    let k = angles.len() / 2;
    let median = *angles.select_nth_unstable_by(k, f64::total_cmp).1;
    let max = angles.iter().copied().fold(0.0, f64::max);
    (median > DISAGREE_DEG).then(|| Warning {
        path: ds.source.clone(),
        message: format!(
            "its light directions disagree with {} seen from the lights' sphere centre ({:.3} \
             {:.3} {:.3}): median {median:.1} degrees, largest {max:.1}; the positions are used",
            pos.display(),
            centre.x,
            centre.y,
            centre.z
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    /// A DiLiGenT folder of `n` empty images with `files` written into it.
    fn folder_with(n: usize, files: &[(&str, String)]) -> tempfile::TempDir {
        let d = tempfile::tempdir().unwrap();
        let mut names = String::new();
        for i in 0..n {
            let name = format!("{i}.png");
            fs::write(d.path().join(&name), b"").unwrap();
            names += &format!("{name}\n");
        }
        fs::write(d.path().join("filenames.txt"), names).unwrap();
        for (name, text) in files {
            fs::write(d.path().join(name), text).unwrap();
        }
        d
    }

    fn dome(n: usize) -> Vec<DVec3> {
        (0..n)
            .map(|i| {
                let a = i as f64 * 2.4;
                let z = 0.1 + 0.8 * i as f64 / n as f64;
                let r = (1.0 - z * z).sqrt();
                DVec3::new(0.0, 0.0, -12.0) + 8.0 * DVec3::new(r * a.cos(), r * a.sin(), z)
            })
            .collect()
    }

    fn rows(v: &[DVec3]) -> String {
        v.iter()
            .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
            .collect()
    }

    const K: &str = "500 0 63.5\n0 500 31.5\n0 0 1\n";

    #[test]
    fn positions_alone_make_a_dataset_and_its_geometry() {
        let lights = dome(8);
        let d = folder_with(
            8,
            &[
                (POSITIONS, rows(&lights)),
                (INTRINSICS, K.into()),
                (PRINCIPAL, "0 0 -1\n".repeat(8)),
                (MU, "2\n".into()),
            ],
        );
        let ds = crate::open_dataset(d.path()).unwrap();
        // The distant directions are those from the dome's centre.
        let c = DVec3::new(0.0, 0.0, -12.0);
        for (l, p) in ds.lights.iter().zip(&lights) {
            assert!(l.angle_between(*p - c) < 1e-9);
        }
        let g = open_near_geometry(&ds).unwrap().unwrap();
        assert_eq!(
            g.camera.k(),
            [[500.0, 0.0, 63.5], [0.0, 500.0, 31.5], [0.0, 0.0, 1.0]]
        );
        assert_eq!(g.lights.len(), 8);
        assert_eq!(g.lights[3].position, lights[3]);
        assert_eq!(g.lights[3].principal, Some(-DVec3::Z));
        assert_eq!(g.lights[3].mu, 2.0);
        assert!((g.dome.unwrap().0 - c).length() < 1e-9);
        assert!(g.warnings.is_empty(), "{:?}", g.warnings);
        assert_eq!(g.files.len(), 4);
    }

    /// An `.lp` whose rows are positions (in mm: far from unit length) with K.txt beside it is
    /// read as near lights: the positions as written, the distant directions from the dome's
    /// centre, no warning; without K.txt its rows are directions, normalised and warned about.
    #[test]
    fn lp_rows_far_from_unit_length_are_positions_beside_k() {
        let mm: Vec<DVec3> = dome(8).iter().map(|p| *p * 100.0).collect();
        let lp_text = mm.iter().enumerate().fold("8\n".to_string(), |t, (i, p)| {
            t + &format!("{i}.png {} {} {}\n", p.x, p.y, p.z)
        });
        let d = folder_with(8, &[("lights.lp", lp_text.clone()), (INTRINSICS, K.into())]);
        let lp = d.path().join("lights.lp");
        let ds = crate::open_dataset(&lp).unwrap();
        assert!(ds.warnings.is_empty(), "{:?}", ds.warnings);
        let c = DVec3::new(0.0, 0.0, -1200.0);
        for (l, p) in ds.lights.iter().zip(&mm) {
            assert!(
                l.angle_between(*p - c) < 1e-6,
                "{}",
                l.angle_between(*p - c)
            );
        }
        let g = open_near_geometry(&ds).unwrap().unwrap();
        for (l, p) in g.lights.iter().zip(&mm) {
            assert!((l.position - *p).length() < 1e-9 * p.length());
        }
        assert_eq!(g.files[0], lp);
        assert!(g.warnings.is_empty(), "{:?}", g.warnings);
        // Without K.txt: directions from the origin, and the warning.
        let d = folder_with(8, &[("lights.lp", lp_text)]);
        let ds = crate::open_dataset(&d.path().join("lights.lp")).unwrap();
        assert!(ds.lights[0].angle_between(mm[0]) < 1e-9);
        assert!(
            ds.warnings
                .iter()
                .any(|w| w.message.contains("far from unit length")),
            "{:?}",
            ds.warnings
        );
        assert_eq!(open_near_geometry(&ds).unwrap(), None);
    }

    #[test]
    fn directions_that_disagree_are_warned_about() {
        let lights = dome(8);
        let wrong: Vec<DVec3> = lights.iter().map(|p| p.normalize()).collect();
        let d = folder_with(
            8,
            &[
                (POSITIONS, rows(&lights)),
                (INTRINSICS, K.into()),
                ("light_directions.txt", rows(&wrong)),
            ],
        );
        let ds = crate::open_dataset(d.path()).unwrap();
        let g = open_near_geometry(&ds).unwrap().unwrap();
        assert_eq!(g.warnings.len(), 1);
        let w = g.warnings[0].to_string();
        assert!(w.contains("disagree") && w.contains(POSITIONS), "{w}");
    }

    #[test]
    fn bad_files_are_named_with_their_line() {
        let lights = dome(8);
        let err = |files: &[(&str, String)]| -> String {
            let d = folder_with(8, files);
            let r = crate::open_dataset(d.path()).and_then(|ds| open_near_geometry(&ds));
            r.expect_err("expected an error").to_string()
        };
        let e = err(&[(POSITIONS, rows(&lights))]);
        assert!(
            e.contains(POSITIONS) && e.contains("K.txt is missing"),
            "{e}"
        );
        let e = err(&[(POSITIONS, rows(&lights[..7])), (INTRINSICS, K.into())]);
        assert!(
            e.contains("7 light positions") && e.contains("8 images"),
            "{e}"
        );
        let e = err(&[
            (POSITIONS, rows(&lights)),
            (INTRINSICS, "500 0 63.5\n0 500 x\n0 0 1\n".into()),
        ]);
        assert!(e.contains("K.txt:2:") && e.contains("'x'"), "{e}");
        let e = err(&[
            (POSITIONS, rows(&lights)),
            (INTRINSICS, "500 0 63.5\n0 500 31.5\n".into()),
        ]);
        assert!(e.contains("K.txt") && e.contains("found 2 rows"), "{e}");
        let e = err(&[
            (POSITIONS, rows(&lights)),
            (INTRINSICS, "500 0 63.5\n0 500 31.5\n0 0 2\n".into()),
        ]);
        assert!(e.contains("K.txt") && e.contains("0 0 1"), "{e}");
        let mut bad = rows(&lights);
        bad += "1 2\n";
        let e = err(&[(POSITIONS, bad), (INTRINSICS, K.into())]);
        assert!(e.contains("light_positions.txt:9:"), "{e}");
        let e = err(&[
            (POSITIONS, rows(&lights)),
            (INTRINSICS, K.into()),
            (PRINCIPAL, "0 0 -1\n".repeat(8)),
            (MU, "2\n-1\n".into()),
        ]);
        assert!(e.contains("light_mu.txt:2:"), "{e}");
        let e = err(&[
            (POSITIONS, rows(&lights)),
            (INTRINSICS, K.into()),
            (MU, "2\n".into()),
        ]);
        assert!(e.contains(MU) && e.contains(PRINCIPAL), "{e}");
        // Lights on a plane, no directions: where the object is cannot be told.
        let flat: Vec<DVec3> = (0..8)
            .map(|i| DVec3::new(i as f64, (i % 3) as f64, 0.0))
            .collect();
        let e = err(&[(POSITIONS, rows(&flat)), (INTRINSICS, K.into())]);
        assert!(
            e.contains("no sphere") && e.contains("light_directions.txt"),
            "{e}"
        );
    }
}
