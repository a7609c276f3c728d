//! Light directions from a mirror (chrome) sphere in the frame, as RTI captures do.
//!
//! Pixel convention of the sphere's circle ([`Circle`]): x right from the image's left edge, y
//! down from its top edge, in pixels; the centre of the top-left pixel is `(0.5, 0.5)`. (Half a
//! pixel off moves a highlight's normal by `0.5 / r` radians and the light by twice that: about
//! 2 degrees on a sphere 30 pixels across.)
//!
//! Per image ([`Highlight::find`]): the brightest connected spot on the sphere (saturated pixels,
//! `NaN` in a decoded image, count as the brightest), thresholded at a fraction of its peak
//! above the sphere's median. A spot small against the ball (at most 16 pixels, or a square a
//! seventh of the radius across: a lamp's reflection smaller than a pixel, spread by the lens)
//! is located by its centroid in the image over the spot and a halo, less a plane fitted to the
//! background around it: a sub-pixel position, as a thresholded centroid is not. A spot broad
//! against the ball (a rough ball's lobe, a large lamp) is located by the mean of the
//! sphere normals under it weighted by what each holds above the threshold (in normal space:
//! the rim squeezes such a spot in the image). The light is the view `(0, 0, 1)` mirrored about
//! the normal there. No spot bright enough, or a second spot carrying a large share of the
//! first one's weight, is an error for that image (the command drops it with a warning).
//!
//! [`Detection::find`] finds the sphere when its circle is not given: the connected region
//! brighter than the image border (its median), in the mean over all images, that holds the
//! brightest spot of most images; its circle first has the region's centroid and the radius of
//! a disc of the same area, then is fitted to the rim (`refine_circle`: the edge of a blurred
//! step along rays from the centre, a robust circle fit). It needs a background darker than the
//! sphere all around it (the sphere not touching the object); otherwise give the circle.
//!
//! Measured on anti-aliased renders with a lens blur ([`crate::render::MirrorBall`]) in
//! docs/capture.md, "Light calibration from a chrome sphere".

use glam::DVec3;

mod highlight;
mod matte;
mod sphere;

pub use highlight::Highlight;

/// The settings of light calibration: how a chrome sphere's highlight is told from the rest
/// ([`Highlight::find`]) and which pixels of a matte sphere or plane measure a light's intensity
/// ([`CalibrationParams::intensity`] and its near-light forms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationParams {
    /// The highlight's spot is the pixels above `median + highlight_fraction * (peak -
    /// median)`. Higher: a smaller spot, nearer the peak.
    pub highlight_fraction: f64,
    /// The highlight's peak must be at least this many times the sphere's median (plus a small
    /// floor), or be saturated. Higher: more images refused as having no highlight.
    pub highlight_min_contrast: f64,
    /// A second spot with at least this share of the main spot's weight makes the image
    /// ambiguous. Lower: more images refused as having several highlights.
    pub highlight_several_ratio: f64,
    /// Matte pixels where the light is this close to grazing (`n.l` below it) are left out:
    /// their values are small, and a cast shadow or a slightly wrong normal there weighs most.
    pub matte_min_cosine: f64,
    /// Matte pixels within this many pixels of the rim are left out (partly covered by the
    /// sphere).
    pub matte_rim_margin: f64,
    /// Fewest usable matte pixels for a fit.
    pub matte_min_pixels: usize,
}

impl Default for CalibrationParams {
    fn default() -> Self {
        Self {
            highlight_fraction: 0.3,
            highlight_min_contrast: 5.0,
            highlight_several_ratio: 0.2,
            matte_min_cosine: 0.2,
            matte_rim_margin: 1.5,
            matte_min_pixels: 20,
        }
    }
}

/// Why a light was not measured in one image: no single highlight on the chrome sphere, or
/// too few usable pixels on the matte one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// No sphere pixel in the image.
    #[error("the sphere's circle holds no pixel of the image")]
    OffImage,
    /// Nothing on the sphere stands out.
    #[error(
        "no highlight on the sphere (peak {contrast:.1}x the sphere's median, {min:.0}x needed)"
    )]
    None {
        /// Peak over median.
        contrast: f64,
        /// The contrast asked for.
        min: f64,
    },
    /// Two or more comparable spots.
    #[error(
        "{count} highlights on the sphere (the second has {share:.0}% of the first's weight); \
         near ({x1:.1}, {y1:.1}) and ({x2:.1}, {y2:.1})"
    )]
    Several {
        /// Spots above the threshold.
        count: usize,
        /// Weight of the second spot over the first's, percent.
        share: f64,
        /// Centre of the first, x.
        x1: f64,
        /// Centre of the first, y.
        y1: f64,
        /// Centre of the second, x.
        x2: f64,
        /// Centre of the second, y.
        y2: f64,
    },
    /// Too few matte-sphere pixels face the light (a light far behind the sphere) or are
    /// usable, or their normals are too alike to fix the light.
    #[error("only {pixels} pixels of the matte sphere face the light usably ({needed} needed)")]
    TooFewPixels {
        /// Usable pixels.
        pixels: usize,
        /// Pixels needed.
        needed: usize,
    },
}
#[cfg(test)]
pub(crate) use sphere::outline_points;
pub use sphere::Detection;

/// A circle in image pixels: centre `(cx, cy)` (x right, y down, top-left pixel centre at
/// `(0.5, 0.5)`) and radius `r`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Circle {
    /// Centre, x (right), pixels.
    pub cx: f64,
    /// Centre, y (down), pixels.
    pub cy: f64,
    /// Radius, pixels.
    pub r: f64,
}

impl Circle {
    /// Parses `CX,CY,R`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("expected CX,CY,R (three numbers), got '{s}'"))?;
        match v[..] {
            [cx, cy, r] if v.iter().all(|x| x.is_finite()) && r > 0.0 => Ok(Self { cx, cy, r }),
            _ => Err(format!(
                "expected CX,CY,R: three finite numbers with R > 0, got '{s}'"
            )),
        }
    }

    /// Checks that the circle fits a `width x height` image: finite numbers, a positive radius
    /// no larger than the image's diagonal, the centre inside the image and at least half of
    /// the disc in the frame; else why not (the sentence after "does not fit the image").
    pub fn check_fits(&self, width: usize, height: usize) -> Result<(), String> {
        let (w, h) = (width as f64, height as f64);
        let diagonal = w.hypot(h);
        if !(self.cx.is_finite() && self.cy.is_finite() && self.r.is_finite() && self.r > 0.0) {
            return Err("the centre and radius must be finite, the radius > 0".into());
        }
        if !((0.0..=w).contains(&self.cx) && (0.0..=h).contains(&self.cy)) {
            return Err("its centre is outside the image".into());
        }
        if self.r > diagonal {
            return Err(format!(
                "its radius is larger than the image's diagonal ({diagonal:.1} px)"
            ));
        }
        let inside = self.area_inside(w, h) / (std::f64::consts::PI * self.r * self.r);
        if inside < 0.5 - 1e-3 {
            return Err(format!(
                "it is mostly outside the frame ({:.0}% of the disc inside)",
                100.0 * inside
            ));
        }
        Ok(())
    }

    /// The area of the disc inside the rectangle `[0, w] x [0, h]` (square pixels), by the
    /// midpoint rule over 4096 columns of its chords.
    fn area_inside(&self, w: f64, h: f64) -> f64 {
        let (x0, x1) = ((self.cx - self.r).max(0.0), (self.cx + self.r).min(w));
        if x1 <= x0 {
            return 0.0;
        }
        let n = 4096;
        let dx = (x1 - x0) / n as f64;
        (0..n)
            .map(|i| {
                let x = x0 + (i as f64 + 0.5) * dx;
                let s = (self.r * self.r - (x - self.cx).powi(2)).max(0.0).sqrt();
                ((self.cy + s).min(h) - (self.cy - s).max(0.0)).max(0.0) * dx
            })
            .sum()
    }

    /// The sphere's unit normal (camera frame: x right, y up, z toward the camera) seen at
    /// image point `(x, y)`, `None` outside the circle.
    pub fn normal_at(&self, x: f64, y: f64) -> Option<DVec3> {
        let nx = (x - self.cx) / self.r;
        let ny = -(y - self.cy) / self.r;
        let rr = nx * nx + ny * ny;
        (rr < 1.0).then(|| DVec3::new(nx, ny, (1.0 - rr).sqrt()))
    }

    /// The image point where the sphere's normal is `n` (its projection).
    pub fn point_of(&self, n: DVec3) -> (f64, f64) {
        (self.cx + n.x * self.r, self.cy - n.y * self.r)
    }

    /// Whether pixel `(col, row)`'s centre is inside the circle.
    fn covers(&self, col: usize, row: usize) -> bool {
        let (x, y) = (col as f64 + 0.5 - self.cx, row as f64 + 0.5 - self.cy);
        x * x + y * y < self.r * self.r
    }

    /// The pixel range `(col0..col1, row0..row1)` the circle touches, clipped to the image.
    fn bounds(&self, width: usize, height: usize) -> (usize, usize, usize, usize) {
        let clip = |v: f64, n: usize| (v.max(0.0) as usize).min(n);
        (
            clip((self.cx - self.r).floor(), width),
            clip((self.cx + self.r).ceil(), width),
            clip((self.cy - self.r).floor(), height),
            clip((self.cy + self.r).ceil(), height),
        )
    }
}

/// The light direction (surface toward light) whose mirror reflection about `n` is the view
/// `(0, 0, 1)`: `l = 2 (n . v) n - v`.
pub(crate) fn light_from_normal(n: DVec3) -> DVec3 {
    (2.0 * n.z * n - DVec3::Z).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{Brdf, Ggx};
    use crate::render::{Scene, TangentField};

    fn grey(rgb: &[f32]) -> Vec<f32> {
        rgb.chunks_exact(3)
            .map(|p| (p[0] + p[1] + p[2]) / 3.0)
            .collect()
    }

    fn angle_deg(a: DVec3, b: DVec3) -> f64 {
        a.normalize()
            .dot(b.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    #[test]
    fn circles_are_checked_against_the_image() {
        let c = |cx, cy, r| Circle { cx, cy, r };
        // Inside, and with half of it in the frame at an edge.
        assert_eq!(c(48.0, 16.0, 12.0).check_fits(96, 32), Ok(()));
        assert_eq!(c(48.0, 0.0, 10.0).check_fits(96, 32), Ok(()));
        assert_eq!(c(48.0, 16.0, 101.0).check_fits(96, 32).ok(), None);
        let why = |cx, cy, r| c(cx, cy, r).check_fits(96, 32).unwrap_err();
        assert!(why(8.0, 8.0, 1e12).contains("diagonal (101.2 px)"));
        assert!(why(-40.0, 16.0, 10.0).contains("centre is outside"));
        assert!(why(48.0, 100.0, 10.0).contains("centre is outside"));
        assert!(why(0.0, 0.0, 20.0).contains("mostly outside the frame (25% of the disc"));
        assert!(why(8.0, 8.0, f64::NAN).contains("finite"));
        assert!(why(8.0, 8.0, 0.0).contains("> 0"));
        // The area inside: a quarter of a disc at a corner, all of one in the middle.
        let q = c(0.0, 0.0, 10.0).area_inside(96.0, 32.0);
        assert!(
            (q / (25.0 * std::f64::consts::PI) - 1.0).abs() < 1e-4,
            "{q}"
        );
        let a = c(48.0, 16.0, 12.0).area_inside(96.0, 32.0);
        assert!(
            (a / (144.0 * std::f64::consts::PI) - 1.0).abs() < 1e-4,
            "{a}"
        );
    }

    #[test]
    fn circle_parsing_and_geometry() {
        let c = Circle::parse("10.5, 20, 8").unwrap();
        assert_eq!((c.cx, c.cy, c.r), (10.5, 20.0, 8.0));
        for bad in ["1,2", "1,2,0", "a,b,c", "1,2,3,4", "1,nan,3"] {
            assert!(Circle::parse(bad).is_err(), "{bad}");
        }
        // Up in the image (smaller y) is +y in the camera frame.
        let n = c.normal_at(10.5, 16.0).unwrap();
        assert!((n - DVec3::new(0.0, 0.5, 0.75f64.sqrt())).length() < 1e-12);
        let (x, y) = c.point_of(n);
        assert!((x - 10.5).abs() < 1e-12 && (y - 16.0).abs() < 1e-12);
        assert!(c.normal_at(0.0, 0.0).is_none());
        // Head-on normal: light along the view; 45 degrees: light in the image plane.
        assert!((light_from_normal(DVec3::Z) - DVec3::Z).length() < 1e-12);
        let l = light_from_normal(DVec3::new(0.5f64.sqrt(), 0.0, 0.5f64.sqrt()));
        assert!((l - DVec3::X).length() < 1e-12);
    }

    #[test]
    fn highlights_on_a_rendered_chrome_sphere_give_the_lights() {
        let size = 96;
        let scene = Scene::sphere(size, TangentField::Circular);
        let chrome = Ggx::new([0.02; 3], [0.9; 3], 0.05, 0.05);
        let circle = Circle {
            cx: size as f64 / 2.0,
            cy: size as f64 / 2.0,
            r: size as f64 / 2.0,
        };
        let mut worst: f64 = 0.0;
        // Up to 62 degrees of normal: lights up to 124 degrees from the view (behind it).
        for (k, theta) in [0.0f64, 10.0, 25.0, 40.0, 50.0, 62.0].iter().enumerate() {
            let phi = (k as f64 * 67.0).to_radians();
            let n = DVec3::new(
                theta.to_radians().sin() * phi.cos(),
                theta.to_radians().sin() * phi.sin(),
                theta.to_radians().cos(),
            );
            let l = light_from_normal(n);
            let img = grey(&scene.render(&chrome as &dyn Brdf, l));
            let h = Highlight::find(size, size, &img, &circle, &CalibrationParams::default())
                .unwrap_or_else(|e| panic!("theta {theta}: {e}"));
            worst = worst.max(angle_deg(h.light, l));
        }
        assert!(worst < 1.0, "worst light error {worst} degrees");
    }

    /// Light errors (mean, max, degrees) of [`Highlight::find`] on a mirror ball of radius
    /// `r` at a sub-pixel position under 120 lamps up to 130 degrees from the view, with the
    /// circle given (exact) and detected; 8-bit images (the lamp clipped) where `eight_bit`.
    fn mirror_ball_errors(r: f64, eight_bit: bool) -> [(f64, f64); 2] {
        use crate::frames::rig::uniform_cone_lights;
        use crate::render::MirrorBall;
        let size = (2.0 * r + 12.0).ceil() as usize;
        let ball = MirrorBall::new(size as f64 / 2.0 + 0.37, size as f64 / 2.0 - 0.21, r);
        let lights = uniform_cone_lights(120, 65.0);
        let images: Vec<Vec<f32>> = lights
            .iter()
            .map(|&l| {
                let mut img = ball.render(size, size, l);
                if eight_bit {
                    // Exposed so the room's reflection is about a tenth of the white level (the
                    // lamp's clips).
                    for v in &mut img {
                        let q = (*v / (8.0 * ball.room as f32) * 255.0).round().min(255.0);
                        *v = if q >= 255.0 { f32::NAN } else { q / 255.0 };
                    }
                }
                img
            })
            .collect();
        let mut mean = vec![0f32; size * size];
        let mut brightest = Vec::new();
        for img in &images {
            for (m, v) in mean.iter_mut().zip(img) {
                *m += if v.is_finite() { *v } else { 1.0 } / images.len() as f32;
            }
            let b = (0..img.len())
                .max_by(|&a, &b| {
                    let v = |i: usize| if img[i].is_finite() { img[i] } else { f32::MAX };
                    v(a).total_cmp(&v(b))
                })
                .unwrap();
            brightest.push(b);
        }
        let detected = Detection::find(size, size, &mean, &brightest)
            .unwrap()
            .circle;
        let given = Circle {
            cx: ball.cx,
            cy: ball.cy,
            r: ball.r,
        };
        [given, detected].map(|circle| {
            let errors: Vec<f64> = images
                .iter()
                .zip(&lights)
                .map(|(img, &l)| {
                    match Highlight::find(size, size, img, &circle, &CalibrationParams::default()) {
                        Ok(h) => angle_deg(h.light, l),
                        Err(e) => panic!("light {l}: {e}"),
                    }
                })
                .collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            (mean, errors.iter().copied().fold(0.0, f64::max))
        })
    }

    #[test]
    fn mirror_ball_lights_to_a_tenth_of_a_degree() {
        // docs/capture.md, "Light calibration from a chrome sphere": the targets are a ball of
        // 56 px radius's (float and 8-bit); the 30 px ball is printed beside them.
        for (r, eight_bit) in [(55.8, false), (55.8, true), (30.3, false), (30.3, true)] {
            let [(gm, gx), (dm, dx)] = mirror_ball_errors(r, eight_bit);
            eprintln!(
                "| {r} px | {} | given {gm:.3} / {gx:.3} | detected {dm:.3} / {dx:.3} |",
                if eight_bit {
                    "8-bit, lamp clipped"
                } else {
                    "float"
                }
            );
            if r > 50.0 {
                assert!(gm <= 0.15 && gx <= 0.5, "given: {gm} / {gx}");
                assert!(dm <= 0.2 && dx <= 0.6, "detected: {dm} / {dx}");
            } else if !eight_bit {
                assert!(gm <= 0.15 && gx <= 0.5, "given: {gm} / {gx}");
            }
        }
    }

    #[test]
    fn saturated_cores_none_and_several() {
        let size = 64;
        let circle = Circle {
            cx: 32.0,
            cy: 32.0,
            r: 32.0,
        };
        let p = CalibrationParams::default();
        // A flat, dim sphere: no highlight.
        let mut img = vec![0.0f32; size * size];
        for (i, v) in img.iter_mut().enumerate() {
            if circle.covers(i % size, i / size) {
                *v = 0.1;
            }
        }
        assert!(matches!(
            Highlight::find(size, size, &img, &circle, &p),
            Err(CalibrationError::None { .. })
        ));
        // A saturated 3 x 3 core (NaN) at pixel (40, 20): its centre.
        let mut sat = img.clone();
        for r in 19..22 {
            for c in 39..42 {
                sat[r * size + c] = f32::NAN;
            }
        }
        let h = Highlight::find(size, size, &sat, &circle, &p).unwrap();
        assert!(
            (h.x - 40.5).abs() < 0.2 && (h.y - 20.5).abs() < 0.2,
            "{h:?}"
        );
        assert_eq!(h.saturated, 9);
        // A second, equally bright spot: ambiguous.
        let mut two = sat.clone();
        for r in 40..43 {
            for c in 20..23 {
                two[r * size + c] = f32::NAN;
            }
        }
        let e = Highlight::find(size, size, &two, &circle, &p).unwrap_err();
        assert!(
            matches!(e, CalibrationError::Several { count: 2, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("2 highlights"));
        // A faint second spot (a tenth of the weight) does not matter.
        let mut faint = sat;
        faint[45 * size + 20] = 1.0;
        assert!(Highlight::find(size, size, &faint, &circle, &p).is_ok());
        // Off the image.
        let off = Circle {
            cx: -100.0,
            cy: 5.0,
            r: 10.0,
        };
        assert_eq!(
            Highlight::find(size, size, &img, &off, &p),
            Err(CalibrationError::OffImage)
        );
    }

    #[test]
    fn a_round_region_with_the_brightest_spots_is_found() {
        let (w, h) = (120, 80);
        let truth = Circle {
            cx: 80.3,
            cy: 38.7,
            r: 25.4,
        };
        let mut mean = vec![0.0f32; w * h];
        for (i, v) in mean.iter_mut().enumerate() {
            if truth.covers(i % w, i / w) {
                *v = 0.05;
            }
            // A brighter square object on the left.
            let (r, c) = (i / w, i % w);
            if (10..50).contains(&c) && (20..60).contains(&r) {
                *v = 0.4;
            }
        }
        let brightest = vec![38 * w + 80, 30 * w + 75, 45 * w + 90, 30 * w + 30];
        let d = Detection::find(w, h, &mean, &brightest).unwrap();
        assert!((d.circle.cx - truth.cx).abs() < 0.1, "{d:?}");
        assert!((d.circle.cy - truth.cy).abs() < 0.1, "{d:?}");
        assert!((d.circle.r - truth.r).abs() < 0.15, "{d:?}");
        assert!((d.highlight_share - 0.75).abs() < 1e-9);
        // Only the square holds bright spots: not round.
        let e = Detection::find(w, h, &mean, &[30 * w + 30]).unwrap_err();
        assert!(e.contains("not round"), "{e}");
        assert!(Detection::find(w, h, &vec![0.0; w * h], &brightest).is_err());
    }
}
