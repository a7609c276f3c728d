//! Text files read a line at a time, never whole: line ends, byte-order mark, `#` comments,
//! fields, and the cap on their entries.

use std::io::BufRead;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::limits::MAX_LIGHTS;

/// The lines of a text file, read one at a time through a buffer (the file is never held
/// whole): each without its line end (LF, CR LF or a lone CR), numbered from 1, a byte-order
/// mark at the start dropped. Lines must be UTF-8.
pub(crate) struct TextLines<R> {
    path: PathBuf,
    reader: R,
    line: Vec<u8>,
    number: usize,
    /// The last line ended with a CR: an LF right after it belongs to that line end.
    after_cr: bool,
}

impl TextLines<std::io::BufReader<std::io::Take<std::fs::File>>> {
    /// The lines of the light file `path`, bounded ([`crate::open_bounded`],
    /// [`crate::limits::MAX_TEXT_FILE_BYTES`]).
    pub(crate) fn open(path: &Path) -> Result<Self> {
        Self::open_as(path, "a light file")
    }

    /// The lines of the text file `path`, `what` ("an image list": named by the size cap's
    /// error), bounded as [`Self::open`].
    pub(super) fn open_as(path: &Path, what: &str) -> Result<Self> {
        let reader = crate::open_bounded(path, what, crate::limits::MAX_TEXT_FILE_BYTES)?;
        Ok(Self::new(path, reader))
    }
}

/// Reads the list file `path` (`what`: "an image list"), one entry a line, a line at a time
/// and bounded as light files are: `each(line, entry)` is called for every meaningful line
/// (comments stripped, trimmed, blank lines skipped); more than [`MAX_LIGHTS`] entries
/// (`entries`: "image filenames") are refused at the line that passes the cap.
pub fn read_list<E: From<Error>>(
    path: &Path,
    what: &str,
    entries: &str,
    mut each: impl FnMut(usize, &str) -> std::result::Result<(), E>,
) -> std::result::Result<(), E> {
    let mut lines = TextLines::open_as(path, what)?;
    let mut count = 0;
    while let Some((line, text)) = lines.next_content()? {
        if count == MAX_LIGHTS {
            let why =
                format!("more than {MAX_LIGHTS} {entries}: {what} holds at most {MAX_LIGHTS}");
            return Err(Error::parse(path, line, why).into());
        }
        count += 1;
        each(line, text)?;
    }
    Ok(())
}

impl<R: BufRead> TextLines<R> {
    /// The lines `reader` gives, of the file `path` (for messages).
    pub(crate) fn new(path: &Path, reader: R) -> Self {
        Self {
            path: path.to_path_buf(),
            reader,
            line: Vec::new(),
            number: 0,
            after_cr: false,
        }
    }

    /// Reads the next line into `self.line` (a byte-order mark at the start of the file
    /// dropped; checked to be UTF-8); `false` after the last.
    fn advance(&mut self) -> Result<bool> {
        self.line.clear();
        let mut any = false;
        loop {
            let buf = self
                .reader
                .fill_buf()
                .map_err(|e| Error::read(&self.path, e))?;
            if buf.is_empty() {
                if !any {
                    return Ok(false);
                }
                break;
            }
            if std::mem::take(&mut self.after_cr) && buf[0] == b'\n' {
                self.reader.consume(1);
                continue;
            }
            any = true;
            match buf.iter().position(|&b| b == b'\n' || b == b'\r') {
                Some(i) => {
                    self.after_cr = buf[i] == b'\r';
                    self.line.extend_from_slice(&buf[..i]);
                    self.reader.consume(i + 1);
                    break;
                }
                None => {
                    let n = buf.len();
                    self.line.extend_from_slice(buf);
                    self.reader.consume(n);
                }
            }
        }
        self.number += 1;
        if self.number == 1 && self.line.starts_with("\u{feff}".as_bytes()) {
            self.line.drain(..3);
        }
        if std::str::from_utf8(&self.line).is_err() {
            return Err(Error::decode(&self.path, "not a UTF-8 text file"));
        }
        Ok(true)
    }

    /// The line last read (checked to be UTF-8 by [`Self::advance`]).
    fn text(&self) -> &str {
        std::str::from_utf8(&self.line).unwrap_or("")
    }

    /// The next line: its number and text; `None` after the last.
    pub(crate) fn next_line(&mut self) -> Result<Option<(usize, &str)>> {
        Ok(self.advance()?.then(|| (self.number, self.text())))
    }

    /// The next meaningful line: comments stripped, surrounding whitespace trimmed, blank lines
    /// skipped; `None` after the last.
    pub(crate) fn next_content(&mut self) -> Result<Option<(usize, &str)>> {
        loop {
            if !self.advance()? {
                return Ok(None);
            }
            if !content(self.text()).is_empty() {
                return Ok(Some((self.number, content(self.text()))));
            }
        }
    }
}

/// A line's content: before any `#`, trimmed.
fn content(line: &str) -> &str {
    line.split('#').next().unwrap_or("").trim()
}

/// The error for a file with more than [`MAX_LIGHTS`] `what` (lights, light directions,
/// image filenames), at `line`, where the cap was passed.
pub(super) fn too_many(path: &Path, line: usize, what: &str) -> Error {
    Error::parse(
        path,
        line,
        format!("more than {MAX_LIGHTS} {what}: a light file holds at most {MAX_LIGHTS} lights"),
    )
}

/// The whitespace-separated fields of `text`: the first `N` in `out`, and how many there are
/// in all (no allocation per line).
pub(super) fn fields<'a, const N: usize>(text: &'a str, out: &mut [&'a str; N]) -> usize {
    let mut count = 0;
    for (i, f) in text.split_whitespace().enumerate() {
        if i < N {
            out[i] = f;
        }
        count += 1;
    }
    count
}

/// The meaningful lines of `bytes`, the content of the text file `path`, as `(1-based line
/// number, content)` (what the parsers see).
#[cfg(test)]
pub(crate) fn parse_content_lines(path: &Path, bytes: &[u8]) -> Result<Vec<(usize, String)>> {
    let mut lines = TextLines::new(path, bytes);
    let mut out = Vec::new();
    while let Some((n, l)) = lines.next_content()? {
        out.push((n, l.to_string()));
    }
    Ok(out)
}

/// `text` as an error message quotes it: at most 60 characters, else cut with `...`.
pub(super) fn quoted(text: &str) -> String {
    match text.char_indices().nth(60) {
        Some((i, _)) => format!("{}...", &text[..i]),
        None => text.to_string(),
    }
}

/// Whether line `line` (1-based) of the text file `path` has a `#` after some content (a
/// trailing comment: then a file name cut at it is the likely mistake).
pub(super) fn has_trailing_comment(path: &Path, line: usize) -> bool {
    let Ok(mut lines) = TextLines::open(path) else {
        return false;
    };
    while let Ok(Some((n, text))) = lines.next_line() {
        if n == line {
            return text
                .split_once('#')
                .is_some_and(|(before, _)| !before.trim().is_empty());
        }
    }
    false
}
