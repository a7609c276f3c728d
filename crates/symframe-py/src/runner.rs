//! Runs a job on a worker thread while the calling Python thread waits with the GIL released:
//! Ctrl-C (a pending signal) and an exception raised by the progress callback set the job's
//! stop flag; the job then finishes the images or tiles in progress and returns, and the
//! exception is raised in Python. Job errors become [`SymframeError`] with the command line's
//! one-line message.

use std::ffi::CString;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use pyo3::exceptions::{PyKeyboardInterrupt, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use symframe_job::{one_line, Control, Interrupted, Progress};

use crate::SymframeError;

/// How often the waiting thread looks for Ctrl-C.
const POLL: Duration = Duration::from_millis(50);
/// Least time between two progress calls of one stage (the first and last always come).
const THROTTLE: Duration = Duration::from_millis(100);

/// A job error as a Python exception.
pub fn to_py(e: anyhow::Error) -> PyErr {
    if e.is::<Interrupted>() {
        PyKeyboardInterrupt::new_err(e.to_string())
    } else {
        SymframeError::new_err(one_line(&e))
    }
}

/// Locks a mutex, ignoring poisoning (a panicking holder cannot leave these values broken).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Runs `job` with a [`Control`] wired to Python: see the module documentation. `threads`
/// sizes a thread pool of its own for the job (`None`: the global one, all cores).
pub fn run_job<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
    job: impl FnOnce(&Control) -> anyhow::Result<T> + Send,
) -> PyResult<T> {
    let pool = match threads {
        None => None,
        Some(n) => {
            let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
            let most = (4 * cores).min(1024);
            if n == 0 || n > most {
                return Err(PyValueError::new_err(format!(
                    "threads={n}: give 1 to {most} (4 per available core, at most 1024; {cores} \
                     cores here)"
                )));
            }
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| {
                        SymframeError::new_err(format!("cannot start {n} threads: {e}"))
                    })?,
            )
        }
    };
    let stop = AtomicBool::new(false);
    let callback_error: Mutex<Option<PyErr>> = Mutex::new(None);
    let last_call: Mutex<Option<(&'static str, Instant)>> = Mutex::new(None);
    let warnings: Mutex<Vec<String>> = Mutex::new(Vec::new());

    let show = |p: Progress| {
        let Some(callback) = &progress else {
            return;
        };
        if stop.load(Ordering::SeqCst) {
            return;
        }
        {
            let mut last = lock(&last_call);
            let now = Instant::now();
            let edge = p.done <= 1 || p.done >= p.total;
            let same_stage_recently = last.is_some_and(|(stage, t)| {
                stage == p.stage.name() && now.duration_since(t) < THROTTLE
            });
            if same_stage_recently && !edge {
                return;
            }
            *last = Some((p.stage.name(), now));
        }
        Python::attach(|py| {
            if let Err(e) = callback.call1(py, (p.stage.name(), p.done, p.total)) {
                stop.store(true, Ordering::SeqCst);
                lock(&callback_error).get_or_insert(e);
            }
        });
    };
    let warn = |line: &str| lock(&warnings).push(line.to_string());

    let (tx, rx) = mpsc::channel::<anyhow::Result<T>>();
    let (result, interrupt) = std::thread::scope(|s| {
        let (stop, show, warn, pool) = (&stop, &show, &warn, &pool);
        s.spawn(move || {
            let ctl = Control {
                stop,
                progress: show,
                warning: warn,
                ..Control::default()
            };
            let run = || match pool {
                Some(p) => p.install(|| job(&ctl)),
                None => job(&ctl),
            };
            let result = std::panic::catch_unwind(AssertUnwindSafe(run)).unwrap_or_else(|panic| {
                let what = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                Err(anyhow::anyhow!("internal error: {what}"))
            });
            let _ = tx.send(result);
        });
        let mut rx = rx;
        let mut interrupt: Option<PyErr> = None;
        loop {
            let (back, got) = py.detach(move || {
                let got = rx.recv_timeout(POLL);
                (rx, got)
            });
            rx = back;
            match got {
                // A signal that came in since the last poll is the caller's too, though the job
                // finished first: raised here, inside the call, not at whatever bytecode runs
                // next (which may be outside the caller's `try`).
                Ok(result) => {
                    if interrupt.is_none() {
                        interrupt = py.check_signals().err();
                    }
                    break (result, interrupt);
                }
                Err(RecvTimeoutError::Timeout) => {
                    if interrupt.is_none() {
                        if let Err(e) = py.check_signals() {
                            stop.store(true, Ordering::SeqCst);
                            interrupt = Some(e);
                        }
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    break (
                        Err(anyhow::anyhow!(
                            "internal error: the job ended without a result"
                        )),
                        interrupt,
                    )
                }
            }
        }
    });

    for line in lock(&warnings).drain(..) {
        let message = CString::new(line.replace('\0', " ")).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
    }
    if let Some(e) = lock(&callback_error).take() {
        return Err(e);
    }
    if let Some(e) = interrupt {
        return Err(e);
    }
    result.map_err(to_py)
}
