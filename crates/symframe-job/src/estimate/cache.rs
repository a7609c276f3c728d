//! The tile cache a job runs from: where it lives, opening or building it, the mask read at
//! its size, its removal, and the fingerprints of a job's lights and mask.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Context, Result};
use glam::DVec3;
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{
    CacheInfo, CacheOptions, Dataset, DecodeOptions, Fingerprints, TileCache, TileGrid,
};

use crate::{Control, Interrupted, Progress, Stage};

/// Default folder of the tile cache inside an output folder.
pub const CACHE_DIR: &str = ".symframe-cache";

/// Where the decoded images are cached and how.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CacheConfig {
    /// Cache folder (`None`: `.symframe-cache` inside the output folder). A cache of the same
    /// inputs there is reused; several jobs (shards) may share one folder.
    pub dir: Option<PathBuf>,
    /// Remove the cache once the job has finished (default: keep it for reruns).
    pub remove_after: bool,
    /// Tile size and decoding memory.
    pub options: CacheOptions,
}

/// The cache folder of `cache` for a job writing into `output`.
pub(crate) fn cache_dir(cache: &CacheConfig, output: &Path) -> PathBuf {
    cache.dir.clone().unwrap_or_else(|| output.join(CACHE_DIR))
}

/// Feeds a mask (or its absence) into a fingerprint.
pub(crate) fn fingerprint_mask(f: &mut Fingerprint, mask: Option<&[bool]>) {
    match mask {
        None => {
            f.u64(0);
        }
        Some(m) => {
            f.u64(1);
            for chunk in m.chunks(64) {
                let bits = chunk
                    .iter()
                    .enumerate()
                    .fold(0u64, |a, (k, &b)| a | ((b as u64) << k));
                f.u64(bits);
            }
        }
    }
}

/// Feeds light directions into a fingerprint.
pub(crate) fn fingerprint_lights<'a>(
    f: &mut Fingerprint,
    lights: impl IntoIterator<Item = &'a DVec3>,
) {
    for l in lights {
        f.f64(l.x).f64(l.y).f64(l.z);
    }
}

/// Opens (or builds) the tile cache of `ds` in `dir`, reporting decoding progress and the
/// loader's warnings about the inputs. The dataset's fingerprints are computed first and given
/// to `check`, so a job can refuse its inputs before anything is decoded.
pub(crate) fn open_cache(
    ds: &Dataset,
    decode: &DecodeOptions,
    dir: &Path,
    options: CacheOptions,
    ctl: &Control,
    check: &dyn Fn(&Fingerprints) -> Result<()>,
) -> Result<(TileCache, CacheInfo, Fingerprints)> {
    // Image sizes are compared from the headers first (`dataset_fingerprints`): one of another
    // size fails before any is read whole.
    let fps = symframe_io::dataset_fingerprints(ds, decode, options.trust_mtime, options.format)?;
    check(&fps)?;
    let decoded = AtomicU64::new(0);
    let total = ds.images.len() as u64;
    let (cache, info) =
        TileCache::open_or_build_with(ds, decode, dir, options, Some(fps), ctl.stop, &|| {
            let n = decoded.fetch_add(1, Ordering::SeqCst) + 1;
            ctl.report(Progress::new(Stage::Decoding, n, total));
        })
        .map_err(|e| match e {
            symframe_io::Error::Interrupted => anyhow::Error::from(Interrupted),
            e => e.into(),
        })?;
    for w in &info.warnings {
        ctl.warn(&w.to_string());
    }
    Ok((cache, info, fps))
}

/// Reads the mask of a job (`mask`, else the dataset's) at the cache's image size.
pub(crate) fn read_mask(
    mask: &Option<PathBuf>,
    ds: &Dataset,
    grid: &TileGrid,
) -> Result<(Option<PathBuf>, Option<Vec<bool>>)> {
    let path = mask.clone().or_else(|| ds.mask.clone());
    let mask = match &path {
        Some(p) => Some(symframe_io::read_mask(p, grid.width, grid.height)?),
        None => None,
    };
    Ok((path, mask))
}

/// Removes the cache file of a finished job (and its folder, when nothing else is left in it).
pub(crate) fn remove_cache(cache_path: &Path, dir: &Path) -> Result<()> {
    std::fs::remove_file(cache_path)
        .with_context(|| format!("{}: cannot remove", cache_path.display()))?;
    let _ = std::fs::remove_file(cache_path.with_extension("lock"));
    let _ = std::fs::remove_dir(dir);
    Ok(())
}
