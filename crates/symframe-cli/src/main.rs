//! The `symframe` command: parses flags into a validated configuration, calls the libraries,
//! and maps errors to exit codes (0 success, 1 failure with a one-line message, 2 usage).

mod cli;
mod colorbar;
mod demo;
mod estimate;
mod eval_cmd;
mod experiment;
mod fit_cmd;
mod outdir;
mod progress;
mod relight_cmd;
mod synth;

use clap::Parser;

fn main() {
    let cli = cli::Cli::parse();
    if let Some(n) = cli.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("symframe: error: cannot start {n} threads: {e}");
            std::process::exit(1);
        }
    }
    let result = match cli.command {
        cli::Command::Estimate(args) => estimate::run(&args).map(|_| ()),
        cli::Command::Fit(args) => fit_cmd::run(&args).map(|_| ()),
        cli::Command::Relight(args) => relight_cmd::run(&args).map(|_| ()),
        cli::Command::Demo(args) => demo::run(&args),
        cli::Command::Eval(args) => eval_cmd::run(&args).map(|_| ()),
        cli::Command::Synth(args) => synth::run(&args).map(|_| ()),
        cli::Command::Experiment(args) => experiment::run(&args),
    };
    if let Err(e) = result {
        // One line: the context chain joined, outermost first.
        let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
        eprintln!("symframe: error: {}", msg.join(": "));
        std::process::exit(1);
    }
}
