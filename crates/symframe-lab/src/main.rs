//! `symframe-lab`: the validation experiments and the benchmarks of symframe, apart from the
//! user's `symframe` command. `experiment` re-runs the paper's figures and the other studies
//! (docs/validation.md); `bench` times `symframe estimate` at paper scale and `bench scaling`
//! sweeps size, lights and threads (docs/performance.md). Exit codes as `symframe`'s: 0
//! success, 1 failure with a one-line message, 2 usage, 130 interrupted.

mod bench;
mod cli;
mod experiment;

use cli::{BenchCommand, Cli, Command};

fn main() {
    symframe_console::main(
        "symframe-lab",
        |cli: &Cli| &cli.globals,
        |cli| match cli.command {
            Command::Experiment(args) => experiment::run(&args),
            Command::Bench(args) => match args.other {
                Some(BenchCommand::Scaling(scaling)) => bench::scaling::run(&scaling),
                None => bench::run(&args.paper),
            },
        },
    );
}
