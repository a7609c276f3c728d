//! The calibration's images: the list of them (a folder, an `.lp` file or a list file), their
//! size from the first one's header, and reading one a band of rows at a time (only the
//! spheres' rows kept). Calibrate and calibrate --K share them.

use std::path::{Component, Path, PathBuf};

use anyhow::{bail, Context, Result};
use symframe::Circle;
use symframe_io::DecodeOptions;

/// Image file extensions read from a folder.
const EXTENSIONS: &[&str] = &["exr", "png", "tif", "tiff", "hdr", "pfm", "jpg", "jpeg"];

/// The image list: every image file of a folder sorted by name (leaving out `mask.*`), the
/// images of an `.lp` file, or a list file of paths (one per line, relative to the list's
/// folder; blank lines and `#` comments allowed).
pub(crate) fn image_list(input: &Path) -> Result<Vec<PathBuf>> {
    if input.is_dir() {
        let mut v: Vec<PathBuf> = std::fs::read_dir(input)
            .with_context(|| format!("{}: cannot read folder", input.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                !p.is_dir()
                    && p.extension()
                        .and_then(|e| e.to_str())
                        .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
                    && p.file_stem().and_then(|s| s.to_str()) != Some("mask")
            })
            .collect();
        // An image that is not a regular file (a FIFO, a device, a dangling link) is an error
        // naming it, not left out unsaid.
        for p in &v {
            symframe_io::check_regular_file(p)?;
        }
        v.sort();
        if v.is_empty() {
            bail!("{}: no image files in the folder", input.display());
        }
        return Ok(v);
    }
    if input
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("lp"))
    {
        return Ok(symframe_io::open_dataset(input)?.images);
    }
    let dir = input.parent().unwrap_or(Path::new(""));
    let mut v = Vec::new();
    symframe_io::read_list(input, "an image list", "images", |line, entry| {
        let p = dir.join(entry);
        match symframe_io::check_regular_file(&p) {
            Ok(_) => {}
            Err(symframe_io::Error::Read { source, .. })
                if source.kind() == std::io::ErrorKind::NotFound =>
            {
                bail!(
                    "{}: line {line}: image {} does not exist",
                    input.display(),
                    p.display()
                );
            }
            Err(e) => bail!("{}: line {line}: {e}", input.display()),
        }
        v.push(p);
        Ok(())
    })?;
    if v.is_empty() {
        bail!("{}: the image list is empty", input.display());
    }
    Ok(v)
}

/// The most pixels an image given to calibrate may have (8192 x 8192): it holds the brightest
/// (or the sum) of all images, 4 bytes a pixel, and of each image it reads the sphere's rows
/// and the matte sphere's (in RGB), so a file of a few KB declaring a larger image is refused
/// from its header.
pub(super) const MAX_CALIBRATE_PIXELS: usize = 1 << 26;

/// The memory for the images read at once (the spheres' rows): as many in parallel as fit, at
/// least one.
pub(crate) const DECODE_MEMORY: usize = 256 << 20;

/// Checks the size image `path` declares (read from its header, undecoded) against the first
/// image's.
fn check_declared(path: &Path, opts: &DecodeOptions, (w, h): (usize, usize)) -> Result<()> {
    let (iw, ih) = symframe_io::read_image_size(path, opts)?;
    if (iw, ih) != (w, h) {
        bail!(
            "{}: {iw}x{ih} pixels, but the first image is {w}x{h}",
            path.display()
        );
    }
    Ok(())
}

/// Reads one image a band of rows at a time (its declared size checked against the first
/// image's before anything is decoded), giving `band(y, grey, rgb)` each band: its first row,
/// its grey values (the mean of the channels; `NaN` where any is saturated) and its RGB.
pub(crate) fn read_grey(
    path: &Path,
    opts: &DecodeOptions,
    size: (usize, usize),
    band: &mut symframe_io::GreyBand<'_>,
) -> Result<()> {
    check_declared(path, opts, size)?;
    let (iw, ih) = symframe_io::read_image_grey(path, opts, band)?;
    if (iw, ih) != size {
        bail!(
            "{}: {iw}x{ih} pixels, but the first image is {}x{}",
            path.display(),
            size.0,
            size.1
        );
    }
    Ok(())
}

/// The rows a circle's pixels lie in, clipped to an image of `height` rows (as
/// [`CalibrationParams::intensity`] and [`Highlight::find`] bound their pixels).
pub(crate) fn circle_rows(c: &Circle, height: usize) -> std::ops::Range<usize> {
    let y0 = (c.cy - c.r).floor().max(0.0) as usize;
    let y1 = ((c.cy + c.r).ceil().max(0.0) as usize).min(height);
    y0.min(y1)..y1
}

/// Copies the rows of `band` (of `width` samples a row, starting at row `y`) that fall in
/// `rows` to `out`, which holds those rows from its start (`rows.start` is its row 0).
pub(crate) fn keep_rows(
    band: &[f32],
    y: usize,
    width: usize,
    rows: &std::ops::Range<usize>,
    out: &mut [f32],
) {
    let n = band.len() / width.max(1);
    let (a, b) = (rows.start.clamp(y, y + n), rows.end.clamp(y, y + n));
    if a < b {
        out[(a - rows.start) * width..(b - rows.start) * width]
            .copy_from_slice(&band[(a - y) * width..(b - y) * width]);
    }
}

/// `path` relative to folder `base` when it lies below it (else absolute).
pub(crate) fn relative_to(path: &Path, base: &Path) -> PathBuf {
    let abs = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let (p, b) = (abs(path), abs(base));
    let (pc, bc): (Vec<Component>, Vec<Component>) =
        (p.components().collect(), b.components().collect());
    let common = pc.iter().zip(&bc).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return p;
    }
    let mut out = PathBuf::new();
    for _ in common..bc.len() {
        out.push("..");
    }
    for c in &pc[common..] {
        out.push(c.as_os_str());
    }
    out
}

/// The size of the images from the first one's header, `path`: nothing is decoded before it is
/// checked (a few KB may declare gigabytes of pixels: docs/performance.md, "Memory model").
/// Refused where empty or larger than [`MAX_CALIBRATE_PIXELS`].
pub(crate) fn image_size(path: &Path, opts: &DecodeOptions) -> Result<(usize, usize)> {
    let (w, h) = symframe_io::read_image_size(path, opts)?;
    if w == 0 || h == 0 {
        bail!("{}: the image is empty", path.display());
    }
    if w.saturating_mul(h) > MAX_CALIBRATE_PIXELS {
        bail!(
            "{}: {w}x{h} pixels, more than the {MAX_CALIBRATE_PIXELS} (8192 x 8192) calibrate \
             reads; crop the images to the spheres",
            path.display()
        );
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An image list is read a line at a time, never whole (any line end, comments),
    /// its errors naming the line, and holds at most `MAX_LIGHTS` images.
    #[test]
    fn an_image_list_is_read_a_line_at_a_time() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("a.png"), b"x").unwrap();
        let list = d.path().join("images.txt");
        std::fs::write(&list, "# shots\ra.png\r\n\ra.png # again\r").unwrap();
        let v = image_list(&list).unwrap();
        assert_eq!(v, vec![d.path().join("a.png"); 2]);
        std::fs::write(&list, "a.png\n\nb.png\n").unwrap();
        let e = format!("{:#}", image_list(&list).unwrap_err());
        assert!(e.contains("images.txt: line 3: image") && e.ends_with("b.png does not exist"));
        let many = "a.png\n".repeat(symframe_io::limits::MAX_LIGHTS + 1);
        std::fs::write(&list, many).unwrap();
        let e = format!("{:#}", image_list(&list).unwrap_err());
        assert!(
            e.ends_with(
                "images.txt:100001: more than 100000 images: an image list holds at most 100000"
            ),
            "{e}"
        );
    }
}
