//! Command-line flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// Surface normals and tangents from photographs under many lights, by BRDF symmetry
/// (Holroyd et al. 2008).
#[derive(Debug, Parser)]
#[command(name = "symframe", version, about, long_about = None)]
pub struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true, value_parser = clap::value_parser!(usize))]
    pub threads: Option<usize>,
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Estimate normal and tangent maps from a capture (.lp file or DiLiGenT-style folder).
    Estimate(EstimateArgs),
    /// Combine the outputs of `estimate --tiles K/N` shards into the full maps.
    Merge(MergeArgs),
    /// Render a built-in synthetic object, estimate its frames and report the error (no download).
    Demo(DemoArgs),
    /// Paper-scale benchmark: generate a synthetic stack once, time `estimate` on it.
    #[command(hide = true)]
    BenchPaper(BenchArgs),
}

/// One shard of a sharded run: the K-th (1-based) of N disjoint sets of tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardSpec {
    /// 1-based shard number.
    pub k: usize,
    /// Number of shards.
    pub n: usize,
}

impl std::str::FromStr for ShardSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("expected K/N with 1 <= K <= N (e.g. 3/32), got '{s}'");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if k == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }
}

impl std::fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// Cosine handling in the symmetry distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CosineArg {
    /// The paper's cross-multiplied cosines (exact for diffuse; default).
    Cross,
    /// Raw radiances (exact for microfacet lobes, wrong for diffuse).
    Raw,
    /// Diffuse-compensated power form (see --cosine-power): exact for diffuse plus a lobe
    /// whose radiance goes as (n.l)^p; refines the paper's solution.
    Compensated,
}

/// Flags of `symframe estimate`.
#[derive(Debug, Clone, Args)]
pub struct EstimateArgs {
    /// A `.lp` light file, a folder holding one, or a DiLiGenT-style folder.
    pub input: PathBuf,
    /// Output folder (created; files in it with the same names are replaced).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Mask image: only pixels where it is non-zero are estimated (default: mask.png beside
    /// the input, if any).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Light cone: lights whose halfway vector is more than this many degrees from the view are
    /// dropped.
    #[arg(long, default_value_t = 65.0)]
    pub theta_d_max: f64,
    /// Pixels with confidence below this are culled (NaN in the maps).
    #[arg(long, default_value_t = 0.0)]
    pub min_confidence: f32,
    /// Pixels with anisotropy below this get no tangent (NaN): the slice is isotropic.
    #[arg(long, default_value_t = 0.6)]
    pub min_anisotropy: f32,
    /// Smallest symmetry domain, in lights, that counts as non-empty (default: 1.5% of the
    /// lights used, at least 6).
    #[arg(long)]
    pub min_domain: Option<u32>,
    /// Cosine handling in the symmetry distance.
    #[arg(long, value_enum, default_value_t = CosineArg::Cross)]
    pub cosine: CosineArg,
    /// Cosine power p of `--cosine compensated` (0.5 is exact for Ward, 0 for Cook-Torrance-like
    /// lobes, 1 for Blinn-Phong).
    #[arg(long, default_value_t = 0.5)]
    pub cosine_power: f64,
    /// Treat 8-bit images as linear (default: sRGB-decode them).
    #[arg(long)]
    pub linear: bool,
    /// Integer samples at or above this fraction of the format's maximum are saturated and
    /// excluded.
    #[arg(long, default_value_t = 0.995)]
    pub saturation: f32,
    /// Skip tangents (normals only; faster).
    #[arg(long)]
    pub no_tangents: bool,
    /// Folder of the on-disk tile cache of the decoded images (default: OUTPUT/.symframe-cache).
    /// A cache of the same images is reused; several runs (shards) may share one folder.
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Delete the tile cache once the run has finished (default: keep it, so a rerun with other
    /// parameters does not decode the images again).
    #[arg(long)]
    pub no_keep_cache: bool,
    /// Estimate only the K-th of N disjoint sets of tiles (tiles t with t % N == K-1) into
    /// OUTPUT (tile results and shard.json); combine the shards with `symframe merge`.
    #[arg(long, value_name = "K/N")]
    pub tiles: Option<ShardSpec>,
    /// Tile side in pixels (the unit of work, of resumption and of the cache layout).
    #[arg(long, default_value_t = 32)]
    pub tile_size: usize,
    /// Memory for one batch of decoded images while the cache is built, in MiB.
    #[arg(long, default_value_t = 1024, value_name = "MIB")]
    pub decode_memory: usize,
    /// Testing aid: behave as if interrupted once this many tiles are finished.
    #[arg(long, hide = true)]
    pub stop_after_tiles: Option<usize>,
}

/// Flags of `symframe merge`.
#[derive(Debug, Clone, Args)]
pub struct MergeArgs {
    /// Output folders of `symframe estimate --tiles K/N`, one per shard.
    #[arg(required = true, num_args = 1..)]
    pub shards: Vec<PathBuf>,
    /// Output folder for the full maps.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Flags of `symframe bench-paper`.
#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Folder for the generated dataset (reused when it exists) and the runs' outputs.
    #[arg(long, default_value = "symframe-bench")]
    pub dir: PathBuf,
    /// Image size in pixels (the paper's captures: 1024).
    #[arg(long, default_value_t = 1024)]
    pub size: usize,
    /// Number of lights (the paper's captures: 1512).
    #[arg(long, default_value_t = 1512)]
    pub lights: usize,
    /// Skip the baseline run even when `estimate --method woodham` exists.
    #[arg(long)]
    pub no_baseline: bool,
    /// Delete the tile cache first, so the run decodes every image (default: reuse it).
    #[arg(long)]
    pub cold: bool,
    /// Passed to `estimate --decode-memory` (MiB per batch of decoded images).
    #[arg(long, default_value_t = 1024, value_name = "MIB")]
    pub decode_memory: usize,
    /// Estimate only this shard of the tiles (`estimate --tiles K/N`): the whole cache is
    /// still built, so decoding and memory are measured at full size in a fraction of the time.
    #[arg(long, value_name = "K/N")]
    pub tiles: Option<ShardSpec>,
}

/// Flags of `symframe demo`.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Output folder for the rendered dataset and the estimated maps.
    #[arg(short, long, default_value = "symframe-demo")]
    pub output: PathBuf,
    /// Image size in pixels (the sphere fills it).
    #[arg(long, default_value_t = 96)]
    pub size: usize,
    /// Number of lights, uniform over the 65-degree cone.
    #[arg(long, default_value_t = 1000)]
    pub lights: usize,
}
