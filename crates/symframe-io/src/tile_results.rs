//! Per-tile result files of the tiled pipeline: one small binary file per finished tile, written
//! atomically (temporary file, then rename), so a folder of them is always a set of complete
//! tiles, whatever interrupted the run.
//!
//! File `tile-NNNNNN.bin`: a 48-byte header (magic `SYMFTILE`, format version, the job's
//! fingerprint, the tile index, the pixel count, a checksum), then 48 bytes per pixel in tile
//! order (little-endian): status (1 byte), source (1 byte, a [`PixelSource`] code), 2 padding,
//! normal (3 x f32), tangent (3 x f32), confidence, anisotropy, tangent confidence, residual
//! (f32), objective evaluations (u32). The job fingerprint covers everything the results
//! depend on (inputs, mask, parameters, tile size, this format's version): a file of another
//! job is stale. The checksum (XXH3-64 of the
//! header's first 40 bytes and the records) catches a file changed after it was written (disk
//! or copy errors, a stray edit): such a file is [`TileFile::Corrupt`], recomputed by a resumed
//! run and named by a merge, never trusted.

use std::io::Read;
use std::path::{Path, PathBuf};

use symframe::{PixelRecord, PixelSource, PixelStatus};

use crate::atomic::write_bytes;
use crate::error::{Error, Result};

const MAGIC: &[u8; 8] = b"SYMFTILE";
/// Format version of tile result files (1 had neither a source byte nor a checksum, 3 no
/// tangent confidence, 4 no residual). A file of another version is stale: recomputed by a
/// resumed run, refused by a merge.
pub const TILE_RESULT_VERSION: u32 = 5;
const HEADER: usize = 48;
/// Bytes of the header the checksum covers (all but the checksum itself).
const HEADER_SUMMED: usize = 40;
const RECORD: usize = 48;

/// The length in bytes of the result file of a tile of `n` pixels (header and records).
pub fn tile_result_len(n: usize) -> u64 {
    HEADER as u64 + RECORD as u64 * n as u64
}

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

fn header(job: u64, t: usize, n: usize) -> [u8; HEADER_SUMMED] {
    let mut b = [0u8; HEADER_SUMMED];
    b[..8].copy_from_slice(MAGIC);
    b[8..12].copy_from_slice(&TILE_RESULT_VERSION.to_le_bytes());
    b[16..24].copy_from_slice(&job.to_le_bytes());
    b[24..32].copy_from_slice(&(t as u64).to_le_bytes());
    b[32..40].copy_from_slice(&(n as u64).to_le_bytes());
    b
}

/// The checksum of a tile file: XXH3-64 over the header's first 40 bytes and the records.
fn checksum(head: &[u8], records: &[u8]) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    h.update(head);
    h.update(records);
    h.digest()
}

/// Writes tile `t`'s records atomically to `path`, tagged with the job's fingerprint.
pub fn write_tile_result(path: &Path, job: u64, t: usize, records: &[PixelRecord]) -> Result<()> {
    let mut b = Vec::with_capacity(HEADER + RECORD * records.len());
    b.extend_from_slice(&header(job, t, records.len()));
    b.extend_from_slice(&[0u8; 8]);
    for r in records {
        b.extend_from_slice(&[status_code(r.status), r.source as u8, 0, 0]);
        for v in r.normal.iter().chain(&r.tangent).chain([
            &r.confidence,
            &r.anisotropy,
            &r.tangent_confidence,
            &r.residual,
        ]) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&r.evals.to_le_bytes());
    }
    let sum = checksum(&b[..HEADER_SUMMED], &b[HEADER..]);
    b[HEADER_SUMMED..HEADER].copy_from_slice(&sum.to_le_bytes());
    write_bytes(path, &b)
}

/// What a tile result file holds, as far as a run that wants tile `t` of job `job` is concerned.
#[derive(Debug)]
pub enum TileFile {
    /// No such file: the tile is still to do.
    Missing,
    /// A verified result of this tile of this job.
    Done,
    /// A well-formed file of another job, tile or format version (e.g. parameters changed):
    /// to be recomputed, nothing to warn about.
    Stale,
    /// A file that cannot be read, does not parse or fails its checksum: to be recomputed, with
    /// this error (which names the file) shown as a warning.
    Corrupt(Error),
}

/// Why a tile file's bytes are not the wanted result.
enum Problem {
    Stale(String),
    Corrupt(String),
}

/// Parses and verifies a tile result file's bytes as tile `t`'s `n` records of job `job`.
fn parse(b: &[u8], job: u64, t: usize, n: usize) -> std::result::Result<Vec<PixelRecord>, Problem> {
    check_head(b, b.len() as u64, job, t, n)?;
    records(b)
}

/// Checks a tile result file of `len` bytes whose first bytes are `b` (the whole file, or only
/// its header when its length is not the expected one: then the file is never read whole, and
/// this always fails) as tile `t`'s `n` records of job `job`; the checksum is verified when `b`
/// is the whole file.
fn check_head(
    b: &[u8],
    len: u64,
    job: u64,
    t: usize,
    n: usize,
) -> std::result::Result<(), Problem> {
    check_header(b, len, job, t, n, b.len() as u64 == len)
}

/// [`check_head`] of `b`, the whole file when `whole` (its checksum then verified), else its
/// header alone (judged without the records: read before them, so that a file of the right
/// length that is not the tile's result is refused unread).
fn check_header(
    b: &[u8],
    len: u64,
    job: u64,
    t: usize,
    n: usize,
    whole: bool,
) -> std::result::Result<(), Problem> {
    use Problem::{Corrupt, Stale};
    if b.len() < 12 || &b[..8] != MAGIC {
        return Err(Corrupt("not a symframe tile result".into()));
    }
    let version = u32::from_le_bytes(b[8..12].try_into().unwrap());
    if version != TILE_RESULT_VERSION {
        return Err(Stale(format!(
            "tile result of another format version ({version}, expected {TILE_RESULT_VERSION})"
        )));
    }
    if len < HEADER as u64
        || b.len() < HEADER
        || !(len - HEADER as u64).is_multiple_of(RECORD as u64)
    {
        return Err(Corrupt(format!(
            "corrupt tile result (truncated or extended: {len} bytes)"
        )));
    }
    let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    if whole && checksum(&b[..HEADER_SUMMED], &b[HEADER..]) != u64_at(HEADER_SUMMED) {
        return Err(Corrupt("corrupt tile result (checksum mismatch)".into()));
    }
    let pixels = u64_at(32);
    let in_file = (len - HEADER as u64) / RECORD as u64;
    if pixels != in_file {
        return Err(Corrupt(format!(
            "corrupt tile result ({pixels} pixels in the header, {in_file} in the file)"
        )));
    }
    if u64_at(16) != job {
        return Err(Stale(format!(
            "tile result of another job (fingerprint {:016x}, expected {job:016x})",
            u64_at(16)
        )));
    }
    // (A file of another length than the tile's fails here: its header's pixels are those of
    // its length.)
    if u64_at(24) != t as u64 || pixels != n as u64 {
        return Err(Stale(format!(
            "not the result of tile {t} ({n} pixels) but of tile {} ({pixels} pixels)",
            u64_at(24)
        )));
    }
    Ok(())
}

/// The records of a checked tile result file's bytes.
fn records(b: &[u8]) -> std::result::Result<Vec<PixelRecord>, Problem> {
    use Problem::Corrupt;
    b[HEADER..]
        .chunks_exact(RECORD)
        .enumerate()
        .map(|(k, r)| {
            let f = |k: usize| f32::from_le_bytes(r[4 + 4 * k..8 + 4 * k].try_into().unwrap());
            Ok(PixelRecord {
                status: status_from(r[0]).ok_or_else(|| {
                    Corrupt(format!(
                        "corrupt tile result (bad status {} of pixel {k})",
                        r[0]
                    ))
                })?,
                source: PixelSource::from_code(r[1]).ok_or_else(|| {
                    Corrupt(format!(
                        "corrupt tile result (bad source {} of pixel {k})",
                        r[1]
                    ))
                })?,
                normal: [f(0), f(1), f(2)],
                tangent: [f(3), f(4), f(5)],
                confidence: f(6),
                anisotropy: f(7),
                tangent_confidence: f(8),
                residual: f(9),
                evals: u32::from_le_bytes(r[44..48].try_into().unwrap()),
            })
        })
        .collect()
}

/// Parses tile result bytes (any job, tile and size), for fuzzing the parser: the records, or
/// the one-line reason they were refused.
#[cfg(any(test, feature = "fuzzing"))]
pub fn parse_tile_result_bytes(b: &[u8]) -> std::result::Result<Vec<PixelRecord>, String> {
    let field = |o: usize| {
        b.get(o..o + 8)
            .map_or(0, |s| u64::from_le_bytes(s.try_into().unwrap()))
    };
    parse(b, field(16), field(24) as usize, field(32) as usize).map_err(|p| match p {
        Problem::Stale(m) | Problem::Corrupt(m) => m,
    })
}

/// Reads and verifies tile `t`'s `n` records of job `job` from `path`: `None` if there is no
/// such file. Anything but a regular file (a link, FIFO, device) is an error and never opened
/// ([`crate::open_own_file`]); a file whose length is not that of the tile is judged by its
/// header alone, and no more than the tile's length is ever read (a sparse file of gigabytes
/// there is never read whole).
fn load(
    path: &Path,
    job: u64,
    t: usize,
    n: usize,
) -> Result<Option<std::result::Result<Vec<PixelRecord>, Problem>>> {
    let Some((f, len)) = crate::open_own_file(path)? else {
        return Ok(None);
    };
    let expected = tile_result_len(n);
    let mut b = Vec::new();
    (&f).take(HEADER as u64)
        .read_to_end(&mut b)
        .map_err(|e| Error::read(path, e))?;
    if len != expected {
        return Ok(Some(check_head(&b, len, job, t, n).map(|_| Vec::new())));
    }
    // The header first: a file of the tile's length that is not its result (a sparse forged
    // one of 670 MB) is refused before its records are read.
    if let Err(p) = check_header(&b, len, job, t, n, false) {
        return Ok(Some(Err(p)));
    }
    b.reserve_exact((expected - HEADER as u64) as usize);
    f.take(expected - HEADER as u64)
        .read_to_end(&mut b)
        .map_err(|e| Error::read(path, e))?;
    Ok(Some(parse(&b, job, t, n)))
}

/// What `path` holds for tile `t` (`n` pixels) of job `job`: the file (of the tile's length, a
/// few tens of kilobytes) is read and verified; a link, FIFO, device or folder there is
/// [`TileFile::Corrupt`], never opened.
pub fn check_tile_result(path: &Path, job: u64, t: usize, n: usize) -> TileFile {
    match load(path, job, t, n) {
        Ok(None) => TileFile::Missing,
        Err(e) => TileFile::Corrupt(e),
        Ok(Some(Ok(_))) => TileFile::Done,
        Ok(Some(Err(Problem::Stale(_)))) => TileFile::Stale,
        Ok(Some(Err(Problem::Corrupt(m)))) => TileFile::Corrupt(Error::invalid(path, m)),
    }
}

/// Whether `path` holds a verified result of tile `t` (`n` pixels) of job `job`
/// ([`check_tile_result`] is [`TileFile::Done`]).
pub fn tile_result_done(path: &Path, job: u64, t: usize, n: usize) -> bool {
    matches!(check_tile_result(path, job, t, n), TileFile::Done)
}

/// Reads tile `t`'s `n` records of job `job` from `path`. Errors name the file: missing, not a
/// tile result, corrupt (checksum, length or a bad record), of another job (stale) or of
/// another tile.
pub fn read_tile_result(path: &Path, job: u64, t: usize, n: usize) -> Result<Vec<PixelRecord>> {
    let missing = || Error::read(path, std::io::Error::from_raw_os_error(libc::ENOENT));
    load(path, job, t, n)?
        .ok_or_else(missing)?
        .map_err(|p| match p {
            Problem::Stale(m) | Problem::Corrupt(m) => Error::invalid(path, m),
        })
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
                tangent_confidence: 0.75,
                residual: 0.0625,
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
        assert_eq!(std::fs::metadata(&p).unwrap().len(), tile_result_len(2));
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
        assert!(matches!(check_tile_result(&p, 8, 7, 2), TileFile::Stale));
        assert!(matches!(
            check_tile_result(&d.path().join("none"), 9, 7, 2),
            TileFile::Missing
        ));
    }

    fn records(n: usize) -> Vec<PixelRecord> {
        (0..n)
            .map(|k| PixelRecord {
                status: PixelStatus::Estimated,
                source: PixelSource::Symmetry,
                normal: [0.0, 0.6, 0.8],
                tangent: [1.0, 0.0, 0.0],
                confidence: 0.5,
                anisotropy: k as f32 / n as f32,
                tangent_confidence: 0.5,
                residual: k as f32 / (2 * n) as f32,
                evals: k as u32,
            })
            .collect()
    }

    /// Asserts the file is corrupt: not done, a warning naming the file, and a read error.
    fn assert_corrupt(p: &Path, n: usize, what: &str) {
        assert!(!tile_result_done(p, 1, 3, n));
        match check_tile_result(p, 1, 3, n) {
            TileFile::Corrupt(e) => {
                let e = e.to_string();
                assert!(e.contains("tile-000003.bin: corrupt tile result"), "{e}");
                assert!(e.contains(what), "{e}");
            }
            other => panic!("{other:?}"),
        }
        let e = read_tile_result(p, 1, 3, n).unwrap_err().to_string();
        assert!(e.contains("tile-000003.bin: corrupt tile result"), "{e}");
    }

    /// Overwritten normals of a finished tile, length and header kept, fail the checksum.
    #[test]
    fn overwritten_normals_fail_the_checksum() {
        let d = tempfile::tempdir().unwrap();
        let p = tile_result_path(d.path(), 3);
        write_tile_result(&p, 1, 3, &records(64)).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        let len = b.len();
        for k in 0..64 {
            let o = HEADER + k * RECORD + 4;
            b[o..o + 12].copy_from_slice(bytemuck::cast_slice(&[1.0f32, 0.0, 0.0]));
        }
        assert_eq!(b.len(), len);
        std::fs::write(&p, &b).unwrap();
        assert_corrupt(&p, 64, "checksum mismatch");
    }

    /// One bad status byte blocked the folder for good ("bad pixel status" on every rerun).
    #[test]
    fn a_bad_status_byte_is_corrupt_not_fatal() {
        let d = tempfile::tempdir().unwrap();
        let p = tile_result_path(d.path(), 3);
        write_tile_result(&p, 1, 3, &records(8)).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        b[HEADER + 5 * RECORD] = 9;
        std::fs::write(&p, &b).unwrap();
        assert_corrupt(&p, 8, "checksum mismatch");
        // Even with the checksum recomputed (a writer bug), the status is refused, not trusted.
        let sum = checksum(&b[..HEADER_SUMMED], &b[HEADER..]);
        b[HEADER_SUMMED..HEADER].copy_from_slice(&sum.to_le_bytes());
        std::fs::write(&p, &b).unwrap();
        assert_corrupt(&p, 8, "bad status 9 of pixel 5");
        // Truncated, and garbage.
        std::fs::write(&p, &b[..b.len() - 3]).unwrap();
        assert_corrupt(&p, 8, "truncated");
        std::fs::write(&p, b"garbage").unwrap();
        match check_tile_result(&p, 1, 3, 8) {
            TileFile::Corrupt(e) => assert!(e.to_string().contains("not a symframe tile result")),
            other => panic!("{other:?}"),
        }
    }

    /// Files of the previous format (no checksum) are stale, recomputed silently.
    #[test]
    fn old_format_is_stale() {
        let d = tempfile::tempdir().unwrap();
        let p = tile_result_path(d.path(), 3);
        let mut b = header(1, 3, 0).to_vec();
        b[8..12].copy_from_slice(&1u32.to_le_bytes());
        std::fs::write(&p, &b).unwrap();
        assert!(matches!(check_tile_result(&p, 1, 3, 0), TileFile::Stale));
    }
}
