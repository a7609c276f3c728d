//! Relighting fitted Ward or glTF maps under new lights, with appearance edits (paper Section 5.1):
//! scaling the diffuse part, the specular part and the roughness, and rotating the tangent field
//! about the normal inside a region (the paper's logo example: tangents turned by 90 degrees
//! inside a mask change the direction of the brushed highlight there).
//!
//! The image under a distant light `l` of unit intensity is the radiance
//! `f(l, v) (n.l)` of each pixel's [`Ward`] model in its frame (x = t, y = b = n x t, z = n),
//! `v = (0, 0, 1)`: the same quantity the fit matched, so relighting a fit under one of the
//! measured lights reproduces that measurement. Pixels without a model are 0. A glTF fit
//! ([`GltfMaps`]) is rendered the same way with its [`GltfPbr`] model under lights of its
//! fitted intensity ([`GltfMaps::exposure`]): "unit intensity" means the photographs' lights.

use glam::DVec3;
use rayon::prelude::*;

use crate::appearance::fit::{GltfMaps, LobeMaps, WardMaps};
use crate::appearance::lobe_fit::LobeModel;
use crate::brdf::gltf::GltfPbr;
use crate::brdf::ward::Ward;
use crate::brdf::Brdf;
use crate::error::{Error, Result};
use crate::eval::vec_at;
use crate::geometry::tangent_basis;
use crate::stack::check_mask_size;

/// Appearance edits applied when relighting.
#[derive(Debug, Clone, PartialEq)]
pub struct Edits {
    /// Factor on the diffuse albedo (>= 0).
    pub diffuse_scale: f64,
    /// Factor on the specular albedo (>= 0).
    pub specular_scale: f64,
    /// Factor on both roughnesses (> 0; below 1 = glossier).
    pub roughness_scale: f64,
    /// Rotation of the tangent about the normal, degrees (right-handed about n), applied inside
    /// `region` (everywhere when there is none). Pixels without a tangent are unaffected.
    pub tangent_rotation_deg: f64,
    /// Where the tangent rotation applies (`H x W`, row-major).
    pub region: Option<Vec<bool>>,
}

impl Default for Edits {
    fn default() -> Self {
        Self {
            diffuse_scale: 1.0,
            specular_scale: 1.0,
            roughness_scale: 1.0,
            tangent_rotation_deg: 0.0,
            region: None,
        }
    }
}

impl Edits {
    /// Checks the factors and the region's size against `width x height`.
    pub fn check(&self, width: usize, height: usize) -> Result<()> {
        for (name, v) in [
            ("diffuse scale", self.diffuse_scale),
            ("specular scale", self.specular_scale),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(Error::BadParameter(format!(
                    "{name} must be finite and >= 0, got {v}"
                )));
            }
        }
        if !(self.roughness_scale > 0.0 && self.roughness_scale.is_finite()) {
            return Err(Error::BadParameter(format!(
                "roughness scale must be finite and > 0, got {}",
                self.roughness_scale
            )));
        }
        if !self.tangent_rotation_deg.is_finite() {
            return Err(Error::BadParameter(
                "tangent rotation must be finite".into(),
            ));
        }
        if let Some(r) = &self.region {
            check_mask_size(r, width, height, "region")?;
        }
        Ok(())
    }
}

/// A pixel's (edited) BRDF and the light intensity it is lit with.
#[derive(Debug, Clone)]
enum Material {
    Ward(Ward),
    Gltf(GltfPbr, f64),
    Lobes(LobeModel),
}

/// One pixel's model: its frame and its material.
#[derive(Debug, Clone)]
struct PixelModel {
    t: DVec3,
    b: DVec3,
    n: DVec3,
    anisotropic: bool,
    material: Material,
}

impl PixelModel {
    #[inline]
    fn radiance(&self, l: DVec3) -> [f32; 3] {
        let nl = self.n.dot(l);
        if nl <= 0.0 {
            return [0.0; 3];
        }
        let local = |d: DVec3| DVec3::new(d.dot(self.t), d.dot(self.b), d.dot(self.n));
        let (f, e) = match &self.material {
            Material::Ward(w) => (w.eval(local(l), local(DVec3::Z)), 1.0),
            Material::Gltf(g, e) => (g.eval(local(l), local(DVec3::Z)), *e),
            Material::Lobes(m) => (m.eval(local(l), local(DVec3::Z)), 1.0),
        };
        f.map(|v| (e * v * nl) as f32)
    }
}

/// Renders fitted (and edited) Ward maps under any distant light.
#[derive(Debug, Clone)]
pub struct Relighter {
    width: usize,
    height: usize,
    pixels: Vec<Option<PixelModel>>,
}

fn rgb(v: &[f32], p: usize) -> Option<[f64; 3]> {
    let s = &v[p * 3..p * 3 + 3];
    s.iter()
        .all(|x| x.is_finite())
        .then(|| [s[0] as f64, s[1] as f64, s[2] as f64])
}

impl Relighter {
    /// Builds the per-pixel models from `maps` with `edits` applied. A pixel has a model where
    /// its normal faces the view and its albedos and roughnesses are finite (roughnesses
    /// positive); a NaN tangent means isotropic.
    pub fn new(maps: &WardMaps, edits: &Edits) -> Result<Self> {
        maps.check()?;
        edits.check(maps.width, maps.height)?;
        let (sin, cos) = edits.tangent_rotation_deg.to_radians().sin_cos();
        let pixels = (0..maps.width * maps.height)
            .map(|p| {
                let n = vec_at(&maps.normals, p).filter(|n| n.z > 0.0)?;
                let (kd, ks) = (rgb(&maps.kd, p)?, rgb(&maps.ks, p)?);
                let (at, ab) = (maps.alpha_t[p] as f64, maps.alpha_b[p] as f64);
                if !(at > 0.0 && ab > 0.0 && at.is_finite() && ab.is_finite()) {
                    return None;
                }
                let (t, anisotropic) = edited_frame(&maps.tangents, n, p, edits, sin, cos);
                let ward = Ward::new(
                    kd.map(|v| v * edits.diffuse_scale),
                    ks.map(|v| v * edits.specular_scale),
                    at * edits.roughness_scale,
                    ab * edits.roughness_scale,
                );
                Some(PixelModel {
                    t,
                    b: n.cross(t),
                    n,
                    anisotropic,
                    material: Material::Ward(ward),
                })
            })
            .collect();
        Ok(Self {
            width: maps.width,
            height: maps.height,
            pixels,
        })
    }

    /// Builds the per-pixel models of a glTF fit with `edits` applied: the diffuse scale
    /// multiplies the base colour and the roughness scale the roughness (both clamped to 1);
    /// the specular scale must be 1 (the model has no free specular albedo). A pixel has a
    /// model where its normal faces the view and its parameters are finite and in range.
    pub fn gltf(maps: &GltfMaps, edits: &Edits) -> Result<Self> {
        maps.check()?;
        edits.check(maps.width, maps.height)?;
        if edits.specular_scale != 1.0 {
            return Err(Error::BadParameter(
                "a specular scale cannot edit a glTF fit (its specular part follows from the \
                 base colour and metalness); use the diffuse or roughness scale"
                    .into(),
            ));
        }
        let (sin, cos) = edits.tangent_rotation_deg.to_radians().sin_cos();
        let pixels = (0..maps.width * maps.height)
            .map(|p| {
                let n = vec_at(&maps.normals, p).filter(|n| n.z > 0.0)?;
                let base = rgb(&maps.base_color, p)?;
                let (m, r, s) = (
                    maps.metallic[p] as f64,
                    maps.roughness[p] as f64,
                    maps.anisotropy[p] as f64,
                );
                let unit = |x: f64| (0.0..=1.0).contains(&x);
                if !(unit(m) && r > 0.0 && r <= 1.0 && unit(s) && base.iter().all(|&c| c >= 0.0)) {
                    return None;
                }
                let (t, anisotropic) = edited_frame(&maps.tangents, n, p, edits, sin, cos);
                let g = GltfPbr::new(
                    base.map(|c| (c * edits.diffuse_scale).min(1.0)),
                    m,
                    (r * edits.roughness_scale).min(1.0),
                    if anisotropic { s } else { 0.0 },
                );
                Some(PixelModel {
                    t,
                    b: n.cross(t),
                    n,
                    anisotropic,
                    material: Material::Gltf(g, maps.exposure),
                })
            })
            .collect();
        Ok(Self {
            width: maps.width,
            height: maps.height,
            pixels,
        })
    }

    /// The relighter of a fit of any model ([`FitModel`](crate::appearance::fit::FitModel)):
    /// each pixel rendered with the model fitted there, its glTF parameters where `gltf` has
    /// them, else its Ward parameters (an automatic fit has either at each pixel). The edits
    /// apply as [`Relighter::new`] and [`Relighter::gltf`] apply them; a specular scale is
    /// refused where there are glTF pixels.
    pub fn of_fit(ward: &WardMaps, gltf: Option<&GltfMaps>, edits: &Edits) -> Result<Self> {
        let mut out = Self::new(ward, edits)?;
        let Some(g) = gltf else {
            return Ok(out);
        };
        if (g.width, g.height) != (ward.width, ward.height) {
            return Err(Error::BadParameter(format!(
                "the glTF maps are {}x{} but the Ward maps {}x{}",
                g.width, g.height, ward.width, ward.height
            )));
        }
        let g = Self::gltf(g, edits)?;
        for (w, g) in out.pixels.iter_mut().zip(g.pixels) {
            if g.is_some() {
                *w = g;
            }
        }
        Ok(out)
    }

    /// This relighter with the pixels of `lobes` that have a two-lobe model rendered with it
    /// (an automatic or two-lobe fit), `edits` applied: the diffuse scale multiplies `kd`,
    /// the specular scale both lobes' reflectances, the roughness scale every roughness; the
    /// tangent rotation turns the frame as for the other models.
    pub fn with_lobes(mut self, lobes: &LobeMaps, edits: &Edits) -> Result<Self> {
        lobes.check()?;
        edits.check(lobes.width, lobes.height)?;
        if (lobes.width, lobes.height) != (self.width, self.height) {
            return Err(Error::BadParameter(format!(
                "the two-lobe maps are {}x{} but the other maps {}x{}",
                lobes.width, lobes.height, self.width, self.height
            )));
        }
        let (sin, cos) = edits.tangent_rotation_deg.to_radians().sin_cos();
        for (p, px) in self.pixels.iter_mut().enumerate() {
            let Some(m) = lobes.model(p) else {
                continue;
            };
            let Some(n) = vec_at(&lobes.normals, p).filter(|n| n.z > 0.0) else {
                continue;
            };
            let (t, anisotropic) = edited_frame(&lobes.tangents, n, p, edits, sin, cos);
            let r = edits.roughness_scale;
            let m = LobeModel {
                kd: m.kd.map(|v| v * edits.diffuse_scale),
                ka: m.ka.map(|v| v * edits.specular_scale),
                kb: m.kb.map(|v| v * edits.specular_scale),
                alpha_t: m.alpha_t * r,
                alpha_b: m.alpha_b * r,
                alpha_c: m.alpha_c * r,
                ..m
            };
            *px = Some(PixelModel {
                t,
                b: n.cross(t),
                n,
                anisotropic,
                material: Material::Lobes(m),
            });
        }
        Ok(self)
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The image under a distant light of unit intensity from `light` (camera frame, surface
    /// toward light; normalised here): interleaved linear RGB radiance, `H x W x 3`, 0 where a
    /// pixel has no model or faces away from the light. Parallel over rows.
    pub fn render(&self, light: DVec3) -> Vec<f32> {
        let mut out = vec![0.0f32; self.width * self.height * 3];
        let Some(l) = light.try_normalize() else {
            return out;
        };
        let w = self.width;
        out.par_chunks_mut(w.max(1) * 3)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, px) in row.chunks_exact_mut(3).enumerate() {
                    if let Some(m) = &self.pixels[y * w + x] {
                        px.copy_from_slice(&m.radiance(l));
                    }
                }
            });
        out
    }

    /// The frame pixel `p` (row-major) is shaded in by [`Relighter::render`]: its tangent and
    /// normal (unit, camera frame) and whether the tangent came from the tangent map (only those
    /// are turned by a tangent rotation; an isotropic pixel gets a tangent of its own), or `None`
    /// where the pixel has no model. For renderers of the same maps elsewhere (the viewer's
    /// shader), so that they shade exactly the pixels this one shades, in the same frames.
    pub fn frame(&self, p: usize) -> Option<(DVec3, DVec3, bool)> {
        let m = self.pixels.get(p)?.as_ref()?;
        Some((m.t, m.n, m.anisotropic))
    }

    /// The tangent field after the edits (`H x W x 3`, NaN where there is no model or no
    /// tangent).
    pub fn tangents(&self) -> Vec<f32> {
        self.pixels
            .iter()
            .flat_map(|m| match m {
                Some(m) if m.anisotropic => m.t.as_vec3().to_array(),
                _ => [f32::NAN; 3],
            })
            .collect()
    }
}

/// The tangent of pixel `p` (projected off the normal `n`), turned by the edit's rotation
/// (`sin`, `cos`) inside its region, and whether the map has one (else a tangent of its own).
fn edited_frame(
    tangents: &[f32],
    n: DVec3,
    p: usize,
    edits: &Edits,
    sin: f64,
    cos: f64,
) -> (DVec3, bool) {
    let tangent = vec_at(tangents, p)
        .map(|t| t - t.dot(n) * n)
        .and_then(|t| t.try_normalize());
    let anisotropic = tangent.is_some();
    let mut t = tangent.unwrap_or_else(|| tangent_basis(n).0);
    let in_region = edits.region.as_ref().is_none_or(|r| r[p]);
    if anisotropic && in_region && edits.tangent_rotation_deg != 0.0 {
        t = t * cos + n.cross(t) * sin;
    }
    (t, anisotropic)
}

impl Relighter {
    /// Scales linear RGB by `2^exposure_stops` and clamps to `[0, 1]` (NaN becomes 0), ready
    /// for an sRGB-encoded 8-bit picture.
    pub fn tone_map(rgb: &[f32], exposure_stops: f64) -> Vec<f32> {
        let k = 2f64.powf(exposure_stops) as f32;
        rgb.iter()
            .map(|&v| {
                if v.is_nan() {
                    0.0
                } else {
                    (v * k).clamp(0.0, 1.0)
                }
            })
            .collect()
    }

    /// PSNR (dB) of an image against a reference, both `H x W x 3`, over the pixels inside `mask`
    /// (all when `None`): `20 log10(peak / RMS)`, `peak` the reference's largest value there.
    /// Infinite when the images are equal; NaN when no pixel is compared.
    pub fn image_psnr(image: &[f32], reference: &[f32], mask: Option<&[bool]>) -> f64 {
        let (mut sse, mut count, mut peak) = (0.0f64, 0usize, 0.0f64);
        for (p, (a, b)) in image
            .chunks_exact(3)
            .zip(reference.chunks_exact(3))
            .enumerate()
        {
            if mask.is_some_and(|m| !m[p]) {
                continue;
            }
            for c in 0..3 {
                sse += (a[c] as f64 - b[c] as f64).powi(2);
                peak = peak.max(b[c] as f64);
            }
            count += 3;
        }
        if count == 0 {
            return f64::NAN;
        }
        crate::appearance::fit::psnr_db(peak, (sse / count as f64).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{Scene, TangentField};

    /// Maps of a sphere with one Ward material, in the scene's (wide-axis = t) frames.
    fn sphere_maps(size: usize, w: &Ward) -> (Scene, WardMaps) {
        let scene = Scene::sphere(size, TangentField::Circular);
        let n = scene.n_pixels();
        let fill3 = |v: [f64; 3]| -> Vec<f32> {
            (0..n)
                .flat_map(|p| {
                    if scene.mask[p] {
                        v.map(|x| x as f32)
                    } else {
                        [f32::NAN; 3]
                    }
                })
                .collect()
        };
        let fill1 = |v: f64| -> Vec<f32> {
            (0..n)
                .map(|p| if scene.mask[p] { v as f32 } else { f32::NAN })
                .collect()
        };
        // The scene's tangent is the model's y axis when alpha_y is the larger.
        let (at, ab) = (w.alpha_x.max(w.alpha_y), w.alpha_x.min(w.alpha_y));
        let maps = WardMaps {
            width: size,
            height: size,
            normals: scene.gt_normals(),
            tangents: scene.gt_tangents(),
            kd: fill3(w.kd),
            ks: fill3(w.ks),
            alpha_t: fill1(at),
            alpha_b: fill1(ab),
        };
        (scene, maps)
    }

    #[test]
    fn relighting_true_parameters_reproduces_the_renderer() {
        let w = Ward::new([0.3, 0.2, 0.1], [0.4, 0.5, 0.6], 0.1, 0.4);
        let (scene, maps) = sphere_maps(24, &w);
        let r = Relighter::new(&maps, &Edits::default()).unwrap();
        for l in [DVec3::new(0.3, 0.4, 0.8), DVec3::new(-0.7, 0.1, 0.5)] {
            let a = r.render(l);
            let b = scene.render(&w, l);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() <= 1e-5 * y.abs().max(1.0), "{x} {y}");
            }
        }
    }

    #[test]
    fn relighting_a_gltf_fit_reproduces_the_renderer_at_its_exposure() {
        let g = GltfPbr::new([0.8, 0.6, 0.3], 0.7, 0.35, 0.5);
        let scene = Scene::sphere(20, TangentField::Circular);
        let n = scene.n_pixels();
        let masked = |v: f32, p: usize| if scene.mask[p] { v } else { f32::NAN };
        let maps = GltfMaps {
            width: 20,
            height: 20,
            normals: scene.gt_normals(),
            tangents: scene.gt_tangents(),
            base_color: (0..n)
                .flat_map(|p| g.base_color.map(|c| masked(c as f32, p)))
                .collect(),
            metallic: (0..n).map(|p| masked(0.7, p)).collect(),
            roughness: (0..n).map(|p| masked(0.35, p)).collect(),
            anisotropy: (0..n).map(|p| masked(0.5, p)).collect(),
            exposure: 2.5,
        };
        let r = Relighter::gltf(&maps, &Edits::default()).unwrap();
        for l in [DVec3::new(0.3, 0.4, 0.8), DVec3::new(-0.7, 0.1, 0.5)] {
            let a = r.render(l);
            let b = scene.render(&g, l);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - 2.5 * y).abs() <= 1e-5 * y.abs().max(1.0), "{x} {y}");
            }
        }
        // No specular albedo to scale; an exposure that is not positive is refused.
        let spec = Edits {
            specular_scale: 2.0,
            ..Edits::default()
        };
        assert!(Relighter::gltf(&maps, &spec).is_err());
        let dark = GltfMaps {
            exposure: 0.0,
            ..maps
        };
        assert!(Relighter::gltf(&dark, &Edits::default()).is_err());
    }

    #[test]
    fn scales_edit_the_parts() {
        let w = Ward::new([0.3, 0.2, 0.1], [0.4, 0.5, 0.6], 0.1, 0.4);
        let (scene, maps) = sphere_maps(16, &w);
        let l = DVec3::new(0.2, 0.1, 0.9).normalize();
        let diffuse_only = Relighter::new(
            &maps,
            &Edits {
                specular_scale: 0.0,
                ..Edits::default()
            },
        )
        .unwrap()
        .render(l);
        let lambert = Ward::new(w.kd, [0.0; 3], 0.1, 0.4);
        let want = scene.render(&lambert, l);
        for (x, y) in diffuse_only.iter().zip(&want) {
            assert!((x - y).abs() < 1e-6);
        }
        let glossy = Relighter::new(
            &maps,
            &Edits {
                diffuse_scale: 0.5,
                specular_scale: 2.0,
                roughness_scale: 0.5,
                ..Edits::default()
            },
        )
        .unwrap()
        .render(l);
        let want = scene.render(
            &Ward::new(
                w.kd.map(|v| v * 0.5),
                w.ks.map(|v| v * 2.0),
                w.alpha_x * 0.5,
                w.alpha_y * 0.5,
            ),
            l,
        );
        for (x, y) in glossy.iter().zip(&want) {
            assert!((x - y).abs() <= 1e-5 * y.abs().max(1.0), "{x} {y}");
        }
    }

    #[test]
    fn tangent_rotation_changes_only_the_region() {
        let w = Ward::new([0.2; 3], [0.6; 3], 0.08, 0.4);
        let (scene, maps) = sphere_maps(32, &w);
        let region: Vec<bool> = (0..32 * 32).map(|p| (p % 32) < 16).collect();
        let edits = Edits {
            tangent_rotation_deg: 90.0,
            region: Some(region.clone()),
            ..Edits::default()
        };
        let plain = Relighter::new(&maps, &Edits::default()).unwrap();
        let edited = Relighter::new(&maps, &edits).unwrap();
        let l = DVec3::new(-0.3, 0.2, 0.93).normalize();
        let (a, b) = (plain.render(l), edited.render(l));
        let mut changed = 0;
        for p in 0..32 * 32 {
            let same = a[p * 3..p * 3 + 3] == b[p * 3..p * 3 + 3];
            if !region[p] {
                assert!(same, "pixel {p} outside the region changed");
            } else if scene.mask[p] && !same {
                changed += 1;
            }
        }
        let inside = (0..32 * 32).filter(|&p| region[p] && scene.mask[p]).count();
        // Far from the highlight the lobe vanishes in f32 and only the diffuse part is left.
        assert!(changed > inside * 2 / 3, "{changed} of {inside}");
        // A 90-degree rotation swaps the roles of t and b: the same as swapping the roughnesses.
        let mut swapped = maps.clone();
        std::mem::swap(&mut swapped.alpha_t, &mut swapped.alpha_b);
        let c = Relighter::new(&swapped, &Edits::default())
            .unwrap()
            .render(l);
        for p in (0..32 * 32).filter(|&p| region[p]) {
            for k in 0..3 {
                let (x, y) = (b[p * 3 + k], c[p * 3 + k]);
                assert!((x - y).abs() <= 1e-5 * y.abs().max(1.0));
            }
        }
        // The edited tangent field is perpendicular to the original inside the region.
        let (t0, t1) = (plain.tangents(), edited.tangents());
        for p in (0..32 * 32).filter(|&p| region[p] && scene.mask[p]) {
            let d: f32 = (0..3).map(|k| t0[p * 3 + k] * t1[p * 3 + k]).sum();
            assert!(d.abs() < 1e-5);
        }
    }

    #[test]
    fn frames_are_those_rendered() {
        let w = Ward::new([0.2; 3], [0.6; 3], 0.08, 0.4);
        let (scene, mut maps) = sphere_maps(16, &w);
        // One pixel isotropic: it keeps a model, with a tangent of its own.
        let iso = (0..16 * 16).find(|&p| scene.mask[p]).unwrap();
        maps.tangents[iso * 3..iso * 3 + 3].fill(f32::NAN);
        let r = Relighter::new(&maps, &Edits::default()).unwrap();
        let tangents = r.tangents();
        for p in 0..16 * 16 {
            let Some((t, n, aniso)) = r.frame(p) else {
                assert!(!scene.mask[p], "pixel {p} inside lost its model");
                continue;
            };
            assert!((t.length() - 1.0).abs() < 1e-9 && t.dot(n).abs() < 1e-9);
            assert_eq!(aniso, p != iso);
            if aniso {
                assert!((tangents[p * 3] - t.x as f32).abs() < 1e-6);
            } else {
                assert!(tangents[p * 3].is_nan());
            }
        }
        assert!(r.frame(16 * 16).is_none());
    }

    #[test]
    fn bad_edits_are_refused() {
        let w = Ward::new([0.2; 3], [0.6; 3], 0.08, 0.4);
        let (_, maps) = sphere_maps(8, &w);
        let e = Edits {
            region: Some(vec![true; 10]),
            ..Edits::default()
        };
        assert!(matches!(Relighter::new(&maps, &e), Err(Error::BadMask(_))));
        let e = Edits {
            roughness_scale: 0.0,
            ..Edits::default()
        };
        assert!(Relighter::new(&maps, &e).is_err());
        let mut short = maps.clone();
        short.kd.pop();
        assert!(Relighter::new(&short, &Edits::default()).is_err());
    }

    #[test]
    fn psnr_and_tone_map() {
        let a = vec![1.0f32, 0.5, 0.0, 0.2, 0.2, 0.2];
        assert!(Relighter::image_psnr(&a, &a, None).is_infinite());
        let mut b = a.clone();
        b[0] = 0.9;
        // RMS = sqrt(0.01 / 6), peak 1.
        let want = 20.0 * (1.0 / (0.01f64 / 6.0).sqrt()).log10();
        assert!((Relighter::image_psnr(&b, &a, None) - want).abs() < 1e-4);
        assert_eq!(
            Relighter::tone_map(&[0.25, f32::NAN, 2.0], 1.0),
            vec![0.5, 0.0, 1.0]
        );
    }
}
