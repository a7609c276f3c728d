//! Dataset I/O for symframe: light files (`.lp`, DiLiGenT folders), image decoding into a
//! pixel-major [`symframe::Stack`] or an on-disk tile cache, per-tile results, result-map
//! writers and synthetic-dataset output.
//!
//! A capture written as an `.lp` dataset and read back as a stack:
//!
//! ```
//! use glam::DVec3;
//! use symframe_io::{load_stack, open_dataset, write_lp_dataset, DecodeOptions, ImageFormat};
//!
//! # fn main() -> symframe_io::Result<()> {
//! let dir = tempfile::tempdir().unwrap();
//! // Two 2 x 1 images, one per light: light 0 brighter on the left pixel.
//! let lights = [DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.5, 0.0, 0.866)];
//! let images = vec![vec![0.5, 0.5, 0.5, 0.25, 0.25, 0.25], vec![0.125; 6]];
//! let lp = write_lp_dataset(
//!     dir.path(), &lights, &images, 2, 1, ImageFormat::Exr, None, None, None,
//! )?;
//! let ds = open_dataset(&lp)?;
//! let stack = load_stack(&ds, &DecodeOptions::default(), &|| {})?;
//! assert_eq!((stack.width, stack.height, stack.n_lights), (2, 1, 2));
//! // Pixel-major: the left pixel under both lights, then the right one.
//! assert_eq!(stack.pixel(0), &[0.5, 0.5, 0.5, 0.125, 0.125, 0.125]);
//! # Ok(())
//! # }
//! ```

#![deny(unreachable_pub)]

mod atomic;
mod bounded;
pub mod codecs;
pub mod dataset;
pub mod error;
pub mod fingerprint;
mod lights;
pub mod limits;
pub mod output;
pub mod stack;
pub mod synth_out;
pub mod tile_cache;
pub mod tile_results;

pub use atomic::{open_no_follow, write_bytes};
pub use bounded::{
    check_regular_file, open_bounded, open_own_file, read_at_most, read_bounded, read_text_bounded,
};
pub use codecs::{
    declared_size, decode_image, linear_to_srgb, read_image, read_pfm, srgb_to_linear,
    write_exr_channels, write_exr_rgb, write_pfm, write_png16_rgb, write_png8_rgb, ColourTag,
    DecodeOptions, Gamma, Image, PngRows, SampleKind,
};
pub use codecs::{read_image_grey, GreyBand};
pub use dataset::near;
pub use dataset::near::{open_near_geometry, NearGeometry};
pub use dataset::{open_dataset, Dataset};
pub use error::{Error, Result, Warning};
pub use lights::{lp_path_convention, read_light_directions, read_list, LpPaths};
pub use output::{
    gray_map_rgb8, normal_map_rgb8, normal_map_values, normal_png16_row, read_npy_f32, read_npy_u8,
    source_map_rgb8, tangent_map_rgb8, write_exr_map, write_exr_map_with, write_normal_png16,
    write_npy_f32, write_npy_u8, write_png_rgb8, NormalPng, NpyRows, SOURCE_PALETTE,
};
pub use stack::{
    capture_noise, load_stack, load_stack_with_warnings, read_image_size, read_mask,
    read_mask_any_size,
};
pub use synth_out::{
    check_synth_target, write_lp_dataset, write_near_dataset, ImageFormat, NearFiles,
    OUTPUT_LOCK_FILE,
};
pub use tile_cache::{
    cache_holds_work, dataset_fingerprints, CacheFormat, CacheInfo, CacheOptions, Fingerprints,
    StampKind, TileCache, TileGather, TileGrid, TileView,
};
pub use tile_results::{
    check_tile_result, read_tile_result, tile_result_done, tile_result_path, write_tile_result,
    TileFile,
};
