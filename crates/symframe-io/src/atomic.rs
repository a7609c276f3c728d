//! Atomic file writes: data goes to a temporary file in the destination's folder, which is
//! renamed over the destination only once fully written, so no reader ever sees half a file.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Distinguishes temporary files of concurrent writes within this process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A temporary sibling name for `path` (hidden, unique per process and call).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// Writes `path` atomically: `fill` writes the content into a buffered temporary file, which
/// is flushed and renamed to `path`. On any error the temporary file is removed. (No fsync:
/// this guards against failed or interrupted writes, not against power loss.)
pub(crate) fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let tmp = temp_path(path);
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| Error::write(path, e))?;
    let mut w = BufWriter::new(file);
    let result = fill(&mut w).and_then(|()| {
        let file = w
            .into_inner()
            .map_err(|e| Error::write(path, e.into_error()))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(|e| Error::write(path, e))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| {
        w.write_all(bytes).map_err(|e| Error::write(path, e))
    })
}

/// Opens `path` with `options`, never through a symbolic link at its last component (a link
/// planted where this tool keeps a file of its own is an error, not a way to write
/// elsewhere). Unix only; elsewhere a plain open.
pub fn open_no_follow(options: &mut OpenOptions, path: &Path) -> std::io::Result<File> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // Non-blocking: a FIFO planted there fails at once instead of waiting for a peer.
        options.custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK);
    }
    options.open(path)
}
