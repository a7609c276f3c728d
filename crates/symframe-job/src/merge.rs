//! Shards: the manifest a finished shard writes, and the merge of the shards of one job into
//! the full maps.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use symframe::{EstimateMaps, PixelCounts};
use symframe_io::TileGrid;

use crate::maps_out::{result_warnings, write_estimate_outputs, TileResults, WriteOptions};
use crate::outdir::{in_locked_output, lock_warnings, OutputDir};
use crate::tiles::{peak_rss_bytes, tile_path, TILES_DIR};
use crate::{Control, Progress, Stage};

/// A shard's manifest, written once all its tiles are done.
pub const MANIFEST: &str = "shard.json";
pub(crate) const MANIFEST_FORMAT: &str = "symframe-shard";
pub(crate) const MANIFEST_VERSION: u32 = 1;

/// What a merge produced (the maps are written, never held whole).
#[derive(Debug, Clone)]
pub struct MergeOutcome {
    /// What happened to the pixels of the maps written.
    pub pixels: PixelCounts,
    /// The maps written, when the caller asked to keep them (34 bytes per pixel).
    pub maps: Option<EstimateMaps>,
    /// How many shards were merged.
    pub shards: usize,
}

/// A finished shard's manifest (`shard.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardManifest {
    /// Always `symframe-shard`.
    pub format: String,
    /// Manifest format version.
    pub version: u32,
    /// The job's fingerprint (hex): shards of one job have the same.
    pub job: String,
    /// This shard's number, 1-based.
    pub shard: usize,
    /// Number of shards.
    pub of: usize,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Tile side.
    pub tile_size: usize,
    /// Number of tiles of the whole image.
    pub n_tiles: usize,
    /// The tiles this shard holds.
    pub tiles: Vec<usize>,
    /// The shard's own report (what `report.json` of a full run would say, for its tiles).
    pub report: serde_json::Value,
}

impl ShardManifest {
    /// Checks the numbers a manifest declares before any of them sizes or divides anything:
    /// shard `1..=of`, sizes within the image limits, a positive tile size, the tile count of
    /// the grid, tiles that exist.
    fn validate(&self, path: &Path) -> Result<()> {
        use symframe_io::limits::{MAX_PIXELS, MAX_SIDE};
        let bad = |what: String| {
            anyhow::anyhow!("{}: not a valid shard manifest: {what}", path.display())
        };
        if self.of == 0 || self.shard == 0 || self.shard > self.of {
            return Err(bad(format!(
                "shard {} of {} (expected 1 <= shard <= of)",
                self.shard, self.of
            )));
        }
        let (w, h) = (self.width, self.height);
        // Sides checked before they are multiplied: no product below can overflow.
        let sides_ok = (1..=MAX_SIDE).contains(&w) && (1..=MAX_SIDE).contains(&h);
        if !sides_ok || w as u64 * h as u64 > MAX_PIXELS as u64 {
            return Err(bad(format!(
                "image of {w}x{h} pixels (1 to {MAX_SIDE} per side, at most {MAX_PIXELS} pixels)"
            )));
        }
        if self.tile_size == 0 || self.tile_size > MAX_SIDE {
            return Err(bad(format!("tile size {}", self.tile_size)));
        }
        // At most MAX_PIXELS tiles (one-pixel tiles), so the count fits any usize.
        let n = (w.div_ceil(self.tile_size) as u64 * h.div_ceil(self.tile_size) as u64) as usize;
        if self.n_tiles != n {
            return Err(bad(format!(
                "{} tiles recorded, {n} expected",
                self.n_tiles
            )));
        }
        if self.tiles.len() > n {
            return Err(bad(format!(
                "{} tiles listed, the image has {n}",
                self.tiles.len()
            )));
        }
        if let Some(t) = self.tiles.iter().find(|&&t| t >= n) {
            return Err(bad(format!("tile {t} does not exist")));
        }
        // A shard holds the tiles t with t % of == shard - 1, and no more shards than tiles
        // are made: a forged count or a tile of another shard is refused.
        if self.of > n {
            return Err(bad(format!("{} shards of an image of {n} tiles", self.of)));
        }
        if let Some(t) = self.tiles.iter().find(|&&t| t % self.of != self.shard - 1) {
            return Err(bad(format!(
                "tile {t} is not one of shard {} of {}",
                self.shard, self.of
            )));
        }
        Ok(())
    }

    /// Parses `text` (the content of `path`) as a manifest of this version and checks what it
    /// declares ([`ShardManifest::validate`]).
    fn parse(text: &str, path: &Path) -> Result<Self> {
        let m: ShardManifest = serde_json::from_str(text)
            .with_context(|| format!("{}: not a shard manifest", path.display()))?;
        if m.format != MANIFEST_FORMAT || m.version != MANIFEST_VERSION {
            bail!(
                "{}: not a shard manifest of this version (format {} {})",
                path.display(),
                m.format,
                m.version
            );
        }
        m.validate(path)?;
        Ok(m)
    }

    /// The job fingerprint as a number.
    fn job_u64(&self, path: &Path) -> Result<u64> {
        u64::from_str_radix(&self.job, 16)
            .with_context(|| format!("{}: bad job fingerprint '{}'", path.display(), self.job))
    }
}

/// Writes a shard manifest atomically.
/// Parses and checks a shard manifest as `merge` does before it reads any tile (for the fuzz
/// target): the number of tiles it lists.
#[cfg(any(test, feature = "fuzzing"))]
pub fn check_shard_manifest(text: &str) -> Result<usize> {
    ShardManifest::parse(text, Path::new(MANIFEST)).map(|m| m.tiles.len())
}

pub(crate) fn write_manifest(out: &Path, m: &ShardManifest) -> Result<()> {
    // Atomic, through a temporary file created anew (never opened through a planted link).
    let text = serde_json::to_string_pretty(m)? + "\n";
    Ok(symframe_io::write_bytes(
        &out.join(MANIFEST),
        text.as_bytes(),
    )?)
}

/// A short list of tile numbers: the first few (`first`, at most 12 shown) of `total`, and how
/// many more.
fn list_tiles(first: &[usize], total: usize) -> String {
    let shown: Vec<String> = first.iter().take(12).map(|t| t.to_string()).collect();
    if total > shown.len() {
        format!("{} and {} more", shown.join(", "), total - shown.len())
    } else {
        shown.join(", ")
    }
}

/// The tiles of `0..n` missing from `covered` (sorted, without repeats), without a list of
/// them all (`n` comes from a manifest: nothing of its size is allocated): the first 12, how
/// many in all, and the first 13 shard numbers (1-based, of `of` shards) that hold them.
fn missing_tiles(covered: &[usize], n: usize, of: usize) -> (Vec<usize>, usize, Vec<usize>) {
    let mut first = Vec::new();
    let mut shards = std::collections::BTreeSet::new();
    let mut start = 0;
    for end in covered.iter().copied().chain([n]) {
        // The gap start..end; its tiles' shards are t % of + 1, distinct for up to `of`
        // consecutive tiles, so 25 of them hold 13 new ones if there are (12 seen at most).
        first.extend((start..end).take(12 - first.len().min(12)));
        for t in (start..end).take(of.min(25)) {
            if shards.len() < 13 {
                shards.insert(t % of + 1);
            }
        }
        start = end + 1;
    }
    (first, n - covered.len(), shards.into_iter().collect())
}

/// `symframe merge`: checks the shards belong to one job and cover every tile, then writes the
/// usual outputs from the shards' tiles a band at a time (the maps are returned whole only if
/// `keep_maps` asks for them).
pub fn merge(
    shards: &[PathBuf],
    output: &Path,
    keep_maps: bool,
    ctl: &Control,
) -> Result<MergeOutcome> {
    in_locked_output(output, ctl, |ctl, out, warnings| {
        run(shards, (out, warnings), keep_maps, ctl)
    })
}

/// The merge in the locked output folder `out`, `warnings` holding those told so far (the
/// folder's recovery's).
fn run(
    shards: &[PathBuf],
    (out, warnings): (&OutputDir, &Mutex<Vec<String>>),
    keep_maps: bool,
    ctl: &Control,
) -> Result<MergeOutcome> {
    let t0 = Instant::now();
    if shards.is_empty() {
        bail!("no shard folders given");
    }
    let mut manifests: Vec<(PathBuf, ShardManifest)> = Vec::new();
    for dir in shards {
        let path = dir.join(MANIFEST);
        if !dir.is_dir() {
            bail!("{}: no such shard folder", dir.display());
        }
        let text = match symframe_io::read_text_bounded(
            &path,
            "a shard manifest",
            symframe_io::limits::MAX_TEXT_FILE_BYTES,
        ) {
            Ok(t) => t,
            Err(symframe_io::Error::Read { source, .. })
                if source.kind() == std::io::ErrorKind::NotFound =>
            {
                bail!(
                "{}: not a finished shard (no {MANIFEST}); run its `symframe estimate ... --tiles K/N` \
                 command again to finish it",
                dir.display()
                )
            }
            Err(e) => return Err(e.into()),
        };
        manifests.push((dir.clone(), ShardManifest::parse(&text, &path)?));
    }
    let (first_dir, first) = &manifests[0];
    for (dir, m) in &manifests[1..] {
        if (m.width, m.height, m.tile_size, m.of)
            != (first.width, first.height, first.tile_size, first.of)
        {
            bail!(
                "{}: shard {}/{} of {}x{} pixels in {}-pixel tiles does not belong with {} \
                 (shard {}/{} of {}x{} in {}-pixel tiles)",
                dir.display(),
                m.shard,
                m.of,
                m.width,
                m.height,
                m.tile_size,
                first_dir.display(),
                first.shard,
                first.of,
                first.width,
                first.height,
                first.tile_size
            );
        }
        if m.job != first.job {
            bail!(
                "{}: belongs to another job than {} (different inputs or parameters: job {} vs {})",
                dir.display(),
                first_dir.display(),
                m.job,
                first.job
            );
        }
    }
    let job = first.job_u64(&first_dir.join(MANIFEST))?;
    let grid = TileGrid::new(first.width, first.height, first.tile_size);
    if grid.n_tiles() != first.n_tiles {
        bail!(
            "{}: {} tiles recorded, {} expected",
            first_dir.join(MANIFEST).display(),
            first.n_tiles,
            grid.n_tiles()
        );
    }
    // Nothing the size of the declared image is allocated before the tiles listed cover the
    // grid and every tile's file is there with the length of its records: what the manifests
    // declare is then backed by files of 48 bytes per pixel (a forged `shard.json` of a few
    // bytes may declare gigabytes of maps: docs/performance.md, "Memory model").
    // Which shard folder holds each tile: the first that lists it (memory in proportion to the
    // manifests' lists, already read).
    let mut listed: Vec<(usize, usize)> = manifests
        .iter()
        .enumerate()
        .flat_map(|(i, (_, m))| m.tiles.iter().map(move |&t| (t, i)))
        .collect();
    listed.sort_unstable();
    listed.dedup_by_key(|&mut (t, _)| t);
    if listed.len() < grid.n_tiles() {
        let covered: Vec<usize> = listed.iter().map(|&(t, _)| t).collect();
        let (shown, count, absent) = missing_tiles(&covered, grid.n_tiles(), first.of);
        let mut shards: Vec<String> = absent
            .iter()
            .take(12)
            .map(|k| format!("{k}/{}", first.of))
            .collect();
        if absent.len() > 12 {
            shards.push("and others".into());
        }
        bail!(
            "missing tiles {} of {}: shard{} {} not given",
            list_tiles(&shown, count),
            grid.n_tiles(),
            if absent.len() > 1 { "s" } else { "" },
            shards.join(", ")
        );
    }
    // Tiles are in range (validated) and without repeats: listed[t] is tile t's.
    let owner: Vec<usize> = listed.into_iter().map(|(_, i)| i).collect();
    for (t, &i) in owner.iter().enumerate() {
        let path = tile_path(&manifests[i].0.join(TILES_DIR), t);
        // Not through a link, and only a regular file (a FIFO or device there is never opened).
        let meta = fs::symlink_metadata(&path).map_err(|source| symframe_io::Error::Read {
            path: path.clone(),
            source,
        })?;
        if !meta.file_type().is_file() {
            bail!(
                "{}: not a regular file ({}), not a result of tile {t}",
                path.display(),
                if meta.file_type().is_symlink() {
                    "a symbolic link"
                } else if meta.is_dir() {
                    "a folder"
                } else {
                    "a FIFO, device or socket"
                }
            );
        }
        let len = meta.len();
        let expected = symframe_io::tile_results::tile_result_len(grid.tile_pixels(t));
        if len != expected {
            bail!(
                "{}: not a result of tile {t} ({} pixels): {len} bytes, {expected} expected",
                path.display(),
                grid.tile_pixels(t)
            );
        }
    }
    // The report: the first shard's, with the whole image's counts and the shards' timings.
    let mut report = first.report.clone();
    let shard_timings: Vec<serde_json::Value> = manifests
        .iter()
        .map(|(dir, m)| {
            serde_json::json!({
                "folder": dir,
                "shard": format!("{}/{}", m.shard, m.of),
                "tiles": m.report.get("tiles").cloned().unwrap_or_default(),
                "timings": m.report.get("timings").cloned().unwrap_or_default(),
            })
        })
        .collect();
    let estimate_s: f64 = manifests
        .iter()
        .filter_map(|(_, m)| m.report.pointer("/timings/estimate_s")?.as_f64())
        .sum();
    report["tiles"] = serde_json::json!({
        "size": grid.tile,
        "count": grid.n_tiles(),
        "shards": first.of,
    });
    report["shards"] = serde_json::Value::Array(shard_timings);
    // The recovery's warnings, told when the folder was locked, then the shards' own.
    let mut warnings: Vec<String> = lock_warnings(warnings).clone();
    for (_, m) in &manifests {
        for w in m.report["warnings"].as_array().into_iter().flatten() {
            warnings.push(format!(
                "shard {}/{}: {}",
                m.shard,
                m.of,
                w.as_str().unwrap_or_default()
            ));
        }
    }
    let total = grid.n_tiles() as u64;
    let path_of = |t: usize| tile_path(&manifests[owner[t]].0.join(TILES_DIR), t);
    let tiles = TileResults {
        grid,
        job,
        path_of: &path_of,
    };
    let opts = WriteOptions {
        normal_png: symframe_io::NormalPng::OpenGl,
        keep_maps,
        covered: None,
        on_tiles: &|n| ctl.report(Progress::new(Stage::Merging, n as u64, total)),
        // The shards' reports carry no light directions: a merge draws no `lights.png`.
        lights: None,
    };
    let (summary, maps) = write_estimate_outputs(out, &tiles, &opts, ctl, |write_s, summary| {
        report["pixels"] = serde_json::to_value(summary.counts)?;
        report["sources"] = serde_json::to_value(&summary.sources)?;
        report["evals_per_pixel"] =
            serde_json::json!(summary.evals as f64 / summary.counts.estimated.max(1) as f64);
        // The reach warning needs the rig: each shard's own warnings (above) carry it.
        for w in result_warnings(&summary.counts, None, summary.light_axes) {
            ctl.warn(&w);
            warnings.push(w);
        }
        report["warnings"] = serde_json::json!(warnings);
        report["timings"] = serde_json::json!({
            "estimate_s_all_shards": estimate_s,
            "merge_s": t0.elapsed().as_secs_f64() - write_s,
            "write_s": write_s,
            "total_s": t0.elapsed().as_secs_f64(),
            "peak_rss_bytes": peak_rss_bytes(),
        });
        Ok(report)
    })?;
    Ok(MergeOutcome {
        pixels: summary.counts,
        maps,
        shards: manifests.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fuzz target's seed passes; what a forged manifest declares beyond its own numbers
    /// is refused before anything is sized by it.
    #[test]
    fn manifests_are_checked_before_they_size_anything() {
        let seed = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fuzz/seeds/shard_manifest/two_of_four.json"
        );
        let text = std::fs::read_to_string(seed).unwrap();
        assert_eq!(check_shard_manifest(&text).unwrap(), 2);
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let forged = |key: &str, value: serde_json::Value| {
            let mut m = v.clone();
            m[key] = value;
            check_shard_manifest(&m.to_string())
        };
        assert!(
            forged("width", 65536.into()).is_err(),
            "tile count no longer matches"
        );
        assert!(forged("width", (u64::MAX).into()).is_err());
        assert!(forged("tile_size", 0.into()).is_err());
        assert!(forged("shard", 3.into()).is_err());
        assert!(forged("tiles", serde_json::json!([0, 4])).is_err());
        assert!(forged("tiles", serde_json::json!([0, 1, 2, 3, 0])).is_err());
        assert!(forged("version", 2.into()).is_err());
        // More shards than tiles, and a tile of another shard.
        assert!(forged("of", (u64::MAX).into()).is_err());
        assert!(forged("of", 5.into()).is_err());
        assert!(forged("tiles", serde_json::json!([0, 1])).is_err());
    }

    #[test]
    fn missing_tiles_are_listed_from_the_gaps() {
        // 9 tiles of 3 shards, shard 2 (tiles 1, 4, 7) not given.
        assert_eq!(
            missing_tiles(&[0, 2, 3, 5, 6, 8], 9, 3),
            (vec![1, 4, 7], 3, vec![2])
        );
        // 134 million tiles declared, 3 covered: the first 12 and the count, no list of all.
        let n = 1 << 27;
        let (first, count, shards) = missing_tiles(&[0, 1, 2], n, 1);
        assert_eq!((first, count, shards), ((3..15).collect(), n - 3, vec![1]));
        // Many shards: the first 13 of those missing.
        let (_, _, shards) = missing_tiles(&[], 1000, 500);
        assert_eq!(shards, (1..=13).collect::<Vec<_>>());
        let (_, _, shards) = missing_tiles(&[0, 1, 2, 3], 1000, usize::MAX);
        assert_eq!(shards, (5..=17).collect::<Vec<_>>());
        assert_eq!(missing_tiles(&[0, 1], 2, 2), (vec![], 0, vec![]));
    }
}
