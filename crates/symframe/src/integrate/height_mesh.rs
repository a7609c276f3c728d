//! The mesh of a height map: a vertex at every pixel with a height and a normal, triangles on
//! the pixel grid, none across a depth discontinuity.

use super::DepthMap;

/// A triangle mesh on the pixel grid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions `(x, y, z)`: x = column + 0.5, y = height - row - 0.5 (up), z = the
    /// height; pixel units (a perspective mesh, [`crate::Pinhole::mesh`]: the
    /// camera-frame points the pixels see, in the depths' unit).
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals (the normal map's).
    pub normals: Vec<[f32; 3]>,
    /// Pixel `(col, row)` of each vertex.
    pub pixels: Vec<[u32; 2]>,
    /// Triangles, counter-clockwise seen from the camera (+z).
    pub triangles: Vec<[u32; 3]>,
    /// Triangles left out because an edge crossed a depth discontinuity.
    pub dropped: usize,
}

impl DepthMap {
    /// Builds a mesh with a vertex at the centre of every pixel with a height and a normal, two
    /// triangles per 2 x 2 block (one where only three of its pixels are valid), leaving out any
    /// triangle with an edge whose height difference departs from what the normals predict by more
    /// than `max_jump * (1 + |predicted|)` pixels (a depth discontinuity).
    pub fn mesh(&self, normals: &[f32], max_jump: f64) -> Mesh {
        let (w, h) = (self.width, self.height);
        let mut index = vec![u32::MAX; w * h];
        let mut m = Mesh::default();
        let slope = |i: usize| -> Option<(f64, f64)> {
            let v = &normals[3 * i..3 * i + 3];
            if !v.iter().all(|x| x.is_finite()) {
                return None;
            }
            let nz = (v[2] as f64).max(0.05);
            Some((-(v[0] as f64) / nz, v[1] as f64 / nz))
        };
        for i in 0..w * h {
            let v = &normals[3 * i..3 * i + 3];
            if self.depth[i].is_finite() && v.iter().all(|x| x.is_finite()) {
                index[i] = m.positions.len() as u32;
                let (r, q) = (i / w, i % w);
                m.positions
                    .push([q as f32 + 0.5, (h - r) as f32 - 0.5, self.depth[i]]);
                let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-30);
                m.normals.push([v[0] / len, v[1] / len, v[2] / len]);
                m.pixels.push([q as u32, r as u32]);
            }
        }
        // An edge a -> b is continuous when its height step agrees with the mean slope.
        let height = |i: usize| self.depth[i] as f64;
        let continuous = |a, b| continuous_edge(w, a, b, &slope, &height, 1.0, max_jump);
        triangulate_grid(w, h, &index, continuous, &mut m);
        m
    }
}

/// Whether the edge from pixel `a` to pixel `b` of a `w`-wide grid is continuous: the step
/// `scale * (value(b) - value(a))` departs from the one the ends' mean slopes predict (`slope`:
/// per column, per row; times `scale`) by at most `max_jump * (1 + |predicted|)`. Not where an
/// end has no slope.
pub(crate) fn continuous_edge(
    w: usize,
    a: usize,
    b: usize,
    slope: &impl Fn(usize) -> Option<(f64, f64)>,
    value: &impl Fn(usize) -> f64,
    scale: f64,
    max_jump: f64,
) -> bool {
    let (Some((pa, qa)), Some((pb, qb))) = (slope(a), slope(b)) else {
        return false;
    };
    let dq = (b % w) as f64 - (a % w) as f64;
    let dr = (b / w) as f64 - (a / w) as f64;
    let predicted = scale * (0.5 * (pa + pb) * dq + 0.5 * (qa + qb) * dr);
    let step = scale * (value(b) - value(a));
    (step - predicted).abs() <= max_jump * (1.0 + predicted.abs())
}

/// The triangles of a mesh on a `w` x `h` pixel grid whose vertices `index` numbers (`u32::MAX`
/// where a pixel has none): two per 2 x 2 block, one where only three of its pixels have a
/// vertex, counter-clockwise seen from the camera; a triangle with an edge that is not
/// `continuous` (a depth discontinuity) is left out and counted in `m.dropped`.
pub(crate) fn triangulate_grid(
    w: usize,
    h: usize,
    index: &[u32],
    continuous: impl Fn(usize, usize) -> bool,
    m: &mut Mesh,
) {
    let ok = |i: usize| index[i] != u32::MAX;
    for r in 0..h.saturating_sub(1) {
        for q in 0..w.saturating_sub(1) {
            let a = r * w + q; // top left
            let b = a + 1; // top right
            let c = a + w; // bottom left
            let d = c + 1; // bottom right
            let tris: &[[usize; 3]] = match (ok(a), ok(b), ok(c), ok(d)) {
                (true, true, true, true) => &[[a, c, b], [b, c, d]],
                (true, true, true, false) => &[[a, c, b]],
                (false, true, true, true) => &[[b, c, d]],
                (true, false, true, true) => &[[a, c, d]],
                (true, true, false, true) => &[[a, d, b]],
                _ => &[],
            };
            for t in tris {
                if continuous(t[0], t[1]) && continuous(t[1], t[2]) && continuous(t[2], t[0]) {
                    m.triangles.push(t.map(|i| index[i]));
                } else {
                    m.dropped += 1;
                }
            }
        }
    }
}
