//! A photometric dataset description: which images, lit from which directions, with what
//! intensities, and an optional mask. Opening a dataset reads only text files, not images.

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::error::{Error, Result, Warning};
use crate::lights;

/// Where a dataset's images are and how each was lit.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The file or folder the dataset was opened from (for messages).
    pub source: PathBuf,
    /// Unit light directions (surface toward light, camera frame), one per image.
    pub lights: Vec<DVec3>,
    /// Image paths (absolute, or relative to the current directory), one per light.
    pub images: Vec<PathBuf>,
    /// Optional per-light RGB intensities; images are divided by them when loaded.
    pub intensities: Option<Vec<[f32; 3]>>,
    /// Optional mask image (`mask.png` beside the light file): non-zero pixels are processed.
    pub mask: Option<PathBuf>,
    /// What the user should know about how the dataset was read (a `light_intensities.txt`
    /// beside an `.lp` applied although another `.lp` beside it has as many lights, or not
    /// applied because it is another one's); jobs print them and list them in their reports.
    pub warnings: Vec<Warning>,
}

/// File names of a DiLiGenT-style folder.
const FILENAMES: &str = "filenames.txt";
const DIRECTIONS: &str = "light_directions.txt";
const INTENSITIES: &str = "light_intensities.txt";
const MASK: &str = "mask.png";
pub mod near;

use near::POSITIONS;

/// Opens a dataset from an RTI `.lp` file, a folder holding exactly one `.lp` file, or a
/// DiLiGenT-style folder (`filenames.txt`, `light_directions.txt`, optional
/// `light_intensities.txt` and `mask.png`).
///
/// `.lp` format: the light count `N` on the first meaningful line, then `N` lines
/// `<image> <lx> <ly> <lz>`, image paths relative to the `.lp` file's folder (a path with spaces
/// is everything before the last three numbers; fields are separated by spaces or tabs). Blank
/// lines and `#` comments are allowed. Directions are normalised (lights far from unit length,
/// near-light positions perhaps, are warned about); every listed image must exist. The row
/// variants other tools write are read or refused as `lights.rs` says.
pub fn open_dataset(input: &Path) -> Result<Dataset> {
    if input.is_dir() {
        return open_folder(input);
    }
    if !input.exists() {
        if input.symlink_metadata().is_ok() {
            return Err(Error::invalid(
                input,
                "is a broken symbolic link (its target does not exist)",
            ));
        }
        let message = match suggestion(input) {
            Some(near) => format!("no such file or folder; did you mean {}?", near.display()),
            None => "no such file or folder".to_string(),
        };
        return Err(Error::read(
            input,
            std::io::Error::new(std::io::ErrorKind::NotFound, message),
        ));
    }
    let name = input.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if is_lp(input) {
        return open_lp(input);
    }
    if name == FILENAMES || name == DIRECTIONS || name == INTENSITIES || name == POSITIONS {
        let dir = parent_dir(input);
        return open_diligent(&dir, input);
    }
    Err(Error::invalid(
        input,
        "not a dataset: expected a .lp light file or a folder with one .lp file or with \
         filenames.txt and light_directions.txt",
    ))
}

/// The entry of a missing path's folder whose name is nearest its own (Jaro-Winkler
/// similarity at least 0.8, as clap suggests flags; an `.lp` file for a missing `.lp` whatever
/// its name, when it is the folder's only one): the mistyped name or the dataset's real light
/// file. `None` where the folder is missing or holds nothing near.
fn suggestion(missing: &Path) -> Option<PathBuf> {
    let name = missing.file_name()?.to_str()?;
    let dir = parent_dir(missing);
    let listed = if dir.as_os_str().is_empty() {
        std::fs::read_dir(".")
    } else {
        std::fs::read_dir(&dir)
    };
    let entries: Vec<String> = listed
        .ok()?
        .flatten()
        .take(10_000)
        .filter_map(|e| e.file_name().into_string().ok())
        .collect();
    let best = entries
        .iter()
        .map(|e| {
            (
                strsim::jaro_winkler(&name.to_lowercase(), &e.to_lowercase()),
                e,
            )
        })
        .filter(|(score, _)| *score >= 0.8)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, e)| e.clone());
    let lone_lp = || {
        let mut lps = entries.iter().filter(|e| is_lp(Path::new(e)));
        match (lps.next(), lps.next()) {
            (Some(only), None) if is_lp(missing) => Some(only.clone()),
            _ => None,
        }
    };
    best.or_else(lone_lp).map(|e| dir.join(e))
}

/// How many files of `dir` are images symframe reads (by extension).
fn image_count(dir: &Path) -> usize {
    const IMAGES: &[&str] = &["exr", "png", "tif", "tiff", "hdr", "pfm", "jpg", "jpeg"];
    std::fs::read_dir(dir).map_or(0, |rd| {
        rd.flatten()
            .filter(|e| {
                e.path()
                    .extension()
                    .and_then(|x| x.to_str())
                    .is_some_and(|x| IMAGES.contains(&x.to_ascii_lowercase().as_str()))
            })
            .count()
    })
}

/// Whether `p` has the `.lp` extension (case-insensitive).
fn is_lp(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("lp"))
}

/// The folder of a file, `""` (the current directory) when the path has none.
fn parent_dir(p: &Path) -> PathBuf {
    p.parent().map(Path::to_path_buf).unwrap_or_default()
}

/// `dir/mask.png` if there is one; an error if that name is taken by something that is not a
/// file (a folder, a broken link, a FIFO), which would otherwise be silently ignored.
fn mask_in(dir: &Path) -> Result<Option<PathBuf>> {
    let m = dir.join(MASK);
    if m.symlink_metadata().is_err() {
        return Ok(None);
    }
    match lights::not_a_file(&m) {
        None => Ok(Some(m)),
        Some(why) => Err(Error::invalid(
            &m,
            why.strip_prefix(&format!("{} ", m.display()))
                .unwrap_or(&why)
                .replace("an image file", "a mask image"),
        )),
    }
}

/// Opens a dataset folder: one `.lp` file, else the DiLiGenT tables.
fn open_folder(dir: &Path) -> Result<Dataset> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::read(dir, e))?;
    let mut lps = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| Error::read(dir, e))?;
        let p = entry.path();
        if p.is_file() && is_lp(&p) {
            lps.push(p);
        }
    }
    lps.sort();
    if lps.len() == 1 {
        return open_lp(&lps[0]);
    }
    if dir.join(FILENAMES).is_file()
        && (dir.join(DIRECTIONS).is_file() || dir.join(POSITIONS).is_file())
    {
        return open_diligent(dir, dir);
    }
    if lps.len() > 1 {
        let names: Vec<String> = lps
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        return Err(Error::invalid(
            dir,
            format!(
                "not a dataset: found several .lp files ({}); give one of them",
                names.join(", ")
            ),
        ));
    }
    let images = image_count(dir);
    let hint = if images > 0 {
        format!(
            "; the folder holds {images} images but not their lights: list them in an .lp \
             file (the count, then one `image x y z` row per image, x right, y up, z toward \
             the camera), or, with a chrome sphere in the frame, `symframe calibrate {} -o \
             {}`",
            dir.display(),
            dir.join("lights.lp").display()
        )
    } else {
        String::new()
    };
    Err(Error::invalid(
        dir,
        format!(
            "not a dataset: looked for one .lp light file, or filenames.txt and \
             light_directions.txt{hint}"
        ),
    ))
}

/// Opens an `.lp` dataset; `mask.png` beside it is picked up, and so is
/// `light_intensities.txt` (one `r g b` row per light, in the `.lp`'s order, as `symframe
/// calibrate --matte-sphere` writes it) by the rule of [`lp_intensities`].
fn open_lp(lp: &Path) -> Result<Dataset> {
    let lights::LpFile {
        images,
        lights,
        lengths,
        ..
    } = lights::parse_lp(lp)?;
    let dir = parent_dir(lp);
    let (intensities, mut warnings) = lp_intensities(lp, &dir, images.len())?;
    // Rows that are the positions of near lights: their distant directions are those from the
    // centre of the sphere through them, as for light_positions.txt alone.
    let from_positions = positions_of(&dir, &lights, &lengths)
        .and_then(|p| near::directions_from_positions(lp, &p).ok());
    let lights = match from_positions {
        Some(directions) => directions,
        None => {
            warnings.extend(convention_warning(lp, &lights));
            warnings.extend(length_warning(lp, &lengths));
            lights
        }
    };
    Ok(Dataset {
        source: lp.to_path_buf(),
        lights,
        images,
        intensities,
        mask: mask_in(&dir)?,
        warnings,
    })
}

/// Share of the lights pointing away from the camera (`z < 0`) above which the light file's
/// convention is doubted: a dome or an arc lights the object from the camera's side; a
/// symmetric rig whose halfway vectors fill a 65-degree cone (lights to 130 degrees from the
/// view) has under half of its lights behind; a dome read with its z axis the other way has
/// nearly all.
const BEHIND_SHARE: f64 = 0.75;

/// A warning where most of `lights` (read from `path`) point away from the camera: the
/// commonest convention mix-up (z toward the scene instead of toward the camera) runs without
/// an error, with the lights that survive the cone mirrored, and normals far off.
fn convention_warning(path: &Path, lights: &[DVec3]) -> Option<Warning> {
    let behind = lights.iter().filter(|l| l.z < 0.0).count();
    (!lights.is_empty() && behind as f64 > BEHIND_SHARE * lights.len() as f64).then(|| Warning {
        path: path.to_path_buf(),
        message: format!(
            "{behind} of {} lights point away from the camera (z < 0): symframe reads x right, \
             y up, z toward the camera, each light from the object toward the lamp; if this \
             file's z points into the scene, negate its z column",
            lights.len()
        ),
    })
}

/// How far from 1 a light's length as written may be (a factor either way) and still count
/// as a direction: unit vectors written to 6 digits, hand-written `0 0 2` or `1 1 1` are; light
/// positions in millimetres or centimetres are not.
const UNIT_FACTOR: f64 = 3.0;

/// Whether most of the lengths as written are far from unit length ([`UNIT_FACTOR`]).
fn mostly_far(lengths: &[f64]) -> bool {
    let far = lengths
        .iter()
        .filter(|l| !(1.0 / UNIT_FACTOR..=UNIT_FACTOR).contains(*l))
        .count();
    far * 2 > lengths.len()
}

/// An `.lp`'s rows (unit `lights` and their `lengths` as written) as the positions of near
/// lights, where they are: most of them far from unit length ([`UNIT_FACTOR`]) and `K.txt`
/// beside the file in `dir` without `light_positions.txt` (a perspective camera whose lights'
/// positions are in the `.lp`, as domes record them). `None` otherwise.
fn positions_of(dir: &Path, lights: &[DVec3], lengths: &[f64]) -> Option<Vec<DVec3>> {
    let beside = |name: &str| dir.join(name).symlink_metadata().is_ok();
    (mostly_far(lengths) && beside(near::INTRINSICS) && !beside(near::POSITIONS)).then(|| {
        lights
            .iter()
            .zip(lengths)
            .map(|(l, &len)| *l * len)
            .collect()
    })
}

/// The rows of the `.lp` file `lp` as the positions of near lights, where they are (the rule
/// of [`positions_of`]); `None` otherwise.
pub(crate) fn lp_positions(lp: &Path) -> Result<Option<Vec<DVec3>>> {
    let lights::LpFile {
        lights, lengths, ..
    } = lights::parse_lp(lp)?;
    Ok(positions_of(&parent_dir(lp), &lights, &lengths))
}

/// A warning where most of a light file's vectors are far from unit length (lengths as written,
/// `lengths`): they are read as directions and normalised, as every tool that reads `.lp`
/// files does (relight's `parseLP`, the HSH fitter), but where they are the positions of near
/// lights (ramamoorthyluxman/illumi-net reads `.lp` rows so, the distance being the vector's
/// length) the direction from the scene's origin is right only there. Said, never silent.
fn length_warning(path: &Path, lengths: &[f64]) -> Option<Warning> {
    if !mostly_far(lengths) {
        return None;
    }
    let far: Vec<f64> = lengths
        .iter()
        .copied()
        .filter(|l| !(1.0 / UNIT_FACTOR..=UNIT_FACTOR).contains(l))
        .collect();
    let min = far.iter().copied().fold(f64::INFINITY, f64::min);
    let max = far.iter().copied().fold(0.0, f64::max);
    let shown = |x: f64| {
        if (1e-3..1e6).contains(&x) {
            format!("{}", (x * 1000.0).round() / 1000.0)
        } else {
            format!("{x:.3e}")
        }
    };
    Some(Warning {
        path: path.to_path_buf(),
        message: format!(
            "{} of {} lights are far from unit length (lengths {} to {}): each is read as a \
             direction toward the light and normalised, as RTI tools read .lp rows; if these \
             are the positions of near lights (say in mm), symframe takes each light as \
             distant, in its direction from the origin, which is right only at the origin; \
             with the camera's K.txt beside the file they are read as positions",
            far.len(),
            lengths.len(),
            shown(min),
            shown(max)
        ),
    })
}

/// Per-light RGB intensities.
type Intensities = Vec<[f32; 3]>;

/// The intensities of `lp` (`n` lights) from `light_intensities.txt` in its folder `dir`, and
/// never silently: one that cannot be read (or is not a file) is an error; one with `n` rows
/// is applied, with a warning when another `.lp` beside it has `n` lights too (which one it
/// belongs to cannot be told); one with another row count is an error, unless another `.lp`
/// beside it has that many lights (then it is that one's: not applied, with a warning).
fn lp_intensities(lp: &Path, dir: &Path, n: usize) -> Result<(Option<Intensities>, Vec<Warning>)> {
    let int_path = dir.join(INTENSITIES);
    if int_path.symlink_metadata().is_err() {
        return Ok((None, Vec::new()));
    }
    let v = lights::parse_intensities(&int_path)?;
    let others = other_lp_counts(lp, dir);
    let names = |count: usize| {
        others
            .iter()
            .filter(|(_, c)| *c == count)
            .map(|(name, _)| name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let lp_name = lp.file_name().unwrap_or(lp.as_os_str()).to_string_lossy();
    if v.len() == n {
        let same = names(n);
        let warnings = if same.is_empty() {
            Vec::new()
        } else {
            vec![Warning {
                path: int_path,
                message: format!(
                    "applied to {lp_name} (its {n} rows match its {n} lights), but {same} \
                     beside it has {n} lights too: if the intensities are of another light \
                     file, move them to that one's folder"
                ),
            }]
        };
        return Ok((Some(v), warnings));
    }
    let theirs = names(v.len());
    if theirs.is_empty() {
        return Err(Error::invalid(
            &int_path,
            format!(
                "{} light intensities but {} lists {n} images",
                v.len(),
                lp.display()
            ),
        ));
    }
    let warning = Warning {
        path: int_path,
        message: format!(
            "not applied to {lp_name}: its {} rows are not {lp_name}'s {n} lights but those of \
             {theirs} beside it (the images are used as they are, not divided by light \
             intensities)",
            v.len()
        ),
    };
    Ok((None, vec![warning]))
}

/// The other `.lp` files in `dir` (than `lp`) and their declared light counts (those whose
/// count cannot be read are left out).
fn other_lp_counts(lp: &Path, dir: &Path) -> Vec<(String, usize)> {
    let listed = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let Ok(rd) = std::fs::read_dir(listed) else {
        return Vec::new();
    };
    let mut v: Vec<(String, usize)> = rd
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.is_file() && is_lp(p) && p.file_name() != lp.file_name())
        .filter_map(|p| {
            // The first meaningful line alone: the rest is never read.
            let mut lines = lights::TextLines::open(&p).ok()?;
            let count = lines.next_content().ok()??.1.parse().ok()?;
            Some((p.file_name()?.to_string_lossy().into_owned(), count))
        })
        .collect();
    v.sort();
    v
}

/// Opens a DiLiGenT-style folder; `source` is what the user named (folder or one of its files).
fn open_diligent(dir: &Path, source: &Path) -> Result<Dataset> {
    let names_path = dir.join(FILENAMES);
    let mut dirs_path = dir.join(DIRECTIONS);
    let positions_path = dir.join(POSITIONS);
    // Near lights alone: the directions are those from the lights' sphere centre.
    let from_positions = !dirs_path.is_file() && positions_path.is_file();
    if from_positions {
        dirs_path = positions_path;
    }
    for p in [&names_path, &dirs_path] {
        if !p.is_file() {
            return Err(Error::invalid(
                dir,
                format!(
                    "not a dataset: {} is missing (a DiLiGenT folder needs filenames.txt and \
                     light_directions.txt or light_positions.txt)",
                    p.display()
                ),
            ));
        }
    }
    let images = lights::parse_filenames(&names_path, dir)?;
    let lights = if from_positions {
        near::directions_from_positions(&dirs_path, &lights::parse_positions(&dirs_path)?)?
    } else {
        lights::parse_directions(&dirs_path)?
    };
    if lights.len() != images.len() {
        return Err(Error::invalid(
            &dirs_path,
            format!(
                "{} light {} but {} lists {} images",
                lights.len(),
                if from_positions {
                    "positions"
                } else {
                    "directions"
                },
                names_path.display(),
                images.len()
            ),
        ));
    }
    let int_path = dir.join(INTENSITIES);
    let intensities = if int_path.is_file() {
        let v = lights::parse_intensities(&int_path)?;
        if v.len() != images.len() {
            return Err(Error::invalid(
                &int_path,
                format!(
                    "{} light intensities but {} lists {} images",
                    v.len(),
                    names_path.display(),
                    images.len()
                ),
            ));
        }
        Some(v)
    } else {
        None
    };
    let warnings = convention_warning(&dirs_path, &lights)
        .into_iter()
        .collect();
    Ok(Dataset {
        source: source.to_path_buf(),
        lights,
        images,
        intensities,
        mask: mask_in(dir)?,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    /// Creates empty image files `names` in `dir`.
    fn touch(dir: &Path, names: &[&str]) {
        for n in names {
            let p = dir.join(n);
            fs::create_dir_all(p.parent().unwrap()).unwrap();
            fs::write(p, b"").unwrap();
        }
    }

    fn err_string(r: Result<Dataset>) -> String {
        r.expect_err("expected an error").to_string()
    }

    #[test]
    fn a_missing_path_suggests_the_nearest_name_and_a_folder_of_images_the_lights() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png"]);
        fs::write(d.path().join("lights.lp"), "2\na.png 0 0 1\nb.png 0 1 1\n").unwrap();
        // The suggestion is in the error's source (the not-found reason), as printed.
        let reason = |p: &Path| {
            let e = open_dataset(p).expect_err("expected an error");
            std::error::Error::source(&e).map_or(String::new(), |s| s.to_string())
        };
        let e = reason(&d.path().join("ligths.lp"));
        assert!(
            e.contains("did you mean") && e.ends_with("lights.lp?"),
            "{e}"
        );
        // Another name for the folder's only .lp.
        let e = reason(&d.path().join("capture.lp"));
        assert!(e.ends_with("lights.lp?"), "{e}");
        // Nothing near: no suggestion.
        let e = reason(&d.path().join("zzzzzz.txt"));
        assert!(!e.contains("did you mean"), "{e}");
        // A folder of images without lights points to the format and to calibrate.
        fs::remove_file(d.path().join("lights.lp")).unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("holds 2 images") && e.contains("symframe calibrate"),
            "{e}"
        );
    }

    #[test]
    fn lights_pointing_away_from_the_camera_are_warned_about() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png", "c.png", "d.png"]);
        let lp = d.path().join("rig.lp");
        // A dome read with z the other way: every light behind the object.
        fs::write(
            &lp,
            "4\na.png 0 0.5 -1\nb.png 0.5 0 -1\nc.png 0 -0.5 -1\nd.png -0.5 0 -0.2\n",
        )
        .unwrap();
        let ds = open_dataset(&lp).unwrap();
        assert_eq!(ds.warnings.len(), 1, "{:?}", ds.warnings);
        let w = ds.warnings[0].to_string();
        assert!(
            w.contains("rig.lp") && w.contains("4 of 4") && w.contains("negate its z"),
            "{w}"
        );
        // The same dome as it should be read: nothing to say; nor with half the lights behind
        // (a symmetric rig reaching 130 degrees from the view).
        fs::write(
            &lp,
            "4\na.png 0 0.5 1\nb.png 0.5 0 1\nc.png 0 -0.5 -1\nd.png -0.5 0 -0.2\n",
        )
        .unwrap();
        assert!(open_dataset(&lp).unwrap().warnings.is_empty());
    }

    /// Light positions in an `.lp` (ramamoorthyluxman/illumi-net 2a411f25,
    /// utils/dataset_class.py, reads `.lp` rows as positions, the distance to a pixel from the
    /// vector): normalised as every `.lp` row is, and said when most lights are far from unit
    /// length; directions written to 6 digits, or a few hand-scaled rows, are not.
    #[test]
    fn near_light_positions_are_normalised_and_warned_about() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png", "c.png"]);
        let lp = d.path().join("mm.lp");
        fs::write(
            &lp,
            "3\na.png 120 -40 300\nb.png 0 0 250\nc.png -90 60 280\n",
        )
        .unwrap();
        let ds = open_dataset(&lp).unwrap();
        assert!((ds.lights[1] - DVec3::Z).length() < 1e-15);
        assert_eq!(ds.warnings.len(), 1, "{:?}", ds.warnings);
        let w = ds.warnings[0].to_string();
        assert!(
            w.contains("mm.lp: 3 of 3 lights are far from unit length (lengths 250 to 325.576)")
                && w.contains("positions of near lights"),
            "{w}"
        );
        fs::write(
            &lp,
            "3\na.png 1e200 0 1e200\nb.png 0 0 2e300\nc.png 0 0 1\n",
        )
        .unwrap();
        let w = open_dataset(&lp).unwrap().warnings[0].to_string();
        assert!(
            w.contains("2 of 3 lights") && w.contains("1.414e200 to 2.000e300"),
            "{w}"
        );
        // Unit rows, and one scaled row of three: nothing to say.
        fs::write(&lp, "3\na.png 0 0 1\nb.png 0 0.6 0.8\nc.png 3 0 4\n").unwrap();
        assert!(open_dataset(&lp).unwrap().warnings.is_empty());
    }

    #[test]
    fn lp_with_comments_and_blank_lines() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["img/a.png", "img/b.png", "img/c.png"]);
        let lp = d.path().join("rig.lp");
        fs::write(
            &lp,
            "# a comment\n\n3   # three lights\nimg/a.png 0 0 2\n\n# middle\n\
             img/b.png 3 0 4 # trailing\n  img/c.png\t-1 1 0\n",
        )
        .unwrap();
        let ds = open_dataset(&lp).unwrap();
        assert_eq!(ds.images.len(), 3);
        assert_eq!(ds.images[1], d.path().join("img/b.png"));
        assert!((ds.lights[0] - DVec3::Z).length() < 1e-15);
        assert!((ds.lights[1] - DVec3::new(0.6, 0.0, 0.8)).length() < 1e-15);
        let s = 0.5f64.sqrt();
        assert!((ds.lights[2] - DVec3::new(-s, s, 0.0)).length() < 1e-15);
        assert_eq!(ds.mask, None);
        assert_eq!(ds.intensities, None);
        assert_eq!(ds.source, lp);

        // The folder resolves to its only .lp file and picks up mask.png beside it.
        touch(d.path(), &["mask.png"]);
        let ds2 = open_dataset(d.path()).unwrap();
        assert_eq!(ds2.images, ds.images);
        assert_eq!(ds2.mask, Some(d.path().join("mask.png")));
    }

    #[test]
    fn lp_too_few_entries_names_file() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png"]);
        let lp = d.path().join("few.lp");
        fs::write(&lp, "3\na.png 0 0 1\nb.png 0 1 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("few.lp"), "{e}");
        assert!(e.contains("3 lights declared on line 1 but only 2"), "{e}");
    }

    #[test]
    fn lp_too_many_entries_names_file_and_line() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png"]);
        let lp = d.path().join("many.lp");
        fs::write(&lp, "1\na.png 0 0 1\n# extra\nb.png 0 1 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(
            e.contains("many.lp:4: more entries than the 1 lights"),
            "{e}"
        );
    }

    #[test]
    fn lp_zero_and_nan_lights_name_line() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png"]);
        let lp = d.path().join("zero.lp");
        fs::write(&lp, "2\na.png 0 0 1\nb.png 0 0 0\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.ends_with("zero.lp:3: light direction is zero"), "{e}");

        fs::write(&lp, "2\na.png NaN 0 1\nb.png 0 0 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(
            e.ends_with("zero.lp:2: light direction is not finite (NaN)"),
            "{e}"
        );

        fs::write(&lp, "2\na.png 0 0 1\nb.png 0 x 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("zero.lp:3:") && e.contains("'x'"), "{e}");
    }

    #[test]
    fn lp_bad_count_spaces_and_missing_image() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png"]);
        let lp = d.path().join("bad.lp");
        fs::write(&lp, "\n# c\nthree\na.png 0 0 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("bad.lp:3: expected the number of lights"), "{e}");

        // A path with spaces is read whole (everything before the three numbers).
        fs::write(&lp, "1\nmy image.png 0 0 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(
            e.contains("bad.lp:2:") && e.contains("my image.png does not exist"),
            "{e}"
        );

        fs::write(&lp, "1\nmissing.png 0 0 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("bad.lp:2:") && e.contains("missing.png"), "{e}");

        fs::write(&lp, "# nothing\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("bad.lp") && e.contains("empty"), "{e}");
    }

    /// Writes a DiLiGenT-style folder with `n` images.
    fn diligent(dir: &Path, n: usize) {
        let names: Vec<String> = (0..n).map(|i| format!("{:03}.png", i + 1)).collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        touch(dir, &refs);
        fs::write(dir.join("filenames.txt"), names.join("\n") + "\n").unwrap();
    }

    #[test]
    fn diligent_folder_with_intensities_and_mask() {
        let d = tempfile::tempdir().unwrap();
        diligent(d.path(), 2);
        touch(d.path(), &["mask.png"]);
        fs::write(d.path().join("light_directions.txt"), "0 0 1\n0 -2 0\n").unwrap();
        fs::write(
            d.path().join("light_intensities.txt"),
            "1 2 3\n0.5 0.5 0.25\n",
        )
        .unwrap();
        let ds = open_dataset(d.path()).unwrap();
        assert_eq!(
            ds.images,
            vec![d.path().join("001.png"), d.path().join("002.png")]
        );
        assert_eq!(ds.lights, vec![DVec3::Z, DVec3::NEG_Y]);
        assert_eq!(
            ds.intensities,
            Some(vec![[1.0, 2.0, 3.0], [0.5, 0.5, 0.25]])
        );
        assert_eq!(ds.mask, Some(d.path().join("mask.png")));
        // Naming one of the folder's files opens the same dataset.
        let ds2 = open_dataset(&d.path().join("filenames.txt")).unwrap();
        assert_eq!(ds2.lights, ds.lights);
        assert_eq!(ds2.images, ds.images);
    }

    #[test]
    fn diligent_mismatched_rows_name_the_file() {
        let d = tempfile::tempdir().unwrap();
        diligent(d.path(), 3);
        fs::write(d.path().join("light_directions.txt"), "0 0 1\n0 1 1\n").unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("light_directions.txt: 2 light directions"),
            "{e}"
        );
        assert!(e.contains("3 images"), "{e}");

        fs::write(
            d.path().join("light_directions.txt"),
            "0 0 1\n0 1 1\n1 0 1\n",
        )
        .unwrap();
        fs::write(d.path().join("light_intensities.txt"), "1 1 1\n").unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("light_intensities.txt: 1 light intensities"),
            "{e}"
        );

        fs::write(
            d.path().join("light_intensities.txt"),
            "1 1 1\n1 0 1\n1 1 1\n",
        )
        .unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("light_intensities.txt:2: light intensity must be finite"),
            "{e}"
        );

        fs::remove_file(d.path().join("light_intensities.txt")).unwrap();
        fs::write(
            d.path().join("light_directions.txt"),
            "0 0 1\n0 1 1\n0 0 0\n",
        )
        .unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("light_directions.txt:3: light direction is zero"),
            "{e}"
        );

        fs::write(d.path().join("light_directions.txt"), "0 0 1\n0 1\n1 0 1\n").unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("light_directions.txt:2: expected 3 numbers"),
            "{e}"
        );
    }

    #[test]
    fn folder_without_dataset_says_what_was_looked_for() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["x.png"]);
        let e = err_string(open_dataset(d.path()));
        assert!(e.contains(".lp") && e.contains("filenames.txt"), "{e}");
        assert!(e.contains(&d.path().display().to_string()), "{e}");

        touch(d.path(), &["a.lp", "b.lp"]);
        let e = err_string(open_dataset(d.path()));
        assert!(e.contains("several .lp files") && e.contains("a.lp"), "{e}");

        let e = err_string(open_dataset(&d.path().join("x.png")));
        assert!(e.contains("x.png: not a dataset"), "{e}");

        let e = err_string(open_dataset(&d.path().join("nope.lp")));
        assert!(e.contains("nope.lp: cannot read"), "{e}");
    }

    /// A byte-order mark is skipped, not read into the count ("expected the number of lights,
    /// found '2'").
    #[test]
    fn a_bom_before_the_light_count_is_ignored() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png"]);
        let lp = d.path().join("bom.lp");
        fs::write(&lp, "\u{feff}2\r\na.png 0 0 1\r\nb.png 0 1 1\r\n").unwrap();
        assert_eq!(open_dataset(&lp).unwrap().images.len(), 2);
        fs::write(d.path().join(FILENAMES), "\u{feff}a.png\nb.png\n").unwrap();
        fs::write(d.path().join(DIRECTIONS), "\u{feff}0 0 1\n0 1 1\n").unwrap();
        fs::write(d.path().join(INTENSITIES), "\u{feff}1 1 1\n2 2 2\n").unwrap();
        fs::remove_file(&lp).unwrap();
        let ds = open_dataset(d.path()).unwrap();
        assert_eq!(ds.intensities.unwrap().len(), 2);
    }

    /// `#` in a file name is explained, not blamed on spaces (nor the cut name reported
    /// missing).
    #[test]
    fn a_hash_in_a_file_name_is_explained() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["img#1.png", "img"]);
        let lp = d.path().join("h.lp");
        fs::write(&lp, "1\nimg#1.png 0 0 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("h.lp:2: expected '<image> <lx> <ly> <lz>' ('#' starts a comment, so image paths may not contain '#'), found 1 fields"), "{e}");
        assert!(!e.contains("spaces"), "{e}");
        fs::write(&lp, "1\nimg one.png 0\n").unwrap();
        assert!(err_string(open_dataset(&lp)).contains("a path with spaces needs three numbers"));
        fs::remove_file(&lp).unwrap();
        fs::write(d.path().join(FILENAMES), "x#1.png\n").unwrap();
        fs::write(d.path().join(DIRECTIONS), "0 0 1\n").unwrap();
        let e = err_string(open_dataset(d.path()));
        assert!(
            e.contains("filenames.txt:1: image")
                && e.contains(
                    "x does not exist ('#' starts a comment: image paths may not contain '#')"
                ),
            "{e}"
        );
    }

    /// A folder, FIFO or broken link among the images is named as such, not "does not exist";
    /// a mask.png that is a folder is an error, not silently ignored.
    #[cfg(unix)]
    #[test]
    fn folders_fifos_and_broken_links_are_named_as_such() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png"]);
        fs::create_dir(d.path().join("dir.png")).unwrap();
        std::os::unix::fs::symlink(d.path().join("gone.png"), d.path().join("link.png")).unwrap();
        let fifo = std::ffi::CString::new(d.path().join("fifo.png").to_str().unwrap()).unwrap();
        // SAFETY: mkfifo on a NUL-terminated path we own.
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
        let lp = d.path().join("k.lp");
        for (name, want) in [
            ("dir.png", "dir.png is a folder, not an image file"),
            (
                "link.png",
                "link.png is a broken symbolic link (its target does not exist)",
            ),
            (
                "fifo.png",
                "fifo.png is not a regular file (a FIFO, socket or device)",
            ),
            ("none.png", "none.png does not exist"),
        ] {
            fs::write(&lp, format!("1\n{name} 0 0 1\n")).unwrap();
            let e = err_string(open_dataset(&lp));
            assert!(e.contains("k.lp:2: image ") && e.ends_with(want), "{e}");
        }
        fs::write(&lp, "1\na.png 0 0 1\n").unwrap();
        assert_eq!(open_dataset(&lp).unwrap().mask, None);
        fs::create_dir(d.path().join(MASK)).unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(
            e.ends_with("mask.png: is a folder, not a mask image"),
            "{e}"
        );
        // The dataset argument itself as a broken link.
        let broken = d.path().join("broken.lp");
        std::os::unix::fs::symlink(d.path().join("nothing.lp"), &broken).unwrap();
        let e = err_string(open_dataset(&broken));
        assert!(e.contains("broken.lp: is a broken symbolic link"), "{e}");
    }

    /// `light_intensities.txt` is applied by its row count, never silently ignored, also where
    /// a second `.lp` sits beside the first.
    #[test]
    fn intensities_beside_an_lp_are_applied_by_row_count_and_never_silently() {
        let d = tempfile::tempdir().unwrap();
        touch(d.path(), &["a.png", "b.png", "c.png"]);
        let lp = d.path().join("rig.lp");
        fs::write(&lp, "2\na.png 0 0 1\nb.png 0 1 1\n").unwrap();
        fs::write(d.path().join(INTENSITIES), "1 1 1\n2 2 2\n").unwrap();
        // The only .lp: applied, nothing to say.
        let ds = open_dataset(&lp).unwrap();
        assert_eq!(ds.intensities.as_ref().unwrap().len(), 2);
        assert!(ds.warnings.is_empty(), "{:?}", ds.warnings);
        // Another .lp of as many lights: applied (rows match), with a warning naming it.
        let other = d.path().join("other.lp");
        fs::write(&other, "2\nb.png 0 0 1\nc.png 1 0 1\n").unwrap();
        let ds = open_dataset(&lp).unwrap();
        assert!(ds.intensities.is_some());
        let w = ds.warnings[0].to_string();
        assert!(
            w.contains("light_intensities.txt: applied to rig.lp (its 2 rows match its 2 lights), but other.lp"),
            "{w}"
        );
        // Rows matching the other .lp only: not applied, with a warning.
        fs::write(&other, "3\na.png 0 0 1\nb.png 0 1 1\nc.png 1 0 1\n").unwrap();
        fs::write(d.path().join(INTENSITIES), "1 1 1\n2 2 2\n3 3 3\n").unwrap();
        let ds = open_dataset(&lp).unwrap();
        assert_eq!(ds.intensities, None);
        let w = ds.warnings[0].to_string();
        assert!(
            w.contains(
                "not applied to rig.lp: its 3 rows are not rig.lp's 2 lights but those of other.lp"
            ),
            "{w}"
        );
        // ... and applied to that one, silently.
        let ds = open_dataset(&other).unwrap();
        assert!(ds.intensities.is_some() && ds.warnings.is_empty());
        // Rows matching no .lp: an error.
        fs::write(d.path().join(INTENSITIES), "1 1 1\n").unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(
            e.contains("light_intensities.txt: 1 light intensities but"),
            "{e}"
        );
        // A light_intensities.txt that is not a file is an error, not ignored.
        fs::remove_file(d.path().join(INTENSITIES)).unwrap();
        fs::create_dir(d.path().join(INTENSITIES)).unwrap();
        let e = err_string(open_dataset(&lp));
        assert!(e.contains("not a regular file (a folder)"), "{e}");
    }
}
