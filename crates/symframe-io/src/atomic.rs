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

/// A temporary sibling of a destination file, renamed over it by [`TempFile::commit`] and
/// removed if dropped uncommitted: the atomic write of a file filled piece by piece.
pub(crate) struct TempFile {
    path: PathBuf,
    tmp: PathBuf,
    armed: bool,
}

impl TempFile {
    /// Creates the temporary file for `path` (created anew, never through a planted link):
    /// the guard and the file to write into.
    pub(crate) fn create(path: &Path) -> Result<(Self, File)> {
        let tmp = temp_path(path);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| Error::write(path, e))?;
        let guard = Self {
            path: path.to_path_buf(),
            tmp,
            armed: true,
        };
        Ok((guard, file))
    }

    /// Renames the temporary file (written and closed by now) to the destination.
    pub(crate) fn commit(mut self) -> Result<()> {
        std::fs::rename(&self.tmp, &self.path).map_err(|e| Error::write(&self.path, e))?;
        self.armed = false;
        Ok(())
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if self.armed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `path` atomically: `fill` writes the content into a buffered temporary file, which
/// is flushed and renamed to `path`. On any error the temporary file is removed. (No fsync:
/// this guards against failed or interrupted writes, not against power loss.)
pub(crate) fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let (guard, file) = TempFile::create(path)?;
    let mut w = BufWriter::new(file);
    fill(&mut w)?;
    let file = w
        .into_inner()
        .map_err(|e| Error::write(path, e.into_error()))?;
    drop(file);
    guard.commit()
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
