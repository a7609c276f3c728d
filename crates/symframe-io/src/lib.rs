//! Dataset I/O for symframe: light files (`.lp`, DiLiGenT folders), image decoding into a
//! pixel-major [`symframe::Stack`] or an on-disk tile cache, per-tile results, result-map writers and synthetic-dataset output.

#![warn(missing_docs)]

mod atomic;
pub mod dataset;
pub mod error;
pub mod fingerprint;
pub mod image;
mod lights;
pub mod output;
pub mod stack;
pub mod synth_out;
pub mod tile_cache;
pub mod tile_results;

pub use dataset::{open_dataset, Dataset};
pub use error::{Error, Result};
pub use image::{
    linear_to_srgb, read_image, read_pfm, srgb_to_linear, write_exr_rgb, write_pfm,
    write_png16_rgb, write_png8_rgb, DecodeOptions, Image,
};
pub use lights::{lp_path_convention, read_light_directions, LpPaths};
pub use output::{
    gray_map_rgb8, normal_map_rgb8, normal_map_values, read_npy_f32, tangent_map_rgb8,
    write_exr_map, write_normal_png16, write_npy_f32, write_png_rgb8, NormalPng,
};
pub use stack::{load_stack, read_mask};
pub use synth_out::{write_lp_dataset, ImageFormat};
pub use tile_cache::{CacheInfo, CacheOptions, TileCache, TileGather, TileGrid, TileView};
pub use tile_results::{read_tile_result, tile_result_done, tile_result_path, write_tile_result};
