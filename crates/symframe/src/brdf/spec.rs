//! Building a model from a short text spec (for the command line).
//!
//! Grammar (whitespace around tokens is ignored, names and keys are case-insensitive):
//!
//! ```text
//! spec   := name [ ':' params ]
//! params := param { ',' param }
//! param  := key '=' value
//! value  := number                      scalars; colours broadcast to R = G = B
//!         | number '/' number '/' number  colours only: R/G/B
//! ```
//!
//! | name (aliases) | keys (default) |
//! | --- | --- |
//! | `lambertian` (`lambert`) | `albedo` (0.8) |
//! | `ward` | `kd` (0.5), `ks` (0.5), `ax` (0.1), `ay` (0.5), `alpha` (sets both ax and ay) |
//! | `blinn-phong` (`phong`) | `kd` (0.5), `ks` (0.5), `e` (50) |
//! | `torrance-sparrow` (`ts`) | `kd` (0.5), `ks` (0.5), `sigma` (0.2) |
//! | `cook-torrance` (`ct`) | `kd` (0.5), `ks` (0.5), `m` (0.2), `ior` (1.5) |
//! | `ashikhmin-shirley` (`as`) | `rd` (0.5), `rs` (0.05), `nu` (100), `nv` (10) |
//! | `ggx` | `kd` (0.1), `f0` (0.9), `ax` (0.3), `ay` (0.1), `alpha` (sets both) |
//! | `beckmann` | `kd` (0), `f0` (0.9), `ax` (0.25), `ay` (0.06), `alpha` (sets both) |
//! | `gltf` | `base` (0.5), `metallic` (0), `roughness` (0.5), `anisotropy` (0) |
//! | `merl` | `path` (required; the rest of the spec after `path=`, commas allowed) |
//! | `merl-trilinear` | as `merl`, with trilinear interpolation between bins |
//!
//! Colour keys: `albedo`, `kd`, `ks`, `rd`, `rs`, `f0`, `base`. Unknown keys, repeated keys, missing
//! values, non-finite numbers and out-of-range parameters (negative colours, non-positive
//! roughness/exponent/index) are errors; the message lists the valid keys. Missing keys take
//! the defaults above. Every model's [`Brdf::name`] prints a spec that parses back to the same
//! model (MERL only when it was read from a file).
//!
//! Examples: `lambertian:albedo=0.8`, `ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5`,
//! `ggx:kd=0.1,f0=0.9,ax=0.3,ay=0.1`, `cook-torrance:kd=0.1/0.2/0.3,ks=0.5,m=0.2,ior=1.5`,
//! `merl:path=data/blue-metallic-paint.binary`.

use super::Brdf;
use super::{
    AshikhminShirley, Beckmann, BlinnPhong, CookTorrance, Ggx, GltfPbr, Lambertian, Merl,
    TorranceSparrow, Ward,
};

/// Formats a colour for a spec: one number when all channels are equal, else `r/g/b`. Uses
/// Rust's shortest round-tripping float formatting.
pub(crate) fn fmt_rgb(c: &[f64; 3]) -> String {
    if c[0] == c[1] && c[1] == c[2] {
        format!("{}", c[0])
    } else {
        format!("{}/{}/{}", c[0], c[1], c[2])
    }
}

/// Parsed `key=value` pairs of one spec, checked against the model's valid keys.
struct Params {
    model: &'static str,
    valid: &'static [&'static str],
    pairs: Vec<(String, String)>,
}

impl Params {
    fn parse(
        model: &'static str,
        valid: &'static [&'static str],
        rest: Option<&str>,
    ) -> Result<Params, String> {
        let mut pairs: Vec<(String, String)> = Vec::new();
        let rest = rest.map(str::trim).unwrap_or("");
        if !rest.is_empty() {
            for item in rest.split(',') {
                let item = item.trim();
                let Some((k, v)) = item.split_once('=') else {
                    return Err(format!(
                        "{model}: expected key=value, got '{item}' (valid keys: {})",
                        valid.join(", ")
                    ));
                };
                let k = k.trim().to_ascii_lowercase();
                let v = v.trim().to_string();
                if !valid.contains(&k.as_str()) {
                    return Err(format!(
                        "{model}: unknown key '{k}' (valid keys: {})",
                        valid.join(", ")
                    ));
                }
                if pairs.iter().any(|(pk, _)| *pk == k) {
                    return Err(format!("{model}: key '{k}' given twice"));
                }
                if v.is_empty() {
                    return Err(format!("{model}: key '{k}' has no value"));
                }
                pairs.push((k, v));
            }
        }
        Ok(Params {
            model,
            valid,
            pairs,
        })
    }

    fn raw(&self, key: &str) -> Option<&str> {
        debug_assert!(self.valid.contains(&key));
        self.pairs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn number(&self, key: &str, text: &str) -> Result<f64, String> {
        let x: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("{}: {key}={text} is not a number", self.model))?;
        if !x.is_finite() {
            return Err(format!("{}: {key}={text} is not finite", self.model));
        }
        Ok(x)
    }

    /// A colour (scalar broadcast or r/g/b), each channel non-negative.
    fn rgb(&self, key: &str, default: f64) -> Result<[f64; 3], String> {
        let Some(text) = self.raw(key) else {
            return Ok([default; 3]);
        };
        let parts: Vec<&str> = text.split('/').collect();
        let c = match parts.len() {
            1 => [self.number(key, parts[0])?; 3],
            3 => [
                self.number(key, parts[0])?,
                self.number(key, parts[1])?,
                self.number(key, parts[2])?,
            ],
            _ => {
                return Err(format!(
                    "{}: {key}={text}: a colour is one number or r/g/b",
                    self.model
                ))
            }
        };
        if c.iter().any(|&x| x < 0.0) {
            return Err(format!("{}: {key}={text} must be non-negative", self.model));
        }
        Ok(c)
    }

    /// A strictly positive scalar.
    fn positive(&self, key: &str, default: f64) -> Result<f64, String> {
        let Some(text) = self.raw(key) else {
            return Ok(default);
        };
        let x = self.number(key, text)?;
        if x <= 0.0 {
            return Err(format!("{}: {key}={text} must be positive", self.model));
        }
        Ok(x)
    }

    /// Two roughnesses `ax`, `ay`, where `alpha` sets both (and an explicit one overrides it).
    fn alpha_pair(&self, dx: f64, dy: f64) -> Result<(f64, f64), String> {
        let (dx, dy) = match self.raw("alpha") {
            Some(_) => {
                let a = self.positive("alpha", 1.0)?;
                (a, a)
            }
            None => (dx, dy),
        };
        Ok((self.positive("ax", dx)?, self.positive("ay", dy)?))
    }
}

/// The model names accepted by [`parse_model`] (canonical spellings).
pub(crate) const MODEL_NAMES: &[&str] = &[
    "lambertian",
    "ward",
    "blinn-phong",
    "torrance-sparrow",
    "cook-torrance",
    "ashikhmin-shirley",
    "ggx",
    "beckmann",
    "gltf",
    "merl",
    "merl-trilinear",
];

/// Builds a BRDF from a spec such as `ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5` (grammar in the
/// module documentation). Errors are human-readable and list the valid names or keys.
pub fn parse_model(spec: &str) -> Result<Box<dyn Brdf>, String> {
    let spec = spec.trim();
    let (name, rest) = match spec.split_once(':') {
        Some((n, r)) => (n.trim(), Some(r)),
        None => (spec, None),
    };
    let name = name.to_ascii_lowercase();
    match name.as_str() {
        "lambertian" | "lambert" => {
            let p = Params::parse("lambertian", &["albedo"], rest)?;
            Ok(Box::new(Lambertian::new(p.rgb("albedo", 0.8)?)))
        }
        "ward" => {
            let p = Params::parse("ward", &["kd", "ks", "ax", "ay", "alpha"], rest)?;
            let (ax, ay) = p.alpha_pair(0.1, 0.5)?;
            Ok(Box::new(Ward::new(
                p.rgb("kd", 0.5)?,
                p.rgb("ks", 0.5)?,
                ax,
                ay,
            )))
        }
        "blinn-phong" | "blinnphong" | "phong" => {
            let p = Params::parse("blinn-phong", &["kd", "ks", "e"], rest)?;
            Ok(Box::new(BlinnPhong::new(
                p.rgb("kd", 0.5)?,
                p.rgb("ks", 0.5)?,
                p.positive("e", 50.0)?,
            )))
        }
        "torrance-sparrow" | "ts" => {
            let p = Params::parse("torrance-sparrow", &["kd", "ks", "sigma"], rest)?;
            Ok(Box::new(TorranceSparrow::new(
                p.rgb("kd", 0.5)?,
                p.rgb("ks", 0.5)?,
                p.positive("sigma", 0.2)?,
            )))
        }
        "cook-torrance" | "ct" => {
            let p = Params::parse("cook-torrance", &["kd", "ks", "m", "ior"], rest)?;
            Ok(Box::new(CookTorrance::new(
                p.rgb("kd", 0.5)?,
                p.rgb("ks", 0.5)?,
                p.positive("m", 0.2)?,
                p.positive("ior", 1.5)?,
            )))
        }
        "ashikhmin-shirley" | "as" => {
            let p = Params::parse("ashikhmin-shirley", &["rd", "rs", "nu", "nv"], rest)?;
            Ok(Box::new(AshikhminShirley::new(
                p.rgb("rd", 0.5)?,
                p.rgb("rs", 0.05)?,
                p.positive("nu", 100.0)?,
                p.positive("nv", 10.0)?,
            )))
        }
        "ggx" => {
            let p = Params::parse("ggx", &["kd", "f0", "ax", "ay", "alpha"], rest)?;
            let (ax, ay) = p.alpha_pair(0.3, 0.1)?;
            let f0 = p.rgb("f0", 0.9)?;
            if f0.iter().any(|&x| x > 1.0) {
                return Err(format!("ggx: f0={} must be at most 1", fmt_rgb(&f0)));
            }
            Ok(Box::new(Ggx::new(p.rgb("kd", 0.1)?, f0, ax, ay)))
        }
        "beckmann" => {
            let p = Params::parse("beckmann", &["kd", "f0", "ax", "ay", "alpha"], rest)?;
            let (ax, ay) = p.alpha_pair(0.25, 0.06)?;
            let f0 = p.rgb("f0", 0.9)?;
            if f0.iter().any(|&x| x > 1.0) {
                return Err(format!("beckmann: f0={} must be at most 1", fmt_rgb(&f0)));
            }
            Ok(Box::new(Beckmann::new(p.rgb("kd", 0.0)?, f0, ax, ay)))
        }
        "gltf" => {
            let p = Params::parse(
                "gltf",
                &["base", "metallic", "roughness", "anisotropy"],
                rest,
            )?;
            let base = p.rgb("base", 0.5)?;
            let unit = |key: &str, default: f64| -> Result<f64, String> {
                let x = match p.raw(key) {
                    Some(t) => p.number(key, t)?,
                    None => default,
                };
                if !(0.0..=1.0).contains(&x) {
                    return Err(format!("gltf: {key}={x} must be in [0, 1]"));
                }
                Ok(x)
            };
            let roughness = unit("roughness", 0.5)?;
            if base.iter().any(|&x| x > 1.0) || roughness == 0.0 {
                return Err(format!(
                    "gltf: base={} must be at most 1 and roughness={roughness} positive",
                    fmt_rgb(&base)
                ));
            }
            Ok(Box::new(GltfPbr::new(
                base,
                unit("metallic", 0.0)?,
                roughness,
                unit("anisotropy", 0.0)?,
            )))
        }
        "merl" | "merl-trilinear" => {
            // The path may contain ',' or '=': everything after "path=" is the path.
            let rest = rest.map(str::trim).unwrap_or("");
            let path = rest
                .strip_prefix("path=")
                .or_else(|| rest.strip_prefix("PATH="))
                .map(str::trim)
                .filter(|p| !p.is_empty())
                .ok_or_else(|| {
                    format!("{name}: expected {name}:path=FILE.binary, got '{name}:{rest}' (valid keys: path)")
                })?;
            let trilinear = name == "merl-trilinear";
            Merl::read(path)
                .map(|m| Box::new(m.with_trilinear(trilinear)) as Box<dyn Brdf>)
                .map_err(|e| e.to_string())
        }
        _ => Err(format!(
            "unknown BRDF model '{name}' (valid: {}; aliases lambert, phong, ts, ct, as)",
            MODEL_NAMES.join(", ")
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;
    use crate::brdf::TangentAxis;

    /// Same values on a set of direction pairs.
    fn same_model(a: &dyn Brdf, b: &dyn Brdf) -> bool {
        direction_pairs(7, 200)
            .into_iter()
            .all(|(l, v)| a.eval(l, v) == b.eval(l, v))
    }

    #[test]
    fn examples_parse_to_the_right_models() {
        let m = parse_model("lambertian:albedo=0.8").unwrap();
        assert_eq!(
            m.eval(glam::DVec3::Z, glam::DVec3::Z),
            [0.8 / std::f64::consts::PI; 3]
        );
        let w = parse_model("ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5").unwrap();
        assert!(same_model(
            w.as_ref(),
            &Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5)
        ));
        assert_eq!(w.tangent_axis(), TangentAxis::Y);
        let g = parse_model("ggx:kd=0.1,f0=0.9,ax=0.3,ay=0.1").unwrap();
        assert!(same_model(
            g.as_ref(),
            &Ggx::new([0.1; 3], [0.9; 3], 0.3, 0.1)
        ));
        assert_eq!(g.tangent_axis(), TangentAxis::X);
        let bk = parse_model("beckmann:kd=0,f0=1/0.71/0.29,ax=0.25,ay=0.06").unwrap();
        assert!(same_model(
            bk.as_ref(),
            &Beckmann::new([0.0; 3], [1.0, 0.71, 0.29], 0.25, 0.06)
        ));
        assert_eq!(bk.name(), "beckmann:kd=0,f0=1/0.71/0.29,ax=0.25,ay=0.06");
        let a = parse_model(" AS : rd = 0.1/0.2/0.3 , rs=0.05, nu=100, nv=10 ").unwrap();
        assert!(same_model(
            a.as_ref(),
            &AshikhminShirley::new([0.1, 0.2, 0.3], [0.05; 3], 100.0, 10.0)
        ));
        let c = parse_model("cook-torrance:kd=0.1/0.2/0.3,ks=0.5,m=0.2,ior=1.5").unwrap();
        assert!(same_model(
            c.as_ref(),
            &CookTorrance::new([0.1, 0.2, 0.3], [0.5; 3], 0.2, 1.5)
        ));
        let t = parse_model("torrance-sparrow:kd=0.2,ks=0.8,sigma=0.1").unwrap();
        assert!(same_model(
            t.as_ref(),
            &TorranceSparrow::new([0.2; 3], [0.8; 3], 0.1)
        ));
        let b = parse_model("blinn-phong:kd=0.2,ks=0.8,e=30").unwrap();
        assert!(same_model(
            b.as_ref(),
            &BlinnPhong::new([0.2; 3], [0.8; 3], 30.0)
        ));
        // alpha sets both roughnesses; an explicit one overrides it.
        let w = parse_model("ward:alpha=0.2,ay=0.3").unwrap();
        assert!(same_model(
            w.as_ref(),
            &Ward::new([0.5; 3], [0.5; 3], 0.2, 0.3)
        ));
        // Defaults.
        let d = parse_model("ward").unwrap();
        assert!(same_model(
            d.as_ref(),
            &Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5)
        ));
    }

    #[test]
    fn names_round_trip() {
        let specs = [
            "lambertian:albedo=0.8/0.5/0.125",
            "ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5",
            "blinn-phong:kd=0.25,ks=0.7,e=42.5",
            "torrance-sparrow:kd=0.1,ks=0.9,sigma=0.3",
            "cook-torrance:kd=0.1/0.2/0.3,ks=0.6,m=0.15,ior=1.7",
            "ashikhmin-shirley:rd=0.3,rs=0.04/0.05/0.06,nu=1000,nv=10",
            "ggx:kd=0,f0=0.9,ax=0.3,ay=0.1",
            "ggx:kd=0.1,f0=0.9,ax=0.30000000000000004,ay=0.1",
        ];
        for s in specs {
            let m = parse_model(s).unwrap();
            assert_eq!(m.name(), s, "canonical name");
            let again = parse_model(&m.name()).unwrap();
            assert!(same_model(m.as_ref(), again.as_ref()), "{s}");
        }
        // Aliases print canonical names.
        assert_eq!(
            parse_model("ts:kd=0.5,ks=0.5,sigma=0.2").unwrap().name(),
            "torrance-sparrow:kd=0.5,ks=0.5,sigma=0.2"
        );
    }

    #[test]
    fn merl_spec_reads_the_file() {
        let path =
            std::env::temp_dir().join(format!("symframe-spec-{}-a,b=c.binary", std::process::id()));
        Merl::from_brdf(&Lambertian::new([0.5; 3]))
            .write(&path)
            .unwrap();
        let spec = format!("merl:path={}", path.display());
        let spec_lin = format!("merl-trilinear:path={}", path.display());
        let m = parse_model(&spec);
        let lin = parse_model(&spec_lin);
        std::fs::remove_file(&path).unwrap();
        for (m, spec) in [(m.unwrap(), spec), (lin.unwrap(), spec_lin)] {
            assert_eq!(m.name(), spec);
            let f = m.eval(glam::DVec3::Z, glam::DVec3::Z);
            assert!((f[0] - 0.5 / std::f64::consts::PI).abs() < 1e-12);
        }
        let e = parse_model("merl:path=/nonexistent/x.binary")
            .err()
            .unwrap();
        assert!(e.contains("/nonexistent/x.binary"), "{e}");
        let e = parse_model("merl").err().unwrap();
        assert!(e.contains("path"), "{e}");
        let e = parse_model("merl:file=x.binary").err().unwrap();
        assert!(e.contains("path"), "{e}");
    }

    #[test]
    fn errors_are_helpful() {
        let e = parse_model("ward:kd=0.5,alpha_x=0.1").err().unwrap();
        assert!(
            e.contains("unknown key 'alpha_x'") && e.contains("kd, ks, ax, ay, alpha"),
            "{e}"
        );
        let e = parse_model("phong:kd=0.5,kd=0.2").err().unwrap();
        assert!(e.contains("twice"), "{e}");
        let e = parse_model("velvet:x=1").err().unwrap();
        assert!(
            e.contains("unknown BRDF model 'velvet'") && e.contains("ggx"),
            "{e}"
        );
        let e = parse_model("ggx:kd").err().unwrap();
        assert!(e.contains("key=value"), "{e}");
        let e = parse_model("ggx:kd=").err().unwrap();
        assert!(e.contains("no value"), "{e}");
        let e = parse_model("ggx:kd=abc").err().unwrap();
        assert!(e.contains("not a number"), "{e}");
        let e = parse_model("ggx:kd=0.1/0.2").err().unwrap();
        assert!(e.contains("r/g/b"), "{e}");
        let e = parse_model("ggx:kd=-0.1").err().unwrap();
        assert!(e.contains("non-negative"), "{e}");
        let e = parse_model("ggx:f0=1.5").err().unwrap();
        assert!(e.contains("at most 1"), "{e}");
        let e = parse_model("ward:ax=0").err().unwrap();
        assert!(e.contains("positive"), "{e}");
        let e = parse_model("ct:ior=inf").err().unwrap();
        assert!(e.contains("not finite"), "{e}");
        let e = parse_model("as:nu=-3").err().unwrap();
        assert!(e.contains("positive"), "{e}");
        let e = parse_model("ward:alpha=0.2/0.3").err().unwrap();
        assert!(e.contains("not a number"), "{e}");
    }

    #[test]
    fn fmt_rgb_broadcasts() {
        assert_eq!(fmt_rgb(&[0.5; 3]), "0.5");
        assert_eq!(fmt_rgb(&[0.1, 0.2, 0.3]), "0.1/0.2/0.3");
    }
}
