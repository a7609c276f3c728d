//! The rig tiles of a near-light round: squares of pixels that share one rig, halved where the
//! rig's geometry is too far from its pixels' own.
//!
//! A tile's rig holds the lights as seen from the tile's mean surface point `q`; a pixel of the
//! tile at `p` sees them from `p`. What the estimator reads of the lights is their halfway
//! vectors `h_i = normalize(l_i + v)` (the symmetry it measures is about the normal in halfway
//! space), so the error a tile leaves its pixel is bounded by how far the pixel's halfway
//! vectors are from the tile's: [`halfway_change_deg`], the largest angle over the lights. A
//! tile is kept when that bound, at its pixel farthest from `q`, is within the tiling's bound;
//! otherwise it is split in four, down to single pixels (exact).

use glam::DVec3;
use rayon::prelude::*;

use crate::near::{Pinhole, PointLight};

/// No rig (outside the mask, or no finite depth).
pub(crate) const NO_TILE: u32 = u32::MAX;

/// One tile: a square of pixels and the surface point its rig is built for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Tile {
    /// Top-left pixel's column and row, width and height, pixels (a square of the tiling's
    /// side, halved, clipped by the image's edges).
    pub x0: usize,
    pub y0: usize,
    pub w: usize,
    pub h: usize,
    /// The mean surface point of the tile's pixels with a depth.
    pub point: DVec3,
    /// The halfway bound at the tile's pixel farthest from `point`, degrees.
    pub bound_deg: f64,
    /// The tile's pixel nearest its pixels' centroid (the one a coarse round estimates).
    pub centre: usize,
}

/// The tiles of an image and each pixel's tile.
#[derive(Debug, Clone)]
pub(crate) struct Tiling {
    pub tiles: Vec<Tile>,
    /// Per pixel, the index of its tile ([`NO_TILE`]: none).
    pub tile_of: Vec<u32>,
}

/// The largest angle (degrees) between the halfway vector of a light seen from `p` and the same
/// light's seen from `q`, over `lights` (each point's view toward the camera's centre).
pub(crate) fn halfway_change_deg(lights: &[PointLight], p: DVec3, q: DVec3) -> f64 {
    let (vp, vq) = ((-p).normalize_or_zero(), (-q).normalize_or_zero());
    let mut worst = 0.0f64;
    for light in lights {
        let a = ((light.position - p).normalize_or_zero() + vp).normalize_or_zero();
        let b = ((light.position - q).normalize_or_zero() + vq).normalize_or_zero();
        worst = worst.max(a.cross(b).length().atan2(a.dot(b)));
    }
    worst.to_degrees()
}

/// Tiles of at most `max_side` pixels over the pixels inside `mask` with a finite positive
/// `depth`: each square of `max_side` is halved while its halfway bound exceeds `bound_deg`
/// (`None`: never, fixed tiles).
#[allow(clippy::too_many_arguments)]
pub(crate) fn tile_image(
    camera: &Pinhole,
    lights: &[PointLight],
    width: usize,
    height: usize,
    depth: &[f32],
    mask: Option<&[bool]>,
    max_side: usize,
    bound_deg: Option<f64>,
) -> Tiling {
    let side = max_side.max(1);
    let (roots_x, roots_y) = (width.div_ceil(side), height.div_ceil(side));
    let usable = |p: usize| {
        let d = depth[p];
        mask.is_none_or(|m| m[p]) && d.is_finite() && d > 0.0
    };
    let tiles: Vec<Tile> = (0..roots_x * roots_y)
        .into_par_iter()
        .flat_map_iter(|r| {
            let mut out = Vec::new();
            let (x0, y0) = ((r % roots_x) * side, (r / roots_x) * side);
            let mut stack = vec![(x0, y0, side.min(width - x0), side.min(height - y0))];
            let mut points = Vec::new();
            while let Some((x0, y0, w, h)) = stack.pop() {
                points.clear();
                for row in y0..y0 + h {
                    for col in x0..x0 + w {
                        let p = row * width + col;
                        if usable(p) {
                            points.push((p, camera.point(col as f64, row as f64, depth[p] as f64)));
                        }
                    }
                }
                if points.is_empty() {
                    continue;
                }
                let n = points.len() as f64;
                let point = points.iter().map(|(_, q)| *q).sum::<DVec3>() / n;
                let far = points
                    .iter()
                    .map(|(_, q)| *q)
                    .max_by(|a, b| {
                        a.distance_squared(point)
                            .total_cmp(&b.distance_squared(point))
                    })
                    .unwrap_or(point);
                let bound = halfway_change_deg(lights, far, point);
                if w * h > 1 && bound_deg.is_some_and(|b| bound > b) {
                    let (wa, ha) = (w.div_ceil(2), h.div_ceil(2));
                    for (dx, sw) in [(0, wa), (wa, w - wa)] {
                        for (dy, sh) in [(0, ha), (ha, h - ha)] {
                            if sw > 0 && sh > 0 {
                                stack.push((x0 + dx, y0 + dy, sw, sh));
                            }
                        }
                    }
                    continue;
                }
                let (mc, mr) = points.iter().fold((0.0, 0.0), |(c, r), &(p, _)| {
                    (c + (p % width) as f64, r + (p / width) as f64)
                });
                let (mc, mr) = (mc / n, mr / n);
                let centre = points
                    .iter()
                    .map(|&(p, _)| p)
                    .min_by(|&a, &b| {
                        let d = |p: usize| {
                            ((p % width) as f64 - mc).powi(2) + ((p / width) as f64 - mr).powi(2)
                        };
                        d(a).total_cmp(&d(b)).then(a.cmp(&b))
                    })
                    .unwrap_or(points[0].0);
                out.push(Tile {
                    x0,
                    y0,
                    w,
                    h,
                    point,
                    bound_deg: bound,
                    centre,
                });
            }
            out
        })
        .collect();
    let mut tile_of = vec![NO_TILE; width * height];
    for (t, tile) in tiles.iter().enumerate() {
        for row in tile.y0..tile.y0 + tile.h {
            for col in tile.x0..tile.x0 + tile.w {
                let p = row * width + col;
                if usable(p) {
                    tile_of[p] = t as u32;
                }
            }
        }
    }
    Tiling { tiles, tile_of }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_split_where_the_halfway_bound_is_exceeded() {
        let camera = Pinhole::centred(64, 64, 30.0);
        let lights: Vec<PointLight> = (0..40)
            .map(|i| {
                let a = i as f64 * 0.7;
                PointLight::isotropic(DVec3::new(3.0 * a.cos(), 3.0 * a.sin(), -8.0 + 2.0))
            })
            .collect();
        // A plane facing the camera on the left half, steeply tilted on the right.
        let depth: Vec<f32> = (0..64 * 64)
            .map(|p| {
                let col = (p % 64) as f32;
                if col < 32.0 {
                    8.0
                } else {
                    8.0 + 0.3 * (col - 32.0)
                }
            })
            .collect();
        let fixed = tile_image(&camera, &lights, 64, 64, &depth, None, 8, None);
        assert_eq!(fixed.tiles.len(), 64);
        assert!(fixed.tiles.iter().all(|t| t.w == 8 && t.h == 8));
        let loosest = fixed.tiles.iter().map(|t| t.bound_deg).fold(0.0, f64::max);
        let bound = 0.5 * loosest;
        let adaptive = tile_image(&camera, &lights, 64, 64, &depth, None, 8, Some(bound));
        assert!(adaptive.tiles.len() > fixed.tiles.len());
        assert!(adaptive
            .tiles
            .iter()
            .all(|t| t.bound_deg <= bound || t.w * t.h == 1));
        // Every pixel has its tile, and lies in it.
        for (p, &t) in adaptive.tile_of.iter().enumerate() {
            let tile = adaptive.tiles[t as usize];
            let (col, row) = (p % 64, p / 64);
            assert!(col >= tile.x0 && col < tile.x0 + tile.w);
            assert!(row >= tile.y0 && row < tile.y0 + tile.h);
        }
        // The tilted half, where depths change fastest, is split the finer.
        let mean_side = |left: bool| {
            let sel: Vec<usize> = adaptive
                .tiles
                .iter()
                .filter(|t| (t.x0 < 32) == left)
                .map(|t| t.w)
                .collect();
            sel.iter().sum::<usize>() as f64 / sel.len() as f64
        };
        assert!(mean_side(false) < mean_side(true));
        // A pixel's own point gives no change; a bound of a single pixel is zero.
        let p = camera.point(3.0, 4.0, 8.0);
        assert_eq!(halfway_change_deg(&lights, p, p), 0.0);
    }
}
