//! The `symframe` command: parses flags into a validated configuration, calls the libraries,
//! and maps errors to exit codes (0 success, 1 failure with a one-line message, 2 usage, 130
//! interrupted: the same command resumes).

mod bench;
mod calibrate_cmd;
mod cli;
mod demo;
mod estimate;
mod eval_cmd;
mod experiment;
mod export_cmd;
mod fit_cmd;
mod integrate_cmd;
mod progress;
mod synth;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use clap::Parser;
use symframe_job::{Checkpoint, Control, Interrupted, Progress};

/// Set by Ctrl-C: the running job starts no new image or tile.
static STOP: AtomicBool = AtomicBool::new(false);

/// Installs the Ctrl-C handler (once): the first Ctrl-C sets [`STOP`] so that the running tiles
/// finish and nothing new starts; a second one exits at once (tile files are written atomically,
/// so even that leaves no corrupt output).
fn install_interrupt_handler() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        let _ = ctrlc::set_handler(|| {
            if STOP.swap(true, Ordering::SeqCst) {
                eprintln!("\nsymframe: interrupted; run the same command again to resume");
                std::process::exit(130);
            }
            eprintln!(
                "\nsymframe: stopping after the images or tiles in progress (Ctrl-C again to quit now)"
            );
        });
    });
}

/// The job control of a command: Ctrl-C stops it, `progress` shows how far it is.
fn control<'a>(
    progress: &'a (dyn Fn(Progress) + Sync),
    stop_after_tiles: Option<usize>,
) -> Control<'a> {
    install_interrupt_handler();
    Control {
        stop: &STOP,
        progress,
        stop_after_tiles,
        warning: &|line| eprintln!("warning: {line}"),
        checkpoint: &test_checkpoint,
    }
}

/// Testing aids for the regression tests of the output folder's guarantees (environment
/// variables, not documented flags): `SYMFRAME_TEST_HOLD_LOCK_S=S` sleeps S seconds once the
/// output folder is locked; `SYMFRAME_TEST_KILL_AFTER_MOVES=N` kills the process (SIGKILL, as
/// `kill -9` does) once N files of the new output set are in place.
pub(crate) fn test_checkpoint(c: Checkpoint) {
    let var = |name: &str| std::env::var(name).ok()?.parse::<u64>().ok();
    match c {
        Checkpoint::OutputLocked => {
            if let Some(s) = var("SYMFRAME_TEST_HOLD_LOCK_S") {
                std::thread::sleep(std::time::Duration::from_secs(s));
            }
        }
        Checkpoint::Moved(n) => {
            if var("SYMFRAME_TEST_KILL_AFTER_MOVES") == Some(n as u64) {
                #[cfg(unix)]
                // SAFETY: sending a signal to this process.
                unsafe {
                    libc::kill(libc::getpid(), libc::SIGKILL);
                }
                std::process::exit(137);
            }
        }
    }
}

fn main() {
    // Output piped into a reader that stops early (`symframe eval ... | head`): end quietly
    // on SIGPIPE as other Unix tools do, instead of panicking on the failed write.
    #[cfg(unix)]
    // SAFETY: restoring the default action of one signal before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = cli::Cli::parse();
    progress::set_quiet(cli.quiet);
    if let Some(n) = cli.threads {
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        let most = (4 * cores).min(1024);
        if n == 0 || n > most {
            eprintln!(
                "symframe: error: --threads {n}: give 1 to {most} (4 per available core, at \
                 most 1024; {cores} cores here)"
            );
            std::process::exit(2);
        }
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
        cli::Command::Relight(args) => fit_cmd::relight(&args).map(|_| ()),
        cli::Command::View(args) => fit_cmd::view(&args).map(|_| ()),
        cli::Command::Demo(args) => demo::run(&args),
        cli::Command::Merge(args) => estimate::merge(&args),
        cli::Command::BenchPaper(args) => bench::run(&args),
        cli::Command::BenchScaling(args) => bench::scaling::run(&args),
        cli::Command::Eval(args) => eval_cmd::run(&args).map(|_| ()),
        cli::Command::Synth(args) => synth::run(&args).map(|_| ()),
        cli::Command::Experiment(args) => experiment::run(&args),
        cli::Command::Calibrate(args) => calibrate_cmd::run(&args).map(|_| ()),
        cli::Command::Export(args) => export_cmd::run(&args).map(|_| ()),
        cli::Command::Integrate(args) => integrate_cmd::run(&args).map(|_| ()),
    };
    if let Err(e) = result {
        if e.is::<Interrupted>() {
            eprintln!("symframe: {e}");
            std::process::exit(130);
        }
        // One line: the context chain joined, outermost first.
        eprintln!("symframe: error: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// The error and its causes on one line, outermost first (each error's message leaves its
/// cause to the chain); a codec's multi-line message is folded onto the line.
fn one_line(e: &anyhow::Error) -> String {
    let parts: Vec<String> = e.chain().map(|c| c.to_string()).collect();
    parts
        .join(": ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chain_is_joined_on_one_line() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such\nfile");
        let e = anyhow::Error::new(io).context("a.exr: cannot read");
        assert_eq!(one_line(&e), "a.exr: cannot read: no such file");
    }
}
