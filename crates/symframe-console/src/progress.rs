//! Progress: bars drawn on a terminal (stderr); plain lines otherwise (logs of Slurm, cron,
//! CI or `2>log`: each tenth of a stage, or every 10 s); nothing with `--quiet`.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use symframe_job::{Progress, Stage};

/// A progress bar of `len` steps of `unit` (`"images"`, `"tiles"`) with a rounded rate and an
/// ETA, hidden when stderr is not a terminal.
pub fn bar(len: u64, what: &str, unit: &str) -> ProgressBar {
    let target = if interactive() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let pb = ProgressBar::with_draw_target(Some(len), target);
    let template = format!(
        "{{prefix:>10}} [{{bar:40.cyan/blue}}] {{pos}}/{{len}} {unit} {{rate}} eta {{eta}} "
    );
    pb.set_style(
        ProgressStyle::with_template(&template)
            .expect("valid progress template")
            .with_key(
                "rate",
                |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = w.write_str(&rate(state.per_sec()));
                },
            )
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    pb
}

/// A rate of steps per second to three significant digits at most (`1055/s`, `12.3/s`,
/// `0.42/s`), or `-` before there is one.
fn rate(per_sec: f64) -> String {
    if !(per_sec.is_finite() && per_sec > 0.0) {
        "-".into()
    } else if per_sec >= 100.0 {
        format!("{per_sec:.0}/s")
    } else if per_sec >= 10.0 {
        format!("{per_sec:.1}/s")
    } else {
        format!("{per_sec:.2}/s")
    }
}

/// A duration as `m:ss` (`h:mm:ss` from an hour).
fn clock(d: Duration) -> String {
    let s = d.as_secs();
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

/// A plain progress line: `estimating 12/64 tiles (19%), 0:42 elapsed, about 2:59 left` (the
/// time left from the rate so far; none before the first step or at the end).
fn line_text(name: &str, done: u64, total: u64, unit: &str, elapsed: Duration) -> String {
    let percent = (100 * done).checked_div(total).unwrap_or(100);
    let mut text = format!(
        "{name} {done}/{total}{unit} ({percent}%), {} elapsed",
        clock(elapsed)
    );
    // A time left needs a rate: none in the first second.
    if done > 0 && done < total && elapsed >= Duration::from_secs(1) {
        let left = elapsed.mul_f64((total - done) as f64 / done as f64);
        text += &format!(", about {} left", clock(left));
    }
    text
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
        Stage::Tiles => " tiles",
        Stage::Merging => " tiles",
        Stage::Rendering => " images",
    }
}

/// Plain progress lines of one stage: printed at each tenth and at least every 10 s.
struct Lines {
    stage: Stage,
    done: u64,
    tenth: u64,
    started: Instant,
    last: Instant,
}

/// Progress of a library job drawn as one bar per stage (hidden when stderr is not a
/// terminal); pass [`Bars::update`] as the job's progress callback.
pub struct Bars {
    /// What the job calls its per-pixel stage (`estimating`, `fitting`).
    work: &'static str,
    current: Mutex<Option<(Stage, ProgressBar)>>,
    lines: Mutex<Option<Lines>>,
}

impl Default for Bars {
    fn default() -> Self {
        Self::new("tiles")
    }
}

impl Bars {
    /// Bars whose per-pixel stage is named `work` (`estimating`, `fitting`).
    pub fn new(work: &'static str) -> Self {
        Self {
            work,
            current: Mutex::new(None),
            lines: Mutex::new(None),
        }
    }

    /// The name shown for `stage`.
    fn name(&self, stage: Stage) -> &'static str {
        match stage {
            Stage::Tiles => self.work,
            other => other.name(),
        }
    }

    /// Moves the bar of `p`'s stage (starting it, and ending the previous stage's, as needed);
    /// off a terminal, prints a plain line (`decoding 300/1000 images (30%), 0:04 elapsed, about
    /// 0:09 left`) at each tenth of the stage and at least every 10 s.
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
            *current = Some((
                p.stage,
                bar(p.total, self.name(p.stage), unit(p.stage).trim()),
            ));
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
                started: Instant::now(),
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
            let text = line_text(
                self.name(p.stage),
                l.done,
                p.total,
                unit(p.stage),
                l.started.elapsed(),
            );
            eprintln!("{text}");
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_rounded_and_lines_say_the_time() {
        assert_eq!(rate(1055.3355), "1055/s");
        assert_eq!(rate(12.345), "12.3/s");
        assert_eq!(rate(0.4249), "0.42/s");
        assert_eq!(rate(0.0), "-");
        assert_eq!(clock(Duration::from_secs(62)), "1:02");
        assert_eq!(clock(Duration::from_secs(3725)), "1:02:05");
        assert_eq!(
            line_text("estimating", 16, 64, " tiles", Duration::from_secs(10)),
            "estimating 16/64 tiles (25%), 0:10 elapsed, about 0:30 left"
        );
        assert_eq!(
            line_text("decoding", 50, 50, " images", Duration::from_secs(3)),
            "decoding 50/50 images (100%), 0:03 elapsed"
        );
    }
}
