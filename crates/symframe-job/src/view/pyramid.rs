//! The viewer's tile pyramid: level `k` is every `2^k`-th pixel of the maps in each direction
//! (values exact, not averaged), cut into square tiles, each a small script
//! (`LEVEL/X_Y.js`, calling the page's `symframeTile`) in a folder beside the page. Scripts,
//! not data files, because a page opened from a `file:` URL may add `<script>` elements but
//! may not `fetch` files. The coarsest level (one tile) travels in the page itself.
//!
//! The levels are built from bands of full-resolution rows (one tile high), so memory holds
//! one band of every level, not the maps.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use super::{encode_halves, Band, TEXTURE_NAMES};

/// The file that marks a pyramid folder as written by `symframe view`.
pub(super) const MARKER: &str = "pyramid.json";
/// The first bytes of [`MARKER`]'s content.
const MARKER_HEAD: &str = "{\"written_by\":\"symframe view\"";

/// The sizes of a pyramid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Layout {
    pub width: usize,
    pub height: usize,
    pub tile: usize,
    /// The coarsest level (the one in the page); 0 when the page holds the maps whole.
    pub top: usize,
}

impl Layout {
    /// Levels halve until both sides fit in one tile.
    pub(super) fn new(width: usize, height: usize, tile: usize) -> Self {
        let mut top = 0;
        while width.div_ceil(1 << top) > tile || height.div_ceil(1 << top) > tile {
            top += 1;
        }
        Self {
            width,
            height,
            tile,
            top,
        }
    }

    /// Width and height of level `k`.
    pub(super) fn level_size(&self, k: usize) -> (usize, usize) {
        (self.width.div_ceil(1 << k), self.height.div_ceil(1 << k))
    }

    /// Tiles across and down of level `k`.
    pub(super) fn tiles(&self, k: usize) -> (usize, usize) {
        let (w, h) = self.level_size(k);
        (w.div_ceil(self.tile), h.div_ceil(self.tile))
    }
}

/// One level's rows not yet cut into tiles.
struct Pending {
    band: Band,
    /// The tile row they start.
    ty: usize,
}

/// Builds the levels from full-resolution bands: tiles of levels below `top` go to files in
/// `dir`, the top level is kept (the page's picture).
pub(super) struct Builder {
    layout: Layout,
    /// `None`: no pyramid (one level, the page's).
    dir: Option<PathBuf>,
    present: [bool; 5],
    levels: Vec<Pending>,
    /// Tile files written and their bytes.
    pub files: usize,
    pub bytes: u64,
}

impl Builder {
    pub(super) fn new(layout: Layout, dir: Option<&Path>, present: [bool; 5]) -> Result<Self> {
        if let Some(dir) = dir {
            for k in 0..layout.top {
                let d = dir.join(k.to_string());
                fs::create_dir(&d).with_context(|| format!("{}: cannot create", d.display()))?;
            }
        } else if layout.top > 0 {
            bail!("viewer: levels without a tile folder");
        }
        Ok(Self {
            layout,
            dir: dir.map(Path::to_path_buf),
            present,
            levels: (0..=layout.top)
                .map(|k| Pending {
                    band: Band::new(layout.level_size(k).0, present),
                    ty: 0,
                })
                .collect(),
            files: 0,
            bytes: 0,
        })
    }

    /// Takes full-resolution rows `y0..` (the next ones, a whole number of tiles high unless
    /// they are the last).
    pub(super) fn push(&mut self, y0: usize, band: &Band) -> Result<()> {
        let rows = band.rows();
        for k in 0..=self.layout.top {
            let (wk, hk) = self.layout.level_size(k);
            let step = 1usize << k;
            let first = y0.div_ceil(step) * step;
            let mut y = first;
            while y < y0 + rows {
                let level = &mut self.levels[k];
                debug_assert_eq!(level.band.width, wk);
                level.band.push_row_sampled(band, y - y0, step);
                let full = level.band.rows() == self.layout.tile || y / step + 1 == hk;
                if full && k < self.layout.top {
                    self.flush(k)?;
                }
                y += step;
            }
        }
        Ok(())
    }

    /// Cuts level `k`'s pending rows into tile files.
    fn flush(&mut self, k: usize) -> Result<()> {
        let tile = self.layout.tile;
        let level = &mut self.levels[k];
        let (across, _) = self.layout.tiles(k);
        let ty = level.ty;
        let fresh = Band::new(level.band.width, self.present);
        let band = std::mem::replace(&mut level.band, fresh);
        level.ty += 1;
        let dir = self
            .dir
            .as_ref()
            .context("viewer: tiles without a tile folder")?
            .join(k.to_string());
        let written: Vec<Result<u64>> = (0..across)
            .into_par_iter()
            .map(|tx| {
                let x0 = tx * tile;
                let x1 = (x0 + tile).min(band.width);
                let part = band.crop(x0, x1);
                let text = tile_script(k, tx, ty, x1 - x0, band.rows(), &part)?;
                let path = dir.join(format!("{tx}_{ty}.js"));
                fs::write(&path, &text)
                    .with_context(|| format!("{}: cannot write", path.display()))?;
                Ok(text.len() as u64)
            })
            .collect();
        for w in written {
            self.bytes += w?;
            self.files += 1;
        }
        Ok(())
    }

    /// The top level's picture, once every row is in.
    pub(super) fn finish(mut self) -> Result<(Band, usize, u64)> {
        let top = self.layout.top;
        let band = std::mem::replace(&mut self.levels[top].band, Band::new(0, self.present));
        let (wt, ht) = self.layout.level_size(top);
        if band.width != wt || band.rows() != ht {
            bail!(
                "viewer pyramid: the top level is {}x{}, {wt}x{ht} expected",
                band.width,
                band.rows()
            );
        }
        if self.dir.is_some() {
            self.write_marker()?;
        }
        Ok((band, self.files, self.bytes))
    }

    fn write_marker(&self) -> Result<()> {
        let l = &self.layout;
        let text = format!(
            "{MARKER_HEAD},\"width\":{},\"height\":{},\"tile\":{},\"levels\":{}}}\n",
            l.width,
            l.height,
            l.tile,
            l.top + 1
        );
        let Some(dir) = &self.dir else { return Ok(()) };
        let path = dir.join(MARKER);
        fs::write(&path, text).with_context(|| format!("{}: cannot write", path.display()))
    }
}

/// The script of one tile: `symframeTile(level, x, y, width, height, {texture: data, ...});`.
fn tile_script(k: usize, tx: usize, ty: usize, w: usize, h: usize, band: &Band) -> Result<String> {
    let mut s = format!("symframeTile({k},{tx},{ty},{w},{h},{{");
    let mut first = true;
    for (i, name) in TEXTURE_NAMES.iter().enumerate() {
        if let Some(t) = &band.textures[i] {
            if !first {
                s.push(',');
            }
            first = false;
            s.push_str(&format!("\"{name}\":\"{}\"", encode_halves(t, 1)?));
        }
    }
    s.push_str("});\n");
    Ok(s)
}

/// The pyramid folder of the page `output`: `NAME_files` beside `NAME.html`.
pub(super) fn folder_of(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    output.with_file_name(format!("{stem}_files"))
}

/// The files of `dir` if it is a pyramid folder written by this tool (a marker, level folders
/// of tile scripts and nothing else, no links); `None` if it is missing; an error naming it
/// otherwise, so that nothing else is ever replaced or removed.
pub(super) fn our_folder(dir: &Path) -> Result<Option<Vec<PathBuf>>> {
    let Ok(meta) = fs::symlink_metadata(dir) else {
        return Ok(None);
    };
    let refuse = |why: &str| {
        anyhow::anyhow!(
            "{}: exists and {why}; it is not a tile folder written by symframe view, refusing \
             to replace it (give another -o)",
            dir.display()
        )
    };
    if !meta.is_dir() {
        return Err(refuse("is not a folder"));
    }
    let marker = dir.join(MARKER);
    let head = fs::symlink_metadata(&marker)
        .ok()
        .filter(fs::Metadata::is_file)
        .and_then(|_| fs::read(&marker).ok())
        .filter(|b| b.starts_with(MARKER_HEAD.as_bytes()));
    if head.is_none() {
        return Err(refuse(&format!("has no {MARKER} of symframe view")));
    }
    let mut files = vec![];
    let entries = |d: &Path| -> Result<Vec<fs::DirEntry>> {
        fs::read_dir(d)
            .and_then(|r| r.collect::<std::io::Result<Vec<_>>>())
            .with_context(|| format!("{}: cannot list", d.display()))
    };
    for e in entries(dir)? {
        let name = e.file_name().to_string_lossy().into_owned();
        let ft = e
            .file_type()
            .with_context(|| format!("{}: cannot read", e.path().display()))?;
        if name == MARKER && ft.is_file() {
            continue;
        }
        if !(ft.is_dir() && !name.is_empty() && name.bytes().all(|b| b.is_ascii_digit())) {
            return Err(refuse(&format!("holds {name}")));
        }
        for t in entries(&e.path())? {
            let tname = t.file_name().to_string_lossy().into_owned();
            let is_tile = tname
                .strip_suffix(".js")
                .and_then(|s| s.split_once('_'))
                .is_some_and(|(a, b)| {
                    [a, b]
                        .iter()
                        .all(|p| !p.is_empty() && p.bytes().all(|c| c.is_ascii_digit()))
                });
            let tft = t
                .file_type()
                .with_context(|| format!("{}: cannot read", t.path().display()))?;
            if !(is_tile && tft.is_file()) {
                return Err(refuse(&format!("holds {name}/{tname}")));
            }
            files.push(t.path());
        }
        files.push(e.path());
    }
    files.push(marker);
    Ok(Some(files))
}

/// Removes a folder [`our_folder`] listed: its tiles, level folders, marker, then itself.
pub(super) fn remove_ours(dir: &Path, files: &[PathBuf]) -> Result<()> {
    for f in files {
        let r = if f.is_dir() {
            fs::remove_dir(f)
        } else {
            fs::remove_file(f)
        };
        r.with_context(|| format!("{}: cannot remove", f.display()))?;
    }
    fs::remove_dir(dir).with_context(|| format!("{}: cannot remove", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_halve_until_one_tile() {
        let l = Layout::new(40, 30, 8);
        assert_eq!(l.top, 3);
        assert_eq!(l.level_size(1), (20, 15));
        assert_eq!(l.level_size(3), (5, 4));
        assert_eq!(l.tiles(0), (5, 4));
        assert_eq!(l.tiles(2), (2, 1));
        assert_eq!(Layout::new(8, 8, 8).top, 0);
        assert_eq!(Layout::new(16384, 16384, 256).top, 6);
    }
}
