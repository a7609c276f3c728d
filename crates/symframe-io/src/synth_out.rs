//! Writing synthetic datasets: images, an `.lp` light file, ground truth and a mask, in the
//! layout [`crate::open_dataset`] reads back.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;

use crate::atomic::write_bytes;
use crate::codecs::{write_exr_rgb, write_png, write_png16_rgb, write_png8_rgb};
use crate::error::{Error, Result};
use crate::output::write_npy_f32;

/// The file format of a synthetic dataset's images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// Float32 OpenEXR (`.exr`), exact linear values.
    Exr,
    /// 16-bit linear PNG (`.png`), values clamped to `[0, 1]`.
    Png16,
    /// 8-bit sRGB-encoded PNG (`.png`), values clamped to `[0, 1]`.
    Png8,
}

impl ImageFormat {
    /// The file extension used for this format.
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Exr => "exr",
            ImageFormat::Png16 | ImageFormat::Png8 => "png",
        }
    }
}

/// Writes a dataset into `dir` (created if needed): `images/img_0000.<ext>` ..., `lights.lp`
/// (count, then `images/img_NNNN.<ext> lx ly lz` at round-trip f64 precision), and when given
/// `gt_normals.npy`, `gt_tangents.npy` (`H x W x 3`) and `mask.png` (8-bit grey, 255 inside).
/// Returns the `.lp` path. Images are `width * height * 3` linear RGB values each.
#[allow(clippy::too_many_arguments)]
pub fn write_lp_dataset(
    dir: &Path,
    lights: &[DVec3],
    images: &[Vec<f32>],
    width: usize,
    height: usize,
    format: ImageFormat,
    gt_normals: Option<&[f32]>,
    gt_tangents: Option<&[f32]>,
    mask: Option<&[bool]>,
) -> Result<PathBuf> {
    if lights.len() != images.len() || lights.is_empty() {
        return Err(Error::invalid(
            dir,
            format!(
                "need one image per light and at least one: {} lights, {} images",
                lights.len(),
                images.len()
            ),
        ));
    }
    let names = write_images_and_truth(
        dir,
        images,
        width,
        height,
        format,
        gt_normals,
        gt_tangents,
        mask,
    )?;
    let lp = dir.join("lights.lp");
    let mut text = format!("{}\n", lights.len());
    for (name, l) in names.iter().zip(lights) {
        let _ = writeln!(text, "{name} {:?} {:?} {:?}", l.x, l.y, l.z);
    }
    write_bytes(&lp, text.as_bytes())?;
    write_synth_marker(dir)?;
    Ok(lp)
}

/// Writes `images/img_NNNN.<ext>`, and when given `gt_normals.npy`, `gt_tangents.npy` and
/// `mask.png`, into `dir`; returns the images' names relative to `dir`.
#[allow(clippy::too_many_arguments)]
fn write_images_and_truth(
    dir: &Path,
    images: &[Vec<f32>],
    width: usize,
    height: usize,
    format: ImageFormat,
    gt_normals: Option<&[f32]>,
    gt_tangents: Option<&[f32]>,
    mask: Option<&[bool]>,
) -> Result<Vec<String>> {
    let img_dir = dir.join("images");
    std::fs::create_dir_all(&img_dir).map_err(|e| Error::write(&img_dir, e))?;
    let names: Vec<String> = (0..images.len())
        .map(|i| format!("images/img_{i:04}.{}", format.extension()))
        .collect();
    names
        .par_iter()
        .zip(images.par_iter())
        .try_for_each(|(name, img)| {
            let p = dir.join(name);
            match format {
                ImageFormat::Exr => write_exr_rgb(&p, width, height, img),
                ImageFormat::Png16 => write_png16_rgb(&p, width, height, img),
                ImageFormat::Png8 => write_png8_rgb(&p, width, height, img, true),
            }
        })?;
    let shape = [height, width, 3];
    if let Some(n) = gt_normals {
        write_npy_f32(&dir.join("gt_normals.npy"), &shape, n)?;
    }
    if let Some(t) = gt_tangents {
        write_npy_f32(&dir.join("gt_tangents.npy"), &shape, t)?;
    }
    if let Some(m) = mask {
        let p = dir.join("mask.png");
        if m.len() != width * height {
            return Err(Error::invalid(
                &p,
                format!("mask has {} values for a {width}x{height} image", m.len()),
            ));
        }
        let bytes: Vec<u8> = m.iter().map(|&b| if b { 255 } else { 0 }).collect();
        write_png(&p, width, height, &bytes, crate::codecs::PngLayout::L8)?;
    }
    Ok(names)
}

/// What a near-light dataset holds besides its images (see [`write_near_dataset`]).
#[derive(Debug, Clone, Copy)]
pub struct NearFiles<'a> {
    /// Light positions, camera frame, one per image.
    pub positions: &'a [DVec3],
    /// Directions from the object's centre to each light (`light_directions.txt`, what a
    /// distant-light reader is given).
    pub directions: &'a [DVec3],
    /// The pinhole intrinsics, OpenCV's convention, row-major.
    pub k: [[f64; 3]; 3],
    /// Depth along the optical axis per pixel (`gt_depth.npy`, `H x W`, NaN on the background).
    pub gt_depth: Option<&'a [f32]>,
}

/// Writes a near-light dataset into `dir` (created if needed) in the DiLiGenT layout: the images
/// as [`write_lp_dataset`] writes them, `filenames.txt`, `light_positions.txt`, `K.txt`,
/// `light_directions.txt` and the truth (`gt_normals.npy`, `gt_tangents.npy`, `gt_depth.npy`,
/// `mask.png`), numbers at round-trip precision. Returns the folder.
#[allow(clippy::too_many_arguments)]
pub fn write_near_dataset(
    dir: &Path,
    near: &NearFiles,
    images: &[Vec<f32>],
    width: usize,
    height: usize,
    format: ImageFormat,
    gt_normals: Option<&[f32]>,
    gt_tangents: Option<&[f32]>,
    mask: Option<&[bool]>,
) -> Result<PathBuf> {
    if near.positions.len() != images.len()
        || near.directions.len() != images.len()
        || images.is_empty()
    {
        return Err(Error::invalid(
            dir,
            format!(
                "need one image, position and direction per light and at least one light: {} \
                 images, {} positions, {} directions",
                images.len(),
                near.positions.len(),
                near.directions.len()
            ),
        ));
    }
    let names = write_images_and_truth(
        dir,
        images,
        width,
        height,
        format,
        gt_normals,
        gt_tangents,
        mask,
    )?;
    if let Some(d) = near.gt_depth {
        write_npy_f32(&dir.join("gt_depth.npy"), &[height, width], d)?;
    }
    let table = |v: &[DVec3]| {
        v.iter().fold(String::new(), |mut t, p| {
            let _ = writeln!(t, "{:?} {:?} {:?}", p.x, p.y, p.z);
            t
        })
    };
    write_bytes(
        &dir.join("filenames.txt"),
        (names.join("\n") + "\n").as_bytes(),
    )?;
    write_bytes(
        &dir.join(crate::dataset::near::POSITIONS),
        table(near.positions).as_bytes(),
    )?;
    write_bytes(
        &dir.join("light_directions.txt"),
        table(near.directions).as_bytes(),
    )?;
    let k: String = near.k.iter().fold(String::new(), |mut t, r| {
        let _ = writeln!(t, "{:?} {:?} {:?}", r[0], r[1], r[2]);
        t
    });
    write_bytes(&dir.join(crate::dataset::near::INTRINSICS), k.as_bytes())?;
    write_synth_marker(dir)?;
    Ok(dir.to_path_buf())
}

/// Writes the [`SYNTH_MARKER`] into `dir`: one text for the distant and the near datasets.
fn write_synth_marker(dir: &Path) -> Result<()> {
    write_bytes(
        &dir.join(SYNTH_MARKER),
        b"Written by symframe: a later `symframe synth -o` may replace this folder's dataset.\n",
    )
}

/// The file that marks a folder as written by [`write_lp_dataset`] (`symframe synth`).
pub const SYNTH_MARKER: &str = ".symframe-synth";

/// The lock file symframe's jobs (`symframe_job::OutputDir`) hold in their output folder; a
/// folder holding only it counts as empty for [`check_synth_target`].
pub const OUTPUT_LOCK_FILE: &str = ".symframe-lock";

/// Whether a synthetic dataset may be written into `dir`, replacing what is there: yes if it
/// does not exist, is empty (but for the [`OUTPUT_LOCK_FILE`]), or holds the [`SYNTH_MARKER`]
/// of an earlier dataset; else an error naming the folder (a user's folder, whose files must
/// not be replaced), unless `force`.
pub fn check_synth_target(dir: &Path, force: bool) -> Result<()> {
    if force || dir.join(SYNTH_MARKER).is_file() {
        return Ok(());
    }
    match std::fs::read_dir(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(_) if !dir.is_dir() => Err(Error::invalid(dir, "exists and is not a folder")),
        Err(e) => Err(Error::read(dir, e)),
        Ok(entries) => {
            let mut others = entries
                .flatten()
                .filter(|e| e.file_name() != OUTPUT_LOCK_FILE);
            if others.next().is_none() {
                return Ok(());
            }
            Err(Error::invalid(
                dir,
                format!(
                    "not written by symframe synth (no {SYNTH_MARKER} in it) and not empty: \
                     refusing to replace its files; give a new or empty folder, or --force"
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::DecodeOptions;
    use crate::{load_stack, open_dataset, read_mask, read_npy_f32};

    fn data(w: usize, h: usize, n: usize) -> (Vec<DVec3>, Vec<Vec<f32>>) {
        let lights = (0..n)
            .map(|i| DVec3::new(0.1 * i as f64 + 1e-17, -0.3, 1.0 / 3.0))
            .collect();
        let images = (0..n)
            .map(|i| {
                (0..w * h * 3)
                    .map(|k| ((i * 7 + k) % 50) as f32 / 64.0)
                    .collect()
            })
            .collect();
        (lights, images)
    }

    #[test]
    fn exr_dataset_round_trips_through_open_and_load() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("set");
        let (w, h) = (4, 3);
        let (lights, images) = data(w, h, 5);
        let normals: Vec<f32> = (0..w * h * 3).map(|i| i as f32).collect();
        let mask: Vec<bool> = (0..w * h).map(|i| i % 3 != 0).collect();
        let lp = write_lp_dataset(
            &dir,
            &lights,
            &images,
            w,
            h,
            ImageFormat::Exr,
            Some(&normals),
            Some(&normals),
            Some(&mask),
        )
        .unwrap();
        assert_eq!(lp, dir.join("lights.lp"));
        assert!(dir.join("images/img_0004.exr").is_file());
        let ds = open_dataset(&dir).unwrap();
        assert_eq!(ds.images.len(), 5);
        for (a, b) in ds.lights.iter().zip(&lights) {
            // Full f64 precision survives the text file.
            assert_eq!(*a, b.normalize());
        }
        let s = load_stack(&ds, &DecodeOptions::default(), &|| {}).unwrap();
        for (i, img) in images.iter().enumerate() {
            assert_eq!(&s.image(i), img);
        }
        let m = read_mask(ds.mask.as_ref().unwrap(), w, h).unwrap();
        assert_eq!(m, mask);
        assert_eq!(
            read_npy_f32(&dir.join("gt_tangents.npy")).unwrap(),
            (vec![h, w, 3], normals)
        );
    }

    #[test]
    fn png_datasets_quantise_as_documented() {
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (2, 2);
        let (lights, images) = data(w, h, 2);
        for fmt in [ImageFormat::Png16, ImageFormat::Png8] {
            let dir = d.path().join(format!("{fmt:?}"));
            write_lp_dataset(&dir, &lights, &images, w, h, fmt, None, None, None).unwrap();
            assert!(!dir.join("mask.png").exists() && !dir.join("gt_normals.npy").exists());
            assert!(dir.join(SYNTH_MARKER).is_file());
            let ds = open_dataset(&dir.join("lights.lp")).unwrap();
            assert_eq!(ds.mask, None);
            let s = load_stack(&ds, &DecodeOptions::default(), &|| {}).unwrap();
            let tol = if fmt == ImageFormat::Png16 {
                1e-5
            } else {
                0.01
            };
            for (i, img) in images.iter().enumerate() {
                for (a, b) in s.image(i).iter().zip(img) {
                    assert!((a - b).abs() < tol, "{fmt:?}: {a} vs {b}");
                }
            }
        }
        let e = write_lp_dataset(
            d.path(),
            &lights,
            &images[..1],
            w,
            h,
            ImageFormat::Exr,
            None,
            None,
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("2 lights, 1 images"), "{e}");
    }

    /// `synth -o DIR` deleted a user's `DIR/images/IMG_0001.CR2`.
    #[test]
    fn only_new_empty_or_marked_folders_are_replaced() {
        let d = tempfile::tempdir().unwrap();
        let user = d.path().join("user");
        std::fs::create_dir_all(user.join("images")).unwrap();
        std::fs::write(user.join("images/IMG_0001.CR2"), b"raw").unwrap();
        let e = check_synth_target(&user, false).unwrap_err().to_string();
        assert!(e.contains("user: not written by symframe synth"), "{e}");
        assert!(check_synth_target(&user, true).is_ok());
        assert!(check_synth_target(&d.path().join("new"), false).is_ok());
        let empty = d.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        assert!(check_synth_target(&empty, false).is_ok());
        let (lights, images) = data(2, 2, 2);
        write_lp_dataset(
            &empty,
            &lights,
            &images,
            2,
            2,
            ImageFormat::Exr,
            None,
            None,
            None,
        )
        .unwrap();
        assert!(check_synth_target(&empty, false).is_ok());
        let file = d.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = check_synth_target(&file, false).unwrap_err().to_string();
        assert!(e.contains("exists and is not a folder"), "{e}");
    }
}
