//! Keyword options, named like the command line's flags (`theta_d_max` for `--theta-d-max`),
//! checked as the command line checks them.

use std::collections::BTreeSet;
use std::path::PathBuf;

use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use symframe::{
    Baseline, BaselineParams, CosineMode, EstimatorParams, Fallback, Interpolation, RigOptions,
};
use symframe_io::{CacheOptions, DecodeOptions, Gamma};
use symframe_job::{CacheConfig, LightModel, MethodConfig, NearOptions, Shard};

/// The keyword options of one call; every key must be read by the end ([`Options::finish`]).
pub struct Options<'py> {
    func: &'static str,
    dict: Option<Bound<'py, PyDict>>,
    known: BTreeSet<&'static str>,
}

impl<'py> Options<'py> {
    /// The options of `func` (for messages).
    pub fn new(func: &'static str, dict: Option<Bound<'py, PyDict>>) -> Self {
        Self {
            func,
            dict,
            known: BTreeSet::new(),
        }
    }

    /// The value of `key` (`None` when absent or `None`).
    pub fn get<T: FromPyObjectOwned<'py>>(&mut self, key: &'static str) -> PyResult<Option<T>> {
        self.known.insert(key);
        let Some(d) = &self.dict else {
            return Ok(None);
        };
        match d.get_item(key)? {
            None => Ok(None),
            Some(v) if v.is_none() => Ok(None),
            Some(v) => v.extract::<T>().map(Some).map_err(|_| {
                let ty = v
                    .get_type()
                    .name()
                    .map(|n| n.to_string())
                    .unwrap_or_else(|_| "?".into());
                PyTypeError::new_err(format!(
                    "{}(): {key} must be {}, got {ty}",
                    self.func,
                    describe(std::any::type_name::<T>())
                ))
            }),
        }
    }

    /// The value of `key`, or `default`.
    pub fn or<T: FromPyObjectOwned<'py>>(&mut self, key: &'static str, default: T) -> PyResult<T> {
        Ok(self.get(key)?.unwrap_or(default))
    }

    /// Rejects keys that were not read.
    pub fn finish(self) -> PyResult<()> {
        let Some(d) = &self.dict else {
            return Ok(());
        };
        for k in d.keys() {
            let k: String = k.extract()?;
            if !self.known.contains(k.as_str()) {
                let known: Vec<&str> = self.known.iter().copied().collect();
                return Err(PyTypeError::new_err(format!(
                    "{}() got an unexpected keyword argument '{k}' (options: {})",
                    self.func,
                    known.join(", ")
                )));
            }
        }
        Ok(())
    }
}

/// What a Rust type is, in Python words.
fn describe(type_name: &str) -> &'static str {
    match type_name.rsplit("::").next().unwrap_or("") {
        "f64" | "f32" => "a number",
        "u32" | "u64" | "usize" => "a non-negative integer",
        "bool" => "True or False",
        "String" => "a string",
        "PathBuf" => "a path (str or os.PathLike)",
        _ => "of another type",
    }
}

fn bad(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

/// The method and its parameters (`method`, `theta_d_max`, `min_confidence`, `min_anisotropy`,
/// `light_error`, `noise`, `min_domain`, `cosine`, `cosine_power`, `fallback`, `no_tangents`,
/// `reference`).
pub fn method(o: &mut Options) -> PyResult<MethodConfig> {
    let d = EstimatorParams::default();
    let theta_d_max = o.or("theta_d_max", RigOptions::default().theta_d_max_deg)?;
    let min_confidence: f32 = o.or("min_confidence", d.min_confidence)?;
    let min_anisotropy: f32 = o.or("min_anisotropy", d.min_anisotropy)?;
    let light_error: Option<f64> = o.get("light_error")?;
    let noise = noise_model(o)?;
    let min_domain: Option<u32> = o.get("min_domain")?;
    let cosine: String = o.or("cosine", "auto".to_string())?;
    let cosine_power: f64 = o.or("cosine_power", 0.5)?;
    let fallback: String = o.or("fallback", "auto".to_string())?;
    let no_tangents: bool = o.or("no_tangents", false)?;
    let reference: bool = o.or("reference", false)?;
    let method: String = o.or("method", "symmetry".to_string())?;

    if !(theta_d_max > 0.0 && theta_d_max <= 90.0) {
        return Err(bad(format!(
            "theta_d_max must be in (0, 90] degrees, got {theta_d_max}"
        )));
    }
    for (name, v) in [
        ("min_confidence", min_confidence),
        ("min_anisotropy", min_anisotropy),
    ] {
        if !(0.0..=1.0).contains(&v) {
            return Err(bad(format!("{name} must be in [0, 1], got {v}")));
        }
    }
    let light_error = light_error.unwrap_or(noise.light_error_deg);
    if !(0.0..=10.0).contains(&light_error) {
        return Err(bad(format!(
            "light_error must be in [0, 10] degrees, got {light_error}"
        )));
    }
    if !(0.0..=1.0).contains(&cosine_power) {
        return Err(bad(format!(
            "cosine_power must be in [0, 1], got {cosine_power}"
        )));
    }
    if min_domain == Some(0) {
        return Err(bad("min_domain must be at least 1".into()));
    }
    let cosine = match cosine.as_str() {
        "auto" => CosineMode::Auto,
        "cross" => CosineMode::CrossMultiplied,
        "raw" => CosineMode::Raw,
        "compensated" => CosineMode::Compensated(cosine_power),
        other => {
            return Err(bad(format!(
                "cosine must be one of auto, cross, raw, compensated, got '{other}'"
            )))
        }
    };
    let fallback = match fallback.as_str() {
        "auto" => Fallback::Auto,
        "none" => Fallback::None,
        other => return Err(bad(format!("fallback must be auto or none, got '{other}'"))),
    };
    let baseline = match method.as_str() {
        "symmetry" => None,
        "woodham" => Some(Baseline::Woodham),
        "woodham-robust" => Some(Baseline::WoodhamRobust),
        "max-reflectance" => Some(Baseline::MaxReflectance),
        "highlight-centroid" => Some(Baseline::HighlightCentroid),
        other => {
            return Err(bad(format!(
                "method must be one of symmetry, woodham, woodham-robust, max-reflectance, \
                 highlight-centroid, got '{other}'"
            )))
        }
    };
    Ok(match baseline {
        None => MethodConfig::Symmetry {
            rig: RigOptions {
                theta_d_max_deg: theta_d_max,
            },
            params: EstimatorParams {
                cosine,
                fallback,
                min_domain,
                min_confidence,
                min_anisotropy,
                noise: symframe::NoiseModel {
                    light_error_deg: light_error,
                    ..noise
                },
                tangents: !no_tangents,
                interpolation: if reference {
                    Interpolation::Exact
                } else {
                    Interpolation::Fast
                },
                ..d
            },
        },
        Some(method) => MethodConfig::Baseline {
            method,
            params: BaselineParams::default(),
        },
    })
}

/// The capture's noise model (`noise`: a dict as `Dataset.noise` gives it and report.json's
/// `parameters.noise` records it), or the noise-free default.
fn noise_model(o: &mut Options) -> PyResult<symframe::NoiseModel> {
    let Some(d) = o.get::<Bound<'_, PyDict>>("noise")? else {
        return Ok(symframe::NoiseModel::default());
    };
    let text: String = d
        .py()
        .import("json")?
        .call_method1("dumps", (d,))?
        .extract()?;
    serde_json::from_str(&text).map_err(|e| bad(format!("noise: {e}")))
}

/// How images are decoded (`gamma`, `linear` its alias for `gamma="linear"`, `saturation`).
pub fn decode(o: &mut Options) -> PyResult<DecodeOptions> {
    let d = DecodeOptions::default();
    let linear: bool = o.or("linear", false)?;
    let gamma = match o.get::<String>("gamma")?.as_deref() {
        None if linear => Gamma::Linear,
        None => d.gamma,
        Some("srgb") if !linear => Gamma::Srgb,
        Some("linear") => Gamma::Linear,
        Some(other) => {
            return Err(bad(format!(
                "gamma must be 'srgb' or 'linear' (linear=True is 'linear'), got '{other}'"
            )))
        }
    };
    let saturation: f32 = o.or("saturation", d.saturation)?;
    if !(saturation > 0.0 && saturation <= 1.0) {
        return Err(bad(format!(
            "saturation must be in (0, 1], got {saturation}"
        )));
    }
    Ok(DecodeOptions {
        gamma,
        saturation,
        ..DecodeOptions::default()
    })
}

/// The tile cache (`cache`, `no_keep_cache`, `trust_mtime`, `tile_size`, `decode_memory`,
/// `cache_format`).
pub fn cache(o: &mut Options) -> PyResult<CacheConfig> {
    let d = CacheOptions::default();
    let dir: Option<PathBuf> = o.get("cache")?;
    let remove_after: bool = o.or("no_keep_cache", false)?;
    let trust_mtime: bool = o.or("trust_mtime", d.trust_mtime)?;
    let tile: usize = o.or("tile_size", d.tile)?;
    let decode_memory: usize = o.or("decode_memory", d.batch_bytes >> 20)?;
    let format = match o.or("cache_format", "auto".to_string())?.as_str() {
        "auto" => symframe_io::CacheFormat::Auto,
        "f32" => symframe_io::CacheFormat::F32,
        "f16" => symframe_io::CacheFormat::F16,
        "u8" => symframe_io::CacheFormat::U8,
        "u16" => symframe_io::CacheFormat::U16,
        other => {
            return Err(bad(format!(
                "cache_format must be auto, f32, f16, u8 or u16, got {other}"
            )))
        }
    };
    if !(1..=4096).contains(&tile) {
        return Err(bad(format!("tile_size must be in [1, 4096], got {tile}")));
    }
    if decode_memory == 0 || decode_memory > (1 << 30) {
        return Err(bad(format!(
            "decode_memory must be at least 1 MiB, got {decode_memory}"
        )));
    }
    Ok(CacheConfig {
        dir,
        remove_after,
        options: CacheOptions {
            tile,
            batch_bytes: decode_memory << 20,
            trust_mtime,
            format,
        },
    })
}

/// `tiles="K/N"`: one shard.
pub fn shard(o: &mut Options) -> PyResult<Option<Shard>> {
    let s: Option<String> = o.get("tiles")?;
    s.map(|s| s.parse::<Shard>().map_err(|e| bad(format!("tiles: {e}"))))
        .transpose()
}

/// Near lights (`light_model`: `"auto"`, `"near"` or `"distant"`; `distance`, `rig_tile`,
/// `rounds`), as `--light-model`, `--distance`, `--rig-tile` and `--rounds`.
pub fn near(o: &mut Options) -> PyResult<NearOptions> {
    let d = NearOptions::default();
    let model: String = o.or("light_model", "auto".to_string())?;
    let model = match model.as_str() {
        "auto" => LightModel::Auto,
        "near" => LightModel::Near,
        "distant" => LightModel::Distant,
        other => {
            return Err(bad(format!(
                "light_model must be 'auto', 'near' or 'distant', got '{other}'"
            )))
        }
    };
    let distance: Option<f64> = o.get("distance")?;
    if distance.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
        return Err(bad(format!(
            "distance must be a positive depth, got {}",
            distance.unwrap_or_default()
        )));
    }
    let tile: usize = o.or("rig_tile", d.tile)?;
    let rounds: usize = o.or("rounds", d.max_iterations)?;
    if tile == 0 || rounds == 0 {
        return Err(bad("rig_tile and rounds must be at least 1".to_string()));
    }
    Ok(NearOptions {
        model,
        distance,
        tile,
        max_iterations: rounds,
        ..d
    })
}
