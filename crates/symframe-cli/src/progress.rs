//! Progress: bars drawn on a terminal (stderr); plain lines otherwise (logs of Slurm, cron,
//! CI or `2>log`: each tenth of a stage, or every 10 s); nothing with `--quiet`.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use symframe_job::{Progress, Stage};

/// A progress bar of `len` steps with an ETA, hidden when stderr is not a terminal.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let target = if interactive() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let pb = ProgressBar::with_draw_target(Some(len), target);
    pb.set_style(
        ProgressStyle::with_template(
            "{prefix:>10} [{bar:40.cyan/blue}] {pos}/{len} {per_sec} eta {eta} ",
        )
        .expect("valid progress template")
        .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    pb
}

/// Set by `--quiet`.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Silences progress and summaries (`--quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::SeqCst);
}

/// Whether summaries and progress are printed (on a terminal or not): not with `--quiet`.
pub fn chatty() -> bool {
    !QUIET.load(Ordering::SeqCst)
}

/// Whether progress is drawn as bars (stderr is a terminal and not `--quiet`).
pub fn interactive() -> bool {
    chatty() && std::io::stderr().is_terminal()
}

/// The unit of a stage's steps in plain progress lines.
fn unit(stage: Stage) -> &'static str {
    match stage {
        Stage::Decoding => " images",
        Stage::Tiles => "",
        Stage::Merging => " tiles",
        Stage::Rendering => " images",
    }
}

/// Plain progress lines of one stage: printed at each tenth and at least every 10 s.
struct Lines {
    stage: Stage,
    done: u64,
    tenth: u64,
    last: Instant,
}

/// Progress of a library job drawn as one bar per stage (hidden when stderr is not a
/// terminal); pass [`Bars::update`] as the job's progress callback.
#[derive(Default)]
pub struct Bars {
    current: Mutex<Option<(Stage, ProgressBar)>>,
    lines: Mutex<Option<Lines>>,
}

impl Bars {
    /// Moves the bar of `p`'s stage (starting it, and ending the previous stage's, as needed);
    /// off a terminal, prints a plain line (`decoding 300/1000 images`, `tiles 12/64`) at each
    /// tenth of the stage and at least every 10 s.
    pub fn update(&self, p: Progress) {
        if !chatty() {
            return;
        }
        if !interactive() {
            // Rendering is quick: no log lines for it.
            if p.stage != Stage::Rendering {
                self.line(p);
            }
            return;
        }
        let mut current = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if current.as_ref().is_none_or(|(stage, _)| *stage != p.stage) {
            if let Some((_, old)) = current.take() {
                old.finish_and_clear();
            }
            *current = Some((p.stage, bar(p.total, p.stage.name())));
        }
        if let Some((_, b)) = current.as_ref() {
            // Updates arrive from several threads, not in order.
            b.set_position(b.position().max(p.done));
        }
    }
}

impl Bars {
    fn line(&self, p: Progress) {
        let mut lines = self.lines.lock().unwrap_or_else(|e| e.into_inner());
        let fresh = lines.as_ref().is_none_or(|l| l.stage != p.stage);
        if fresh {
            *lines = Some(Lines {
                stage: p.stage,
                done: 0,
                tenth: 0,
                last: Instant::now(),
            });
        }
        let Some(l) = lines.as_mut() else { return };
        // Updates arrive from several threads, not in order.
        if p.done <= l.done && !fresh {
            return;
        }
        l.done = l.done.max(p.done);
        let tenth = (l.done * 10).checked_div(p.total).unwrap_or(10);
        if fresh || tenth > l.tenth || l.last.elapsed() >= Duration::from_secs(10) {
            l.tenth = tenth;
            l.last = Instant::now();
            eprintln!("{} {}/{}{}", p.stage.name(), l.done, p.total, unit(p.stage));
        }
    }
}

impl Drop for Bars {
    fn drop(&mut self) {
        if let Some((_, b)) = self.current.get_mut().ok().and_then(|c| c.take()) {
            b.finish_and_clear();
        }
    }
}
