//! What the symframe command-line programs (`symframe` and `symframe-lab`) share: progress on
//! the terminal ([`progress`]), the global flags `--threads` and `--quiet` ([`Globals`]), the
//! Ctrl-C handling of a job ([`control`]), the flags both pass to the tile cache ([`flags`]),
//! and a `main` that maps errors to exit codes ([`main`]: 0 success, 1 failure with a
//! one-line message, 2 usage, 130 interrupted).

pub mod flags;
pub mod progress;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use clap::{Args, Parser};
use symframe_job::{one_line, Checkpoint, Control, Interrupted, Progress};

/// The flags every subcommand takes: flatten into the program's top-level parser.
#[derive(Debug, Clone, Args)]
pub struct Globals {
    /// Worker threads (default: all cores).
    #[arg(long, global = true, value_parser = clap::value_parser!(usize))]
    pub threads: Option<usize>,
    /// No progress lines and no summary (warnings and errors are still printed).
    #[arg(long, short = 'q', global = true)]
    pub quiet: bool,
}

/// Set by Ctrl-C: the running job starts no new image or tile.
static STOP: AtomicBool = AtomicBool::new(false);

/// The program's name in its messages (`symframe`, `symframe-lab`), set by [`main`].
static PROGRAM: OnceLock<&'static str> = OnceLock::new();

/// The program's name in its messages.
fn program() -> &'static str {
    PROGRAM.get().copied().unwrap_or("symframe")
}

/// Installs the Ctrl-C handler (once): the first Ctrl-C sets [`STOP`] so that the running tiles
/// finish and nothing new starts; a second one exits at once (tile files are written atomically,
/// so even that leaves no corrupt output).
fn install_interrupt_handler() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        let _ = ctrlc::set_handler(|| {
            let name = program();
            if STOP.swap(true, Ordering::SeqCst) {
                eprintln!("\n{name}: interrupted; run the same command again to resume");
                std::process::exit(130);
            }
            eprintln!(
                "\n{name}: stopping after the images or tiles in progress (Ctrl-C again to quit now)"
            );
        });
    });
}

/// The job control of a command: Ctrl-C stops it, `progress` shows how far it is, warnings
/// are printed as `warning: ...` lines; `stop_after_tiles` is a testing aid (the job behaves
/// as if interrupted once that many tiles are finished).
pub fn control<'a>(
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
fn test_checkpoint(c: Checkpoint) {
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

/// The `main` of a program named `name`: parses its flags (`C`), applies the [`Globals`] that
/// `globals` finds in them and runs `run`. It returns when `run` succeeds (exit status 0);
/// otherwise it exits with 130 when interrupted (the same command resumes), 1 with
/// `NAME: error: ...` on one line on any other error, and 2 on a usage error (from clap, or a
/// `--threads` out of range).
pub fn main<C: Parser>(
    name: &'static str,
    globals: impl FnOnce(&C) -> &Globals,
    run: impl FnOnce(C) -> anyhow::Result<()>,
) {
    let _ = PROGRAM.set(name);
    // Output piped into a reader that stops early (`symframe eval ... | head`): end quietly
    // on SIGPIPE as other Unix tools do, instead of panicking on the failed write.
    #[cfg(unix)]
    // SAFETY: restoring the default action of one signal before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = C::parse();
    let g = globals(&cli);
    progress::set_quiet(g.quiet);
    if let Some(n) = g.threads {
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        let most = (4 * cores).min(1024);
        if n == 0 || n > most {
            eprintln!(
                "{name}: error: --threads {n}: give 1 to {most} (4 per available core, at \
                 most 1024; {cores} cores here)"
            );
            std::process::exit(2);
        }
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("{name}: error: cannot start {n} threads: {e}");
            std::process::exit(1);
        }
    }
    if let Err(e) = run(cli) {
        if e.is::<Interrupted>() {
            eprintln!("{name}: {e}");
            std::process::exit(130);
        }
        // One line: the context chain joined, outermost first.
        eprintln!("{name}: error: {}", one_line(&e));
        std::process::exit(1);
    }
}
