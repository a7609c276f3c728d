//! Command-line flags of `symframe-lab`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use symframe_console::flags::{default_decode_memory_mib, CacheFormatArg};
use symframe_console::Globals;
use symframe_job::Shard;

/// The symframe lab: the validation experiments (docs/validation.md) and the benchmarks
/// (docs/performance.md) of the `symframe` command.
#[derive(Debug, Parser)]
#[command(name = "symframe-lab", version, about, long_about = None)]
pub struct Cli {
    /// `--threads` and `--quiet`.
    #[command(flatten)]
    pub globals: Globals,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Re-run the validation experiments in memory (the paper's Figures 3, 4 and 10, noise,
    /// relighting, materials, real-capture conditions): tables on stdout, PNG plots and a
    /// markdown report in the output folder.
    Experiment(ExperimentArgs),
    /// Paper-scale benchmark: generate a synthetic stack once, time `symframe estimate` on it;
    /// `bench scaling`: the scaling curves.
    Bench(BenchCommandArgs),
}

/// The experiments of `symframe-lab experiment`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExperimentArg {
    /// Figure 3: error over normal angle x light cone, anisotropic materials.
    Fig3,
    /// Figure 4: symmetry against Woodham and max-reflectance, diffuse to shiny materials.
    Fig4,
    /// Figure 10: normal and error maps at 1512, 743, 380 and 172 lights.
    Fig10,
    /// Error against Gaussian noise and quantisation.
    Noise,
    /// Relighting from per-pixel Ward and glTF fits: held-out PSNR per model and fit, side-by-side
    /// picture.
    Relight,
    /// Every BRDF family over roughness and diffuse fraction, spheres and shadowed bumps, dense,
    /// sparse and narrow rigs: the estimator against every baseline.
    Materials,
    /// Real-capture conditions: bit depth, JPEG quality, clipping, shot noise and
    /// light-direction error swept over one-lobe, two-lobe, woven, sheen and off-family
    /// materials, against the baselines.
    Capture,
    /// Near lights: the distant and the near-light model against the dome's radius over the
    /// object's size, on a plastic, a brushed and a two-lobe material.
    Near,
    /// Every experiment, then the report `<output>.md` (e.g. docs/validation.md).
    All,
}

/// Flags of `symframe-lab experiment`.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// Which experiment to run.
    #[arg(value_enum)]
    pub which: ExperimentArg,
    /// Output folder of the plots (created). A single experiment also writes `<name>.md` into
    /// it; `all` writes the report beside it as `<output>.md`.
    #[arg(short, long, default_value = "docs/validation")]
    pub output: PathBuf,
    /// Reduced sizes (for tests): fewer cells, lights and pixels.
    #[arg(long)]
    pub quick: bool,
}

/// `symframe-lab bench`: the paper-scale benchmark with its flags, or a named other one.
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchCommandArgs {
    /// Another benchmark instead of the paper-scale one.
    #[command(subcommand)]
    pub other: Option<BenchCommand>,
    /// The paper-scale benchmark's flags.
    #[command(flatten)]
    pub paper: BenchArgs,
}

/// The benchmarks besides the paper-scale one.
#[derive(Debug, Clone, Subcommand)]
pub enum BenchCommand {
    /// Scaling curves: time and memory of `symframe estimate` against image size, light count
    /// and threads, a fitted cost model, tables and a plot.
    Scaling(ScalingArgs),
}

/// The image format of a benchmark's synthetic capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BenchFormat {
    /// Float32 OpenEXR.
    Exr,
    /// 8-bit sRGB JPEG of quality 90.
    Jpeg,
    /// 16-bit linear PNG.
    Png16,
}

/// Flags of `symframe-lab bench`.
#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Folder for the generated dataset (reused when it exists) and the runs' outputs.
    #[arg(long, default_value = "symframe-bench")]
    pub dir: PathBuf,
    /// Image size in pixels (the paper's captures: 1024).
    #[arg(long, default_value_t = 1024)]
    pub size: usize,
    /// Image width in pixels, for a layout other than the paper's square (with --height).
    #[arg(long, requires = "height")]
    pub width: Option<usize>,
    /// Image height in pixels, for a layout other than the paper's square (with --width).
    #[arg(long, requires = "width")]
    pub height: Option<usize>,
    /// The images' format: exr (float, the paper's), jpeg (8-bit sRGB, quality 90, as
    /// cameras write) or png16 (16-bit linear).
    #[arg(long, value_enum, default_value_t = BenchFormat::Exr)]
    pub format: BenchFormat,
    /// Number of lights (the paper's captures: 1512).
    #[arg(long, default_value_t = 1512)]
    pub lights: usize,
    /// Skip the baseline run (`woodham` on the same cache; with --near, the distant-light model
    /// on the near images).
    #[arg(long)]
    pub no_baseline: bool,
    /// Delete the tile cache first, so the run decodes every image (default: reuse it).
    #[arg(long)]
    pub cold: bool,
    /// Passed to `estimate --decode-memory` (MiB for a batch of images decoded a band at a time).
    #[arg(long, default_value_t = default_decode_memory_mib(), value_name = "MIB")]
    pub decode_memory: usize,
    /// Passed to `estimate --cache-format`.
    #[arg(long, value_enum, default_value_t = CacheFormatArg::Auto)]
    pub cache_format: CacheFormatArg,
    /// Estimate only this shard of the tiles (`estimate --tiles K/N`): the whole cache is
    /// still built, so decoding and memory are measured at full size in a fraction of the time.
    #[arg(long, value_name = "K/N")]
    pub tiles: Option<Shard>,
    /// Near lights: the capture of `symframe synth --near` (--size wide, half as high: two
    /// spheres under --lights point lights on a dome, light_positions.txt and K.txt), estimated
    /// with near lights and then with distant ones on the same cache, then the paper's
    /// distant-light sphere of about as many pixels under as many lights; the time ratios.
    #[arg(long, conflicts_with_all = ["width", "height", "format", "tiles"])]
    pub near: bool,
}

/// Flags of `symframe-lab bench scaling`.
#[derive(Debug, Clone, Args)]
pub struct ScalingArgs {
    /// Folder for the generated datasets (reused when they exist), the runs' outputs and the
    /// results: scaling.json, scaling.md, scaling.png.
    #[arg(long, default_value = "symframe-scaling")]
    pub dir: PathBuf,
    /// A tiny sweep (for tests): seconds instead of minutes.
    #[arg(long)]
    pub quick: bool,
    /// Measure nothing: fit the model again and rewrite the tables and the plot from the runs
    /// recorded in DIR/scaling.json.
    #[arg(long)]
    pub refit: bool,
    /// Add 1024 x 1024 to the image-size sweep (about 5 GB of cache and minutes more).
    #[arg(long)]
    pub large: bool,
    /// Passed to `estimate --decode-memory` (MiB for a batch of images decoded a band at a time).
    #[arg(long, default_value_t = default_decode_memory_mib(), value_name = "MIB")]
    pub decode_memory: usize,
}
