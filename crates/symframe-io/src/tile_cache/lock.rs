//! The advisory lock on a cache: a lock file beside it (`flock` on Unix).

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{Error, Result};

/// An advisory lock on a cache (a lock file beside it; `flock` on Unix, nothing elsewhere).
#[derive(Debug)]
pub(super) struct CacheLock {
    pub(super) file: File,
    pub(super) path: PathBuf,
}

impl CacheLock {
    /// Takes the shared lock, waiting while another process holds the exclusive one, polling
    /// `stop` every 100 ms: `false` (no lock taken) once it is set.
    #[cfg(unix)]
    pub(super) fn shared_unless_stopped(&self, stop: &AtomicBool) -> Result<bool> {
        use std::os::unix::io::AsRawFd;
        loop {
            // SAFETY: flock on a file descriptor we own.
            if unsafe { libc::flock(self.file.as_raw_fd(), libc::LOCK_SH | libc::LOCK_NB) } == 0 {
                return Ok(true);
            }
            let e = std::io::Error::last_os_error();
            match e.kind() {
                std::io::ErrorKind::Interrupted => {}
                std::io::ErrorKind::WouldBlock => {
                    if stop.load(Ordering::Relaxed) {
                        return Ok(false);
                    }
                    std::thread::sleep(std::time::Duration::from_millis(100));
                }
                _ => return Err(Error::write(&self.path, e)),
            }
        }
    }

    /// Takes the shared lock (no locking off Unix).
    #[cfg(not(unix))]
    pub(super) fn shared_unless_stopped(&self, _stop: &AtomicBool) -> Result<bool> {
        Ok(true)
    }

    pub(super) fn open(path: &Path) -> Result<Self> {
        let file = crate::atomic::open_no_follow(
            OpenOptions::new().create(true).truncate(false).write(true),
            path,
        )
        .map_err(|e| Error::write(path, e))?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
        })
    }

    #[cfg(unix)]
    pub(super) fn set(&self, exclusive: bool) -> Result<()> {
        use std::os::unix::io::AsRawFd;
        let op = if exclusive {
            libc::LOCK_EX
        } else {
            libc::LOCK_SH
        };
        loop {
            // SAFETY: flock on a file descriptor we own.
            if unsafe { libc::flock(self.file.as_raw_fd(), op) } == 0 {
                return Ok(());
            }
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(Error::write(&self.path, e));
            }
        }
    }

    #[cfg(not(unix))]
    pub(super) fn set(&self, _exclusive: bool) -> Result<()> {
        Ok(())
    }

    /// Takes the exclusive lock if no one else holds the lock; `false` if someone does (then
    /// this process holds no lock: a failed conversion gives up the shared one).
    #[cfg(unix)]
    pub(super) fn try_exclusive(&self) -> Result<bool> {
        use std::os::unix::io::AsRawFd;
        loop {
            // SAFETY: flock on a file descriptor we own.
            if unsafe { libc::flock(self.file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
                return Ok(true);
            }
            let e = std::io::Error::last_os_error();
            match e.kind() {
                std::io::ErrorKind::Interrupted => continue,
                std::io::ErrorKind::WouldBlock => return Ok(false),
                _ => return Err(Error::write(&self.path, e)),
            }
        }
    }

    #[cfg(not(unix))]
    pub(super) fn try_exclusive(&self) -> Result<bool> {
        Ok(true)
    }
}
