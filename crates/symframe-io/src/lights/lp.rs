//! RTI light-position files (`.lp`): the count line, each row's image and direction as the
//! tools that write them lay it out, and the image paths resolved (relative, absolute, Windows).

use std::io::BufRead;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::text::{has_trailing_comment, quoted, TextLines};
use super::{image_problem, not_a_file, parse_triple, unit_direction};
use crate::error::{Error, Result};
use crate::limits::MAX_LIGHTS;

/// An `.lp` file as [`parse_lp`] reads it.
#[derive(Debug)]
pub(crate) struct LpFile {
    /// The images, resolved (relative to the `.lp` file's folder, or absolute).
    pub images: Vec<PathBuf>,
    /// Unit light directions, one per image.
    pub lights: Vec<DVec3>,
    /// The length of each light's vector as written (1 for a unit direction; the distance for
    /// a light position): how far a row is from being a direction.
    pub lengths: Vec<f64>,
    /// How the image paths were read.
    pub paths: LpPaths,
}

/// Parses an RTI light-position file: the count `N`, then `N` lines `<image> <lx> <ly> <lz>`.
///
/// Image paths are relative to the `.lp` file's folder (absolute paths are kept) and may not
/// contain `#`; a path with spaces is everything before a row's last three numbers; fields are
/// separated by spaces or tabs. Every row variant of the tools that write `.lp` files is read,
/// and every other row refused naming its line and what it holds ([`lp_row`]). Returns the
/// resolved image paths, unit light directions and the vectors' lengths as written.
pub(crate) fn parse_lp(path: &Path) -> Result<LpFile> {
    let mut lines = TextLines::open(path)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let Some((count_line, count_text)) = lines.next_content()? else {
        return Err(Error::invalid(
            path,
            "empty light file: expected the number of lights on the first line",
        ));
    };
    let count: usize = count_text
        .parse()
        .map_err(|_| Error::parse(path, count_line, count_expected(count_text)))?;
    if count == 0 {
        return Err(Error::parse(path, count_line, "the light count is zero"));
    }
    check_declared(path, count_line, count)?;
    let (entries, extra) = declared_entries(&mut lines, count)?;
    if let Some((extra_line, found)) = extra {
        return Err(Error::parse(
            path,
            extra_line,
            format!(
                "more entries than the {count} lights declared on line {count_line} ({found} \
                 found)"
            ),
        ));
    }
    if entries.len() < count {
        return Err(Error::invalid(
            path,
            format!(
                "{count} lights declared on line {count_line} but only {} entries found",
                entries.len()
            ),
        ));
    }
    let mut out = LpFile {
        images: Vec::with_capacity(count),
        lights: Vec::with_capacity(count),
        lengths: Vec::with_capacity(count),
        paths: LpPaths::AsWritten,
    };
    for (line, text) in &entries {
        let (name, numbers) = match lp_row(text) {
            Ok(LpRow::Light(name, numbers)) => (name, numbers),
            Ok(LpRow::FourNumbers {
                name,
                joined,
                numbers,
            }) => {
                // `scan 2 0 0 1`: the image `scan 2`, if there is one (relight reads it so).
                if resolve_lp_image_unquoted(dir, joined).is_none() {
                    return Err(Error::parse(path, *line, four_numbers(name)));
                }
                (joined, [numbers[1], numbers[2], numbers[3]])
            }
            Ok(LpRow::Nameless(_)) => return Err(Error::parse(path, *line, NAMELESS_IN_A_CAPTURE)),
            Err(e) => {
                let hint = has_trailing_comment(path, *line)
                    .then_some("'#' starts a comment, so image paths may not contain '#'");
                return Err(Error::parse(path, *line, e.message("<image>", hint)));
            }
        };
        let v = parse_triple(path, *line, 3, &numbers, "light direction")?;
        out.lights.push(unit_direction(path, *line, v)?);
        out.lengths.push(vector_length(v));
        let Some((img, convention)) = resolve_lp_image_unquoted(dir, name) else {
            if is_windows_path(name) {
                return Err(Error::parse(
                    path,
                    *line,
                    format!(
                        "image {} does not exist (a Windows path: looked for {} next to the .lp)",
                        name,
                        dir.join(windows_file_name(name)).display()
                    ),
                ));
            }
            let tried = dir.join(name);
            let why = not_a_file(&tried)
                .unwrap_or_else(|| format!("{} is not a readable file", tried.display()));
            return Err(image_problem(path, *line, why));
        };
        if convention == LpPaths::Windows {
            out.paths = LpPaths::Windows;
        }
        out.images.push(img);
    }
    Ok(out)
}

/// The length of `v`, finite for any finite `v` short of the largest floats (scaled by its
/// largest component, as [`unit_light`] normalises it).
pub(super) fn vector_length(v: [f64; 3]) -> f64 {
    let largest = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if largest == 0.0 || !largest.is_finite() {
        return largest;
    }
    largest * (DVec3::from_array(v) / largest).length()
}

/// The message for a first line `text` that is not a light count: a light row there means the
/// count line is missing (relight crashed on such a file, cnr-isti-vclab/relight issue #19).
pub(super) fn count_expected(text: &str) -> String {
    let row = matches!(lp_row(text), Ok(LpRow::Light(name, _)) if name.parse::<f64>().is_err());
    if row {
        format!(
            "expected the number of lights, found the light row '{}': an .lp file starts with \
             its light count N on a line of its own, then N rows (RTIBuilder, relight and the \
             PTM and HSH fitters all write and need it); add the count as the first line",
            quoted(text)
        )
    } else {
        format!("expected the number of lights, found '{}'", quoted(text))
    }
}

/// Why a row of only three numbers under an `.lp` count is not a capture's row.
const NAMELESS_IN_A_CAPTURE: &str = "3 numbers and no image: a light without its image (a \
     table of lights under a count, as psmImages' lights.txt; NeuralRTI pairs such rows with \
     the folder's images sorted by name, which symframe does not guess) is read only as lights \
     to relight under (relight --lights); name each row's image ('<image> <x> <y> <z>'), or \
     give a DiLiGenT folder (filenames.txt and light_directions.txt)";

/// Why a row of four numbers after the image `name` is refused.
pub(super) fn four_numbers(name: &str) -> String {
    format!(
        "4 numbers after the image '{}': a row holds 3 (x y z toward the light), as RTIBuilder, \
         relight and the PTM and HSH fitters write and read it; a 4th column (a per-light \
         intensity?) is not read, and which 3 are the direction is not guessed (relight would \
         take the first as part of the image name); give intensities in light_intensities.txt \
         beside the .lp (one 'r g b' row per light)",
        quoted(name)
    )
}

/// What an `.lp` row (after the count) holds.
#[derive(Debug, PartialEq)]
pub(super) enum LpRow<'a> {
    /// `<image> <x> <y> <z>`: the image (a path with spaces whole) and the three numbers.
    Light(&'a str, [&'a str; 3]),
    /// `<image> <n> <x> <y> <z>`: four numbers after a name. The image's name may end in the
    /// first (`scan 2`, `joined`), else the row has a fourth column.
    FourNumbers {
        /// The image name before the four numbers.
        name: &'a str,
        /// The name with the first number: the image if its name ends in a number.
        joined: &'a str,
        /// The four numbers.
        numbers: [&'a str; 4],
    },
    /// `<x> <y> <z>` and no image: a table of lights under a count (psmImages' lights.txt):
    /// lights to render under, not a capture's row.
    Nameless([&'a str; 3]),
}

/// Why a row is not an `.lp` row.
#[derive(Debug, PartialEq)]
pub(super) enum RowError<'a> {
    /// Fewer than four fields, `numbers` of them numbers at the end; the text, for hints.
    Fields {
        count: usize,
        numbers: usize,
        text: &'a str,
    },
    /// One of the three fields meant as the direction (the last three) is not a number; the
    /// row ends in `numbers` numbers.
    NotANumber { token: &'a str, numbers: usize },
    /// Numbers in another count than three after the image (`name`), or numbers only.
    Columns {
        name: Option<&'a str>,
        numbers: usize,
    },
}

impl RowError<'_> {
    /// The message: `what` names the first field (`<image>`, `<name>`), `hint` (a trailing
    /// comment) explains a short row.
    pub(super) fn message(&self, what: &str, hint: Option<&str>) -> String {
        match *self {
            RowError::Fields {
                count,
                numbers,
                text,
            } => {
                let why = if let Some(h) = hint {
                    h.to_string()
                } else if numbers == 2 {
                    "2 numbers after the image: a row holds x y z toward the light, not angles"
                        .to_string()
                } else if text.contains([',', ';']) {
                    "fields are separated by spaces or tabs, not commas or semicolons".to_string()
                } else {
                    "a path with spaces needs three numbers after it".to_string()
                };
                format!("expected '{what} <lx> <ly> <lz>' ({why}), found {count} fields")
            }
            RowError::NotANumber { token, numbers } => {
                let mut m = format!(
                    "light direction: cannot parse '{}' as a number",
                    quoted(token)
                );
                if token.contains(',') {
                    m.push_str(" (a decimal comma? write 0.5, not 0,5)");
                } else if numbers == 2 {
                    m.push_str(" (the row ends in 2 numbers: it needs x y z)");
                }
                m
            }
            RowError::Columns {
                name: None,
                numbers,
            } => format!(
                "{numbers} numbers and no image: expected '{what} <lx> <ly> <lz>' (x y z \
                 toward the light)"
            ),
            RowError::Columns {
                name: Some(name),
                numbers,
            } => {
                let what_else = if numbers == 6 {
                    " (x y z and r g b intensities?)"
                } else {
                    ""
                };
                format!(
                    "{numbers} numbers after the image '{}'{what_else}: a row holds 3 (x y z \
                     toward the light), as RTIBuilder, relight and the PTM and HSH fitters \
                     write and read it; other columns are not read, and which 3 are the \
                     direction is not guessed; give intensities in light_intensities.txt \
                     beside the .lp (one 'r g b' row per light)",
                    quoted(name)
                )
            }
        }
    }
}

/// Most trailing numbers a row's reading keeps (the count goes on).
const KEPT: usize = 7;

/// Reads an `.lp` row (after the count line): the name is everything before the row's trailing
/// numbers (a path with spaces whole, as RTIBuilder writes one from a folder named so), the
/// fields separated by spaces or tabs (the PTM fitter's samples put a tab after the path).
/// Three numbers after a name are a light; three numbers alone a light without its image; four
/// after a name an image whose name may end in the first; anything else is refused, saying what
/// the row holds (no silent reading of an extra column as z).
pub(super) fn lp_row(text: &str) -> std::result::Result<LpRow<'_>, RowError<'_>> {
    let text = text.trim();
    let mut rest = text;
    let mut kept = [""; KEPT];
    let mut numbers = 0;
    while !rest.is_empty() {
        let (before, last) = match rest.rsplit_once(char::is_whitespace) {
            Some((before, last)) => (before.trim_end(), last),
            None => ("", rest),
        };
        if last.parse::<f64>().is_err() {
            break;
        }
        if numbers < KEPT {
            kept[numbers] = last;
        }
        numbers += 1;
        rest = before;
    }
    // `kept` holds the trailing numbers, last first.
    let xyz = [kept[2], kept[1], kept[0]];
    if rest.is_empty() {
        return match numbers {
            3 => Ok(LpRow::Nameless(xyz)),
            // `0001 x y z`: an image named by a number (relight and RTIBuilder read it so).
            4 if kept[3].bytes().all(|b| b.is_ascii_digit()) => Ok(LpRow::Light(kept[3], xyz)),
            n => Err(RowError::Columns {
                name: None,
                numbers: n,
            }),
        };
    }
    match numbers {
        3 => Ok(LpRow::Light(rest, xyz)),
        4 => {
            let first = kept[3];
            let end = first.as_ptr() as usize - text.as_ptr() as usize + first.len();
            Ok(LpRow::FourNumbers {
                name: rest,
                joined: &text[..end],
                numbers: [first, kept[2], kept[1], kept[0]],
            })
        }
        n if n < 3 => {
            let count = n + rest.split_whitespace().count();
            if count < 4 {
                return Err(RowError::Fields {
                    count,
                    numbers: n,
                    text,
                });
            }
            let token = rest.rsplit(char::is_whitespace).next().unwrap_or(rest);
            Err(RowError::NotANumber { token, numbers: n })
        }
        n => Err(RowError::Columns {
            name: Some(rest),
            numbers: n,
        }),
    }
}

/// [`resolve_lp_image`], and for a name in quotes (`"my photos/a.jpg"`, as a spreadsheet or
/// CSV export writes one) that is not found as written, the name without them.
fn resolve_lp_image_unquoted(dir: &Path, name: &str) -> Option<(PathBuf, LpPaths)> {
    resolve_lp_image(dir, name).or_else(|| {
        let inner = ['"', '\'']
            .iter()
            .find_map(|&q| name.strip_prefix(q)?.strip_suffix(q))?;
        (!inner.is_empty())
            .then(|| resolve_lp_image(dir, inner))
            .flatten()
    })
}

/// Refuses a light count `count` (declared at `line` of `path`) above [`MAX_LIGHTS`].
pub(super) fn check_declared(path: &Path, line: usize, count: usize) -> Result<()> {
    if count > MAX_LIGHTS {
        return Err(Error::parse(
            path,
            line,
            format!("{count} lights declared: a light file holds at most {MAX_LIGHTS} lights"),
        ));
    }
    Ok(())
}

/// A line number and text: a meaningful line of a light file, or the line of the first extra
/// entry and how many there are.
type Entry = (usize, String);

/// The meaningful lines after a declared light count `count` (at most [`MAX_LIGHTS`]), at
/// most `count` of them kept; when there are more, the line of the first extra one and how
/// many there are in all (`"7"`, or `"more than 100000"`: counting stops at the cap).
pub(super) fn declared_entries<R: BufRead>(
    lines: &mut TextLines<R>,
    count: usize,
) -> Result<(Vec<Entry>, Option<Entry>)> {
    let mut entries = Vec::with_capacity(count);
    while let Some((line, text)) = lines.next_content()? {
        if entries.len() < count {
            entries.push((line, text.to_string()));
            continue;
        }
        let mut found = count + 1;
        while found <= MAX_LIGHTS && lines.next_content()?.is_some() {
            found += 1;
        }
        let found = if found > MAX_LIGHTS {
            format!("more than {MAX_LIGHTS}")
        } else {
            found.to_string()
        };
        return Ok((entries, Some((line, found))));
    }
    Ok((entries, None))
}

/// How the image paths of an `.lp` file were read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LpPaths {
    /// Relative to the `.lp` file's folder (or absolute), as written.
    AsWritten,
    /// Windows paths (`C:\capture\img_0000.jpg`, or relative with backslashes), matched by
    /// their path below the `.lp` file's folder or, failing that, by file name next to it.
    Windows,
}

impl std::fmt::Display for LpPaths {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LpPaths::AsWritten => "image paths relative to the .lp file",
            LpPaths::Windows => {
                "Windows image paths, matched by file name (or relative path) next to the .lp file"
            }
        })
    }
}

/// Whether an `.lp` image entry is written the Windows way: a drive (`C:`) or backslashes.
pub(super) fn is_windows_path(token: &str) -> bool {
    let b = token.as_bytes();
    token.contains('\\') || (b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':')
}

/// The file name of a Windows path (after the last `\` or `/`, and any drive).
pub(super) fn windows_file_name(token: &str) -> &str {
    let tail = token.rsplit(['\\', '/']).next().unwrap_or(token);
    match tail.as_bytes() {
        [d, b':', ..] if d.is_ascii_alphabetic() => &tail[2..],
        _ => tail,
    }
}

/// The image an `.lp` entry names: as written relative to `dir`; else, for a Windows path, its
/// relative form with `/` separators below `dir`, else its file name in `dir`.
fn resolve_lp_image(dir: &Path, token: &str) -> Option<(PathBuf, LpPaths)> {
    let direct = dir.join(token);
    if direct.is_file() {
        return Some((direct, LpPaths::AsWritten));
    }
    if !is_windows_path(token) {
        return None;
    }
    let b = token.as_bytes();
    let has_drive = b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':';
    if !has_drive && !token.starts_with('\\') {
        let rel = dir.join(token.replace('\\', "/"));
        if rel.is_file() {
            return Some((rel, LpPaths::Windows));
        }
    }
    let by_name = dir.join(windows_file_name(token));
    by_name.is_file().then_some((by_name, LpPaths::Windows))
}

/// How an `.lp` file's image paths are read (see [`LpPaths`]): `Windows` when any entry needed
/// the Windows reading. Errors as opening the dataset would give them.
pub fn lp_path_convention(path: &Path) -> Result<LpPaths> {
    Ok(parse_lp(path)?.paths)
}
