//! Reading one tile: its samples, gathered per pixel in any light order.

use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};

use super::codes::CodeTables;

/// A tile's samples as stored: float32 as they are, half floats with one factor per light
/// block (the inverse of the block's power-of-two scale), or the images' integer codes with
/// their decoding.
#[derive(Debug, Clone, Copy)]
pub(super) enum Samples<'a> {
    F32(&'a [f32]),
    F16(&'a [u16], &'a [f32]),
    U8(&'a [u8], &'a CodeTables),
    U16(&'a [u16], &'a CodeTables),
}

/// The samples of one tile: blocks of `light_block` lights (the last block shorter), each block
/// pixel-major (the tile's pixels in [`TileGrid::pixels`] order, each pixel's RGB under the
/// block's lights contiguous). With one block of float32 this is a [`symframe::Stack`] of the
/// tile.
///
/// [`TileGrid::pixels`]: super::TileGrid::pixels
#[derive(Debug, Clone, Copy)]
pub struct TileView<'a> {
    pub(super) data: Samples<'a>,
    pub(super) n_pixels: usize,
    pub(super) n_lights: usize,
    pub(super) light_block: usize,
}

impl<'a> TileView<'a> {
    /// Number of pixels of the tile.
    pub fn n_pixels(&self) -> usize {
        self.n_pixels
    }

    /// Where light `i`'s sample of pixel 0 is, and the step from one pixel to the next.
    pub(super) fn locate(&self, i: usize) -> (usize, usize) {
        let b = i / self.light_block;
        let len = self.light_block.min(self.n_lights - b * self.light_block);
        (
            (b * self.light_block * self.n_pixels + (i - b * self.light_block)) * 3,
            len * 3,
        )
    }

    /// A gatherer of the samples of `lights` (input indices), in that order, pixel by pixel.
    pub fn gatherer(&self, lights: &[usize]) -> TileGather<'a> {
        let in_order =
            lights.len() == self.n_lights && lights.iter().enumerate().all(|(k, &i)| k == i);
        // In the file's order (each block's run of a pixel's samples read front to back, the
        // output written out of order in a buffer that stays in cache: docs/performance.md,
        // "The tile cache's gather").
        let mut table: Vec<(usize, usize, usize, usize)> = lights
            .iter()
            .enumerate()
            .map(|(o, &i)| {
                let (base, step) = self.locate(i);
                (base, step, o * 3, i)
            })
            .collect();
        table.sort_unstable_by_key(|&(base, _, _, _)| base);
        TileGather {
            view: *self,
            table,
            in_order,
        }
    }

    /// Every light's RGB at pixel `k` of the tile, in input order (`n_lights * 3` values).
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        match self.data {
            Samples::F32(data) => {
                for (i, o) in out.chunks_exact_mut(3).enumerate() {
                    let (base, step) = self.locate(i);
                    o.copy_from_slice(&data[base + k * step..base + k * step + 3]);
                }
            }
            Samples::F16(halves, factors) => self.pixel_f16(halves, factors, k, out),
            Samples::U8(codes, tables) => self.pixel_codes(codes, tables, k, out),
            Samples::U16(codes, tables) => self.pixel_codes(codes, tables, k, out),
        }
    }

    /// [`Self::pixel`] from an integer cache's codes, made linear light by light.
    fn pixel_codes<T: Copy + Into<u32>>(
        &self,
        codes: &[T],
        tables: &CodeTables,
        k: usize,
        out: &mut [f32],
    ) {
        for (i, o) in out.chunks_exact_mut(3).enumerate() {
            let (base, step) = self.locate(i);
            tables.rgb(i, &codes[base + k * step..base + k * step + 3], o);
        }
    }

    /// [`Self::pixel`] from half floats: each block's run of the pixel's samples converted at
    /// once (F16C where the CPU has it) and rescaled, without a float copy of the whole tile:
    /// read so, a half-float cache is as fast as a float32 one, where the copy made it slower
    /// (docs/performance.md, "Half-float cache").
    fn pixel_f16(&self, halves: &[u16], factors: &[f32], k: usize, out: &mut [f32]) {
        let lb = self.light_block;
        for (b, &f) in factors.iter().enumerate() {
            let len = lb.min(self.n_lights - b * lb) * 3;
            let from = b * lb * self.n_pixels * 3 + k * len;
            let dst = &mut out[b * lb * 3..b * lb * 3 + len];
            halves[from..from + len]
                .reinterpret_cast::<half::f16>()
                .convert_to_f32_slice(dst);
            if f != 1.0 {
                for v in dst.iter_mut() {
                    *v *= f;
                }
            }
        }
    }
}

/// Gathers chosen lights' samples of a tile's pixels ([`TileView::gatherer`]).
#[derive(Debug, Clone)]
pub struct TileGather<'a> {
    view: TileView<'a>,
    /// Per chosen light: its samples' offset at pixel 0 and per pixel, where its values go
    /// in the output, and its input index; sorted by where they lie in the file.
    table: Vec<(usize, usize, usize, usize)>,
    /// Every light, in input order: half floats are then converted run by run.
    in_order: bool,
}

impl TileGather<'_> {
    /// The chosen lights' RGB at pixel `k` of the tile (`3` values per light, in `out`).
    #[inline]
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        match self.view.data {
            Samples::F32(data) => {
                for &(base, step, o, _) in &self.table {
                    let at = base + k * step;
                    out[o..o + 3].copy_from_slice(&data[at..at + 3]);
                }
            }
            Samples::U8(codes, tables) => self.pixel_codes(codes, tables, k, out),
            Samples::U16(codes, tables) => self.pixel_codes(codes, tables, k, out),
            Samples::F16(halves, factors) if self.in_order => {
                self.view.pixel_f16(halves, factors, k, out)
            }
            Samples::F16(halves, factors) => {
                let per_block = self.view.light_block * self.view.n_pixels * 3;
                for &(base, step, o, _) in &self.table {
                    let at = base + k * step;
                    let f = factors[base / per_block];
                    for (o, &h) in out[o..o + 3].iter_mut().zip(&halves[at..at + 3]) {
                        *o = half::f16::from_bits(h).to_f32() * f;
                    }
                }
            }
        }
    }

    /// [`Self::pixel`] from an integer cache's codes.
    #[inline]
    fn pixel_codes<T: Copy + Into<u32>>(
        &self,
        codes: &[T],
        tables: &CodeTables,
        k: usize,
        out: &mut [f32],
    ) {
        for &(base, step, o, i) in &self.table {
            let at = base + k * step;
            tables.rgb(i, &codes[at..at + 3], &mut out[o..o + 3]);
        }
    }
}
