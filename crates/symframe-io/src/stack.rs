//! Loading a dataset's images into a pixel-major [`Stack`], and reading masks.

use std::path::Path;
use std::sync::Mutex;

use rayon::prelude::*;
use symframe::Stack;

use crate::codecs::{declared_size, ColourTag, DecodeOptions, Rows, SampleKind};
use crate::dataset::Dataset;
use crate::error::{Error, Result, Warning};

/// Decodes every image of `ds` (in parallel) into a pixel-major stack, divided by the lights'
/// intensities when the dataset has them; saturated or non-finite pixels are `NaN`.
///
/// All images must have the size of the first one (the error names the offending file and both
/// sizes; the size each file's header declares is compared before its pixels are decoded).
/// The first image is decoded alone, the others in parallel chunks, scattered into the stack
/// chunk by chunk, so only one chunk of decoded images is held beside the stack. `on_image` is called once per
/// decoded image (from worker threads), e.g. to advance a progress bar.
pub fn load_stack(
    ds: &Dataset,
    opts: &DecodeOptions,
    on_image: &(dyn Fn() + Sync),
) -> Result<Stack> {
    load_stack_with_warnings(ds, opts, on_image).map(|(s, _)| s)
}

/// [`load_stack`], and the warnings about mixed inputs (see `Notes::warnings`) for the caller
/// to print.
pub fn load_stack_with_warnings(
    ds: &Dataset,
    opts: &DecodeOptions,
    on_image: &(dyn Fn() + Sync),
) -> Result<(Stack, Vec<Warning>)> {
    check_dataset(ds)?;
    check_header_sizes(ds, opts)?;
    let n = ds.images.len();
    let notes = Notes::new(n);
    let chunk = 32.max(2 * rayon::current_num_threads());
    let (w, h, first) = decode_stack_image(ds, 0, opts, &notes, None)?;
    on_image();
    let mut stack = Stack::zeros(w, h, n);
    scatter_into(&mut stack, 0, &[first]);
    for start in (1..n).step_by(chunk) {
        let end = n.min(start + chunk);
        let decoded: Vec<Result<(usize, usize, Vec<f32>)>> = (start..end)
            .into_par_iter()
            .map(|i| {
                let r = decode_stack_image(ds, i, opts, &notes, Some((w, h)))?;
                on_image();
                Ok(r)
            })
            .collect();
        let mut images = Vec::with_capacity(decoded.len());
        for (j, r) in decoded.into_iter().enumerate() {
            let (iw, ih, rgb) = r?;
            check_size(ds, start + j, (iw, ih), (w, h))?;
            images.push(rgb);
        }
        scatter_into(&mut stack, start, &images);
    }
    Ok((stack, notes.warnings(ds)))
}

/// Copies `images` (interleaved RGB), the stack's images `start..`, into the pixel-major stack.
fn scatter_into(s: &mut Stack, start: usize, images: &[Vec<f32>]) {
    let stride = s.n_lights * 3;
    s.data
        .par_chunks_mut(stride * 256)
        .enumerate()
        .for_each(|(block, dst)| {
            for (k, px) in dst.chunks_exact_mut(stride).enumerate() {
                let p = block * 256 + k;
                for (j, img) in images.iter().enumerate() {
                    let o = (start + j) * 3;
                    px[o..o + 3].copy_from_slice(&img[p * 3..p * 3 + 3]);
                }
            }
        });
}

/// What was noticed of one decoded image.
#[derive(Debug, Clone)]
struct ImageNote {
    kind: SampleKind,
    grey: bool,
    negative: usize,
    colour: Option<ColourTag>,
}

/// Notes of every decoded image of a dataset (filled from worker threads), turned into the
/// mixed-input warnings once all are decoded.
#[derive(Debug)]
pub(crate) struct Notes(Mutex<Vec<Option<ImageNote>>>);

impl Notes {
    /// Room for `n` images, none noted yet.
    pub(crate) fn new(n: usize) -> Self {
        Self(Mutex::new(vec![None; n]))
    }

    fn set(&self, i: usize, note: ImageNote) {
        if let Ok(mut v) = self.0.lock() {
            if let Some(slot) = v.get_mut(i) {
                *slot = Some(note);
            }
        }
    }

    /// Warnings about the noted images (images not decoded, e.g. by an earlier interrupted
    /// build, are not considered): sample types that are converted differently (8-bit images
    /// are sRGB-decoded, 16-bit and float ones are not) mixed in one stack; grey images among
    /// RGB ones (their one channel is used for all three); negative samples (kept as they are,
    /// though no radiance is negative). Each names the first image concerned.
    pub(crate) fn warnings(&self, ds: &Dataset) -> Vec<Warning> {
        let notes: Vec<(usize, ImageNote)> = match self.0.lock() {
            Ok(v) => v
                .iter()
                .enumerate()
                .filter_map(|(i, n)| Some((i, n.clone()?)))
                .collect(),
            Err(_) => return Vec::new(),
        };
        let mut out = Vec::new();
        let mut kinds = std::collections::BTreeMap::<SampleKind, (usize, usize)>::new();
        for (i, n) in &notes {
            kinds.entry(n.kind).or_insert((0, *i)).0 += 1;
        }
        if let Some((&major, _)) = kinds
            .iter()
            .max_by_key(|(_, &(c, first))| (c, usize::MAX - first))
        {
            for (&k, &(count, first)) in kinds.iter().filter(|(&k, _)| k != major) {
                out.push(Warning {
                    path: ds.images[first].clone(),
                    message: format!(
                        "{} image among {} ones ({count} such, this is the first): the two \
                         are made linear differently, so their brightness may not compare; \
                         convert the stack to one format",
                        k.describe(),
                        major.describe()
                    ),
                });
            }
        }
        let grey: Vec<usize> = notes
            .iter()
            .filter(|(_, n)| n.grey)
            .map(|(i, _)| *i)
            .collect();
        if !grey.is_empty() && grey.len() < notes.len() {
            out.push(Warning {
                path: ds.images[grey[0]].clone(),
                message: format!(
                    "grey image among RGB ones ({} such, this is the first): its one channel \
                     is used for red, green and blue",
                    grey.len()
                ),
            });
        }
        let neg: Vec<(usize, usize)> = notes
            .iter()
            .filter(|(_, n)| n.negative > 0)
            .map(|(i, n)| (*i, n.negative))
            .collect();
        if let Some(&(first, _)) = neg.first() {
            out.push(Warning {
                path: ds.images[first].clone(),
                message: format!(
                    "{} negative samples in {} images (this is the first): no radiance is \
                     negative (a dark frame subtracted?); they are used as they are",
                    neg.iter().map(|&(_, c)| c).sum::<usize>(),
                    neg.len()
                ),
            });
        }
        out.extend(colour_warnings(ds, &notes));
        out
    }
}

/// Warnings about colour tags that disagree with the decoding: a profile that is not sRGB
/// (its primaries are not converted), a linear tag on sRGB-decoded samples, an sRGB-like curve
/// on samples taken as linear. One warning per kind of disagreement, naming the first image
/// and the count.
fn colour_warnings(ds: &Dataset, notes: &[(usize, ImageNote)]) -> Vec<Warning> {
    let mut found: Vec<(&'static str, usize, usize, String)> = Vec::new();
    let mut note =
        |key: &'static str, i: usize, text: String| match found.iter_mut().find(|f| f.0 == key) {
            Some(f) => f.2 += 1,
            None => found.push((key, i, 1, text)),
        };
    for (i, n) in notes {
        let Some(tag) = &n.colour else { continue };
        let decoded_srgb = matches!(n.kind, SampleKind::Srgb8 | SampleKind::Srgb16);
        let decoded_linear = matches!(n.kind, SampleKind::Linear8 | SampleKind::U16);
        if tag.source == "ICC profile" && !tag.srgb {
            note(
                "profile",
                *i,
                format!(
                    "{} '{}' is not sRGB: its colours are taken as they are (not converted), \
                     so hues and the balance of the channels may be off",
                    tag.source, tag.name
                ),
            );
        }
        if tag.says_linear() && decoded_srgb {
            note(
                "linear",
                *i,
                format!(
                    "its {} says the samples are linear, but they were sRGB-decoded (decode \
                     them as linear)",
                    tag.source
                ),
            );
        } else if tag.says_srgb_curve() && !tag.says_linear() && decoded_linear {
            note(
                "srgb",
                *i,
                format!(
                    "its {} ({}) says the samples are gamma-encoded, but they were taken as \
                     linear (decode them as sRGB)",
                    tag.source, tag.name
                ),
            );
        }
    }
    found
        .into_iter()
        .map(|(_, first, count, text)| Warning {
            path: ds.images[first].clone(),
            message: format!("{text} ({count} of the images; this is the first)"),
        })
        .collect()
}

/// Checks that a dataset has images, and one light (and intensity, if any) per image.
pub(crate) fn check_dataset(ds: &Dataset) -> Result<()> {
    let n = ds.images.len();
    if n == 0 {
        return Err(Error::invalid(&ds.source, "the dataset has no images"));
    }
    if ds.lights.len() != n {
        return Err(Error::invalid(
            &ds.source,
            format!("{} lights for {n} images", ds.lights.len()),
        ));
    }
    if let Some(int) = &ds.intensities {
        if int.len() != n {
            return Err(Error::invalid(
                &ds.source,
                format!("{} light intensities for {n} images", int.len()),
            ));
        }
    }
    Ok(())
}

/// Checks that image `i` of `ds`, `size` (width, height), is the size of the first image.
pub(crate) fn check_size(
    ds: &Dataset,
    i: usize,
    size: (usize, usize),
    first: (usize, usize),
) -> Result<()> {
    if size == first {
        return Ok(());
    }
    Err(Error::SizeMismatch {
        path: ds.images[i].clone(),
        width: size.0,
        height: size.1,
        first: ds.images[0].clone(),
        first_width: first.0,
        first_height: first.1,
    })
}

/// Bytes of each image the size check before decoding reads ([`check_header_sizes`]): a
/// header past them (a JPEG with a large EXIF block, a TIFF with its directory at the end) is
/// left to the decode's own check.
const SIZE_CHECK_BYTES: u64 = 64 << 10;

/// Compares every image's size, from the first [`SIZE_CHECK_BYTES`] of its file, with the
/// first image's before any is decoded: one image of another size fails the run at once,
/// naming it, instead of after the images before it were decoded. A file that cannot be read
/// or whose header is not in those bytes is left to the decode, which reports it.
pub(crate) fn check_header_sizes(ds: &Dataset, opts: &DecodeOptions) -> Result<()> {
    let size = |p: &Path| -> Option<(usize, usize)> {
        let f = std::fs::File::open(p).ok()?;
        let prefix = crate::read_at_most(f, p, SIZE_CHECK_BYTES).ok()?;
        crate::codecs::declared_size(p, &prefix, opts).ok()
    };
    let Some(first) = ds.images.first().and_then(|p| size(p)) else {
        return Ok(());
    };
    for (i, p) in ds.images.iter().enumerate().skip(1) {
        if let Some(s) = size(p) {
            check_size(ds, i, s, first)?;
        }
    }
    Ok(())
}

/// Files up to this length are read whole at once; of a longer one this much is read first for
/// its header (image headers, EXIF and ICC profiles included, fit in a few MB).
const HEADER_PREFIX_BYTES: u64 = 16 << 20;

/// Refuses an image file longer than any encoding of its declared `size` needs: four float32
/// channels a pixel (16 bytes), twice over for a codec's worst case, plus 16 MiB of metadata.
/// A forged (or sparse) file of gigabytes declaring a small image is never read whole.
fn check_file_length(path: &Path, len: u64, (w, h): (usize, usize)) -> Result<()> {
    let most = (w as u64)
        .saturating_mul(h as u64)
        .saturating_mul(32)
        .saturating_add(HEADER_PREFIX_BYTES);
    if len > most {
        return Err(Error::invalid(
            path,
            format!(
                "{len} bytes, more than any encoding of the {w} x {h} image its header declares \
                 needs (at most {most}); the file is corrupt or padded: re-encode it"
            ),
        ));
    }
    Ok(())
}

/// The image size the header of the file `path` declares, read from its first
/// [`HEADER_PREFIX_BYTES`]: `None` when that prefix does not hold a readable header and the
/// decoder is left to report (a small file: it is read whole anyway; a TIFF, whose directory
/// may sit at its end). A larger file of another format with no readable header there, or one
/// longer than any encoding of its declared image needs, is refused unread.
fn checked_header(path: &Path, opts: &DecodeOptions) -> Result<Option<(usize, usize)>> {
    let len = crate::check_regular_file(path)?;
    let f = std::fs::File::open(path).map_err(|e| Error::read(path, e))?;
    let prefix = crate::read_at_most(f, path, HEADER_PREFIX_BYTES)?;
    let tiff = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"));
    match declared_size(path, &prefix, opts) {
        Ok(size) => {
            check_file_length(path, len, size)?;
            Ok(Some(size))
        }
        Err(e) if len > HEADER_PREFIX_BYTES && !tiff => Err(e),
        Err(_) => Ok(None),
    }
}

/// The width and height the image file `path` declares (for an EXR, of the layer `opts`
/// picks), from its header, without decoding its pixels: its first 16 MiB, or the whole file
/// when the header is not there (a TIFF whose directory sits at its end). The errors of a
/// decode for a header that cannot be read; a file far longer than its image needs is
/// refused unread.
pub fn read_image_size(path: &Path, opts: &DecodeOptions) -> Result<(usize, usize)> {
    match checked_header(path, opts)? {
        Some(size) => Ok(size),
        None => {
            let bytes = crate::codecs::read_image_file(path)?;
            declared_size(path, &bytes, opts)
        }
    }
}

/// Image `i` of a dataset opened to be read a band of rows at a time as a stack stores it:
/// interleaved RGB (grey replicated), divided by the light's intensity when the dataset has
/// intensities.
pub(crate) struct StackImage {
    i: usize,
    rows: Rows,
    /// The light's intensity, when the dataset has intensities.
    intensity: Option<[f32; 3]>,
}

/// Opens image `i` of `ds` (see [`StackImage`]). Given `first`, the stack's image size, the
/// size the file's header declares is compared with it before any pixel is decoded (so an
/// image of another size costs no more memory than its file: `--decode-memory` holds).
pub(crate) fn open_stack_image(
    ds: &Dataset,
    i: usize,
    opts: &DecodeOptions,
    first: Option<(usize, usize)>,
) -> Result<StackImage> {
    let path = &ds.images[i];
    // A large file's header is read first: its declared size is compared with the stack's and
    // bounds the file's length before the whole file is read.
    if crate::check_regular_file(path)? > HEADER_PREFIX_BYTES {
        if let (Some(size), Some(first)) = (checked_header(path, opts)?, first) {
            check_size(ds, i, size, first)?;
        }
    }
    let rows = Rows::open(path, opts, &|size| match first {
        Some(first) => check_size(ds, i, size, first),
        None => Ok(()),
    })?;
    if let Some(first) = first {
        check_size(ds, i, rows.size(), first)?;
    }
    Ok(StackImage {
        i,
        rows,
        intensity: ds.intensities.as_ref().map(|int| int[i]),
    })
}

impl StackImage {
    /// Width and height.
    pub(crate) fn size(&self) -> (usize, usize) {
        self.rows.size()
    }

    /// What the file stores and how it is made linear.
    pub(crate) fn kind(&self) -> SampleKind {
        self.rows.kind()
    }

    /// What the reader holds besides its band of `band_rows` rows (see [`Rows`]).
    pub(crate) fn resident_bytes(&self, band_rows: usize) -> usize {
        self.rows.resident_bytes(band_rows)
    }

    /// Reads the next `out.len() / (3 * width)` rows into `out`, as interleaved RGB.
    pub(crate) fn read_rgb(&mut self, out: &mut [f32]) -> Result<()> {
        self.rows.read(out, 3)?;
        if let Some(k) = self.intensity {
            for px in out.chunks_exact_mut(3) {
                for c in 0..3 {
                    px[c] /= k[c];
                }
            }
        }
        Ok(())
    }

    /// Reads the next `out.len() / (3 * width)` rows into `out` as the file's integer codes
    /// (3 a pixel, grey replicated), not made linear nor divided by the intensity: what an
    /// integer tile cache stores; see [`Rows::read_codes`].
    pub(crate) fn read_codes(&mut self, out: &mut [u16]) -> Result<()> {
        self.rows.read_codes(out)
    }

    /// How the codes [`Self::read_codes`] gives become what [`Self::read_rgb`] gives: the
    /// sample kind (its transfer curve), the first saturated code and the light's intensity.
    pub(crate) fn code_decoding(&self) -> (SampleKind, u32, Option<[f32; 3]>) {
        (
            self.rows.kind(),
            self.rows.first_saturated(),
            self.intensity,
        )
    }

    /// Ends the reading (every row read; see [`Rows::finish`]) and notes the image.
    pub(crate) fn finish(&mut self, notes: &Notes) -> Result<()> {
        self.rows.finish()?;
        notes.set(
            self.i,
            ImageNote {
                kind: self.rows.kind(),
                grey: self.rows.grey(),
                negative: self.rows.negative(),
                colour: self.rows.colour().cloned(),
            },
        );
        Ok(())
    }
}

/// Decodes image `i` of `ds` whole, as a stack stores it (see [`open_stack_image`]). Returns
/// width, height, samples.
pub(crate) fn decode_stack_image(
    ds: &Dataset,
    i: usize,
    opts: &DecodeOptions,
    notes: &Notes,
    first: Option<(usize, usize)>,
) -> Result<(usize, usize, Vec<f32>)> {
    let mut img = open_stack_image(ds, i, opts, first)?;
    let (w, h) = img.size();
    let mut rgb = vec![0.0; w * h * 3];
    img.read_rgb(&mut rgb)?;
    img.finish(notes)?;
    Ok((w, h, rgb))
}

/// The images [`capture_noise`] reads: at most this many, spread over the stack.
const NOISE_IMAGES: usize = 4;

/// The noise model of a dataset's capture (docs/method.md, "Noise model"): the quantisation and
/// clip level its first image's sample type implies (an integer file's white level is where
/// `opts.saturation` puts it, over the brightest light's intensity; float files clip nothing),
/// shot and read noise estimated from a few of its images spread over the stack.
pub fn capture_noise(ds: &Dataset, opts: &DecodeOptions) -> Result<symframe::NoiseModel> {
    use symframe::Quantisation;
    let n = ds.images.len();
    let picks: Vec<usize> = {
        let mut v: Vec<usize> = (0..NOISE_IMAGES.min(n))
            .map(|k| k * (n - 1) / (NOISE_IMAGES - 1).max(1))
            .collect();
        v.dedup();
        v
    };
    let mut model = symframe::NoiseModel::default();
    let mut samples: Option<symframe::NoiseSamples> = None;
    let mut first = None;
    // One row in memory at a time, read as the stack's loader reads it (header checks,
    // intensities); an image of another size than the first, or one that fails to decode
    // part way, ends the sampling (the loader names it).
    let mut row = Vec::new();
    for &i in &picks {
        let mut img = match open_stack_image(ds, i, opts, first) {
            Ok(d) => d,
            Err(_) if first.is_some() => break,
            Err(e) => return Err(e),
        };
        let (w, h) = img.size();
        if first.is_none() {
            first = Some((w, h));
            let (q, max) = match img.kind() {
                SampleKind::Srgb8 => (Quantisation::Srgb(8), 255.0),
                SampleKind::Linear8 => (Quantisation::Linear(8), 255.0),
                SampleKind::U16 => (Quantisation::Linear(16), 65535.0),
                SampleKind::Srgb16 => (Quantisation::Srgb(16), 65535.0),
                SampleKind::Float => (Quantisation::Float, 0.0),
            };
            model.quantisation = q;
            if max > 0.0 && opts.saturation <= 1.0 {
                // The smallest raw value the decoder counts as saturated, made linear.
                let raw = ((opts.saturation * max).ceil() / max).min(1.0);
                let linear = match q {
                    Quantisation::Srgb(_) => crate::codecs::srgb_to_linear(raw),
                    _ => raw,
                };
                let brightest = ds.intensities.as_ref().map_or(1.0, |int| {
                    int.iter().flatten().fold(0.0f32, |a, &b| a.max(b))
                });
                model.clip_level = (brightest > 0.0).then(|| linear / brightest);
            }
        }
        let samples = samples.get_or_insert_with(|| symframe::NoiseSamples::new(&model));
        let step = symframe::NoiseSamples::row_step(w, h);
        row.resize(w * 3, 0.0);
        // Rows are decoded in order; those after the last one sampled are not read.
        let last = if h == 0 { 0 } else { (h - 1) / step * step + 1 };
        let mut failed = None;
        for y in 0..last {
            if let Err(e) = img.read_rgb(&mut row) {
                failed = Some(e);
                break;
            }
            if y % step == 0 {
                samples.add_row(&row, 3, None);
            }
        }
        match failed {
            Some(e) if i == picks[0] => return Err(e),
            Some(_) => break,
            None => {}
        }
    }
    Ok(match samples.as_mut() {
        Some(s) => model.fit(s),
        None => model,
    })
}

/// Reads a mask image: a pixel is inside where any colour channel is non-zero and its alpha
/// (if the image has alpha) is non-zero too (any format [`crate::read_image`] reads; raw
/// samples, no sRGB decoding or saturation test). The mask must be `width x height` and have
/// at least one pixel inside.
pub fn read_mask(path: &Path, width: usize, height: usize) -> Result<Vec<bool>> {
    // The size its header declares first: a mask of another size is refused undecoded.
    if let Ok(size) = read_image_size(path, &DecodeOptions::default()) {
        check_mask_size(path, size, (width, height))?;
    }
    let (w, h, mask) = read_mask_any_size(path)?;
    check_mask_size(path, (w, h), (width, height))?;
    Ok(mask)
}

/// Reads a mask image of any size (see [`read_mask`]): width, height and the pixels inside;
/// an error if it cannot be read or has no pixel inside.
pub fn read_mask_any_size(path: &Path) -> Result<(usize, usize, Vec<bool>)> {
    let (w, h, mask) = crate::codecs::read_mask_pixels(path)?;
    if !mask.iter().any(|&m| m) {
        return Err(Error::invalid(
            path,
            "mask is empty (no pixel is inside: every pixel is black or fully transparent)",
        ));
    }
    Ok((w, h, mask))
}

/// Checks that the mask at `path`, of `mask` (width, height), has the images' size.
pub(crate) fn check_mask_size(
    path: &Path,
    mask: (usize, usize),
    images: (usize, usize),
) -> Result<()> {
    if mask == images {
        return Ok(());
    }
    Err(Error::invalid(
        path,
        format!(
            "mask is {}x{} but the images are {}x{}",
            mask.0, mask.1, images.0, images.1
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::{write_exr_rgb, write_png};
    use glam::DVec3;
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A dataset over `paths`, lights all +z.
    fn ds(paths: Vec<PathBuf>) -> Dataset {
        Dataset {
            source: PathBuf::from("test.lp"),
            lights: vec![DVec3::Z; paths.len()],
            images: paths,
            intensities: None,
            mask: None,
            warnings: Vec::new(),
        }
    }

    #[test]
    fn load_stack_scatters_pixel_major_over_several_chunks() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (3usize, 2usize, 70usize);
        let paths: Vec<PathBuf> = (0..n)
            .map(|i| {
                let p = d.path().join(format!("{i}.exr"));
                let rgb: Vec<f32> = (0..w * h * 3).map(|k| (i * 1000 + k) as f32).collect();
                write_exr_rgb(&p, w, h, &rgb).unwrap();
                p
            })
            .collect();
        let count = AtomicUsize::new(0);
        let s = load_stack(&ds(paths), &DecodeOptions::default(), &|| {
            count.fetch_add(1, Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!(count.load(Ordering::Relaxed), n);
        assert_eq!((s.width, s.height, s.n_lights), (w, h, n));
        for p in 0..w * h {
            for i in 0..n {
                for c in 0..3 {
                    assert_eq!(s.data[(p * n + i) * 3 + c], (i * 1000 + p * 3 + c) as f32);
                }
            }
        }
    }

    #[test]
    fn load_stack_divides_by_intensity_and_replicates_grey() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a.exr");
        write_exr_rgb(&a, 1, 2, &[1.0, 2.0, 3.0, 4.0, 5.0, f32::NAN]).unwrap();
        let b = d.path().join("b.pfm");
        crate::codecs::write_pfm(&b, 1, 2, 1, &[8.0, 16.0]).unwrap();
        let mut dset = ds(vec![a, b]);
        dset.intensities = Some(vec![[1.0, 2.0, 4.0], [2.0, 4.0, 8.0]]);
        let s = load_stack(&dset, &DecodeOptions::default(), &|| {}).unwrap();
        assert_eq!(s.pixel(0), &[1.0, 1.0, 0.75, 4.0, 2.0, 1.0]);
        let p1 = s.pixel(1);
        assert!(p1[..3].iter().all(|v| v.is_nan()));
        assert_eq!(&p1[3..], &[8.0, 4.0, 2.0]);
    }

    #[test]
    fn load_stack_size_mismatch_names_second_file() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("first.exr");
        let b = d.path().join("second.exr");
        write_exr_rgb(&a, 2, 2, &[0.0; 12]).unwrap();
        write_exr_rgb(&b, 3, 2, &[0.0; 18]).unwrap();
        let e = load_stack(&ds(vec![a, b]), &DecodeOptions::default(), &|| {})
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("second.exr: image is 3x2 but the first image")
                && e.contains("first.exr) is 2x2"),
            "{e}"
        );
    }

    #[test]
    fn load_stack_missing_image_is_named() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a.exr");
        write_exr_rgb(&a, 1, 1, &[0.0; 3]).unwrap();
        let gone = d.path().join("gone.exr");
        let e = load_stack(&ds(vec![a, gone]), &DecodeOptions::default(), &|| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains("gone.exr: cannot read"), "{e}");
        let e = load_stack(&ds(vec![]), &DecodeOptions::default(), &|| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.lp: the dataset has no images"), "{e}");
    }

    /// Any colour channel and the alpha count: a pure blue mask is not empty, a red and green
    /// one keeps its green half, and a mask transparent outside is not all inside.
    #[test]
    fn a_mask_pixel_is_inside_by_any_colour_channel_and_its_alpha() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.png");
        let rgb = crate::codecs::PngLayout::Rgb8;
        write_png(&p, 2, 1, &[0, 0, 255, 0, 0, 0], rgb).unwrap();
        assert_eq!(read_mask(&p, 2, 1).unwrap(), vec![true, false]);
        write_png(&p, 3, 1, &[255, 0, 0, 0, 255, 0, 0, 0, 0], rgb).unwrap();
        assert_eq!(read_mask(&p, 3, 1).unwrap(), vec![true, true, false]);
        // Black and white with alpha 255 everywhere: colour decides.
        let rgba = crate::codecs::PngLayout::Rgba8;
        write_png(&p, 2, 1, &[255, 255, 255, 255, 0, 0, 0, 255], rgba).unwrap();
        assert_eq!(read_mask(&p, 2, 1).unwrap(), vec![true, false]);
        // Transparent outside, colour everywhere: alpha decides.
        write_png(&p, 2, 1, &[90, 60, 30, 0, 90, 60, 30, 255], rgba).unwrap();
        assert_eq!(read_mask(&p, 2, 1).unwrap(), vec![false, true]);
        // Grey with alpha, 16-bit.
        let la16 = crate::codecs::PngLayout::La16;
        let px: Vec<u8> = [1u16, 0, 1, 7, 0, 7]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        write_png(&p, 3, 1, &px, la16).unwrap();
        assert_eq!(read_mask(&p, 3, 1).unwrap(), vec![false, true, false]);
        write_png(&p, 1, 1, &[255, 255, 255, 0], rgba).unwrap();
        let e = read_mask(&p, 1, 1).unwrap_err().to_string();
        assert!(e.contains("m.png: mask is empty"), "{e}");
    }

    #[test]
    fn masks() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("mask.png");
        write_png(&p, 3, 1, &[0, 255, 1], crate::codecs::PngLayout::L8).unwrap();
        assert_eq!(read_mask(&p, 3, 1).unwrap(), vec![false, true, true]);
        let e = read_mask(&p, 4, 2).unwrap_err().to_string();
        assert!(
            e.contains("mask.png: mask is 3x1 but the images are 4x2"),
            "{e}"
        );
        // Any colour channel counts for RGB masks.
        write_png(
            &p,
            3,
            1,
            &[0, 9, 9, 7, 0, 0, 0, 0, 0],
            crate::codecs::PngLayout::Rgb8,
        )
        .unwrap();
        assert_eq!(read_mask(&p, 3, 1).unwrap(), vec![true, true, false]);
        write_png(&p, 2, 1, &[0, 0], crate::codecs::PngLayout::L8).unwrap();
        let e = read_mask(&p, 2, 1).unwrap_err().to_string();
        assert!(e.contains("mask.png: mask is empty"), "{e}");
    }

    /// Mixed inputs passed silently: 8-bit among 16-bit, grey among RGB, negative samples.
    #[test]
    fn mixed_inputs_are_warned_about() {
        use crate::codecs::write_png16_rgb;
        let d = tempfile::tempdir().unwrap();
        let p = |n: &str| d.path().join(n);
        for n in ["a.png", "b.png", "d.png"] {
            write_png16_rgb(&p(n), 2, 1, &[0.25; 6]).unwrap();
        }
        write_png(&p("c.png"), 2, 1, &[10, 20], crate::codecs::PngLayout::L8).unwrap();
        let set = ds(["a.png", "b.png", "c.png", "d.png"].map(p).to_vec());
        let (_, w) = load_stack_with_warnings(&set, &DecodeOptions::default(), &|| {}).unwrap();
        let w: Vec<String> = w.iter().map(|w| w.to_string()).collect();
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].contains("c.png: 8-bit (sRGB-decoded) image among 16-bit (linear) ones (1 such"),
            "{w:?}"
        );
        assert!(
            w[1].contains("c.png: grey image among RGB ones (1 such"),
            "{w:?}"
        );

        // The cache reports the same, when built and when reused.
        let dir = p("cache");
        let go = std::sync::atomic::AtomicBool::new(false);
        let open = || {
            crate::TileCache::open_or_build(
                &set,
                &DecodeOptions::default(),
                &dir,
                Default::default(),
                &go,
                &|| {},
            )
            .unwrap()
            .1
        };
        let built = open();
        assert!(!built.hit);
        let reused = open();
        assert!(reused.hit);
        for info in [built, reused] {
            let v: Vec<String> = info.warnings.iter().map(|w| w.to_string()).collect();
            assert_eq!(v, w);
        }

        // Uniform inputs: no warning; negative float samples: one.
        let (_, w) = load_stack_with_warnings(
            &ds(["a.png", "b.png"].map(p).to_vec()),
            &DecodeOptions::default(),
            &|| {},
        )
        .unwrap();
        assert!(w.is_empty(), "{w:?}");
        crate::codecs::write_pfm(&p("e.pfm"), 2, 1, 1, &[0.5, 0.5]).unwrap();
        crate::codecs::write_pfm(&p("f.pfm"), 2, 1, 1, &[-0.01, 0.5]).unwrap();
        let (_, w) = load_stack_with_warnings(
            &ds(["e.pfm", "f.pfm"].map(p).to_vec()),
            &DecodeOptions::default(),
            &|| {},
        )
        .unwrap();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].to_string()
                .contains("f.pfm: 1 negative samples in 1 images"),
            "{w:?}"
        );
    }

    /// The noise model from images read a row at a time is the one from whole images.
    #[test]
    fn capture_noise_reads_rows_as_whole_images_read() {
        let d = tempfile::tempdir().unwrap();
        let ds = fixture::every_kind(d.path());
        let opts = DecodeOptions::default();
        let model = capture_noise(&ds, &opts).unwrap();
        let n = ds.images.len();
        let notes = Notes::new(n);
        let images: Vec<Vec<f32>> = [0, 5, 10, 16]
            .iter()
            .map(|&i| decode_stack_image(&ds, i, &opts, &notes, None).unwrap().2)
            .collect();
        let whole = symframe::NoiseModel {
            shot: 0.0,
            read: 0.0,
            ..model
        }
        .estimate(images.iter().map(|v| &v[..]), fixture::W, None);
        assert_eq!(model, whole);
        assert!(model.shot > 0.0 || model.read > 0.0, "{model:?}");
    }

    /// Every kind of image the decoders read, decoded as version 0.1 decoded it (whole, through
    /// `image`, `tiff`, `exr` and the PFM parser), for each transfer curve: size, channels,
    /// sample kind, colour tag and the XXH3-64 of the samples' bits are pinned.
    #[test]
    fn every_kind_of_image_decodes_as_pinned() {
        use crate::codecs::Gamma;
        let d = tempfile::tempdir().unwrap();
        let ds = fixture::every_kind(d.path());
        let pinned = [
            ("rgb8.png", Gamma::Auto, "37x23x3 Srgb8", 0x8fd51bc69b7784fb),
            ("rgb8.png", Gamma::Srgb, "37x23x3 Srgb8", 0x8fd51bc69b7784fb),
            (
                "rgb8.png",
                Gamma::Linear,
                "37x23x3 Linear8",
                0x3e0c60ed0cbad7f5,
            ),
            (
                "grey8.png",
                Gamma::Auto,
                "37x23x1 Srgb8",
                0x5b8e6b0ba352e3ba,
            ),
            (
                "grey8.png",
                Gamma::Srgb,
                "37x23x1 Srgb8",
                0x5b8e6b0ba352e3ba,
            ),
            (
                "grey8.png",
                Gamma::Linear,
                "37x23x1 Linear8",
                0x494312a77c89b7c1,
            ),
            ("rgb16.png", Gamma::Auto, "37x23x3 U16", 0x8e626d3efacb299b),
            (
                "rgb16.png",
                Gamma::Srgb,
                "37x23x3 Srgb16",
                0xe96237066e2f1d18,
            ),
            (
                "rgb16.png",
                Gamma::Linear,
                "37x23x3 U16",
                0x8e626d3efacb299b,
            ),
            (
                "rgba8.png",
                Gamma::Auto,
                "37x23x3 Srgb8",
                0xd8997f51c050e2b4,
            ),
            (
                "rgba8.png",
                Gamma::Srgb,
                "37x23x3 Srgb8",
                0xd8997f51c050e2b4,
            ),
            (
                "rgba8.png",
                Gamma::Linear,
                "37x23x3 Linear8",
                0x905fcbcf60974540,
            ),
            ("la16.png", Gamma::Auto, "37x23x1 U16", 0x0f423ce62f3edfe8),
            (
                "la16.png",
                Gamma::Srgb,
                "37x23x1 Srgb16",
                0x68366c40b16c70b2,
            ),
            ("la16.png", Gamma::Linear, "37x23x1 U16", 0x0f423ce62f3edfe8),
            (
                "grey1.png",
                Gamma::Auto,
                "37x23x1 Srgb8",
                0x9ac6ac20e9fb11a0,
            ),
            (
                "grey1.png",
                Gamma::Srgb,
                "37x23x1 Srgb8",
                0x9ac6ac20e9fb11a0,
            ),
            (
                "grey1.png",
                Gamma::Linear,
                "37x23x1 Linear8",
                0x9ac6ac20e9fb11a0,
            ),
            (
                "grey4.png",
                Gamma::Auto,
                "37x23x1 Srgb8",
                0xa94d678d937ba9eb,
            ),
            (
                "grey4.png",
                Gamma::Srgb,
                "37x23x1 Srgb8",
                0xa94d678d937ba9eb,
            ),
            (
                "grey4.png",
                Gamma::Linear,
                "37x23x1 Linear8",
                0x03bee95d79ce911f,
            ),
            (
                "palette2.png",
                Gamma::Auto,
                "37x23x3 Srgb8",
                0x18f60e50a003ac95,
            ),
            (
                "palette2.png",
                Gamma::Srgb,
                "37x23x3 Srgb8",
                0x18f60e50a003ac95,
            ),
            (
                "palette2.png",
                Gamma::Linear,
                "37x23x3 Linear8",
                0x2ba6b817b11a3172,
            ),
            (
                "palette8.png",
                Gamma::Auto,
                "37x23x3 Srgb8",
                0x8a226d456d8fe85d,
            ),
            (
                "palette8.png",
                Gamma::Srgb,
                "37x23x3 Srgb8",
                0x8a226d456d8fe85d,
            ),
            (
                "palette8.png",
                Gamma::Linear,
                "37x23x3 Linear8",
                0x140d1867268a7e41,
            ),
            (
                "grey_trns.png",
                Gamma::Auto,
                "37x23x1 Srgb8",
                0xc0da97f10ecd322f,
            ),
            (
                "grey_trns.png",
                Gamma::Srgb,
                "37x23x1 Srgb8",
                0xc0da97f10ecd322f,
            ),
            (
                "grey_trns.png",
                Gamma::Linear,
                "37x23x1 Linear8",
                0x0154ab0754ccd427,
            ),
            (
                "adam7.png",
                Gamma::Auto,
                "37x23x3 Srgb8",
                0xa889a891e01d406a,
            ),
            (
                "adam7.png",
                Gamma::Srgb,
                "37x23x3 Srgb8",
                0xa889a891e01d406a,
            ),
            (
                "adam7.png",
                Gamma::Linear,
                "37x23x3 Linear8",
                0xc55430948f6e668f,
            ),
            (
                "srgb16.png",
                Gamma::Auto,
                "37x23x3 U16 sRGB",
                0x84485d2435c33a08,
            ),
            (
                "srgb16.png",
                Gamma::Srgb,
                "37x23x3 Srgb16 sRGB",
                0x3666dceee0bd4882,
            ),
            (
                "srgb16.png",
                Gamma::Linear,
                "37x23x3 U16 sRGB",
                0x84485d2435c33a08,
            ),
            ("rgb.pfm", Gamma::Auto, "37x23x3 Float", 0x8b4ba516dcd69e6c),
            ("rgb.pfm", Gamma::Srgb, "37x23x3 Float", 0x8b4ba516dcd69e6c),
            (
                "rgb.pfm",
                Gamma::Linear,
                "37x23x3 Float",
                0x8b4ba516dcd69e6c,
            ),
            ("grey.pfm", Gamma::Auto, "37x23x1 Float", 0x75b8d589aa881178),
            ("grey.pfm", Gamma::Srgb, "37x23x1 Float", 0x75b8d589aa881178),
            (
                "grey.pfm",
                Gamma::Linear,
                "37x23x1 Float",
                0x75b8d589aa881178,
            ),
            ("rgb.exr", Gamma::Auto, "37x23x3 Float", 0xf037bd41f37978fd),
            ("rgb.exr", Gamma::Srgb, "37x23x3 Float", 0xf037bd41f37978fd),
            (
                "rgb.exr",
                Gamma::Linear,
                "37x23x3 Float",
                0xf037bd41f37978fd,
            ),
            ("rgb.jpg", Gamma::Auto, "37x23x3 Srgb8", 0x6a5b199e3066d470),
            ("rgb.jpg", Gamma::Srgb, "37x23x3 Srgb8", 0x6a5b199e3066d470),
            (
                "rgb.jpg",
                Gamma::Linear,
                "37x23x3 Linear8",
                0xbc07fd2f191896b8,
            ),
            ("rgb16.tif", Gamma::Auto, "37x23x3 U16", 0xdcf33ea13e201396),
            (
                "rgb16.tif",
                Gamma::Srgb,
                "37x23x3 Srgb16",
                0x0feca2402a73ecc9,
            ),
            (
                "rgb16.tif",
                Gamma::Linear,
                "37x23x3 U16",
                0xdcf33ea13e201396,
            ),
        ];
        assert_eq!(pinned.len(), ds.images.len() * 3);
        for (name, gamma, what, hash) in pinned {
            let opts = DecodeOptions {
                gamma,
                ..Default::default()
            };
            let img = crate::read_image(&d.path().join(name), &opts).unwrap();
            let colour = img.colour.as_ref().map_or("", |c| c.name.as_str());
            let got = format!(
                "{}x{}x{} {:?} {colour}",
                img.width, img.height, img.channels, img.kind
            );
            assert_eq!(got.trim_end(), what.trim_end(), "{name} {gamma:?}");
            let bits: Vec<u8> = img
                .data
                .iter()
                .flat_map(|v| v.to_bits().to_le_bytes())
                .collect();
            let sum = xxhash_rust::xxh3::xxh3_64(&bits);
            assert_eq!(sum, hash, "{name} {gamma:?}: {sum:#018x}");
        }
    }
}

#[cfg(test)]
pub(crate) mod fixture {
    //! A stack of every kind of image the decoders read (PNG of every bit depth and colour
    //! type, palette, transparency and interlacing; PFM, EXR, JPEG, TIFF), for tests that pin
    //! the decoded samples and the cache layout bit for bit.

    use std::path::{Path, PathBuf};

    use glam::DVec3;

    use crate::codecs::{write_exr_rgb, write_pfm};
    use crate::dataset::Dataset;

    /// Width and height of the fixture's images (tiles of 8 are cropped on both sides).
    pub(crate) const W: usize = 37;
    /// See [`W`].
    pub(crate) const H: usize = 23;

    /// A small deterministic generator (xorshift64*).
    pub(crate) struct Rng(pub(crate) u64);

    impl Rng {
        pub(crate) fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        fn bytes(&mut self, n: usize) -> Vec<u8> {
            (0..n).map(|_| (self.next() >> 32) as u8).collect()
        }
    }

    /// Writes a PNG of packed, big-endian rows `data` with the `png` crate.
    #[allow(clippy::too_many_arguments)]
    fn png_raw(
        path: &Path,
        colour: png::ColorType,
        depth: png::BitDepth,
        data: &[u8],
        palette: Option<Vec<u8>>,
        trns: Option<Vec<u8>>,
        srgb: bool,
    ) {
        let f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        let mut e = png::Encoder::new(f, W as u32, H as u32);
        e.set_color(colour);
        e.set_depth(depth);
        if let Some(p) = palette {
            e.set_palette(p);
        }
        if let Some(t) = trns {
            e.set_trns(t);
        }
        if srgb {
            e.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        }
        let mut w = e.write_header().unwrap();
        w.write_image_data(data).unwrap();
        w.finish().unwrap();
    }

    /// The CRC-32 of PNG chunks.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    /// An Adam7-interlaced 8-bit RGB PNG of `rgb`, made by hand (the `png` encoder writes no
    /// interlaced files): each pass's rows unfiltered, in stored deflate blocks.
    fn interlaced_png(path: &Path, rgb: &[u8]) {
        const PASSES: [(usize, usize, usize, usize); 7] = [
            (0, 0, 8, 8),
            (4, 0, 8, 8),
            (0, 4, 4, 8),
            (2, 0, 4, 4),
            (0, 2, 2, 4),
            (1, 0, 2, 2),
            (0, 1, 1, 2),
        ];
        let mut raw = Vec::new();
        for (x0, y0, dx, dy) in PASSES {
            if x0 >= W || y0 >= H {
                continue;
            }
            for y in (y0..H).step_by(dy) {
                raw.push(0);
                for x in (x0..W).step_by(dx) {
                    raw.extend_from_slice(&rgb[(y * W + x) * 3..(y * W + x) * 3 + 3]);
                }
            }
        }
        let mut z = vec![0x78, 0x01];
        let blocks: Vec<&[u8]> = raw.chunks(65535).collect();
        for (i, b) in blocks.iter().enumerate() {
            z.push((i + 1 == blocks.len()) as u8);
            z.extend((b.len() as u16).to_le_bytes());
            z.extend((!(b.len() as u16)).to_le_bytes());
            z.extend_from_slice(b);
        }
        let (mut a, mut b) = (1u32, 0u32);
        for &v in &raw {
            a = (a + v as u32) % 65521;
            b = (b + a) % 65521;
        }
        z.extend(((b << 16) | a).to_be_bytes());
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut chunk = |kind: &[u8], body: &[u8]| {
            png.extend((body.len() as u32).to_be_bytes());
            let mut c = kind.to_vec();
            c.extend_from_slice(body);
            png.extend(&c);
            png.extend(crc32(&c).to_be_bytes());
        };
        let mut ihdr = (W as u32).to_be_bytes().to_vec();
        ihdr.extend((H as u32).to_be_bytes());
        ihdr.extend([8, 2, 0, 0, 1]);
        chunk(b"IHDR", &ihdr);
        chunk(b"IDAT", &z);
        chunk(b"IEND", &[]);
        std::fs::write(path, png).unwrap();
    }

    /// Packs samples of `bits` (1, 2 or 4) into rows, most significant bits first.
    fn pack(v: &[u8], bits: usize) -> Vec<u8> {
        let per = 8 / bits;
        let row = W.div_ceil(per);
        let mut out = vec![0u8; row * H];
        for y in 0..H {
            for x in 0..W {
                let s = v[y * W + x] & ((1 << bits) - 1) as u8;
                out[y * row + x / per] |= s << (8 - bits * (x % per + 1));
            }
        }
        out
    }

    /// Writes the fixture's images into `dir`: the stack, all `W x H`, with light intensities.
    pub(crate) fn every_kind(dir: &Path) -> Dataset {
        use png::{BitDepth as D, ColorType as C};
        let mut rng = Rng(0x5eed_1234_abcd_0001);
        let n = W * H;
        let mut images: Vec<PathBuf> = Vec::new();
        let mut add = |name: &str| {
            let p = dir.join(name);
            images.push(p.clone());
            p
        };
        // 8-bit RGB: random, so some samples are saturated.
        png_raw(
            &add("rgb8.png"),
            C::Rgb,
            D::Eight,
            &rng.bytes(n * 3),
            None,
            None,
            false,
        );
        png_raw(
            &add("grey8.png"),
            C::Grayscale,
            D::Eight,
            &rng.bytes(n),
            None,
            None,
            false,
        );
        png_raw(
            &add("rgb16.png"),
            C::Rgb,
            D::Sixteen,
            &rng.bytes(n * 6),
            None,
            None,
            false,
        );
        png_raw(
            &add("rgba8.png"),
            C::Rgba,
            D::Eight,
            &rng.bytes(n * 4),
            None,
            None,
            false,
        );
        png_raw(
            &add("la16.png"),
            C::GrayscaleAlpha,
            D::Sixteen,
            &rng.bytes(n * 4),
            None,
            None,
            false,
        );
        png_raw(
            &add("grey1.png"),
            C::Grayscale,
            D::One,
            &pack(&rng.bytes(n), 1),
            None,
            None,
            false,
        );
        png_raw(
            &add("grey4.png"),
            C::Grayscale,
            D::Four,
            &pack(&rng.bytes(n), 4),
            None,
            None,
            false,
        );
        let palette = rng.bytes(4 * 3);
        png_raw(
            &add("palette2.png"),
            C::Indexed,
            D::Two,
            &pack(&rng.bytes(n), 2),
            Some(palette),
            Some(vec![255, 0, 128]),
            false,
        );
        let palette = rng.bytes(256 * 3);
        png_raw(
            &add("palette8.png"),
            C::Indexed,
            D::Eight,
            &rng.bytes(n),
            Some(palette),
            None,
            false,
        );
        png_raw(
            &add("grey_trns.png"),
            C::Grayscale,
            D::Eight,
            &rng.bytes(n),
            None,
            Some(vec![0, 77]),
            false,
        );
        interlaced_png(&add("adam7.png"), &rng.bytes(n * 3));
        png_raw(
            &add("srgb16.png"),
            C::Rgb,
            D::Sixteen,
            &rng.bytes(n * 6),
            None,
            None,
            true,
        );
        // Floats with negative, infinite and NaN samples.
        let floats = |rng: &mut Rng, len: usize| -> Vec<f32> {
            (0..len)
                .map(|_| match rng.next() % 50 {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    2 => -0.25,
                    k => (rng.next() % 100_000) as f32 / 1e4 + k as f32,
                })
                .collect()
        };
        write_pfm(&add("rgb.pfm"), W, H, 3, &floats(&mut rng, n * 3)).unwrap();
        write_pfm(&add("grey.pfm"), W, H, 1, &floats(&mut rng, n)).unwrap();
        write_exr_rgb(&add("rgb.exr"), W, H, &floats(&mut rng, n * 3)).unwrap();
        {
            let f = std::io::BufWriter::new(std::fs::File::create(add("rgb.jpg")).unwrap());
            image::ImageEncoder::write_image(
                image::codecs::jpeg::JpegEncoder::new_with_quality(f, 90),
                &rng.bytes(n * 3),
                W as u32,
                H as u32,
                image::ExtendedColorType::Rgb8,
            )
            .unwrap();
        }
        {
            use tiff::encoder::{colortype, TiffEncoder};
            let v: Vec<u16> = (0..n * 3).map(|_| (rng.next() >> 48) as u16).collect();
            TiffEncoder::new(std::fs::File::create(add("rgb16.tif")).unwrap())
                .unwrap()
                .write_image::<colortype::RGB16>(W as u32, H as u32, &v)
                .unwrap();
        }
        let k = images.len();
        Dataset {
            source: dir.join("fixture.lp"),
            lights: vec![DVec3::Z; k],
            images,
            intensities: Some(
                (0..k)
                    .map(|i| [1.0, 0.5 + i as f32 * 0.25, 3.0 / (i + 1) as f32])
                    .collect(),
            ),
            mask: None,
            warnings: Vec::new(),
        }
    }
}
