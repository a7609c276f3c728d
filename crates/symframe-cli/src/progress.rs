//! Progress bars: drawn on a terminal (stderr), silent otherwise.

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use symframe_job::{Progress, Stage};

/// A progress bar of `len` steps with an ETA, hidden when stderr is not a terminal.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
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

/// Whether progress and chatter should go to the terminal.
pub fn interactive() -> bool {
    std::io::stderr().is_terminal()
}

/// Progress of a library job drawn as one bar per stage (hidden when stderr is not a
/// terminal); pass [`Bars::update`] as the job's progress callback.
#[derive(Default)]
pub struct Bars {
    current: Mutex<Option<(Stage, ProgressBar)>>,
}

impl Bars {
    /// Moves the bar of `p`'s stage (starting it, and ending the previous stage's, as needed).
    pub fn update(&self, p: Progress) {
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

impl Drop for Bars {
    fn drop(&mut self) {
        if let Some((_, b)) = self.current.get_mut().ok().and_then(|c| c.take()) {
            b.finish_and_clear();
        }
    }
}
