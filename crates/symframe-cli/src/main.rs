//! The `symframe` command: parses flags into a validated configuration, calls the libraries,
//! and maps errors to exit codes (0 success, 1 failure with a one-line message, 2 usage, 130
//! interrupted: the same command resumes).

mod bench;
mod calibrate_cmd;
mod cli;
mod colorbar;
mod demo;
mod estimate;
mod eval_cmd;
mod experiment;
mod export_cmd;
mod fit_cmd;
mod integrate_cmd;
mod outdir;
mod progress;
mod relight_cmd;
mod synth;
mod tiled;

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
        cli::Command::Merge(args) => tiled::merge(&args),
        cli::Command::BenchPaper(args) => bench::run(&args),
        cli::Command::Eval(args) => eval_cmd::run(&args).map(|_| ()),
        cli::Command::Synth(args) => synth::run(&args).map(|_| ()),
        cli::Command::Experiment(args) => experiment::run(&args),
        cli::Command::Calibrate(args) => calibrate_cmd::run(&args).map(|_| ()),
        cli::Command::Export(args) => export_cmd::run(&args).map(|_| ()),
        cli::Command::Integrate(args) => integrate_cmd::run(&args).map(|_| ()),
    };
    if let Err(e) = result {
        if e.is::<tiled::Interrupted>() {
            eprintln!("symframe: {e}");
            std::process::exit(130);
        }
        // One line: the context chain joined, outermost first.
        eprintln!("symframe: error: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// The error and its causes on one line, outermost first, leaving out a cause whose text the
/// message already carries (library errors often include their source's message).
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line.replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_already_in_the_message_are_not_repeated() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = anyhow::Error::new(io).context("a.exr: cannot read: no such file");
        assert_eq!(one_line(&e), "a.exr: cannot read: no such file");
        let e = anyhow::anyhow!("inner").context("outer");
        assert_eq!(one_line(&e), "outer: inner");
    }
}
