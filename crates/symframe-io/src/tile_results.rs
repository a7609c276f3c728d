//! Per-tile result files of the tiled pipeline: one small binary file per finished tile, written
//! atomically (temporary file, then rename), so a folder of them is always a set of complete
//! tiles, whatever interrupted the run.
//!
//! File `tile-NNNNNN.bin`: a 40-byte header (magic `SYMFTILE`, format version, the job's
//! fingerprint, the tile index, the pixel count), then 40 bytes per pixel in tile order
//! (little-endian): status (1 byte), source (1 byte, a [`PixelSource`] code), 2 padding, normal (3 x f32), tangent (3 x f32), confidence,
//! anisotropy (f32), objective evaluations (u32). The job fingerprint covers everything the
//! results depend on (inputs, mask, parameters, tile size): a file of another job is stale.

use std::path::{Path, PathBuf};

use symframe::{PixelRecord, PixelSource, PixelStatus};

use crate::atomic::write_bytes;
use crate::error::{Error, Result};

const MAGIC: &[u8; 8] = b"SYMFTILE";
/// Format version of tile result files.
pub const TILE_RESULT_VERSION: u32 = 2;
const HEADER: usize = 40;
const RECORD: usize = 40;

/// The result file of tile `t` in `dir`.
pub fn tile_result_path(dir: &Path, t: usize) -> PathBuf {
    dir.join(format!("tile-{t:06}.bin"))
}

fn status_code(s: PixelStatus) -> u8 {
    match s {
        PixelStatus::Estimated => 0,
        PixelStatus::Masked => 1,
        PixelStatus::NoData => 2,
        PixelStatus::Discarded => 3,
        PixelStatus::Culled => 4,
    }
}

fn status_from(c: u8) -> Option<PixelStatus> {
    Some(match c {
        0 => PixelStatus::Estimated,
        1 => PixelStatus::Masked,
        2 => PixelStatus::NoData,
        3 => PixelStatus::Discarded,
        4 => PixelStatus::Culled,
        _ => return None,
    })
}

fn header(job: u64, t: usize, n: usize) -> [u8; HEADER] {
    let mut b = [0u8; HEADER];
    b[..8].copy_from_slice(MAGIC);
    b[8..12].copy_from_slice(&TILE_RESULT_VERSION.to_le_bytes());
    b[16..24].copy_from_slice(&job.to_le_bytes());
    b[24..32].copy_from_slice(&(t as u64).to_le_bytes());
    b[32..40].copy_from_slice(&(n as u64).to_le_bytes());
    b
}

/// Writes tile `t`'s records atomically to `path`, tagged with the job's fingerprint.
pub fn write_tile_result(path: &Path, job: u64, t: usize, records: &[PixelRecord]) -> Result<()> {
    let mut b = Vec::with_capacity(HEADER + RECORD * records.len());
    b.extend_from_slice(&header(job, t, records.len()));
    for r in records {
        b.extend_from_slice(&[status_code(r.status), r.source as u8, 0, 0]);
        for v in r
            .normal
            .iter()
            .chain(&r.tangent)
            .chain([&r.confidence, &r.anisotropy])
        {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&r.evals.to_le_bytes());
    }
    write_bytes(path, &b)
}

/// Whether `path` holds tile `t`'s `n` records of job `job` (header and length checked only:
/// files are written atomically, so a well-formed header on a file of the right length means a
/// complete file).
pub fn tile_result_done(path: &Path, job: u64, t: usize, n: usize) -> bool {
    use std::io::Read;
    let Ok(mut f) = std::fs::File::open(path) else {
        return false;
    };
    let Ok(meta) = f.metadata() else {
        return false;
    };
    let mut b = [0u8; HEADER];
    meta.len() == (HEADER + RECORD * n) as u64
        && f.read_exact(&mut b).is_ok()
        && b == header(job, t, n)
}

/// Reads tile `t`'s `n` records of job `job` from `path`. Errors name the file: missing, not a
/// tile result, of another job (stale) or of another tile.
pub fn read_tile_result(path: &Path, job: u64, t: usize, n: usize) -> Result<Vec<PixelRecord>> {
    let b = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    if b.len() < HEADER || &b[..8] != MAGIC {
        return Err(Error::invalid(path, "not a symframe tile result"));
    }
    let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    if u32::from_le_bytes(b[8..12].try_into().unwrap()) != TILE_RESULT_VERSION {
        return Err(Error::invalid(
            path,
            "tile result of another format version",
        ));
    }
    if u64_at(16) != job {
        return Err(Error::invalid(
            path,
            format!(
                "tile result of another job (fingerprint {:016x}, expected {job:016x})",
                u64_at(16)
            ),
        ));
    }
    if u64_at(24) != t as u64 || u64_at(32) != n as u64 || b.len() != HEADER + RECORD * n {
        return Err(Error::invalid(
            path,
            format!("not the result of tile {t} ({n} pixels)"),
        ));
    }
    b[HEADER..]
        .chunks_exact(RECORD)
        .map(|r| {
            let f = |k: usize| f32::from_le_bytes(r[4 + 4 * k..8 + 4 * k].try_into().unwrap());
            Ok(PixelRecord {
                status: status_from(r[0])
                    .ok_or_else(|| Error::invalid(path, "bad pixel status"))?,
                source: PixelSource::from_code(r[1])
                    .ok_or_else(|| Error::invalid(path, "bad pixel source"))?,
                normal: [f(0), f(1), f(2)],
                tangent: [f(3), f(4), f(5)],
                confidence: f(6),
                anisotropy: f(7),
                evals: u32::from_le_bytes(r[36..40].try_into().unwrap()),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_checks() {
        let d = tempfile::tempdir().unwrap();
        let recs = vec![
            PixelRecord::MASKED,
            PixelRecord {
                status: PixelStatus::Estimated,
                source: PixelSource::Symmetry,
                normal: [0.0, 0.6, 0.8],
                tangent: [1.0, 0.0, -0.0],
                confidence: 0.5,
                anisotropy: 0.25,
                evals: 123,
            },
        ];
        let p = tile_result_path(d.path(), 7);
        assert!(p.ends_with("tile-000007.bin"));
        assert!(!tile_result_done(&p, 9, 7, 2));
        write_tile_result(&p, 9, 7, &recs).unwrap();
        assert!(tile_result_done(&p, 9, 7, 2));
        assert!(!tile_result_done(&p, 8, 7, 2));
        assert!(!tile_result_done(&p, 9, 6, 2));
        let back = read_tile_result(&p, 9, 7, 2).unwrap();
        assert_eq!(back[1], recs[1]);
        assert_eq!(back[0].status, PixelStatus::Masked);
        assert_eq!(back[0].source, PixelSource::None);
        assert!(back[0].normal[0].is_nan());
        let e = read_tile_result(&p, 8, 7, 2).unwrap_err().to_string();
        assert!(
            e.contains("tile-000007.bin: tile result of another job"),
            "{e}"
        );
        let e = read_tile_result(&p, 9, 7, 3).unwrap_err().to_string();
        assert!(e.contains("not the result of tile 7"), "{e}");
        // Only the renamed file exists: no temporary left.
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
    }
}
