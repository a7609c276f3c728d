//! Test helpers shared by the BRDF model tests (compiled only under `cfg(test)`).

use super::Brdf;
use glam::DVec3;
use std::f64::consts::PI;

/// Unit direction from spherical angles about z.
pub(crate) fn dir(theta: f64, phi: f64) -> DVec3 {
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// SplitMix64: a tiny deterministic generator for fixed-seed tests.
pub(crate) struct Rng(u64);

impl Rng {
    /// A generator with the given seed.
    pub(crate) fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// Uniform in `[0, 1)`.
    pub(crate) fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform on the open upper hemisphere (z > 0).
    pub(crate) fn hemisphere(&mut self) -> DVec3 {
        let z = 1.0 - self.next_f64(); // (0, 1]
        let phi = 2.0 * PI * self.next_f64();
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A fixed grid over the closed upper hemisphere, including the normal and near-grazing rows.
pub(crate) fn hemisphere_grid() -> Vec<DVec3> {
    let mut out = vec![DVec3::Z];
    let thetas_deg: [f64; 14] = [
        1.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0, 89.0, 89.99, 89.999_999,
    ];
    for &t in &thetas_deg {
        for j in 0..16 {
            out.push(dir(t.to_radians(), 2.0 * PI * j as f64 / 16.0 + 0.1));
        }
    }
    out
}

/// Pairs of directions: the full grid against itself plus random pairs.
pub(crate) fn direction_pairs(seed: u64, n_random: usize) -> Vec<(DVec3, DVec3)> {
    let grid = hemisphere_grid();
    let mut pairs = Vec::new();
    for (i, &a) in grid.iter().enumerate() {
        for &b in grid.iter().skip(i % 7).step_by(7) {
            pairs.push((a, b));
        }
    }
    let mut rng = Rng::new(seed);
    for _ in 0..n_random {
        pairs.push((rng.hemisphere(), rng.hemisphere()));
    }
    // Specular configurations (l = mirror of v about a halfway vector near the normal).
    for _ in 0..n_random / 4 {
        let v = rng.hemisphere();
        let t = 0.3 * rng.next_f64();
        let h = dir(t, 2.0 * PI * rng.next_f64());
        let l = 2.0 * v.dot(h) * h - v;
        if l.z > 0.0 {
            pairs.push((l, v));
        }
    }
    pairs
}

/// `|a - b| <= rel * max(|a|, |b|) + abs` per channel.
pub(crate) fn close(a: [f64; 3], b: [f64; 3], rel: f64, abs: f64) -> bool {
    (0..3).all(|c| (a[c] - b[c]).abs() <= rel * a[c].abs().max(b[c].abs()) + abs)
}

/// Directional albedo `∫ f(l, v) (n·l) dω_l` per channel, integrated over halfway vectors
/// (`dω_l = 4 (v·h) dω_h`) on a fixed midpoint grid with θ_h = (π/2) s², dense near the normal
/// where specular lobes peak.
pub(crate) fn directional_albedo(b: &dyn Brdf, v: DVec3, n: usize) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for i in 0..n {
        let s = (i as f64 + 0.5) / n as f64;
        let theta = 0.5 * PI * s * s;
        let dtheta = PI * s / n as f64;
        for j in 0..n {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
            let h = dir(theta, phi);
            let vh = v.dot(h);
            if vh <= 0.0 {
                continue;
            }
            let l = 2.0 * vh * h - v;
            if l.z <= 0.0 {
                continue;
            }
            let f = b.eval(l, v);
            let w = l.z * 4.0 * vh * theta.sin() * dtheta * (2.0 * PI / n as f64);
            for c in 0..3 {
                sum[c] += f[c] * w;
            }
        }
    }
    sum
}

/// The largest directional albedo over channels and the given view angles (degrees, taken at
/// two azimuths: along x and along y).
pub(crate) fn max_albedo(b: &dyn Brdf, view_deg: &[f64], n: usize) -> f64 {
    let mut m: f64 = 0.0;
    for &t in view_deg {
        for phi in [0.0, 0.5 * PI, 0.8] {
            let a = directional_albedo(b, dir(t.to_radians(), phi), n);
            m = m.max(a[0]).max(a[1]).max(a[2]);
        }
    }
    m
}

/// Asserts the directional albedo stays below `1 + margin` for views from 0 to `max_view_deg`.
pub(crate) fn assert_energy(b: &dyn Brdf, max_view_deg: f64, margin: f64) {
    let mut views = vec![0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0];
    views.retain(|&t| t <= max_view_deg);
    let m = max_albedo(b, &views, 400);
    assert!(
        m <= 1.0 + margin,
        "{}: directional albedo {m} exceeds 1 + {margin}",
        b.name()
    );
}

/// Asserts `f(l, v) = f(v, l)` to a relative tolerance.
pub(crate) fn assert_reciprocal(b: &dyn Brdf, rel: f64) {
    for (l, v) in direction_pairs(11, 3000) {
        let a = b.eval(l, v);
        let c = b.eval(v, l);
        assert!(
            close(a, c, rel, 1e-300),
            "{}: not reciprocal at l={l} v={v}: {a:?} vs {c:?}",
            b.name()
        );
    }
}

/// Asserts zero whenever either direction is at or below the horizon.
pub(crate) fn assert_zero_below_horizon(b: &dyn Brdf) {
    let mut rng = Rng::new(5);
    let mut below = vec![
        DVec3::X,
        DVec3::Y,
        -DVec3::Z,
        DVec3::new(1f64.cos(), 1f64.sin(), 0.0),
    ];
    for _ in 0..50 {
        let mut d = rng.hemisphere();
        d.z = -d.z;
        below.push(d);
    }
    for &u in &below {
        for &w in hemisphere_grid().iter().step_by(3) {
            assert_eq!(b.eval(u, w), [0.0; 3], "{}: l={u} v={w}", b.name());
            assert_eq!(b.eval(w, u), [0.0; 3], "{}: l={w} v={u}", b.name());
        }
    }
}

/// Asserts finite, non-negative values over all grid pairs and random pairs.
pub(crate) fn assert_nonneg_finite(b: &dyn Brdf) {
    let grid = hemisphere_grid();
    let mut pairs: Vec<(DVec3, DVec3)> = Vec::new();
    for &l in &grid {
        for &v in &grid {
            pairs.push((l, v));
        }
    }
    pairs.extend(direction_pairs(3, 2000));
    for (l, v) in pairs {
        let f = b.eval(l, v);
        assert!(
            f.iter().all(|x| x.is_finite() && *x >= 0.0),
            "{}: f({l}, {v}) = {f:?}",
            b.name()
        );
    }
}

/// Asserts invariance under reflection across the x-z plane (y → -y) and the y-z plane (x → -x) of
/// both directions, i.e. the `G_nt` / `G_nb` symmetries of docs/method.md ("The three symmetries").
pub(crate) fn assert_mirror_symmetric(b: &dyn Brdf, rel: f64) {
    let ry = DVec3::new(1.0, -1.0, 1.0);
    let rx = DVec3::new(-1.0, 1.0, 1.0);
    for (l, v) in direction_pairs(17, 3000) {
        let f = b.eval(l, v);
        for r in [rx, ry] {
            let g = b.eval(l * r, v * r);
            assert!(
                close(f, g, rel, 1e-300),
                "{}: mirror {r} breaks symmetry at l={l} v={v}: {f:?} vs {g:?}",
                b.name()
            );
        }
    }
}

/// Asserts invariance under a rotation of both directions about the normal.
pub(crate) fn assert_rotation_invariant(b: &dyn Brdf, rel: f64) {
    let mut rng = Rng::new(23);
    for (l, v) in direction_pairs(19, 2000) {
        let a = 2.0 * PI * rng.next_f64();
        let rot = glam::DQuat::from_rotation_z(a);
        let f = b.eval(l, v);
        let g = b.eval(rot * l, rot * v);
        assert!(
            close(f, g, rel, 1e-12),
            "{}: rotation by {a} changes f at l={l} v={v}: {f:?} vs {g:?}",
            b.name()
        );
    }
}

/// Asserts that the model is NOT invariant under rotation about the normal (anisotropic).
pub(crate) fn assert_not_rotation_invariant(b: &dyn Brdf) {
    let v = dir(0.3, 0.0);
    let h_x = dir(0.25, 0.0);
    let h_y = dir(0.25, 0.5 * PI);
    let v_y = dir(0.3, 0.5 * PI);
    let fx = b.eval(2.0 * v.dot(h_x) * h_x - v, v);
    let fy = b.eval(2.0 * v_y.dot(h_y) * h_y - v_y, v_y);
    assert!(
        !close(fx, fy, 1e-3, 0.0),
        "{}: expected anisotropy, got {fx:?} and {fy:?}",
        b.name()
    );
}

/// The in-plane axis (in halfway-vector space around the normal) along which the specular
/// highlight is wider, measured: compares the model at a halfway vector tilted along x with
/// one tilted along y, with the view at the normal.
pub(crate) fn measured_wide_axis(b: &dyn Brdf) -> super::TangentAxis {
    let v = DVec3::Z;
    let t = 0.2;
    let hx = dir(t, 0.0);
    let hy = dir(t, 0.5 * PI);
    let fx = b.eval(2.0 * hx.z * hx - v, v);
    let fy = b.eval(2.0 * hy.z * hy - v, v);
    let sx: f64 = fx.iter().sum();
    let sy: f64 = fy.iter().sum();
    if (sx - sy).abs() <= 1e-9 * sx.max(sy) {
        super::TangentAxis::None
    } else if sx > sy {
        super::TangentAxis::X
    } else {
        super::TangentAxis::Y
    }
}

/// One pixel's samples (RGB per light) of `brdf` in the frame `(n, t, b = n x t)` (x = t, view
/// `+z`) under `lights` of intensity `scale`: `scale f (n.l)`, 0 where the light is below.
pub(crate) fn render_pixel(
    brdf: &dyn Brdf,
    n: DVec3,
    t: DVec3,
    lights: &[DVec3],
    scale: f64,
) -> Vec<f32> {
    let b = n.cross(t);
    let local = |d: DVec3| DVec3::new(d.dot(t), d.dot(b), d.dot(n));
    let view = local(DVec3::Z);
    lights
        .iter()
        .flat_map(|&l| {
            let nl = n.dot(l).max(0.0);
            brdf.eval(local(l), view).map(|v| (scale * v * nl) as f32)
        })
        .collect()
}
