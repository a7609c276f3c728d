//! Does the normal map say the lights' axes were read in the wrong convention?
//!
//! A light file whose x or y axis is reversed (image rows run down, symframe's y runs up), or
//! whose x and y are swapped, gives normals that are the true ones under the same reflection or
//! rotation: every pixel is self-consistent, so no per-pixel residual shows it. The map as a
//! whole does. The normals of a surface are integrable, `d(dz/dcol)/drow = d(dz/drow)/dcol`,
//! and a reflection of their (x, y) breaks that wherever the surface curves in both directions;
//! at an object's outline the normals point outward, which a half-turn of (x, y) (both axes
//! reversed, integrable again: the surface turned inside out) breaks. [`AxesCheck`] reads the
//! map a row at a time (any size: the normals are averaged over blocks so that the map is about
//! [`AxesCheck::TARGET_BLOCKS`] blocks across, which also averages their noise away) and tells
//! which of the eight turns and reflections of (x, y) makes the map one surface facing out of its
//! outline ([`LightAxes`]). docs/method.md, "Checking the lights' convention", derives it.

/// What reading the lights as given, or with their (x, y) turned or reflected, makes of the
/// normal map: the transform `(x, y) -> (x', y')` under which the normals fit together as one
/// surface facing out of its outline. The same transform applied to each light direction gives
/// the lights that would have produced the truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LightAxes {
    /// The lights as given (or too little evidence to say otherwise).
    AsGiven,
    /// `(x, y) -> (-x, y)`: the x axis reversed.
    XReversed,
    /// `(x, y) -> (x, -y)`: the y axis reversed (rows counted down).
    YReversed,
    /// `(x, y) -> (-x, -y)`: both reversed (a half turn).
    BothReversed,
    /// `(x, y) -> (y, x)`: x and y swapped.
    Swapped,
    /// `(x, y) -> (-y, -x)`: swapped, both reversed.
    SwappedReversed,
    /// `(x, y) -> (-y, x)`: a quarter turn counter-clockwise.
    QuarterTurnCcw,
    /// `(x, y) -> (y, -x)`: a quarter turn clockwise.
    QuarterTurnCw,
    /// One axis reversed, x or y: the normals cannot tell which (no outline to read).
    OneReversed,
    /// Swapped and one axis reversed, or swapped: the outline does not tell which.
    SwappedOrTurned,
}

impl LightAxes {
    /// The transform in words, `(x, y, z) -> (...)`; `None` for [`LightAxes::AsGiven`].
    pub fn mapping(self) -> Option<&'static str> {
        Some(match self {
            LightAxes::AsGiven => return None,
            LightAxes::XReversed => "(x, y, z) -> (-x, y, z): the x axis looks reversed",
            LightAxes::YReversed => {
                "(x, y, z) -> (x, -y, z): the y axis looks reversed (symframe's y runs up the \
                 image)"
            }
            LightAxes::BothReversed => {
                "(x, y, z) -> (-x, -y, z): both x and y look reversed (the object came out \
                 inside out)"
            }
            LightAxes::Swapped => "(x, y, z) -> (y, x, z): x and y look swapped",
            LightAxes::SwappedReversed => {
                "(x, y, z) -> (-y, -x, z): x and y look swapped and reversed"
            }
            LightAxes::QuarterTurnCcw => {
                "(x, y, z) -> (-y, x, z): the lights look turned a quarter turn"
            }
            LightAxes::QuarterTurnCw => {
                "(x, y, z) -> (y, -x, z): the lights look turned a quarter turn"
            }
            LightAxes::OneReversed => {
                "(x, y, z) -> (-x, y, z) or (x, -y, z): one of x and y looks reversed"
            }
            LightAxes::SwappedOrTurned => {
                "(x, y, z) -> (y, x, z), (-y, -x, z) or a quarter turn: x and y look swapped"
            }
        })
    }
}

/// The four classes of (x, y) transforms integrability tells apart (a half turn keeps a field
/// integrable): as given, one axis reversed, swapped, a quarter turn. Each class's first member
/// and its half-turned partner.
const CLASSES: [(LightAxes, LightAxes); 4] = [
    (LightAxes::AsGiven, LightAxes::BothReversed),
    (LightAxes::XReversed, LightAxes::YReversed),
    (LightAxes::Swapped, LightAxes::SwappedReversed),
    (LightAxes::QuarterTurnCcw, LightAxes::QuarterTurnCw),
];

/// `(x, y)` under class `k`'s first member.
fn turn(k: usize, x: f64, y: f64) -> (f64, f64) {
    match k {
        0 => (x, y),
        1 => (-x, y),
        2 => (y, x),
        _ => (-y, x),
    }
}

/// One block of the averaged map: the sum of its normals and how many pixels had one.
#[derive(Clone, Copy, Default)]
struct Block {
    sum: [f64; 3],
    count: u32,
}

/// A block's mean normal, where at least half of its pixels had one.
fn mean_normal(b: &Block, pixels: u32) -> Option<[f64; 3]> {
    if b.count == 0 || 2 * b.count < pixels {
        return None;
    }
    let [x, y, z] = b.sum;
    let len = (x * x + y * y + z * z).sqrt();
    (len > 0.0).then(|| [x / len, y / len, z / len])
}

/// The streaming check: push the normal map's rows in order, then [`AxesCheck::verdict`].
pub struct AxesCheck {
    width: usize,
    block: usize,
    /// Block sums of the block row being filled, and how many image rows it holds.
    filling: Vec<Block>,
    rows_in: usize,
    /// The two block rows before the newest (mean normals), for cells and outlines.
    prev2: Option<Vec<Option<[f64; 3]>>>,
    prev: Option<Vec<Option<[f64; 3]>>>,
    /// Votes of curved cells for each class.
    votes: [u64; 4],
    /// Per class: the sum of `cos` between the outline's outward direction and the steep
    /// normals' (x, y) under the class's first member, and how many outline blocks.
    outline: [f64; 4],
    outline_blocks: u64,
}

impl AxesCheck {
    /// Blocks across the longer side of the map: finer maps are averaged down to this.
    pub const TARGET_BLOCKS: usize = 192;

    /// A cell's smallest curl counts as a vote when the next smallest is larger than this
    /// (slope change per block): below it the cell is flat in both directions and the classes
    /// differ only by noise. A slope of 0.01 is a normal turning about 0.6 degrees.
    const CURVED: f64 = 0.01;
    /// ... and at most this share of the next smallest: one class explains the cell.
    const CLEAR: f64 = 0.3;
    /// Votes needed before anything is said.
    const MIN_VOTES: u64 = 40;
    /// Outline blocks whose normals are steeper than this sine (45 degrees from the view) read
    /// the outline.
    const STEEP: f64 = std::f64::consts::FRAC_1_SQRT_2;
    /// Outline blocks needed, and the mean cosine beyond which the outline decides.
    const MIN_OUTLINE: u64 = 12;
    const OUTLINE_COS: f64 = 0.3;

    /// A check of a `width` x `height` normal map.
    pub fn new(width: usize, height: usize) -> Self {
        // Blocks are square and sized by the longer side.
        let block = width.max(height).div_ceil(Self::TARGET_BLOCKS).max(1);
        Self {
            width,
            block,
            filling: vec![Block::default(); width.div_ceil(block)],
            rows_in: 0,
            prev2: None,
            prev: None,
            votes: [0; 4],
            outline: [0.0; 4],
            outline_blocks: 0,
        }
    }

    /// The next row of the map: `width` unit normals, `(x, y, z)` each, NaN where none.
    pub fn push_row(&mut self, normals: &[f32]) {
        debug_assert_eq!(normals.len(), 3 * self.width);
        for (c, n) in normals.chunks_exact(3).enumerate() {
            if n.iter().all(|v| v.is_finite()) {
                let b = &mut self.filling[c / self.block];
                for (s, &v) in b.sum.iter_mut().zip(n) {
                    *s += v as f64;
                }
                b.count += 1;
            }
        }
        self.rows_in += 1;
        if self.rows_in == self.block {
            self.emit_block_row();
        }
    }

    /// The next rows of the map (`normals` a whole number of rows).
    pub fn push_rows(&mut self, normals: &[f32]) {
        for row in normals.chunks_exact(3 * self.width.max(1)) {
            self.push_row(row);
        }
    }

    fn emit_block_row(&mut self) {
        let rows = self.rows_in as u32;
        let row: Vec<Option<[f64; 3]>> = self
            .filling
            .iter()
            .enumerate()
            .map(|(c, b)| {
                let cols = (self.width - c * self.block).min(self.block) as u32;
                mean_normal(b, rows * cols)
            })
            .collect();
        self.filling.iter_mut().for_each(|b| *b = Block::default());
        self.rows_in = 0;
        if let Some(prev) = self.prev.take() {
            self.cells(&prev, &row);
            let up = self.prev2.take();
            self.outline_row(up.as_deref(), &prev, Some(&row));
            self.prev2 = Some(prev);
        }
        // The first block row's outline is read once the next arrives.
        self.prev = Some(row);
    }

    /// Votes of the cells between two block rows.
    fn cells(&mut self, up: &[Option<[f64; 3]>], down: &[Option<[f64; 3]>]) {
        // Slopes u = nx / nz, v = ny / nz; cells whose corners are steeper than 75 degrees are
        // left out (the slopes explode there).
        let slope = |n: &Option<[f64; 3]>| {
            n.filter(|n| n[2] > 0.25)
                .map(|n| (n[0] / n[2], n[1] / n[2]))
        };
        for c in 0..up.len().saturating_sub(1) {
            let (Some(a), Some(b), Some(d), Some(e)) = (
                slope(&up[c]),
                slope(&up[c + 1]),
                slope(&down[c]),
                slope(&down[c + 1]),
            ) else {
                continue;
            };
            // a = (r, c), b = (r, c+1), d = (r+1, c), e = (r+1, c+1).
            let u_r = 0.5 * ((d.0 + e.0) - (a.0 + b.0));
            let u_c = 0.5 * ((b.0 + e.0) - (a.0 + d.0));
            let v_r = 0.5 * ((d.1 + e.1) - (a.1 + b.1));
            let v_c = 0.5 * ((b.1 + e.1) - (a.1 + d.1));
            // The slopes the camera frame asks for are dz/dcol = -nx/nz and dz/drow = ny/nz
            // (crate::integrate); the curl d(dz/dcol)/drow - d(dz/drow)/dcol under each class.
            let curls = [
                (-u_r - v_c).abs(),
                (u_r - v_c).abs(),
                (-v_r - u_c).abs(),
                (v_r - u_c).abs(),
            ];
            let mut order = [0usize, 1, 2, 3];
            order.sort_by(|&i, &j| curls[i].total_cmp(&curls[j]));
            let (best, next) = (curls[order[0]], curls[order[1]]);
            if next > Self::CURVED && best < Self::CLEAR * next {
                self.votes[order[0]] += 1;
            }
        }
    }

    /// The outline blocks of block row `mid`: a block with a normal beside one without (inside
    /// the map) has its outward direction toward the empty neighbours.
    fn outline_row(
        &mut self,
        up: Option<&[Option<[f64; 3]>]>,
        mid: &[Option<[f64; 3]>],
        down: Option<&[Option<[f64; 3]>]>,
    ) {
        for c in 0..mid.len() {
            let Some(n) = mid[c] else { continue };
            let len = (n[0] * n[0] + n[1] * n[1]).sqrt();
            if len < Self::STEEP {
                continue;
            }
            // Outward in the camera frame: +x along columns, +y up the rows.
            let mut out = (0.0_f64, 0.0_f64);
            if c > 0 && mid[c - 1].is_none() {
                out.0 -= 1.0;
            }
            if c + 1 < mid.len() && mid[c + 1].is_none() {
                out.0 += 1.0;
            }
            if up.is_some_and(|u| u[c].is_none()) {
                out.1 += 1.0;
            }
            if down.is_some_and(|d| d[c].is_none()) {
                out.1 -= 1.0;
            }
            let olen = (out.0 * out.0 + out.1 * out.1).sqrt();
            if olen == 0.0 {
                continue;
            }
            self.outline_blocks += 1;
            for k in 0..4 {
                let (x, y) = turn(k, n[0] / len, n[1] / len);
                self.outline[k] += (x * out.0 + y * out.1) / olen;
            }
        }
    }

    /// What the map says of the lights' axes, once every row is pushed.
    pub fn verdict(mut self) -> LightAxes {
        if self.rows_in > 0 {
            self.emit_block_row();
        }
        if let Some(last) = self.prev.take() {
            let up = self.prev2.take();
            self.outline_row(up.as_deref(), &last, None);
        }
        let total: u64 = self.votes.iter().sum();
        let outline = |k: usize| {
            (self.outline_blocks >= Self::MIN_OUTLINE)
                .then(|| self.outline[k] / self.outline_blocks as f64)
                .filter(|m| m.abs() > Self::OUTLINE_COS)
        };
        // The class the curved cells choose: the most votes, half as many again as the next
        // and more than it by five standard deviations of a sign test (cells that only noise
        // curves vote for any class alike).
        let mut order = [0usize, 1, 2, 3];
        order.sort_by(|&i, &j| self.votes[j].cmp(&self.votes[i]));
        let (vb, vn) = (self.votes[order[0]] as f64, self.votes[order[1]] as f64);
        let class = (order[0] != 0
            && total >= Self::MIN_VOTES
            && 2.0 * vb >= 3.0 * vn
            && vb - vn >= 5.0 * (vb + vn).sqrt())
        .then_some(order[0]);
        match class {
            Some(k) => match outline(k) {
                Some(m) if m > 0.0 => CLASSES[k].0,
                Some(_) => CLASSES[k].1,
                None if k == 1 => LightAxes::OneReversed,
                None => LightAxes::SwappedOrTurned,
            },
            // As given or half turned: only the outline tells.
            None => match outline(0) {
                Some(m) if m < 0.0 => LightAxes::BothReversed,
                _ => LightAxes::AsGiven,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit normals of `z(x, y)` on a `size` x `size` map (camera frame, y up), NaN where
    /// `z` is `None`; then each normal's (x, y) transformed by `t`.
    fn map(
        size: usize,
        z: impl Fn(f64, f64) -> Option<(f64, f64)>,
        t: impl Fn(f64, f64) -> (f64, f64),
        noise_deg: f64,
    ) -> Vec<f32> {
        let mut out = Vec::with_capacity(3 * size * size);
        let mut seed = 0x9e3779b97f4a7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for row in 0..size {
            for col in 0..size {
                let x = (col as f64 + 0.5) / size as f64 * 2.0 - 1.0;
                let y = 1.0 - (row as f64 + 0.5) / size as f64 * 2.0;
                match z(x, y) {
                    Some((zx, zy)) => {
                        // dz/dx and dz/dy (a ratio: the same in map and pixel units).
                        let (nx, ny, nz) = (-zx, -zy, 1.0_f64);
                        let (nx, ny) = t(nx, ny);
                        let k = noise_deg.to_radians();
                        let (nx, ny, nz) = (
                            nx / nz.hypot(nx.hypot(ny)) + k * rnd(),
                            ny / nz.hypot(nx.hypot(ny)) + k * rnd(),
                            nz / nz.hypot(nx.hypot(ny)),
                        );
                        let l = (nx * nx + ny * ny + nz * nz).sqrt();
                        out.extend([(nx / l) as f32, (ny / l) as f32, (nz / l) as f32]);
                    }
                    None => out.extend([f32::NAN; 3]),
                }
            }
        }
        out
    }

    /// A sphere filling most of the map: gradient of `sqrt(r^2 - x^2 - y^2)` (in map units
    /// the radius is 0.9).
    fn sphere(x: f64, y: f64) -> Option<(f64, f64)> {
        let z2 = 0.81 - x * x - y * y;
        (z2 > 0.0).then(|| (-x / z2.sqrt(), -y / z2.sqrt()))
    }

    /// A bumpy height field over the whole map (no outline): Gaussian bumps and a saddle.
    fn bumps(x: f64, y: f64) -> Option<(f64, f64)> {
        let g = |cx: f64, cy: f64, s: f64, a: f64| {
            let e = a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * s * s)).exp();
            (-e * (x - cx) / (s * s), -e * (y - cy) / (s * s))
        };
        let (a, b, c) = (
            g(-0.3, 0.2, 0.25, 0.3),
            g(0.4, -0.3, 0.2, -0.2),
            g(0.1, 0.5, 0.15, 0.1),
        );
        Some((a.0 + b.0 + c.0 + 0.3 * y, a.1 + b.1 + c.1 + 0.3 * x))
    }

    fn check(m: &[f32], size: usize) -> LightAxes {
        let mut c = AxesCheck::new(size, size);
        for band in m.chunks((3 * size * 7).max(1)) {
            c.push_rows(band);
        }
        c.verdict()
    }

    #[test]
    fn each_turn_and_reflection_of_a_spheres_lights_is_named() {
        type Turn = fn(f64, f64) -> (f64, f64);
        let cases: [(LightAxes, Turn); 8] = [
            (LightAxes::AsGiven, |x, y| (x, y)),
            // The estimated normals are the truth under the inverse of what was done to the
            // lights; the verdict names the transform that maps them back.
            (LightAxes::XReversed, |x, y| (-x, y)),
            (LightAxes::YReversed, |x, y| (x, -y)),
            (LightAxes::BothReversed, |x, y| (-x, -y)),
            (LightAxes::Swapped, |x, y| (y, x)),
            (LightAxes::SwappedReversed, |x, y| (-y, -x)),
            (LightAxes::QuarterTurnCcw, |x, y| (y, -x)),
            (LightAxes::QuarterTurnCw, |x, y| (-y, x)),
        ];
        for (size, noise) in [(24, 2.0), (48, 0.5), (96, 5.0), (700, 2.0)] {
            for (want, t) in cases {
                let m = map(size, sphere, t, noise);
                assert_eq!(check(&m, size), want, "size {size}, noise {noise} degrees");
            }
        }
    }

    #[test]
    fn a_surface_without_outline_tells_the_class_but_not_its_member() {
        let size = 300;
        assert_eq!(
            check(&map(size, bumps, |x, y| (x, y), 0.5), size),
            LightAxes::AsGiven
        );
        assert_eq!(
            check(&map(size, bumps, |x, y| (-x, -y), 0.5), size),
            LightAxes::AsGiven
        );
        assert_eq!(
            check(&map(size, bumps, |x, y| (-x, y), 0.5), size),
            LightAxes::OneReversed
        );
        assert_eq!(
            check(&map(size, bumps, |x, y| (y, x), 0.5), size),
            LightAxes::SwappedOrTurned
        );
    }

    #[test]
    fn a_plane_and_an_empty_map_say_nothing() {
        let size = 64;
        let plane = map(size, |_, _| Some((0.3, -0.2)), |x, y| (-x, y), 2.0);
        assert_eq!(check(&plane, size), LightAxes::AsGiven);
        let empty = vec![f32::NAN; 3 * size * size];
        assert_eq!(check(&empty, size), LightAxes::AsGiven);
        assert_eq!(check(&[], 0), LightAxes::AsGiven);
    }

    #[test]
    fn noise_alone_votes_for_nothing() {
        // A tilted plane under up to 10 degrees of noise a pixel, read in every convention:
        // every vote is the noise's, spread over the classes, and none may win.
        for (size, noise) in [(48, 10.0), (200, 3.0), (600, 10.0)] {
            for t in [
                |x, y| (x, y),
                |x: f64, y: f64| (-x, y),
                |x: f64, y: f64| (y, x),
            ] {
                let m = map(size, |_, _| Some((0.4, 0.1)), t, noise);
                assert_eq!(
                    check(&m, size),
                    LightAxes::AsGiven,
                    "size {size}, noise {noise}"
                );
            }
        }
    }
}
