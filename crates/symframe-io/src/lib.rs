//! Dataset I/O for symframe: light files (`.lp`, DiLiGenT folders), image decoding into a
//! pixel-major [`symframe::Stack`], result-map writers and synthetic-dataset output.

#![warn(missing_docs)]

mod atomic;
pub mod dataset;
pub mod error;
pub mod image;
mod lights;
pub mod output;
pub mod stack;
pub mod synth_out;

pub use dataset::{open_dataset, Dataset};
pub use error::{Error, Result};
pub use image::{
    linear_to_srgb, read_image, read_pfm, srgb_to_linear, write_exr_rgb, write_pfm,
    write_png16_rgb, write_png8_rgb, DecodeOptions, Image,
};
pub use lights::read_light_directions;
pub use output::{
    gray_map_rgb8, normal_map_rgb8, read_npy_f32, tangent_map_rgb8, write_exr_map, write_npy_f32,
    write_png_rgb8,
};
pub use stack::{load_stack, read_mask};
pub use synth_out::{write_lp_dataset, ImageFormat};
