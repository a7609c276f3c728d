//! Reading the files a user names, bounded: every file read whole (light files, image lists,
//! images, masks, `.npy` maps, JSON reports) must be a regular file, and no more than a
//! size cap of its kind is read. A FIFO, a device (`/dev/zero`, `/dev/stdin`), a socket or a
//! folder is refused before it is opened (opening a FIFO would wait for a writer), and a file
//! larger than its cap is refused before anything is read; the read itself goes through
//! `take()`, so a file that grows while it is read stops at the cap too.

use std::fs::File;
use std::io::{BufReader, Read, Take};
use std::path::Path;

use crate::error::{Error, Result};

/// What a file that is not a regular file is, for messages: "a character device", "a FIFO".
fn kind_of(ft: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_fifo() {
            return "a FIFO";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    if ft.is_symlink() {
        return "a symbolic link";
    }
    if ft.is_dir() {
        "a folder"
    } else {
        "neither a file nor a folder"
    }
}

/// Checks that `path` (symbolic links followed) is a regular file; returns its length. A
/// missing file is [`Error::Read`] (its cause says so); anything else that is not a regular
/// file is `PATH: not a regular file (a character device)`.
pub fn check_regular_file(path: &Path) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|e| Error::read(path, e))?;
    if !meta.is_file() {
        return Err(Error::invalid(
            path,
            format!("not a regular file ({})", kind_of(&meta.file_type())),
        ));
    }
    Ok(meta.len())
}

/// The cap as a message gives it: "64 MiB", "4 GiB", "1.5 KiB".
pub(crate) fn show_size(bytes: u64) -> String {
    let units = [(1u64 << 30, "GiB"), (1 << 20, "MiB"), (1 << 10, "KiB")];
    for (unit, name) in units {
        if bytes >= unit {
            let v = bytes as f64 / unit as f64;
            return if bytes.is_multiple_of(unit) {
                format!("{} {name}", bytes / unit)
            } else {
                format!("{v:.1} {name}")
            };
        }
    }
    format!("{bytes} bytes")
}

/// Opens `path`, `what` (e.g. "a light file": it names the cap in the error), of at most
/// `max_bytes` bytes: a regular file ([`check_regular_file`]) no longer than the cap, else
/// `PATH: larger than the 64 MiB a light file can be`; the file opened is checked again.
pub(crate) fn open_checked(path: &Path, what: &str, max_bytes: u64) -> Result<File> {
    let len = check_regular_file(path)?;
    if len > max_bytes {
        return Err(too_large(path, what, max_bytes));
    }
    let f = File::open(path).map_err(|e| Error::read(path, e))?;
    // The file opened may not be the one checked (replaced in between): check it again.
    let meta = f.metadata().map_err(|e| Error::read(path, e))?;
    if !meta.is_file() {
        return Err(Error::invalid(
            path,
            format!("not a regular file ({})", kind_of(&meta.file_type())),
        ));
    }
    Ok(f)
}

/// `PATH: larger than the 64 MiB a light file can be`.
fn too_large(path: &Path, what: &str, max_bytes: u64) -> Error {
    Error::invalid(
        path,
        format!("larger than the {} {what} can be", show_size(max_bytes)),
    )
}

/// Opens `path` to be read a line (or a record) at a time, bounded as [`read_bounded`] is: a
/// regular file no longer than `max_bytes`, read through a buffer and never past the cap (a
/// file that grows while it is read ends there), so nothing but the buffer is held.
pub fn open_bounded(path: &Path, what: &str, max_bytes: u64) -> Result<BufReader<Take<File>>> {
    Ok(BufReader::new(
        open_checked(path, what, max_bytes)?.take(max_bytes),
    ))
}

/// Reads the whole of `path`, `what` (e.g. "a light file": it names the cap in the error), of
/// at most `max_bytes` bytes: a regular file ([`check_regular_file`]) no longer than the cap,
/// else `PATH: larger than the 64 MiB a light file can be`.
pub fn read_bounded(path: &Path, what: &str, max_bytes: u64) -> Result<Vec<u8>> {
    let f = open_checked(path, what, max_bytes)?;
    let len = f.metadata().map_err(|e| Error::read(path, e))?.len();
    let mut buf = Vec::with_capacity(len.min(max_bytes) as usize);
    f.take(max_bytes.saturating_add(1))
        .read_to_end(&mut buf)
        .map_err(|e| Error::read(path, e))?;
    if buf.len() as u64 > max_bytes {
        return Err(too_large(path, what, max_bytes));
    }
    Ok(buf)
}

/// [`read_bounded`] of a UTF-8 text file (a byte-order mark is kept; the caller decides).
pub fn read_text_bounded(path: &Path, what: &str, max_bytes: u64) -> Result<String> {
    let bytes = read_bounded(path, what, max_bytes)?;
    String::from_utf8(bytes).map_err(|_| Error::decode(path, "not a UTF-8 text file"))
}

/// Opens `path`, a file this tool wrote into one of its own folders (a tile result, a tile
/// cache), for reading: `None` if there is none; an error naming it if it is not a regular file
/// (`PATH: not a regular file (a FIFO)`): a symbolic link, FIFO, device, socket or folder
/// planted there is never opened (opening a FIFO waits for a writer, a device reads without
/// end). The open does not follow a link nor wait, and the file opened is checked again.
/// Returns the file and its length: read no more than the length its header or grid implies
/// ([`std::io::Read::take`]).
pub fn open_own_file(path: &Path) -> Result<Option<(File, u64)>> {
    let not_regular = |ft: &std::fs::FileType| {
        Error::invalid(path, format!("not a regular file ({})", kind_of(ft)))
    };
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::read(path, e)),
    };
    if !meta.file_type().is_file() {
        return Err(not_regular(&meta.file_type()));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK);
    }
    let f = match options.open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::read(path, e)),
    };
    let meta = f.metadata().map_err(|e| Error::read(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(&meta.file_type()));
    }
    Ok(Some((f, meta.len())))
}

/// The first `len` bytes of `f` (of `path`, for errors), never more; fewer if the file is
/// shorter.
pub fn read_at_most(f: File, path: &Path, len: u64) -> Result<Vec<u8>> {
    let mut buf = Vec::with_capacity(len.min(1 << 20) as usize);
    f.take(len)
        .read_to_end(&mut buf)
        .map_err(|e| Error::read(path, e))?;
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `/dev/zero` as a light file or mask grew until memory ran out.
    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_folders_are_refused_unread() {
        let e = read_bounded(Path::new("/dev/zero"), "a light file", 1 << 20)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "/dev/zero: not a regular file (a character device)");
        let d = tempfile::tempdir().unwrap();
        let fifo = d.path().join("f.lp");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: mkfifo on a NUL-terminated path we own.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // Refused without opening it (opening would wait for a writer).
        let e = read_bounded(&fifo, "a light file", 1 << 20).unwrap_err();
        assert!(
            e.to_string().ends_with("f.lp: not a regular file (a FIFO)"),
            "{e}"
        );
        let e = read_bounded(d.path(), "a light file", 1 << 20).unwrap_err();
        assert!(
            e.to_string().ends_with(": not a regular file (a folder)"),
            "{e}"
        );
        // A link to a device is the device.
        let link = d.path().join("z.png");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = read_bounded(&link, "an image file", 1 << 20).unwrap_err();
        assert!(e
            .to_string()
            .ends_with("z.png: not a regular file (a character device)"));
    }

    #[test]
    fn a_file_over_the_cap_is_refused_and_one_under_it_read() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("big.lp");
        std::fs::write(&p, vec![b'1'; 3000]).unwrap();
        let e = read_bounded(&p, "a light file", 2048)
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with("big.lp: larger than the 2 KiB a light file can be"),
            "{e}"
        );
        assert_eq!(read_bounded(&p, "a light file", 3000).unwrap().len(), 3000);
        assert_eq!(
            read_text_bounded(&p, "a light file", 4096).unwrap().len(),
            3000
        );
        assert_eq!(show_size(64 << 20), "64 MiB");
        assert_eq!(show_size(1536), "1.5 KiB");
        let e = read_bounded(&d.path().join("none.lp"), "a light file", 10).unwrap_err();
        assert!(e.to_string().ends_with("none.lp: cannot read"), "{e}");
    }
}
