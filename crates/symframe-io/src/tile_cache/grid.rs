//! The tile grid: which pixels each tile holds, and in what order.

/// The tiles of a `width x height` image, `tile x tile` pixels each (the last column and row of
/// tiles cropped), numbered row-major over the tile grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileGrid {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Tile side in pixels.
    pub tile: usize,
}

/// A tile's pixel rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRect {
    /// Left column.
    pub x0: usize,
    /// Top row.
    pub y0: usize,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl TileGrid {
    /// The grid of `tile`-pixel tiles over a `width x height` image.
    ///
    /// # Panics
    /// If `tile` is zero.
    pub fn new(width: usize, height: usize, tile: usize) -> Self {
        assert!(tile > 0, "tile size must be positive");
        Self {
            width,
            height,
            tile,
        }
    }

    /// Tiles per row of tiles.
    pub fn tiles_x(&self) -> usize {
        self.width.div_ceil(self.tile)
    }

    /// Rows of tiles.
    pub fn tiles_y(&self) -> usize {
        self.height.div_ceil(self.tile)
    }

    /// Number of tiles.
    pub fn n_tiles(&self) -> usize {
        self.tiles_x() * self.tiles_y()
    }

    /// The pixels of tile `t`.
    pub fn rect(&self, t: usize) -> TileRect {
        let (tx, ty) = (t % self.tiles_x(), t / self.tiles_x());
        let (x0, y0) = (tx * self.tile, ty * self.tile);
        TileRect {
            x0,
            y0,
            width: self.tile.min(self.width - x0),
            height: self.tile.min(self.height - y0),
        }
    }

    /// Number of pixels of tile `t`.
    pub fn tile_pixels(&self, t: usize) -> usize {
        let r = self.rect(t);
        r.width * r.height
    }

    /// Position of tile `t`'s first pixel in tile order (all pixels of the tiles before it).
    pub fn first_pixel(&self, t: usize) -> usize {
        if t >= self.n_tiles() {
            return self.width * self.height;
        }
        let r = self.rect(t);
        // Every row of tiles above is full height; the tiles to the left share this row's height.
        r.y0 * self.width + r.x0 * r.height
    }

    /// Image pixel indices (`y * width + x`) of tile `t`'s pixels, in tile order (row-major
    /// inside the tile).
    pub fn pixels(&self, t: usize) -> impl Iterator<Item = usize> {
        let r = self.rect(t);
        let w = self.width;
        (r.y0..r.y0 + r.height).flat_map(move |y| (r.x0..r.x0 + r.width).map(move |x| y * w + x))
    }
}
