//! The estimate's output set written from the tile result files a band (a row of tiles) at a
//! time: memory bounded by a band whatever the image size (whole maps of a 4096 x 4096 image
//! take 570 MB, their four pictures 50 MB each), the files the same bytes as written from
//! whole maps.

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::Result;
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use symframe::{AxesCheck, EstimateMaps, LightAxes, PixelCounts, PixelSource};
use symframe_io::{NormalPng, NpyRows, PngRows, TileGrid};

use crate::outdir::{OutputDir, OutputSet};
use crate::pictures::LightsPlot;
use crate::{Checkpoint, Control};

/// One code of the source map, as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct SourceCount {
    /// The code in `source.npy`.
    pub code: u8,
    /// Its name.
    pub name: &'static str,
    /// What it means.
    pub description: &'static str,
    /// Pixels with this code.
    pub pixels: usize,
}

/// The source map's legend with per-source pixel counts.
#[derive(Debug, Clone, Serialize)]
pub struct Sources(pub Vec<SourceCount>);

impl Sources {
    /// The legend and counts of a source map (codes of [`PixelSource`]).
    pub fn of(source: &[u8]) -> Self {
        let mut counts = [0usize; PixelSource::ALL.len()];
        for &c in source {
            if let Some(n) = counts.get_mut(c as usize) {
                *n += 1;
            }
        }
        Self::from_counts(&counts)
    }

    /// The legend with `counts[code]` pixels per code (codes without a count: 0).
    pub fn from_counts(counts: &[usize]) -> Self {
        Sources(
            PixelSource::legend()
                .iter()
                .map(|&(code, name, description)| SourceCount {
                    code,
                    name,
                    description,
                    pixels: counts.get(code as usize).copied().unwrap_or(0),
                })
                .collect(),
        )
    }
}

/// The loud warnings about a finished job's maps: nothing estimated, or (given `beyond`, the
/// number of estimated normals whose symmetry centre `h = n` the rig does not cover) most
/// normals beyond the rig's reach, where only the fallbacks answer; and normals that fit
/// together as a surface only with the lights' axes turned or reflected (`axes`).
pub(crate) fn result_warnings(
    counts: &PixelCounts,
    beyond: Option<usize>,
    axes: LightAxes,
) -> Vec<String> {
    let mut w = Vec::new();
    if let Some(mapping) = axes.mapping() {
        w.push(format!(
            "the lights' convention looks wrong: the normals fit together as one surface facing \
             out of its outline only with each light read as {mapping}; check the light file \
             (symframe's lights: x to the image's right, y up the image, z toward the camera)"
        ));
    }
    if counts.estimated == 0 {
        w.push(format!(
            "0 pixels estimated ({} discarded, {} culled, {} without data): the maps are empty",
            counts.discarded, counts.culled, counts.no_data
        ));
    } else if let Some(beyond) = beyond.filter(|&b| b * 2 > counts.estimated) {
        w.push(format!(
            "most pixels beyond the rig's reach: {beyond} of {} estimated normals are where no \
             light pair is symmetric about them, filled by the fallbacks (see source.npy; a \
             rig with lights farther from the view reaches them)",
            counts.estimated
        ));
    }
    w
}

/// The result files of a finished job's tiles: the grid, the job's fingerprint, and where
/// tile `t`'s file is.
pub(crate) struct TileResults<'a> {
    /// The tiling of the image.
    pub grid: TileGrid,
    /// The job whose records the files must hold.
    pub job: u64,
    /// Tile `t`'s result file.
    pub path_of: &'a (dyn Fn(usize) -> PathBuf + Sync),
}

/// Rows `y0..y0 + maps.height` of the image, as maps of the image's width.
pub(crate) struct Band {
    y0: usize,
    maps: EstimateMaps,
}

impl TileResults<'_> {
    /// Band `row`: the maps of the `row`-th row of tiles, its tiles read in parallel.
    pub(crate) fn band(&self, row: usize) -> Result<Band> {
        let g = &self.grid;
        let y0 = row * g.tile;
        let tiles: Vec<usize> = (row * g.tiles_x()..(row + 1) * g.tiles_x()).collect();
        let records = tiles
            .par_iter()
            .map(|&t| {
                symframe_io::read_tile_result(&(self.path_of)(t), self.job, t, g.tile_pixels(t))
            })
            .collect::<symframe_io::Result<Vec<_>>>()?;
        // Sized once the files are read and verified (a forged one is refused first).
        let mut maps = EstimateMaps::empty(g.width, g.tile.min(g.height.saturating_sub(y0)));
        let offset = y0 * g.width;
        for (&t, r) in tiles.iter().zip(records) {
            for (p, rec) in g.pixels(t).zip(r) {
                maps.put(p - offset, &rec);
            }
        }
        Ok(Band { y0, maps })
    }
}

/// What the maps written hold, gathered while writing them.
#[derive(Debug, Clone)]
pub(crate) struct MapSummary {
    /// What happened to the pixels.
    pub counts: PixelCounts,
    /// The source map's legend and counts.
    pub sources: Sources,
    /// Symmetry-objective evaluations, all pixels.
    pub evals: u64,
    /// Estimated normals beyond the rig's reach (when a reach was given).
    pub beyond_reach: Option<usize>,
    /// What the normal map says of the lights' axes (a convention mix-up shows there).
    pub light_axes: LightAxes,
}

/// How the output set is written.
pub(crate) struct WriteOptions<'a> {
    /// The y convention of `normals.png`.
    pub normal_png: NormalPng,
    /// Also return the whole maps (the library's callers; the CLI never holds them).
    pub keep_maps: bool,
    /// Whether a normal is within the rig's reach (its halfway vector `h = n` covered), to
    /// count those beyond it.
    pub covered: Option<&'a (dyn Fn(DVec3) -> bool + Sync)>,
    /// Called after each band of the first pass with the number of tiles read so far.
    pub on_tiles: &'a dyn Fn(usize),
    /// The rig for `lights.png` (none: no such picture, as for a merge, which has no rig).
    pub lights: Option<&'a LightsPlot<'a>>,
}

/// `a += b`, field by field.
fn add_counts(a: &mut PixelCounts, b: &PixelCounts) {
    a.estimated += b.estimated;
    a.with_tangent += b.with_tangent;
    a.culled += b.culled;
    a.discarded += b.discarded;
    a.no_data += b.no_data;
    a.masked += b.masked;
}

/// The `.npy` maps and the pictures, written a band at a time in one pass.
struct RowWriters {
    normals: NpyRows<f32>,
    tangents: NpyRows<f32>,
    confidence: NpyRows<f32>,
    anisotropy: NpyRows<f32>,
    tangent_confidence: NpyRows<f32>,
    residual: NpyRows<f32>,
    source: NpyRows<u8>,
    normals_png: PngRows,
    tangents_png: PngRows,
    confidence_png: PngRows,
    source_png: PngRows,
    residual_png: PngRows,
    gltf_png: PngRows,
}

impl RowWriters {
    fn create(staging: &OutputSet, w: usize, h: usize) -> Result<Self> {
        let p = |n: &str| staging.path(n);
        Ok(Self {
            normals: NpyRows::create(&p("normals.npy"), &[h, w, 3])?,
            tangents: NpyRows::create(&p("tangents.npy"), &[h, w, 3])?,
            confidence: NpyRows::create(&p("confidence.npy"), &[h, w])?,
            anisotropy: NpyRows::create(&p("anisotropy.npy"), &[h, w])?,
            tangent_confidence: NpyRows::create(&p("tangent_confidence.npy"), &[h, w])?,
            residual: NpyRows::create(&p("residual.npy"), &[h, w])?,
            source: NpyRows::create(&p("source.npy"), &[h, w])?,
            normals_png: PngRows::rgb16(&p("normals.png"), w, h)?,
            tangents_png: PngRows::rgb8(&p("tangents.png"), w, h)?,
            confidence_png: PngRows::rgb8(&p("confidence.png"), w, h)?,
            source_png: PngRows::rgb8(&p("source.png"), w, h)?,
            residual_png: PngRows::rgb8(&p("residual.png"), w, h)?,
            gltf_png: PngRows::rgb8(&p("tangents_gltf.png"), w, h)?,
        })
    }

    /// Appends a band's rows to every file.
    fn push(&mut self, m: &EstimateMaps, normal_png: NormalPng) -> Result<()> {
        self.normals.push(&m.normals)?;
        self.tangents.push(&m.tangents)?;
        self.confidence.push(&m.confidence)?;
        self.anisotropy.push(&m.anisotropy)?;
        self.tangent_confidence.push(&m.tangent_confidence)?;
        self.residual.push(&m.residual)?;
        self.source.push(&m.source)?;
        let w = m.width;
        for r in 0..m.height {
            let (n3, n1) = (r * w * 3..(r + 1) * w * 3, r * w..(r + 1) * w);
            let (tangents, strength) = (&m.tangents[n3.clone()], &m.anisotropy[n1.clone()]);
            self.normals_png.push(|row| {
                symframe_io::normal_png16_row(&m.normals[n3.clone()], normal_png, row)
            })?;
            let copy = |rgb: Vec<u8>| move |row: &mut [u8]| row.copy_from_slice(&rgb);
            self.tangents_png
                .push(copy(symframe_io::tangent_map_rgb8(tangents)))?;
            self.confidence_png.push(copy(symframe_io::gray_map_rgb8(
                &m.confidence[n1.clone()],
                0.0,
                1.0,
            )))?;
            self.residual_png.push(copy(crate::pictures::residual_rgb8(
                &m.residual[n1.clone()],
            )))?;
            self.source_png
                .push(copy(symframe_io::source_map_rgb8(&m.source[n1])))?;
            self.gltf_png
                .push(copy(crate::export::gltf_anisotropy_rgb8(
                    tangents, strength,
                )))?;
        }
        Ok(())
    }

    fn finish(self) -> Result<()> {
        self.normals.finish()?;
        self.tangents.finish()?;
        self.confidence.finish()?;
        self.anisotropy.finish()?;
        self.tangent_confidence.finish()?;
        self.residual.finish()?;
        self.source.finish()?;
        self.normals_png.finish()?;
        self.tangents_png.finish()?;
        self.confidence_png.finish()?;
        self.source_png.finish()?;
        self.residual_png.finish()?;
        self.gltf_png.finish()?;
        Ok(())
    }
}

/// Writes an EXR map of `channels` values per pixel (`value(maps, i)` of pixel `i` of a
/// band's maps), reading the bands again as the encoder asks for their rows (in increasing
/// `y`: each band is read once).
fn write_exr_from_bands(
    path: &std::path::Path,
    tiles: &TileResults,
    channels: usize,
    value: fn(&EstimateMaps, usize) -> [f32; 3],
) -> Result<()> {
    let g = tiles.grid;
    // The band in hand, and the first error reading one (the encoder cannot take it).
    let state: Mutex<(Option<Band>, Option<anyhow::Error>)> = Mutex::new((None, None));
    let pixel = |x: usize, y: usize| -> [f32; 3] {
        let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
        let (band, error) = &mut *s;
        let held = band
            .as_ref()
            .is_some_and(|b| (b.y0..b.y0 + b.maps.height).contains(&y));
        if !held {
            if error.is_some() {
                return [f32::NAN; 3];
            }
            match tiles.band(y / g.tile) {
                Ok(b) => *band = Some(b),
                Err(e) => {
                    *error = Some(e);
                    return [f32::NAN; 3];
                }
            }
        }
        match band.as_ref() {
            Some(b) => value(&b.maps, (y - b.y0) * g.width + x),
            None => [f32::NAN; 3],
        }
    };
    let written = symframe_io::write_exr_map_with(path, g.width, g.height, channels, &pixel);
    let (_, error) = state.into_inner().unwrap_or_else(|e| e.into_inner());
    if let Some(e) = error {
        return Err(e);
    }
    Ok(written?)
}

/// Pixel `i`'s three values of `v`.
fn triple(v: &[f32], i: usize) -> [f32; 3] {
    [v[3 * i], v[3 * i + 1], v[3 * i + 2]]
}

/// Writes the maps (`.npy`, `.exr`), pictures, the source map, the legends, `lights.png` and
/// `index.html` ([`crate::pictures`]) and `report.json` (the value
/// `report` returns, given the seconds spent writing the rest and what the maps hold) as one
/// output set: staged inside the locked folder `out`, then switched in with the report last
/// (see [`OutputSet`]). The maps are read from the tile results a band at a time: the `.npy`
/// files and pictures in one pass, each EXR in one more. Returns what the maps hold, and the
/// whole maps if `opts.keep_maps` asked for them.
pub(crate) fn write_estimate_outputs(
    out: &OutputDir,
    tiles: &TileResults,
    opts: &WriteOptions,
    ctl: &Control,
    report: impl FnOnce(f64, &MapSummary) -> Result<serde_json::Value>,
) -> Result<(MapSummary, Option<EstimateMaps>)> {
    let t_write = Instant::now();
    let g = tiles.grid;
    let (w, h) = (g.width, g.height);
    let staging = OutputSet::new(out, |_| false)?;
    let mut rows = RowWriters::create(&staging, w, h)?;
    let mut full = opts.keep_maps.then(|| EstimateMaps::empty(w, h));
    let mut counts = PixelCounts::default();
    let mut evals = 0u64;
    let mut sources = vec![0usize; PixelSource::ALL.len()];
    let mut beyond = 0usize;
    let mut axes = AxesCheck::new(w, h);
    for row in 0..g.tiles_y() {
        let Band { y0, maps: m } = tiles.band(row)?;
        rows.push(&m, opts.normal_png)?;
        axes.push_rows(&m.normals);
        add_counts(&mut counts, &m.counts);
        evals += m.evals;
        for &c in &m.source {
            if let Some(n) = sources.get_mut(c as usize) {
                *n += 1;
            }
        }
        if let Some(covered) = opts.covered {
            beyond += m
                .normals
                .chunks_exact(3)
                .filter(|n| n[0].is_finite())
                .filter(|n| !covered(DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)))
                .count();
        }
        if let Some(f) = &mut full {
            let (a, b) = (y0 * w, (y0 + m.height) * w);
            f.normals[3 * a..3 * b].copy_from_slice(&m.normals);
            f.tangents[3 * a..3 * b].copy_from_slice(&m.tangents);
            f.confidence[a..b].copy_from_slice(&m.confidence);
            f.anisotropy[a..b].copy_from_slice(&m.anisotropy);
            f.tangent_confidence[a..b].copy_from_slice(&m.tangent_confidence);
            f.residual[a..b].copy_from_slice(&m.residual);
            f.status[a..b].copy_from_slice(&m.status);
            f.source[a..b].copy_from_slice(&m.source);
        }
        (opts.on_tiles)((row + 1) * g.tiles_x());
    }
    rows.finish()?;
    write_exr_from_bands(&staging.path("normals.exr"), tiles, 3, |m, i| {
        triple(&m.normals, i)
    })?;
    write_exr_from_bands(&staging.path("tangents.exr"), tiles, 3, |m, i| {
        triple(&m.tangents, i)
    })?;
    let summary = MapSummary {
        counts,
        sources: Sources::from_counts(&sources),
        evals,
        beyond_reach: opts.covered.map(|_| beyond),
        light_axes: axes.verdict(),
    };
    if let Some(f) = &mut full {
        f.counts = counts;
        f.evals = evals;
    }
    let json = report(t_write.elapsed().as_secs_f64(), &summary)?;
    crate::pictures::write_pictures(&staging, &json, opts.lights)?;
    staging.commit("report.json", json, &|n| {
        (ctl.checkpoint)(Checkpoint::Moved(n))
    })?;
    Ok((summary, full))
}

#[cfg(test)]
mod tests {
    use super::*;
    use symframe::{PixelRecord, PixelStatus};

    /// A deterministic mix of every status and source, with `NaN`s where the estimator leaves
    /// them and values outside `[0, 1]` for the pictures' clamping.
    fn record(p: usize) -> PixelRecord {
        let f = |k: usize| ((p * 7919 + k * 104_729) % 2001) as f32 / 1000.0 - 1.0;
        let status = [
            PixelStatus::Estimated,
            PixelStatus::Estimated,
            PixelStatus::Masked,
            PixelStatus::NoData,
            PixelStatus::Discarded,
            PixelStatus::Culled,
        ][p % 6];
        if matches!(status, PixelStatus::Masked | PixelStatus::NoData) {
            return PixelRecord {
                status,
                ..PixelRecord::MASKED
            };
        }
        let n = DVec3::new(f(0) as f64, f(1) as f64, 1.0).normalize();
        let tangent = if p.is_multiple_of(4) {
            [f32::NAN; 3]
        } else {
            [f(2), f(3), f(4)]
        };
        PixelRecord {
            status,
            source: PixelSource::ALL[p % PixelSource::ALL.len()],
            normal: [n.x as f32, n.y as f32, n.z as f32],
            tangent,
            confidence: f(5) * 1.5,
            anisotropy: f(6) + 0.5,
            tangent_confidence: f(7),
            residual: f(8).abs(),
            evals: (p % 97) as u32,
        }
    }

    /// Writes the tile result files of [`record`]'s pixels into `dir/tiles`; returns the
    /// folder and the maps they make.
    fn tile_files(dir: &std::path::Path, grid: &TileGrid, job: u64) -> (PathBuf, EstimateMaps) {
        let tiles_dir = dir.join("tiles");
        std::fs::create_dir_all(&tiles_dir).unwrap();
        let mut whole = EstimateMaps::empty(grid.width, grid.height);
        for t in 0..grid.n_tiles() {
            let records: Vec<PixelRecord> = grid.pixels(t).map(record).collect();
            for (p, r) in grid.pixels(t).zip(&records) {
                whole.put(p, r);
            }
            let path = symframe_io::tile_result_path(&tiles_dir, t);
            symframe_io::write_tile_result(&path, job, t, &records).unwrap();
        }
        (tiles_dir, whole)
    }

    /// The output set written from whole maps: what the streamed writer must equal.
    fn write_whole(dir: &std::path::Path, m: &EstimateMaps, normal_png: NormalPng) {
        use symframe_io::*;
        let (w, h) = (m.width, m.height);
        let p = |n: &str| dir.join(n);
        write_npy_f32(&p("normals.npy"), &[h, w, 3], &m.normals).unwrap();
        write_npy_f32(&p("tangents.npy"), &[h, w, 3], &m.tangents).unwrap();
        write_npy_f32(&p("confidence.npy"), &[h, w], &m.confidence).unwrap();
        write_npy_f32(&p("anisotropy.npy"), &[h, w], &m.anisotropy).unwrap();
        write_npy_f32(&p("tangent_confidence.npy"), &[h, w], &m.tangent_confidence).unwrap();
        write_npy_f32(&p("residual.npy"), &[h, w], &m.residual).unwrap();
        write_npy_u8(&p("source.npy"), &[h, w], &m.source).unwrap();
        write_exr_map(&p("normals.exr"), w, h, 3, &m.normals).unwrap();
        write_exr_map(&p("tangents.exr"), w, h, 3, &m.tangents).unwrap();
        write_normal_png16(&p("normals.png"), w, h, &m.normals, normal_png).unwrap();
        let pictures = [
            ("tangents.png", tangent_map_rgb8(&m.tangents)),
            ("confidence.png", gray_map_rgb8(&m.confidence, 0.0, 1.0)),
            ("source.png", source_map_rgb8(&m.source)),
            ("residual.png", crate::pictures::residual_rgb8(&m.residual)),
            (
                "tangents_gltf.png",
                crate::export::gltf_anisotropy_rgb8(&m.tangents, &m.anisotropy),
            ),
        ];
        for (name, rgb) in pictures {
            write_png_rgb8(&p(name), w, h, &rgb).unwrap();
        }
    }

    /// The outputs written band by band from the tile results are the bytes the whole-map
    /// writer wrote, on a grid with ragged last tiles both ways; the summary and the kept maps
    /// are those of the whole maps.
    #[test]
    fn streamed_outputs_equal_the_whole_map_writer() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h, job) = (37, 23, 0x5eed);
        let grid = TileGrid::new(w, h, 8);
        let (tiles_dir, whole) = tile_files(tmp.path(), &grid, job);
        for normal_png in [NormalPng::OpenGl, NormalPng::DirectX] {
            let reference = tmp.path().join("reference");
            std::fs::create_dir_all(&reference).unwrap();
            write_whole(&reference, &whole, normal_png);

            let streamed = tmp.path().join("streamed");
            let out = OutputDir::lock(&streamed).unwrap();
            let path_of = |t| symframe_io::tile_result_path(&tiles_dir, t);
            let tiles = TileResults {
                grid,
                job,
                path_of: &path_of,
            };
            let covered = |n: DVec3| n.z > 0.9;
            let read = Mutex::new(Vec::new());
            let opts = WriteOptions {
                normal_png,
                keep_maps: true,
                covered: Some(&covered),
                on_tiles: &|n| read.lock().unwrap().push(n),
                lights: None,
            };
            let (summary, kept) =
                write_estimate_outputs(&out, &tiles, &opts, &Control::default(), |_, _| {
                    Ok(serde_json::json!({}))
                })
                .unwrap();
            drop(out);
            for name in crate::estimate::ESTIMATE_FILES {
                // The report, and the pictures made from it, are not the maps'.
                if name == "report.json" || crate::pictures::PICTURE_FILES.contains(&name) {
                    continue;
                }
                let a = std::fs::read(reference.join(name)).unwrap();
                let b = std::fs::read(streamed.join(name)).unwrap();
                assert!(a == b, "{name} ({normal_png:?}) differs");
            }
            assert_eq!(*read.lock().unwrap(), vec![5, 10, 15]);
            let kept = kept.unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&kept.normals), bits(&whole.normals));
            assert_eq!(bits(&kept.tangents), bits(&whole.tangents));
            assert_eq!(bits(&kept.confidence), bits(&whole.confidence));
            assert_eq!(bits(&kept.anisotropy), bits(&whole.anisotropy));
            assert_eq!(
                bits(&kept.tangent_confidence),
                bits(&whole.tangent_confidence)
            );
            assert_eq!(bits(&kept.residual), bits(&whole.residual));
            assert_eq!(
                (&kept.status, &kept.source, kept.counts, kept.evals),
                (&whole.status, &whole.source, whole.counts, whole.evals)
            );
            assert_eq!(summary.counts, whole.counts);
            assert_eq!(summary.evals, whole.evals);
            assert_eq!(
                serde_json::to_value(&summary.sources).unwrap(),
                serde_json::to_value(Sources::of(&whole.source)).unwrap()
            );
            let beyond = whole
                .normals
                .chunks_exact(3)
                .filter(|n| n[0].is_finite() && n[2] <= 0.9)
                .count();
            assert!(beyond > 0);
            assert_eq!(summary.beyond_reach, Some(beyond));
        }
    }

    /// A tile file gone between the passes (after the `.npy` files, before an EXR) is an
    /// error naming it, and nothing is switched in.
    #[test]
    fn a_tile_file_that_fails_mid_write_is_an_error_naming_it() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h, job) = (20, 20, 7);
        let grid = TileGrid::new(w, h, 8);
        let (tiles_dir, _) = tile_files(tmp.path(), &grid, job);
        let streamed = tmp.path().join("streamed");
        let out = OutputDir::lock(&streamed).unwrap();
        let path_of = |t| symframe_io::tile_result_path(&tiles_dir, t);
        let tiles = TileResults {
            grid,
            job,
            path_of: &path_of,
        };
        let last = symframe_io::tile_result_path(&tiles_dir, grid.n_tiles() - 1);
        let opts = WriteOptions {
            normal_png: NormalPng::OpenGl,
            keep_maps: false,
            covered: None,
            // After the first pass's last band: the EXR pass finds the tile gone.
            on_tiles: &|n| {
                if n == grid.n_tiles() {
                    std::fs::remove_file(&last).unwrap();
                }
            },
            lights: None,
        };
        let e = write_estimate_outputs(&out, &tiles, &opts, &Control::default(), |_, _| {
            Ok(serde_json::json!({}))
        })
        .unwrap_err();
        let name = last.file_name().unwrap().to_string_lossy().into_owned();
        assert!(format!("{e:#}").contains(&name), "{e:#}");
        drop(out);
        let left: Vec<_> = std::fs::read_dir(&streamed)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(
            !left.iter().any(|n| n.to_string_lossy().ends_with(".npy")),
            "{left:?}"
        );
    }
}
