//! MERL measured isotropic BRDF (`.binary` files of the MERL BRDF database).
//!
//! Parameters: the table itself, `3 × 90 × 90 × 180` stored values.
//!
//! File layout (Matusik, Pfister, Brand, McMillan, "A Data-Driven Reflectance Model",
//! SIGGRAPH 2003; reference reader `BRDFRead.cpp`): three little-endian `i32` dimensions
//! `(90, 90, 180)` (`θ_h`, `θ_d`, `φ_d` bins), then `3 × 1,458,000` little-endian `f64`,
//! channel-major (all R, then all G, then all B).
//!
//! Lookup, in Rusinkiewicz (1998) half/difference coordinates: `h = normalize(l + v)`,
//! `θ_h = acos(h_z)`, `φ_h = atan2(h_y, h_x)`; the difference vector is `l` rotated by `-φ_h`
//! about z, then by `-θ_h` about y; `θ_d`, `φ_d` are its spherical angles. Bin indices (as in
//! `BRDFRead.cpp`, nearest-lower bin, clamped to the table):
//!
//! ```text
//! i_h = floor(sqrt(θ_h / (π/2) · 8100))        non-linear, dense near the specular peak
//! i_d = floor(θ_d / (π/2) · 90)
//! i_p = floor(φ_d' / π · 180),  φ_d' = φ_d + π if φ_d < 0   (reciprocity folds φ_d mod π)
//! index = i_p + 180 i_d + 180 · 90 i_h
//! f_c = stored[c · 1,458,000 + index] · scale_c,  scale = (1, 1.15, 1.66) / 1500
//! ```
//!
//! A negative stored value means "no data" and evaluates to 0, as do directions below the
//! horizon. Optional trilinear interpolation ([`Merl::trilinear`], off by default so the
//! reference behaviour is kept) blends the 8 surrounding bin centres in index space
//! (`sqrt`-spaced θ_h, linear θ_d, φ_d periodic with period π by reciprocity), clamping at the
//! θ ends and ignoring "no data" corners (renormalising the weights). The table is isotropic (independent of `φ_h`): its tangent axis is `None`.
//! `Merl::from_brdf` (within the crate) tabulates an analytic model at bin centres (`θ_h = (π/2)((i_h+½)/90)²`,
//! `θ_d = (i_d+½)·(π/2)/90`, `φ_d = (i_p+½)·π/180`, `φ_h = 0`), storing `-1` where the light
//! or view would be below the horizon.

use super::{Brdf, TangentAxis};
use glam::DVec3;
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Read;
#[cfg(test)]
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Number of `θ_h` bins.
pub(crate) const RES_THETA_H: usize = 90;
/// Number of `θ_d` bins.
pub(crate) const RES_THETA_D: usize = 90;
/// Number of `φ_d` bins over `[0, π)`.
pub(crate) const RES_PHI_D: usize = 180;
/// Values per channel: `90 · 90 · 180 = 1,458,000`.
pub(crate) const CHANNEL_LEN: usize = RES_THETA_H * RES_THETA_D * RES_PHI_D;
/// Per-channel factors from stored values to BRDF values (1/sr).
pub(crate) const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];
/// Size of a valid file in bytes: 12-byte header plus `3 · 1,458,000` doubles.
pub(crate) const FILE_LEN: u64 = 12 + 8 * 3 * CHANNEL_LEN as u64;

/// Errors reading or writing a MERL `.binary` file; each names the file.
#[derive(Debug, thiserror::Error)]
pub(crate) enum MerlError {
    /// The file could not be opened, read or written.
    #[error("MERL BRDF {}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The header's dimensions are not `(90, 90, 180)`.
    #[error(
        "MERL BRDF {}: header dimensions {dims:?}, expected [90, 90, 180] (not a MERL isotropic BRDF file?)",
        .path.display()
    )]
    WrongDims {
        /// The file.
        path: PathBuf,
        /// The three dimensions found in the header.
        dims: [i32; 3],
    },
    /// The file is shorter (truncated) or longer than the header says.
    #[error(
        "MERL BRDF {}: {actual} bytes, expected {expected} (12-byte header + 3 x 1458000 doubles){}",
        .path.display(),
        if *.actual < *.expected { "; file is truncated" } else { "; trailing data" }
    )]
    WrongSize {
        /// The file.
        path: PathBuf,
        /// Bytes expected.
        expected: u64,
        /// Bytes found.
        actual: u64,
    },
}

/// A MERL isotropic measured BRDF table.
#[derive(Clone)]
pub(crate) struct Merl {
    /// Stored values as in the file (before [`SCALE`]), channel-major, `3 · CHANNEL_LEN` long.
    pub(crate) data: Vec<f64>,
    /// The file the table was read from, if any (used by [`Brdf::name`]).
    pub(crate) source: Option<PathBuf>,
    /// Interpolate trilinearly between bin centres instead of the reference nearest-lower-bin
    /// lookup of `BRDFRead.cpp`.
    pub(crate) trilinear: bool,
}

impl std::fmt::Debug for Merl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The table has 4.4 million entries: summarise instead of printing it.
        let missing = self.data.iter().filter(|&&x| x < 0.0).count();
        f.debug_struct("Merl")
            .field("source", &self.source)
            .field("trilinear", &self.trilinear)
            .field("len", &self.data.len())
            .field("no_data_entries", &missing)
            .finish()
    }
}

/// Rusinkiewicz half/difference angles `(θ_h, φ_h, θ_d, φ_d)` of a light/view pair, computed
/// as in `BRDFRead.cpp` (`l` plays the role of the "in" direction). `l + v` must be non-zero.
pub(crate) fn half_diff_angles(l: DVec3, v: DVec3) -> (f64, f64, f64, f64) {
    let h = (l + v).normalize();
    let theta_h = h.z.clamp(-1.0, 1.0).acos();
    let phi_h = h.y.atan2(h.x);
    // Rotate l by -φ_h about z ...
    let (s, c) = (-phi_h).sin_cos();
    let t = DVec3::new(l.x * c - l.y * s, l.x * s + l.y * c, l.z);
    // ... then by -θ_h about y (right-handed: x' = x cos b + z sin b, z' = z cos b - x sin b).
    let (s, c) = (-theta_h).sin_cos();
    let d = DVec3::new(t.x * c + t.z * s, t.y, t.z * c - t.x * s);
    let theta_d = d.z.clamp(-1.0, 1.0).acos();
    let phi_d = d.y.atan2(d.x);
    (theta_h, phi_h, theta_d, phi_d)
}

/// The light and view directions with the given half/difference angles (the inverse of
/// [`half_diff_angles`]).
#[cfg(test)]
pub(crate) fn from_half_diff(theta_h: f64, phi_h: f64, theta_d: f64, phi_d: f64) -> (DVec3, DVec3) {
    let (sh, ch) = theta_h.sin_cos();
    let (sp, cp) = phi_h.sin_cos();
    let h = DVec3::new(sh * cp, sh * sp, ch);
    let (sd, cd) = theta_d.sin_cos();
    let d = DVec3::new(sd * phi_d.cos(), sd * phi_d.sin(), cd);
    // Rotate by θ_h about y, then φ_h about z.
    let t = DVec3::new(d.x * ch + d.z * sh, d.y, d.z * ch - d.x * sh);
    let l = DVec3::new(t.x * cp - t.y * sp, t.x * sp + t.y * cp, t.z);
    let v = 2.0 * l.dot(h) * h - l;
    (l, v)
}

/// `θ_h` bin, as `theta_half_index` in `BRDFRead.cpp`.
fn theta_h_index(theta_h: f64) -> usize {
    if theta_h <= 0.0 {
        return 0;
    }
    let x = (theta_h / FRAC_PI_2 * (RES_THETA_H * RES_THETA_H) as f64).sqrt();
    (x as usize).min(RES_THETA_H - 1)
}

/// `θ_d` bin, as `theta_diff_index` in `BRDFRead.cpp`.
fn theta_d_index(theta_d: f64) -> usize {
    let x = theta_d / FRAC_PI_2 * RES_THETA_D as f64;
    if x <= 0.0 {
        0
    } else {
        (x as usize).min(RES_THETA_D - 1)
    }
}

/// `φ_d` bin, as `phi_diff_index` in `BRDFRead.cpp` (folded by reciprocity into `[0, π)`).
fn phi_d_index(phi_d: f64) -> usize {
    let p = if phi_d < 0.0 { phi_d + PI } else { phi_d };
    let x = p / PI * RES_PHI_D as f64;
    if x <= 0.0 {
        0
    } else {
        (x as usize).min(RES_PHI_D - 1)
    }
}

/// Flat index of a bin within one channel.
#[inline]
fn flat(i_h: usize, i_d: usize, i_p: usize) -> usize {
    i_p + RES_PHI_D * (i_d + RES_THETA_D * i_h)
}

/// The table index (within a channel) for a light/view pair, both above the horizon.
pub(crate) fn table_index(l: DVec3, v: DVec3) -> usize {
    let (th, _, td, pd) = half_diff_angles(l, v);
    flat(theta_h_index(th), theta_d_index(td), phi_d_index(pd))
}

/// Bin-centre angles `(θ_h, θ_d, φ_d)` of a bin.
#[cfg(test)]
pub(crate) fn bin_centre(i_h: usize, i_d: usize, i_p: usize) -> (f64, f64, f64) {
    let s = (i_h as f64 + 0.5) / RES_THETA_H as f64;
    (
        FRAC_PI_2 * s * s,
        (i_d as f64 + 0.5) * FRAC_PI_2 / RES_THETA_D as f64,
        (i_p as f64 + 0.5) * PI / RES_PHI_D as f64,
    )
}

impl Merl {
    #[cfg(test)]
    /// A table from stored values (channel-major, as in the file). Panics unless
    /// `data.len() == 3 * CHANNEL_LEN`.
    pub(crate) fn new(data: Vec<f64>) -> Self {
        assert_eq!(
            data.len(),
            3 * CHANNEL_LEN,
            "MERL table must hold 3 x 1458000 values"
        );
        Merl {
            data,
            source: None,
            trilinear: false,
        }
    }

    /// Reads a MERL `.binary` file, checking the dimensions and the file size.
    pub(crate) fn read(path: impl AsRef<Path>) -> Result<Merl, MerlError> {
        let path = path.as_ref();
        let io = |source| MerlError::Io {
            path: path.to_path_buf(),
            source,
        };
        // A regular file only (a FIFO would block, a device never end), and no more than one
        // byte past the format's size is read (a longer file is then "wrong size").
        if !std::fs::metadata(path).map_err(io)?.is_file() {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file",
            )));
        }
        let file = std::fs::File::open(path).map_err(io)?;
        let mut bytes = Vec::with_capacity(FILE_LEN as usize);
        file.take(FILE_LEN + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        let wrong_size = |actual: usize| MerlError::WrongSize {
            path: path.to_path_buf(),
            expected: FILE_LEN,
            actual: actual as u64,
        };
        if bytes.len() < 12 {
            return Err(wrong_size(bytes.len()));
        }
        let dim = |k: usize| i32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap());
        let dims = [dim(0), dim(1), dim(2)];
        if dims != [RES_THETA_H as i32, RES_THETA_D as i32, RES_PHI_D as i32] {
            return Err(MerlError::WrongDims {
                path: path.to_path_buf(),
                dims,
            });
        }
        if bytes.len() as u64 != FILE_LEN {
            return Err(wrong_size(bytes.len()));
        }
        let data = bytes[12..]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        Ok(Merl {
            data,
            source: Some(path.to_path_buf()),
            trilinear: false,
        })
    }

    /// The same table with trilinear interpolation switched on or off.
    pub(crate) fn with_trilinear(mut self, trilinear: bool) -> Self {
        self.trilinear = trilinear;
        self
    }

    /// One channel's BRDF value at a flat bin index, `None` where the table has no data.
    #[inline]
    fn value(&self, c: usize, k: usize) -> Option<f64> {
        let x = self.data[c * CHANNEL_LEN + k];
        (x >= 0.0).then(|| x * SCALE[c])
    }

    /// Trilinear interpolation between bin centres (see the module documentation).
    fn eval_trilinear(&self, l: DVec3, v: DVec3) -> [f64; 3] {
        let (th, _, td, pd) = half_diff_angles(l, v);
        // Continuous bin coordinates: bin i's centre is at i + 0.5.
        let xh = (th.max(0.0) / FRAC_PI_2 * (RES_THETA_H * RES_THETA_H) as f64).sqrt() - 0.5;
        let xd = td / FRAC_PI_2 * RES_THETA_D as f64 - 0.5;
        let p = if pd < 0.0 { pd + PI } else { pd };
        let xp = p / PI * RES_PHI_D as f64 - 0.5;
        // Clamped axes (θ_h, θ_d): lower index and weight of the upper one.
        let clamped = |x: f64, n: usize| {
            let x = x.clamp(0.0, (n - 1) as f64);
            let i = (x.floor() as usize).min(n - 2);
            (i, x - i as f64)
        };
        let (ih, wh) = clamped(xh, RES_THETA_H);
        let (id, wd) = clamped(xd, RES_THETA_D);
        // Periodic axis (φ_d, period π = RES_PHI_D bins).
        let fp = xp.floor();
        let wp = xp - fp;
        let ip0 = (fp as i64).rem_euclid(RES_PHI_D as i64) as usize;
        let ip1 = (ip0 + 1) % RES_PHI_D;
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let mut sum = 0.0;
            let mut wsum = 0.0;
            for (a, wa) in [(ih, 1.0 - wh), (ih + 1, wh)] {
                for (b, wb) in [(id, 1.0 - wd), (id + 1, wd)] {
                    for (q, wq) in [(ip0, 1.0 - wp), (ip1, wp)] {
                        let w = wa * wb * wq;
                        if w > 0.0 {
                            if let Some(x) = self.value(c, flat(a, b, q)) {
                                sum += w * x;
                                wsum += w;
                            }
                        }
                    }
                }
            }
            *o = if wsum > 0.0 { sum / wsum } else { 0.0 };
        }
        out
    }

    #[cfg(test)]
    /// Writes the table as a MERL `.binary` file.
    pub(crate) fn write(&self, path: impl AsRef<Path>) -> Result<(), MerlError> {
        let path = path.as_ref();
        let io = |source| MerlError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut w = BufWriter::new(file);
        for d in [RES_THETA_H, RES_THETA_D, RES_PHI_D] {
            w.write_all(&(d as i32).to_le_bytes()).map_err(io)?;
        }
        for x in &self.data {
            w.write_all(&x.to_le_bytes()).map_err(io)?;
        }
        w.flush().map_err(io)
    }

    #[cfg(test)]
    /// Tabulates a model at the bin centres (with `φ_h = 0`). Meant for isotropic models: an
    /// anisotropic model is sampled only along its local x-z plane of halfway vectors.
    pub(crate) fn from_brdf(brdf: &dyn Brdf) -> Merl {
        let mut data = vec![0.0; 3 * CHANNEL_LEN];
        for i_h in 0..RES_THETA_H {
            for i_d in 0..RES_THETA_D {
                for i_p in 0..RES_PHI_D {
                    let (th, td, pd) = bin_centre(i_h, i_d, i_p);
                    let (l, v) = from_half_diff(th, 0.0, td, pd);
                    let k = flat(i_h, i_d, i_p);
                    let f = if l.z > 0.0 && v.z > 0.0 {
                        brdf.eval(l, v)
                    } else {
                        [f64::NAN; 3]
                    };
                    for c in 0..3 {
                        data[c * CHANNEL_LEN + k] =
                            if f[c].is_nan() { -1.0 } else { f[c] / SCALE[c] };
                    }
                }
            }
        }
        Merl {
            data,
            source: None,
            trilinear: false,
        }
    }
}

impl Brdf for Merl {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        if l.z <= 0.0 || v.z <= 0.0 {
            return [0.0; 3];
        }
        if self.trilinear {
            return self.eval_trilinear(l, v);
        }
        let k = table_index(l, v);
        std::array::from_fn(|c| self.value(c, k).unwrap_or(0.0))
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::None
    }

    fn name(&self) -> String {
        let kind = if self.trilinear {
            "merl-trilinear"
        } else {
            "merl"
        };
        match &self.source {
            Some(p) => format!("{kind}:path={}", p.display()),
            None => format!("{kind}:tabulated"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;
    use crate::brdf::{CookTorrance, Lambertian, Ward};

    fn temp_path(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("symframe-merl-{}-{tag}.binary", std::process::id()))
    }

    /// Half/difference angles from geometry alone (independent of the rotation code): θ_d is
    /// the angle between l and h, φ_d the azimuth of l about h measured from the direction of
    /// increasing θ_h.
    fn geometric_angles(l: DVec3, v: DVec3) -> (f64, f64, f64) {
        let h = (l + v).normalize();
        let th = h.z.acos();
        let ph = h.y.atan2(h.x);
        let e_theta = DVec3::new(th.cos() * ph.cos(), th.cos() * ph.sin(), -th.sin());
        let e_phi = DVec3::new(-ph.sin(), ph.cos(), 0.0);
        (th, l.dot(h).acos(), l.dot(e_phi).atan2(l.dot(e_theta)))
    }

    #[test]
    fn half_diff_matches_geometry_and_inverts() {
        let mut rng = Rng::new(1);
        for _ in 0..2000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let (th, ph, td, pd) = half_diff_angles(l, v);
            let (gth, gtd, gpd) = geometric_angles(l, v);
            assert!((th - gth).abs() < 1e-9 && (td - gtd).abs() < 1e-7);
            let dp = (pd - gpd).rem_euclid(2.0 * PI);
            assert!(!(1e-7..=2.0 * PI - 1e-7).contains(&dp), "{pd} vs {gpd}");
            let (l2, v2) = from_half_diff(th, ph, td, pd);
            assert!((l - l2).length() < 1e-12 && (v - v2).length() < 1e-12);
        }
        // Known configurations.
        // Known configurations (exact vectors: at θ_h = 0, φ_d is measured from φ_h, which
        // rounding noise in h could otherwise set to any angle).
        let (s, c) = 0.4f64.sin_cos();
        let (l, v) = (DVec3::new(s, 0.0, c), DVec3::new(-s, 0.0, c));
        let (th, _, td, pd) = half_diff_angles(l, v);
        assert!(th.abs() < 1e-15 && (td - 0.4).abs() < 1e-15 && pd.abs() < 1e-15);
        let (l, v) = (DVec3::new(0.0, s, c), DVec3::new(0.0, -s, c));
        let (_, _, _, pd) = half_diff_angles(l, v);
        assert!((pd - 0.5 * PI).abs() < 1e-15);
    }

    #[test]
    fn bin_indices_follow_the_reference() {
        assert_eq!(theta_h_index(0.0), 0);
        assert_eq!(theta_h_index(FRAC_PI_2), 89);
        // sqrt(θ_h/(π/2)·8100) = 45 at θ_h = π/8 (a quarter of the range): non-linear.
        assert_eq!(theta_h_index(PI / 8.0 + 1e-12), 45);
        assert_eq!(theta_h_index(PI / 8.0 - 1e-9), 44);
        assert_eq!(theta_d_index(FRAC_PI_2 - 1e-9), 89);
        assert_eq!(theta_d_index(45f64.to_radians() + 1e-9), 45);
        assert_eq!(phi_d_index(0.0), 0);
        assert_eq!(phi_d_index(PI - 1e-9), 179);
        assert_eq!(phi_d_index(-1e-9), 179); // folded by reciprocity
        assert_eq!(phi_d_index(-0.5 * PI + 1e-9), 90);
        for i_h in [0, 1, 44, 89] {
            for i_d in [0, 30, 89] {
                for i_p in [0, 90, 179] {
                    let (th, td, pd) = bin_centre(i_h, i_d, i_p);
                    assert_eq!(
                        (theta_h_index(th), theta_d_index(td), phi_d_index(pd)),
                        (i_h, i_d, i_p)
                    );
                }
            }
        }
    }

    #[test]
    fn lambertian_tabulates_exactly() {
        let lam = Lambertian::new([0.8, 0.5, 0.2]);
        let m = Merl::from_brdf(&lam);
        let mut rng = Rng::new(2);
        for _ in 0..5000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let got = m.eval(l, v);
            if got == [0.0; 3] {
                // A bin whose centre lies below the horizon: only at θ_d + θ_h ≳ 90°.
                let (th, _, td, _) = half_diff_angles(l, v);
                assert!(th + td > 1.4, "{th} {td}");
                continue;
            }
            assert!(close(got, lam.eval(l, v), 1e-12, 0.0), "{got:?}");
        }
        assert_eq!(m.tangent_axis(), TangentAxis::None);
        assert_zero_below_horizon(&m);
        assert_nonneg_finite(&m);
    }

    #[test]
    fn write_read_round_trip_and_compare_with_analytic() {
        let ct = CookTorrance::new([0.2, 0.3, 0.4], [0.8; 3], 0.3, 1.5);
        let path = temp_path("ct");
        Merl::from_brdf(&ct).write(&path).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), FILE_LEN);
        let m = Merl::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(m.name(), format!("merl:path={}", path.display()));

        let mut rng = Rng::new(3);
        let mut rel_errs = Vec::new();
        for _ in 0..20000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let (th, _, td, _) = half_diff_angles(l, v);
            let got = m.eval(l, v);
            // Exact: the table holds the analytic value at the bin centre (the centre found by
            // the geometric angles, independently of the lookup code).
            let (gth, gtd, gpd) = geometric_angles(l, v);
            let (ch, cd, cp) = bin_centre(theta_h_index(gth), theta_d_index(gtd), phi_d_index(gpd));
            let (lc, vc) = from_half_diff(ch, 0.0, cd, cp);
            if lc.z > 0.0 && vc.z > 0.0 {
                assert!(close(got, ct.eval(lc, vc), 1e-12, 0.0));
            }
            // Approximate: against the analytic value at (l, v), away from grazing where
            // 1/((n·l)(n·v)) varies fast. Within a bin θ_h moves by at most
            // (π/2)(2i+1)/8100 ≈ 0.02 rad at θ_h = 0.5, θ_d and φ_d by 1°; the lobe's
            // log-derivative in θ_h is 2 tanθ_h/(m² cos²θ_h) ≈ 16/rad there, so
            // nearest-bin errors of up to ~16% are expected on the lobe's flank.
            if l.z > 0.2 && v.z > 0.2 && th < 0.6 && td < 1.2 {
                let a = ct.eval(l, v);
                for c in 0..3 {
                    rel_errs.push((got[c] - a[c]).abs() / a[c]);
                }
            }
        }
        rel_errs.sort_by(f64::total_cmp);
        let median = rel_errs[rel_errs.len() / 2];
        let max = *rel_errs.last().unwrap();
        assert!(median < 0.01, "median relative error {median}");
        assert!(max < 0.2, "max relative error {max}");
    }

    #[test]
    fn trilinear_is_exact_at_centres_and_more_accurate() {
        let ct = CookTorrance::new([0.2, 0.3, 0.4], [0.8; 3], 0.3, 1.5);
        let nearest = Merl::from_brdf(&ct);
        let lin = nearest.clone().with_trilinear(true);
        assert_eq!(lin.name(), "merl-trilinear:tabulated");
        // At bin centres both lookups return the tabulated value.
        for (i_h, i_d, i_p) in [(10, 20, 30), (45, 0, 179), (0, 44, 0), (70, 10, 90)] {
            let (th, td, pd) = bin_centre(i_h, i_d, i_p);
            let (l, v) = from_half_diff(th, 1.0, td, pd);
            if l.z > 0.0 && v.z > 0.0 {
                let a = lin.eval(l, v);
                assert!(close(a, nearest.eval(l, v), 1e-9, 0.0), "{a:?}");
            }
        }
        // Lambertian: constant table, exact wherever every corner has data.
        let lam = Lambertian::new([0.5; 3]);
        let lm = Merl::from_brdf(&lam).with_trilinear(true);
        let mut rng = Rng::new(9);
        for _ in 0..2000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let f = lm.eval(l, v);
            assert!(f == [0.0; 3] || close(f, lam.eval(l, v), 1e-12, 0.0));
        }
        // Smoother: errors against the analytic model are smaller than nearest-bin ones.
        let (mut en, mut el) = (Vec::new(), Vec::new());
        for _ in 0..20000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let (th, _, td, _) = half_diff_angles(l, v);
            if l.z > 0.2 && v.z > 0.2 && th < 0.6 && td < 1.2 {
                let a = ct.eval(l, v)[0];
                en.push((nearest.eval(l, v)[0] - a).abs() / a);
                el.push((lin.eval(l, v)[0] - a).abs() / a);
            }
        }
        en.sort_by(f64::total_cmp);
        el.sort_by(f64::total_cmp);
        let (mn, ml) = (en[en.len() / 2], el[el.len() / 2]);
        let (xn, xl) = (*en.last().unwrap(), *el.last().unwrap());
        assert!(
            ml < 0.5 * mn && xl < 0.5 * xn,
            "median {ml} vs {mn}, max {xl} vs {xn}"
        );
        assert_nonneg_finite(&lin);
        assert_zero_below_horizon(&lin);
    }

    #[test]
    fn tabulated_isotropic_model_is_rotation_invariant() {
        let w = Ward::isotropic([0.3; 3], [0.4; 3], 0.3);
        let m = Merl::from_brdf(&w);
        // A rotation about z changes only φ_h: the bin is the same up to rounding at bin
        // edges, so allow a tiny fraction of mismatches.
        let mut rng = Rng::new(4);
        let mut mismatches = 0;
        for _ in 0..5000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            let rot = glam::DQuat::from_rotation_z(2.0 * PI * rng.next_f64());
            if m.eval(l, v) != m.eval(rot * l, rot * v) {
                mismatches += 1;
            }
        }
        assert!(mismatches <= 2, "{mismatches}");
        // Reciprocity folds φ_d: f(l, v) and f(v, l) share a bin except at bin edges.
        let mut mismatches = 0;
        for _ in 0..5000 {
            let (l, v) = (rng.hemisphere(), rng.hemisphere());
            if m.eval(l, v) != m.eval(v, l) {
                mismatches += 1;
            }
        }
        assert!(mismatches <= 2, "{mismatches}");
    }

    #[test]
    fn read_errors_name_the_file_and_problem() {
        let missing = temp_path("missing");
        let e = Merl::read(&missing).unwrap_err();
        assert!(matches!(e, MerlError::Io { .. }));
        assert!(e.to_string().contains(&missing.display().to_string()));

        let bad_dims = temp_path("dims");
        let mut bytes = Vec::new();
        for d in [90i32, 90, 360] {
            bytes.extend_from_slice(&d.to_le_bytes());
        }
        std::fs::write(&bad_dims, &bytes).unwrap();
        let e = Merl::read(&bad_dims).unwrap_err();
        std::fs::remove_file(&bad_dims).unwrap();
        assert!(
            matches!(
                e,
                MerlError::WrongDims {
                    dims: [90, 90, 360],
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("[90, 90, 360]"));

        let truncated = temp_path("trunc");
        bytes.clear();
        for d in [90i32, 90, 180] {
            bytes.extend_from_slice(&d.to_le_bytes());
        }
        bytes.extend_from_slice(&[0u8; 800]);
        std::fs::write(&truncated, &bytes).unwrap();
        let e = Merl::read(&truncated).unwrap_err();
        std::fs::remove_file(&truncated).unwrap();
        assert!(
            matches!(
                e,
                MerlError::WrongSize {
                    actual: 812,
                    expected: FILE_LEN,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("truncated"), "{e}");

        let tiny = temp_path("tiny");
        std::fs::write(&tiny, [1u8, 2, 3]).unwrap();
        let e = Merl::read(&tiny).unwrap_err();
        std::fs::remove_file(&tiny).unwrap();
        assert!(matches!(e, MerlError::WrongSize { actual: 3, .. }), "{e}");
    }

    #[test]
    fn negative_means_no_data() {
        let mut m = Merl::new(vec![1500.0; 3 * CHANNEL_LEN]);
        let (l, v) = (dir(0.3, 0.1), dir(0.5, 2.0));
        let k = table_index(l, v);
        m.data[CHANNEL_LEN + k] = -1.0;
        let f = m.eval(l, v);
        assert_eq!(f, [1.0, 0.0, 1.66]);
    }
}
