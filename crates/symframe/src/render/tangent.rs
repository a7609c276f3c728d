//! Tangent fields: how the tangent direction varies over a synthetic surface.
//!
//! Every field first proposes a direction `d` (camera frame), then projects it onto the tangent
//! plane orthogonally, `t = normalize(d - (d.n) n)`. Where that projection vanishes (`d` along
//! the normal, or `d = 0` at the centre of a radial field) the projection of camera x is used,
//! then that of camera y.
//!
//! Position-dependent fields use *normalised image coordinates* `(x, y)`: the image centre is
//! `(0, 0)`, x grows to the right and y upward, and the half-size of the larger image side is 1
//! (so a square image spans `[-1, 1]` on both axes; see [`image_position`]).

use std::fmt;

use glam::DVec3;

/// How the tangent direction varies over a surface.
#[derive(Debug, Clone, Copy)]
pub enum TangentField {
    /// Circles around the view axis: `t = normalize(z x n)` (a hue wheel in the tangent map on a
    /// sphere; constant on a plane). Depends on the normal only.
    Circular,
    /// A fixed camera-frame direction projected onto each tangent plane.
    Axial(DVec3),
    /// Away from the image centre: `d = (x, y, 0)` (meridians on a sphere).
    Radial,
    /// A spiral: the image-plane circle direction `(-y, x, 0)` rotated toward the radial one by
    /// the given angle in degrees (0 = circles about the image centre, 90 = radial).
    Swirl(f64),
    /// Any function of the normal and the normalised image position: `f(normal, x, y)` returns
    /// a direction that is projected onto the tangent plane (it need be neither unit nor
    /// perpendicular to the normal).
    Function(fn(DVec3, f64, f64) -> DVec3),
}

impl PartialEq for TangentField {
    fn eq(&self, other: &Self) -> bool {
        use TangentField::*;
        match (self, other) {
            (Circular, Circular) | (Radial, Radial) => true,
            (Axial(a), Axial(b)) => a == b,
            (Swirl(a), Swirl(b)) => a == b,
            // Same function, same address (good enough for a test double).
            (Function(a), Function(b)) => *a as usize == *b as usize,
            _ => false,
        }
    }
}

/// Normalised image coordinates of the centre of pixel `(col, row)` in a `width x height` image:
/// `(0, 0)` at the image centre, x right, y up, the larger half-side scaled to 1.
pub(super) fn image_position(width: usize, height: usize, col: usize, row: usize) -> (f64, f64) {
    let half = width.max(height).max(1) as f64 / 2.0;
    (
        (col as f64 + 0.5 - width as f64 / 2.0) / half,
        -(row as f64 + 0.5 - height as f64 / 2.0) / half,
    )
}

/// The orthogonal projection of `d` onto the plane perpendicular to the unit vector `n`,
/// normalised, falling back to the projections of camera x and y when it (nearly) vanishes,
/// i.e. when less than `1e-6` of the direction's length is left.
pub(super) fn project_to_tangent_plane(d: DVec3, n: DVec3) -> DVec3 {
    [d, DVec3::X, DVec3::Y]
        .into_iter()
        .find_map(|a| {
            let p = a - a.dot(n) * n;
            if p.length().partial_cmp(&(1e-6 * a.length())) != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            // A second Gram-Schmidt pass restores orthogonality lost to cancellation.
            let p = p.normalize();
            (p - p.dot(n) * n).try_normalize()
        })
        .unwrap_or(DVec3::X)
}

impl TangentField {
    /// The unit tangent at normal `n`, evaluating position-dependent fields at the image centre
    /// (use [`TangentField::tangent_at_point`] for those).
    pub fn tangent_at(&self, n: DVec3) -> DVec3 {
        self.tangent_at_point(n, 0.0, 0.0)
    }

    /// The unit tangent at normal `n` seen at normalised image position `(x, y)`.
    pub fn tangent_at_point(&self, n: DVec3, x: f64, y: f64) -> DVec3 {
        let d = match *self {
            TangentField::Circular => DVec3::Z.cross(n),
            TangentField::Axial(d) => d,
            TangentField::Radial => DVec3::new(x, y, 0.0),
            TangentField::Swirl(deg) => {
                let (s, c) = deg.to_radians().sin_cos();
                c * DVec3::new(-y, x, 0.0) + s * DVec3::new(x, y, 0.0)
            }
            TangentField::Function(f) => f(n, x, y),
        };
        project_to_tangent_plane(d, n)
    }

    /// Parses a preset name: `circular`, `radial`, `swirl` (45 degrees) or `swirl:DEG`,
    /// `axial:DEG` (the image-plane direction at DEG degrees counter-clockwise from x, e.g.
    /// `axial:90` is image up) or `axial:X/Y/Z` (any camera-frame direction).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let spec = spec.trim();
        let (name, arg) = match spec.split_once(':') {
            Some((n, a)) => (n.trim(), Some(a.trim())),
            None => (spec, None),
        };
        let number = |a: &str| -> Result<f64, String> {
            a.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("tangent field '{spec}': '{a}' is not a finite number"))
        };
        let no_arg = |f: TangentField| match arg {
            None => Ok(f),
            Some(_) => Err(format!("tangent field '{name}' takes no parameter")),
        };
        match name.to_ascii_lowercase().as_str() {
            "circular" => no_arg(TangentField::Circular),
            "radial" => no_arg(TangentField::Radial),
            "swirl" => Ok(TangentField::Swirl(
                arg.map(number).transpose()?.unwrap_or(45.0),
            )),
            "axial" => {
                let a =
                    arg.ok_or("tangent field 'axial' needs an angle: axial:DEG or axial:X/Y/Z")?;
                let parts: Vec<&str> = a.split('/').collect();
                match parts.len() {
                    1 => {
                        let (s, c) = number(a)?.to_radians().sin_cos();
                        Ok(TangentField::Axial(DVec3::new(c, s, 0.0)))
                    }
                    3 => {
                        let d = DVec3::new(number(parts[0])?, number(parts[1])?, number(parts[2])?);
                        if d.length_squared() == 0.0 {
                            return Err(format!("tangent field '{spec}': zero direction"));
                        }
                        Ok(TangentField::Axial(d))
                    }
                    _ => Err(format!(
                        "tangent field '{spec}': expected axial:DEG or axial:X/Y/Z"
                    )),
                }
            }
            _ => Err(format!(
                "unknown tangent field '{spec}' (valid: circular, radial, swirl[:DEG], \
                 axial:DEG, axial:X/Y/Z)"
            )),
        }
    }
}

impl fmt::Display for TangentField {
    /// The preset spelling [`TangentField::parse`] reads back (`function` for
    /// [`TangentField::Function`], which cannot be parsed).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TangentField::Circular => write!(f, "circular"),
            TangentField::Radial => write!(f, "radial"),
            TangentField::Swirl(a) => write!(f, "swirl:{a}"),
            TangentField::Axial(d) if d.z == 0.0 => {
                write!(f, "axial:{}", d.y.atan2(d.x).to_degrees())
            }
            TangentField::Axial(d) => write!(f, "axial:{}/{}/{}", d.x, d.y, d.z),
            TangentField::Function(_) => write!(f, "function"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_frame(t: DVec3, n: DVec3) {
        assert!((t.length() - 1.0).abs() < 1e-12, "{t}");
        assert!(t.dot(n).abs() < 1e-12, "{t} . {n}");
    }

    #[test]
    fn presets_parse_and_print_back() {
        for s in [
            "circular",
            "radial",
            "swirl:30",
            "axial:90",
            "axial:0/0.5/1",
        ] {
            let f = TangentField::parse(s).unwrap();
            assert_eq!(TangentField::parse(&f.to_string()).unwrap(), f, "{s}");
        }
        assert_eq!(
            TangentField::parse("swirl").unwrap(),
            TangentField::Swirl(45.0)
        );
        let up = TangentField::parse("axial:90").unwrap();
        assert!((up.tangent_at(DVec3::Z) - DVec3::Y).length() < 1e-12);
        for bad in [
            "spiral",
            "axial",
            "axial:x",
            "radial:3",
            "axial:0/0/0",
            "axial:1/2",
        ] {
            let e = TangentField::parse(bad).unwrap_err();
            assert!(!e.is_empty() && !e.contains('\n'), "{bad}: {e}");
        }
    }

    #[test]
    fn fields_are_unit_and_tangent_even_when_degenerate() {
        fn along_normal(n: DVec3, _: f64, _: f64) -> DVec3 {
            n
        }
        let fields = [
            TangentField::Circular,
            TangentField::Axial(DVec3::X),
            TangentField::Radial,
            TangentField::Swirl(45.0),
            TangentField::Function(along_normal),
        ];
        let normals = [
            DVec3::Z,
            DVec3::X,
            DVec3::new(0.3, -0.4, 0.5).normalize(),
            DVec3::new(-1.0, 0.0, 1e-9).normalize(),
        ];
        for f in fields {
            for n in normals {
                for (x, y) in [(0.0, 0.0), (0.5, -0.2), (-1.0, 1.0)] {
                    check_frame(f.tangent_at_point(n, x, y), n);
                }
            }
        }
    }

    #[test]
    fn radial_and_circular_are_perpendicular_on_a_sphere() {
        let (x, y) = (0.3, 0.4);
        let n = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let c = TangentField::Circular.tangent_at_point(n, x, y);
        let r = TangentField::Radial.tangent_at_point(n, x, y);
        assert!(c.dot(r).abs() < 1e-12);
        // Swirl 0 is the image-plane circle, which on a sphere is the circular field.
        let s = TangentField::Swirl(0.0).tangent_at_point(n, x, y);
        assert!((s - c).length() < 1e-12);
    }

    #[test]
    fn image_positions_are_centred_and_y_up() {
        assert_eq!(image_position(4, 4, 0, 0), (-0.75, 0.75));
        assert_eq!(image_position(4, 2, 3, 1), (0.75, -0.25));
    }
}
