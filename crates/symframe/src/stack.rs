//! The measurement stack: every pixel's radiance under every light, pixel-major.

use crate::error::{Error, Result};

/// Radiance samples of an image stack, stored pixel-major so that one pixel's slice is contiguous.
///
/// `data[((y * width + x) * n_lights + i) * 3 + c]` is channel `c` of pixel `(x, y)` (row 0 at
/// the top) under light `i`, linear and divided by the light's intensity. A sample that must not
/// be trusted (saturated, non-finite, missing) is stored as `NaN` in all three channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Stack {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Number of lights (images) in the stack.
    pub n_lights: usize,
    /// Pixel-major RGB samples, `width * height * n_lights * 3` values.
    pub data: Vec<f32>,
}

/// Checks that `mask` (a mask, or an edit region: `what` names it in the error) covers
/// `width x height` pixels.
pub(crate) fn check_mask_size(
    mask: &[bool],
    width: usize,
    height: usize,
    what: &str,
) -> Result<()> {
    if mask.len() != width * height {
        return Err(Error::BadMask(format!(
            "{what} has {} pixels but the images have {width}x{height} = {}",
            mask.len(),
            width * height
        )));
    }
    Ok(())
}

impl Stack {
    /// A stack of the given size with every sample set to zero.
    pub fn zeros(width: usize, height: usize, n_lights: usize) -> Self {
        Self {
            width,
            height,
            n_lights,
            data: vec![0.0; width * height * n_lights * 3],
        }
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width * self.height
    }

    /// The RGB samples of one pixel (index `y * width + x`), `n_lights * 3` values.
    pub fn pixel(&self, pixel: usize) -> &[f32] {
        let n = self.n_lights * 3;
        &self.data[pixel * n..(pixel + 1) * n]
    }

    /// Mutable RGB samples of one pixel.
    pub fn pixel_mut(&mut self, pixel: usize) -> &mut [f32] {
        let n = self.n_lights * 3;
        &mut self.data[pixel * n..(pixel + 1) * n]
    }

    /// Writes one image (`width * height * 3` interleaved RGB values, row-major) as light `light`.
    ///
    /// # Panics
    /// If the image has the wrong length or `light >= n_lights`.
    pub fn set_image(&mut self, light: usize, rgb: &[f32]) {
        assert_eq!(
            rgb.len(),
            self.n_pixels() * 3,
            "image size does not match the stack"
        );
        assert!(light < self.n_lights, "light index out of range");
        let n = self.n_lights * 3;
        for (p, px) in rgb.chunks_exact(3).enumerate() {
            let o = p * n + light * 3;
            self.data[o..o + 3].copy_from_slice(px);
        }
    }

    /// Extracts the image of light `light` as interleaved RGB, row-major.
    pub fn image(&self, light: usize) -> Vec<f32> {
        let n = self.n_lights * 3;
        let mut out = Vec::with_capacity(self.n_pixels() * 3);
        for p in 0..self.n_pixels() {
            let o = p * n + light * 3;
            out.extend_from_slice(&self.data[o..o + 3]);
        }
        out
    }
}

impl Stack {
    /// Checks that a stack of `width x height` pixels and `n_lights` lights fits an estimator
    /// expecting `expected_lights` lights (a rig's `n_input`) and `mask` (the checks of
    /// [`estimate_stack`](crate::estimate_stack), for pipelines that read the stack piecewise).
    pub fn check_inputs(
        width: usize,
        height: usize,
        n_lights: usize,
        expected_lights: usize,
        mask: Option<&[bool]>,
    ) -> Result<()> {
        if n_lights != expected_lights {
            return Err(Error::LightCountMismatch {
                stack: n_lights,
                rig: expected_lights,
            });
        }
        if let Some(m) = mask {
            check_mask_size(m, width, height, "mask")?;
            if !m.iter().any(|&v| v) {
                return Err(Error::BadMask("mask is empty: no pixel inside".into()));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_and_get_image_round_trip() {
        let mut s = Stack::zeros(3, 2, 4);
        let img: Vec<f32> = (0..18).map(|v| v as f32).collect();
        s.set_image(2, &img);
        assert_eq!(s.image(2), img);
        assert_eq!(s.image(1), vec![0.0; 18]);
        assert_eq!(&s.pixel(1)[6..9], &[3.0, 4.0, 5.0]);
    }
}
