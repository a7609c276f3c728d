//! The crate's error type: every variant names the file it is about, so a message alone tells
//! the user what to fix. Where an underlying error (I/O, a codec's) is the cause, it is the
//! error's [`source`](std::error::Error::source), not part of its message: print the chain
//! (as the `symframe` command does) to see both, each once.

use std::path::PathBuf;

/// Everything that can go wrong reading or writing a dataset, image or output map.
///
/// Each variant carries the offending file's path (and the line for text-file parse errors) and
/// formats as a single line.
///
/// ```
/// use std::error::Error as _;
/// let e = symframe_io::read_npy_f32("/no/such/map.npy".as_ref()).unwrap_err();
/// assert_eq!(e.to_string(), "/no/such/map.npy: cannot read");
/// assert!(e.source().is_some()); // the I/O error: not found
/// ```
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be opened or read (missing, permissions, I/O failure).
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },

    /// The file (or its temporary sibling) could not be created, written or renamed.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },

    /// A text file has a bad line (parse error, zero light direction, ...).
    #[error("{}:{line}: {msg}", path.display())]
    Parse {
        /// The text file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was wrong.
        msg: String,
    },

    /// A file's content is wrong as a whole (counts disagree, mask empty, not a dataset, ...).
    #[error("{}: {msg}", path.display())]
    Invalid {
        /// The file or folder.
        path: PathBuf,
        /// What was wrong.
        msg: String,
    },

    /// An image (or array) file is truncated or corrupt.
    #[error("{}: cannot decode", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's error (or complaint).
        source: BoxError,
    },

    /// A file uses a format or layout this crate does not read.
    #[error("{}: unsupported: {msg}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        msg: String,
    },

    /// A file declares more than this crate decodes (see [`crate::limits`]): refused before
    /// anything of that size is allocated.
    #[error("{}: exceeds limits: {msg}", path.display())]
    Limits {
        /// The file.
        path: PathBuf,
        /// What was declared and which limit it exceeds.
        msg: String,
    },

    /// An image of a stack has a different size from the stack's first image.
    #[error(
        "{}: image is {width}x{height} but the first image ({}) is {first_width}x{first_height}",
        path.display(),
        first.display()
    )]
    SizeMismatch {
        /// The offending image.
        path: PathBuf,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// The stack's first image.
        first: PathBuf,
        /// The first image's width.
        first_width: usize,
        /// The first image's height.
        first_height: usize,
    },

    /// The user interrupted the work (Ctrl-C) before it finished; what was done is kept and a
    /// rerun resumes it.
    #[error("interrupted")]
    Interrupted,

    /// An encoder failed while writing an output file.
    #[error("{}: cannot encode", path.display())]
    Encode {
        /// The file.
        path: PathBuf,
        /// The encoder's error.
        source: BoxError,
    },
}

/// A codec's error, kept whole (with its own sources).
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;
/// Something the user should know about the input that does not stop the work (mixed image
/// formats, grey among RGB, negative samples); loaders return these for the caller to print.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Warning {
    /// The file it is about (the first one, when it is about several).
    pub path: PathBuf,
    /// What is wrong, one line.
    pub message: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

/// Result with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// A read error for `path`.
    pub(crate) fn read(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Read {
            path: path.into(),
            source,
        }
    }

    /// A write error for `path`.
    pub(crate) fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Write {
            path: path.into(),
            source,
        }
    }

    /// A parse error at `line` of `path`.
    pub(crate) fn parse(path: impl Into<PathBuf>, line: usize, msg: impl Into<String>) -> Self {
        Error::Parse {
            path: path.into(),
            line,
            msg: msg.into(),
        }
    }

    /// A whole-file content error.
    pub(crate) fn invalid(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.into(),
            msg: msg.into(),
        }
    }

    /// A decode (corrupt/truncated) error caused by `source` (a codec's error or a message).
    pub(crate) fn decode(path: impl Into<PathBuf>, source: impl Into<BoxError>) -> Self {
        Error::Decode {
            path: path.into(),
            source: source.into(),
        }
    }

    /// An unsupported-format error.
    pub(crate) fn unsupported(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.into(),
            msg: msg.into(),
        }
    }

    /// A limits error.
    pub(crate) fn limits(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Limits {
            path: path.into(),
            msg: msg.into(),
        }
    }

    /// An encoder error caused by `source`.
    pub(crate) fn encode(path: impl Into<PathBuf>, source: impl Into<BoxError>) -> Self {
        Error::Encode {
            path: path.into(),
            source: source.into(),
        }
    }
}
