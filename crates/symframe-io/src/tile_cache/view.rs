//! Reading one tile: its samples, gathered per pixel in any light order.

/// The samples of one tile: blocks of `light_block` lights (the last block shorter), each block
/// pixel-major (the tile's pixels in [`TileGrid::pixels`] order, each pixel's RGB under the
/// block's lights contiguous). With one block this is a [`symframe::Stack`] of the tile.
#[derive(Debug, Clone, Copy)]
pub struct TileView<'a> {
    pub(super) data: &'a [f32],
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
        TileGather {
            data: self.data,
            table: lights.iter().map(|&i| self.locate(i)).collect(),
        }
    }

    /// Every light's RGB at pixel `k` of the tile, in input order (`n_lights * 3` values).
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        for (i, o) in out.chunks_exact_mut(3).enumerate() {
            let (base, step) = self.locate(i);
            o.copy_from_slice(&self.data[base + k * step..base + k * step + 3]);
        }
    }
}

/// Gathers chosen lights' samples of a tile's pixels ([`TileView::gatherer`]).
#[derive(Debug, Clone)]
pub struct TileGather<'a> {
    pub(super) data: &'a [f32],
    pub(super) table: Vec<(usize, usize)>,
}

impl TileGather<'_> {
    /// The chosen lights' RGB at pixel `k` of the tile (`3` values per light, in `out`).
    #[inline]
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        for (&(base, step), o) in self.table.iter().zip(out.chunks_exact_mut(3)) {
            let at = base + k * step;
            o.copy_from_slice(&self.data[at..at + 3]);
        }
    }
}
