//! The fit's per-tile results on disk: a fixed-size record per pixel, read back bit for bit
//! (a resumed or merged fit sums exactly what an in-memory one does).

use std::path::Path;

use symframe::{
    GltfFit, HoldoutError, LobeFit, LobeKind, LobeModel, ModelEvidence, PixelOutcome, WardFit,
};
use symframe_io::TileFile;

use crate::tiles::TileRecord;

/// Per-tile fit outcomes: a 40-byte header (magic `SYMFFITR`, format version, the job's
/// fingerprint, the tile index, the pixel count), then [`FIT_RECORD`] bytes per pixel
/// (little-endian): outcome (1 byte: 0 masked, 1 no frame, 2 too few samples, 3 fitted Ward,
/// 4 fitted glTF, 5 fitted clear coat, 6 fitted woven), isotropic (1 byte), 6 padding, twelve
/// parameters (f64: Ward `kd`, `ks`, `alpha_t`, `alpha_b`, 0 x 4; glTF base colour, metallic,
/// roughness, strength, 0 x 5; two-lobe `kd`, `ka`, `kb`, `alpha_t`, `alpha_b`, `alpha_c`),
/// training SSE (f64), training samples (u64), iterations (u32, 4 padding), held-out SSE
/// (f64), held-out samples (u64), held-out peak (f64). Doubles, so the summary sums are those of an in-memory
/// fit bit for bit. This is the format's version.
pub(super) const FIT_TILE_VERSION: u32 = 3;
/// Every fit tile file's header: magic, format version, job, tile, pixel count.
const HEADER: usize = 40;
const FIT_RECORD: usize = 152;
/// Parameters per record.
const FIT_PARAMS: usize = 12;

/// A per-pixel record of fixed size in a fit tile file: a [`HEADER`]-byte header (magic, format
/// version, the job's fingerprint, the tile index, the pixel count), then `SIZE` bytes per pixel.
trait FixedRecord: Sized {
    /// The file's magic number.
    const MAGIC: &'static [u8; 8];
    /// The format's version.
    const VERSION: u32;
    /// Bytes per record.
    const SIZE: usize;
    /// Appends the record's `SIZE` bytes.
    fn encode(&self, b: &mut Vec<u8>);
    /// The record in `r` (`SIZE` bytes); `None` where they are not one.
    fn decode(r: &[u8]) -> Option<Self>;
}

fn header<R: FixedRecord>(job: u64, t: usize, n: usize) -> [u8; HEADER] {
    let mut b = [0u8; HEADER];
    b[..8].copy_from_slice(R::MAGIC);
    b[8..12].copy_from_slice(&R::VERSION.to_le_bytes());
    b[16..24].copy_from_slice(&job.to_le_bytes());
    b[24..32].copy_from_slice(&(t as u64).to_le_bytes());
    b[32..40].copy_from_slice(&(n as u64).to_le_bytes());
    b
}

impl FixedRecord for Option<PixelOutcome> {
    const MAGIC: &'static [u8; 8] = b"SYMFFITR";
    const VERSION: u32 = FIT_TILE_VERSION;
    const SIZE: usize = FIT_RECORD;
    fn encode(&self, b: &mut Vec<u8>) {
        encode(self, b)
    }
    fn decode(r: &[u8]) -> Option<Self> {
        decode(r)
    }
}

/// An automatic fit's evidence per pixel (magic `SYMFEVID`): a tag (0 none, 1 evidence), 7
/// padding, the four candidates' squared errors and the signal (f64, little-endian).
impl FixedRecord for Option<ModelEvidence> {
    const MAGIC: &'static [u8; 8] = b"SYMFEVID";
    const VERSION: u32 = 1;
    const SIZE: usize = 48;
    fn encode(&self, b: &mut Vec<u8>) {
        let start = b.len();
        b.push(self.is_some() as u8);
        b.resize(start + 8, 0);
        if let Some(e) = self {
            for v in e.sse.iter().chain([&e.signal]) {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b.resize(start + Self::SIZE, 0);
    }
    fn decode(r: &[u8]) -> Option<Self> {
        let f =
            |i: usize| f64::from_le_bytes(r[8 + 8 * i..16 + 8 * i].try_into().unwrap_or_default());
        match r[0] {
            0 => Some(None),
            1 => Some(Some(ModelEvidence {
                sse: [f(0), f(1), f(2), f(3)],
                signal: f(4),
            })),
            _ => None,
        }
    }
}

fn encode(r: &Option<PixelOutcome>, b: &mut Vec<u8>) {
    let start = b.len();
    // (tag, isotropic, eight parameters, sse, samples, iterations, held-out error)
    type Fitted<'a> = (bool, [f64; FIT_PARAMS], f64, usize, u32, &'a HoldoutError);
    let pad = |v: &[f64]| -> [f64; FIT_PARAMS] {
        std::array::from_fn(|i| v.get(i).copied().unwrap_or(0.0))
    };
    let (tag, fitted): (u8, Option<Fitted>) = match r {
        None => (0, None),
        Some(PixelOutcome::NoFrame) => (1, None),
        Some(PixelOutcome::TooFewSamples) => (2, None),
        Some(PixelOutcome::Fitted(f, h)) => (
            3,
            Some((
                f.isotropic,
                pad(&[
                    f.kd[0], f.kd[1], f.kd[2], f.ks[0], f.ks[1], f.ks[2], f.alpha_t, f.alpha_b,
                ]),
                f.sse,
                f.samples,
                f.iterations,
                h,
            )),
        ),
        Some(PixelOutcome::FittedGltf(f, h)) => (
            4,
            Some((
                f.isotropic,
                pad(&[
                    f.base_color[0],
                    f.base_color[1],
                    f.base_color[2],
                    f.metallic,
                    f.roughness,
                    f.anisotropy,
                ]),
                f.sse,
                f.samples,
                f.iterations,
                h,
            )),
        ),
        Some(PixelOutcome::FittedLobes(f, h)) => {
            let m = &f.model;
            let mut v = Vec::with_capacity(FIT_PARAMS);
            v.extend(m.kd.iter().chain(&m.ka).chain(&m.kb));
            v.extend([m.alpha_t, m.alpha_b, m.alpha_c]);
            let tag = match m.kind {
                LobeKind::Clearcoat => 5,
                LobeKind::Woven => 6,
            };
            (
                tag,
                Some((f.isotropic, pad(&v), f.sse, f.samples, f.iterations, h)),
            )
        }
    };
    b.extend_from_slice(&[tag, fitted.is_some_and(|f| f.0) as u8]);
    b.resize(start + 8, 0);
    if let Some((_, values, sse, samples, iterations, h)) = fitted {
        for v in values.iter().chain(&[sse]) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(samples as u64).to_le_bytes());
        b.extend_from_slice(&iterations.to_le_bytes());
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(&h.sse.to_le_bytes());
        b.extend_from_slice(&(h.samples as u64).to_le_bytes());
        b.extend_from_slice(&h.peak.to_le_bytes());
    }
    b.resize(start + FIT_RECORD, 0);
}

fn decode(r: &[u8]) -> Option<Option<PixelOutcome>> {
    let f64_at = |o: usize| f64::from_le_bytes(r[o..o + 8].try_into().unwrap_or_default());
    let u64_at = |o: usize| u64::from_le_bytes(r[o..o + 8].try_into().unwrap_or_default());
    // The parameters, then the figures, at the same places for every model.
    let par = |i: usize| f64_at(8 + 8 * i);
    let (sse, samples) = (
        f64_at(8 + 8 * FIT_PARAMS),
        u64_at(16 + 8 * FIT_PARAMS) as usize,
    );
    let iterations = u32::from_le_bytes(
        r[24 + 8 * FIT_PARAMS..28 + 8 * FIT_PARAMS]
            .try_into()
            .unwrap_or_default(),
    );
    let hold = || HoldoutError {
        sse: f64_at(32 + 8 * FIT_PARAMS),
        samples: u64_at(40 + 8 * FIT_PARAMS) as usize,
        peak: f64_at(48 + 8 * FIT_PARAMS),
    };
    Some(match r[0] {
        0 => None,
        1 => Some(PixelOutcome::NoFrame),
        2 => Some(PixelOutcome::TooFewSamples),
        3 => {
            let fit = WardFit {
                kd: [par(0), par(1), par(2)],
                ks: [par(3), par(4), par(5)],
                alpha_t: par(6),
                alpha_b: par(7),
                isotropic: r[1] != 0,
                sse,
                samples,
                iterations,
            };
            Some(PixelOutcome::Fitted(fit, hold()))
        }
        4 => {
            let fit = GltfFit {
                base_color: [par(0), par(1), par(2)],
                metallic: par(3),
                roughness: par(4),
                anisotropy: par(5),
                isotropic: r[1] != 0,
                sse,
                samples,
                iterations,
            };
            Some(PixelOutcome::FittedGltf(fit, hold()))
        }
        tag @ (5 | 6) => {
            let fit = LobeFit {
                model: LobeModel {
                    kind: if tag == 5 {
                        LobeKind::Clearcoat
                    } else {
                        LobeKind::Woven
                    },
                    kd: [par(0), par(1), par(2)],
                    ka: [par(3), par(4), par(5)],
                    kb: [par(6), par(7), par(8)],
                    alpha_t: par(9),
                    alpha_b: par(10),
                    alpha_c: par(11),
                },
                isotropic: r[1] != 0,
                sse,
                samples,
                iterations,
            };
            Some(PixelOutcome::FittedLobes(fit, hold()))
        }
        _ => return None,
    })
}

fn write_records<R: FixedRecord>(
    path: &Path,
    job: u64,
    t: usize,
    records: &[R],
) -> symframe_io::Result<()> {
    let mut b = Vec::with_capacity(HEADER + R::SIZE * records.len());
    b.extend_from_slice(&header::<R>(job, t, records.len()));
    for r in records {
        r.encode(&mut b);
    }
    symframe_io::write_bytes(path, &b)
}

fn check_records<R: FixedRecord>(path: &Path, job: u64, t: usize, n: usize) -> TileFile {
    use std::io::Read;
    // A link, FIFO, device or folder there is not a file this tool wrote: never opened
    // (a FIFO would hang the resumed fit), recomputed with a warning.
    let (f, len) = match symframe_io::open_own_file(path) {
        Ok(Some(f)) => f,
        Ok(None) => return TileFile::Missing,
        Err(e) => return TileFile::Corrupt(e),
    };
    let mut b = [0u8; HEADER];
    if len == (HEADER + R::SIZE * n) as u64
        && f.take(HEADER as u64).read_exact(&mut b).is_ok()
        && b == header::<R>(job, t, n)
    {
        TileFile::Done
    } else {
        TileFile::Stale
    }
}

fn read_records<R: FixedRecord>(
    path: &Path,
    job: u64,
    t: usize,
    n: usize,
) -> symframe_io::Result<Vec<R>> {
    let invalid = |msg: String| symframe_io::Error::Invalid {
        path: path.to_path_buf(),
        msg,
    };
    let (f, len) = symframe_io::open_own_file(path)?.ok_or_else(|| symframe_io::Error::Read {
        path: path.to_path_buf(),
        source: std::io::Error::from_raw_os_error(libc::ENOENT),
    })?;
    let expected = (HEADER + R::SIZE * n) as u64;
    let b = if len == expected {
        symframe_io::read_at_most(f, path, expected)?
    } else {
        Vec::new()
    };
    if b.len() as u64 != expected || b[..HEADER] != header::<R>(job, t, n) {
        return Err(invalid(format!(
            "not the fit result of tile {t} ({n} pixels) of this job"
        )));
    }
    b[HEADER..]
        .chunks_exact(R::SIZE)
        .map(|r| R::decode(r).ok_or_else(|| invalid("bad fit record".into())))
        .collect()
}

/// The fit's outcomes and an automatic fit's evidence: the same file layout, told apart by
/// their magic numbers.
macro_rules! fixed_tile_record {
    ($t:ty) => {
        impl TileRecord for $t {
            fn write(path: &Path, job: u64, t: usize, records: &[Self]) -> symframe_io::Result<()> {
                write_records(path, job, t, records)
            }
            fn check(path: &Path, job: u64, t: usize, n: usize) -> TileFile {
                check_records::<Self>(path, job, t, n)
            }
            fn read(path: &Path, job: u64, t: usize, n: usize) -> symframe_io::Result<Vec<Self>> {
                read_records(path, job, t, n)
            }
        }
    };
}
fixed_tile_record!(Option<PixelOutcome>);
fixed_tile_record!(Option<ModelEvidence>);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tiles::tile_path;

    #[test]
    fn fit_records_round_trip_bit_for_bit() {
        let d = tempfile::tempdir().unwrap();
        let fit = WardFit {
            kd: [0.1, 0.2, 0.3],
            ks: [1.0 / 3.0, 2.5, f64::MIN_POSITIVE],
            alpha_t: 0.07,
            alpha_b: 0.5,
            isotropic: true,
            samples: 321,
            sse: 1e-9,
            iterations: 17,
        };
        let hold = HoldoutError {
            sse: 0.25,
            samples: 12,
            peak: 3.5,
        };
        let gltf = GltfFit {
            base_color: [0.25, 1.0 / 7.0, 1.0],
            metallic: 0.3,
            roughness: 0.07,
            anisotropy: 0.9,
            isotropic: false,
            samples: 99,
            sse: 2e-7,
            iterations: 3,
        };
        let coat = LobeFit {
            model: LobeModel {
                kind: LobeKind::Clearcoat,
                kd: [0.05, 0.08, 0.25],
                ka: [0.5, 0.5, 1.0 / 3.0],
                kb: [0.04; 3],
                alpha_t: 0.35,
                alpha_b: 0.12,
                alpha_c: 0.03,
            },
            isotropic: false,
            samples: 700,
            sse: 3e-5,
            iterations: 9,
        };
        // A woven fit has no coat roughness (NaN): compared by its printed form.
        let woven = LobeFit {
            model: LobeModel {
                kind: LobeKind::Woven,
                alpha_c: f64::NAN,
                ..coat.model
            },
            isotropic: true,
            ..coat
        };
        let recs = vec![
            None,
            Some(PixelOutcome::NoFrame),
            Some(PixelOutcome::TooFewSamples),
            Some(PixelOutcome::Fitted(fit, hold)),
            Some(PixelOutcome::FittedGltf(gltf, hold)),
            Some(PixelOutcome::FittedLobes(coat, hold)),
            Some(PixelOutcome::FittedLobes(woven, hold)),
        ];
        let p = tile_path(d.path(), 3);
        let check = |job| <Option<PixelOutcome>>::check(&p, job, 3, 7);
        assert!(matches!(check(5), TileFile::Missing));
        <Option<PixelOutcome>>::write(&p, 5, 3, &recs).unwrap();
        assert!(matches!(check(5), TileFile::Done));
        assert!(matches!(check(6), TileFile::Stale));
        let back = <Option<PixelOutcome>>::read(&p, 5, 3, 7).unwrap();
        assert_eq!(back[..6], recs[..6]);
        assert_eq!(format!("{:?}", back[6]), format!("{:?}", recs[6]));
        let e = <Option<PixelOutcome>>::read(&p, 6, 3, 7)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not the fit result of tile 3"), "{e}");
    }
}
