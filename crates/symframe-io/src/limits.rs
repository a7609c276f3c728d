//! What the decoders accept: every image and array reader checks the sizes a file declares
//! against these limits, and against the file's own length, before it allocates anything of
//! that size. A header that claims more (a forged or corrupt file, e.g. an EXR of 100000 x
//! 100000 pixels in 1 KB) gives an [`Error::Limits`] naming the file.
//!
//! - At most [`MAX_SIDE`] pixels per side and [`MAX_PIXELS`] pixels per image (134 million:
//!   a 16,384 x 8,192 image). Larger images are not supported; crop or downsample them.
//! - At most [`MAX_PIXELS_PER_BYTE`] declared pixels per byte of the file (beyond a first
//!   [`PIXEL_ALLOWANCE`] pixels that any file may declare). Deflate, the strongest compression
//!   of these formats for constant images, stays near 1,000 bytes per byte, so no real image
//!   comes near this; a file that declares more is corrupt or truncated.
//! - Uncompressed formats (PFM, `.npy`) must hold every value they declare: the pixel data's
//!   length is checked against the file before the buffer is allocated.
//! - An `.npy` array has at most [`MAX_NPY_VALUES`] values.
//! - A light file (`.lp`, `light_directions.txt`, `light_intensities.txt`, `filenames.txt`, a
//!   `relight --lights` file, an image list) holds at most [`MAX_LIGHTS`] lights (rows, images),
//!   read a line at a time: a longer one is refused at the line that passes the cap, before
//!   anything per light is allocated beyond it.
//! - Every file read whole must be a regular file (not a FIFO, device or folder) of at most
//!   [`MAX_TEXT_FILE_BYTES`] (light files, image lists, JSON reports), [`MAX_IMAGE_FILE_BYTES`]
//!   (images, masks) or [`MAX_NPY_FILE_BYTES`] (`.npy` maps); see [`crate::read_bounded`]
//!   (light files and image lists are read a line at a time, [`crate::open_bounded`]).

use std::path::Path;

use crate::error::{Error, Result};

/// Largest image side accepted, in pixels.
pub const MAX_SIDE: usize = 1 << 16;
/// Largest image accepted, in pixels.
pub const MAX_PIXELS: usize = 1 << 27;
/// Pixels any file may declare whatever its length.
pub const PIXEL_ALLOWANCE: u64 = 1 << 20;
/// Most pixels a file may declare per byte of its length beyond [`PIXEL_ALLOWANCE`].
pub const MAX_PIXELS_PER_BYTE: u64 = 1 << 14;
/// Largest `.npy` array accepted, in values (a `MAX_PIXELS` image of 3 channels).
pub const MAX_NPY_VALUES: usize = 3 * MAX_PIXELS;
/// Most lights (images, rows of a light table) a dataset or light file may have: far more than
/// any capture has (DiLiGenT's 96, the 1,512 of the paper's renders), and little memory.
pub const MAX_LIGHTS: usize = 100_000;
/// Largest text file read (a light file, image list or JSON report): 64 MiB, a million lights
/// at 64 bytes a line.
pub const MAX_TEXT_FILE_BYTES: u64 = 64 << 20;
/// Largest image (or mask) file read: 4 GiB, a [`MAX_PIXELS`] image of four 64-bit channels
/// uncompressed.
pub const MAX_IMAGE_FILE_BYTES: u64 = 4 << 30;
/// Largest `.npy` file read: [`MAX_NPY_VALUES`] float32 values and a header.
pub const MAX_NPY_FILE_BYTES: u64 = 4 * MAX_NPY_VALUES as u64 + (1 << 20);
/// Largest decoded buffer a decoder library may allocate for one image, in bytes (a
/// `MAX_PIXELS` image of four 32-bit channels).
pub const MAX_DECODED_BYTES: u64 = 16 * MAX_PIXELS as u64;

/// Checks an image's declared `width x height` (`what` names the format, e.g. "EXR header")
/// against the limits and the file's length `file_len` in bytes.
pub(crate) fn check_image_size(
    path: &Path,
    what: &str,
    width: u64,
    height: u64,
    file_len: u64,
) -> Result<()> {
    if width > MAX_SIDE as u64 || height > MAX_SIDE as u64 {
        return Err(Error::limits(
            path,
            format!("{what} declares {width}x{height} pixels, more than {MAX_SIDE} per side"),
        ));
    }
    let pixels = width * height;
    if pixels > MAX_PIXELS as u64 {
        return Err(Error::limits(
            path,
            format!("{what} declares {width}x{height} pixels, more than {MAX_PIXELS} in all"),
        ));
    }
    let allowed = PIXEL_ALLOWANCE.saturating_add(file_len.saturating_mul(MAX_PIXELS_PER_BYTE));
    if pixels > allowed {
        return Err(Error::limits(
            path,
            format!(
                "{what} declares {width}x{height} pixels in a file of {file_len} bytes \
                 (corrupt or truncated)"
            ),
        ));
    }
    Ok(())
}
