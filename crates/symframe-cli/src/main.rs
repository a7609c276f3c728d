//! The `symframe` command: parses flags into a validated configuration, calls the libraries,
//! and maps errors to exit codes (0 success, 1 failure with a one-line message, 2 usage, 130
//! interrupted: the same command resumes). The experiments and benchmarks are another program,
//! `symframe-lab` (crates/symframe-lab).

mod calibrate_cmd;
mod cli;
mod demo;
mod estimate;
mod eval_cmd;
mod export_cmd;
mod fit_cmd;
mod integrate_cmd;
mod synth;

// The commands' job control (Ctrl-C, progress) and progress display, as `crate::control` and
// `crate::progress`.
use symframe_console::{control, progress};

fn main() {
    symframe_console::main(
        "symframe",
        |cli: &cli::Cli| &cli.globals,
        |cli| match cli.command {
            cli::Command::Estimate(args) => estimate::run(&args).map(|_| ()),
            cli::Command::Fit(args) => fit_cmd::run(&args).map(|_| ()),
            cli::Command::Relight(args) => fit_cmd::relight(&args).map(|_| ()),
            cli::Command::View(args) => fit_cmd::view(&args).map(|_| ()),
            cli::Command::Demo(args) => demo::run(&args),
            cli::Command::Merge(args) => estimate::merge(&args),
            cli::Command::Eval(args) => eval_cmd::run(&args).map(|_| ()),
            cli::Command::Synth(args) => synth::run(&args).map(|_| ()),
            cli::Command::Calibrate(args) => calibrate_cmd::run(&args).map(|_| ()),
            cli::Command::Export(args) => export_cmd::run(&args).map(|_| ()),
            cli::Command::Integrate(args) => integrate_cmd::run(&args).map(|_| ()),
        },
    );
}
