//! Parsers of light files: RTI light-position files (`.lp`) and DiLiGenT-style text tables.
//!
//! `.lp` rows are read as the tools that write them do (surveyed from their sources; the tests
//! name each tool and the file read): RTIBuilder's absolute Windows paths with spaces and CR LF,
//! relight's `%g` numbers, the PTM fitter's tab after the path, SpectralRTI_Toolkit's CR CR LF,
//! rows without an image (psmImages, NeuralRTI) as lights to render under. Every other row is
//! refused naming the file, the line and what the row holds ([`lp_row`]): a fourth number or
//! r g b columns after the direction, two numbers (angles), a missing count line, decimal
//! commas. None is read from the wrong columns. Vectors of any finite length are normalised;
//! the lengths as written are kept ([`LpFile::lengths`]) so that light positions are warned
//! about where a dataset is opened.
//!
//! All text files accept blank lines and `#` comments (whole-line or trailing), so a `#` can not
//! be part of an image path. A UTF-8 byte-order mark at the start (as Windows editors write) is
//! ignored. Lines end with LF, CR LF or a lone CR (old Mac editors, some rig software).
//!
//! Files are read a line at a time ([`TextLines`]), never whole, and hold at most
//! [`MAX_LIGHTS`] lights (rows, images): a longer one is refused at the line that passes the
//! cap, before storage for its lights grows past it.

mod lp;
mod text;

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::error::{Error, Result};
use crate::limits::MAX_LIGHTS;
use lp::{check_declared, count_expected, declared_entries, four_numbers, lp_row, LpRow};
use text::{fields, has_trailing_comment, quoted, too_many};

pub use lp::{lp_path_convention, LpPaths};
pub(crate) use lp::{parse_lp, LpFile};
pub use text::read_list;
pub(crate) use text::TextLines;

/// Why `p`, listed as an image, is not a readable image file: missing, a broken symbolic link,
/// a folder, or not a regular file (FIFO, socket, device); `None` if it is a regular file.
pub(crate) fn not_a_file(p: &Path) -> Option<String> {
    let shown = p.display();
    match std::fs::symlink_metadata(p) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Some(format!("{shown} does not exist"))
        }
        Err(e) => Some(format!("{shown} cannot be accessed ({e})")),
        Ok(m) => {
            let target = if m.file_type().is_symlink() {
                match std::fs::metadata(p) {
                    Ok(t) => t,
                    Err(_) => {
                        return Some(format!(
                            "{shown} is a broken symbolic link (its target does not exist)"
                        ))
                    }
                }
            } else {
                m
            };
            if target.is_file() {
                None
            } else if target.is_dir() {
                Some(format!("{shown} is a folder, not an image file"))
            } else {
                Some(format!(
                    "{shown} is not a regular file (a FIFO, socket or device)"
                ))
            }
        }
    }
}

/// The message for a listed image that is not a file, with the `#` hint when the line had a
/// trailing comment.
pub(super) fn image_problem(list: &Path, line: usize, why: String) -> Error {
    let hint = if has_trailing_comment(list, line) {
        " ('#' starts a comment: image paths may not contain '#')"
    } else {
        ""
    };
    Error::parse(list, line, format!("image {why}{hint}"))
}

/// Parses three numbers of `what` at `line` of `path`: `count` fields were found, the first
/// (up to three) in `tokens`.
pub(super) fn parse_triple(
    path: &Path,
    line: usize,
    count: usize,
    tokens: &[&str],
    what: &str,
) -> Result<[f64; 3]> {
    if count != 3 {
        return Err(Error::parse(
            path,
            line,
            format!("expected 3 numbers for the {what}, found {count}"),
        ));
    }
    let mut v = [0.0; 3];
    for (o, t) in v.iter_mut().zip(tokens) {
        *o = t.parse::<f64>().map_err(|_| {
            Error::parse(
                path,
                line,
                format!("{what}: cannot parse '{}' as a number", quoted(t)),
            )
        })?;
    }
    Ok(v)
}

/// Normalises a light direction, rejecting zero and non-finite vectors with a line-level error
/// that says which. Any finite vector other than zero is fine, however large or small: it is
/// scaled by its largest component before its length is taken (`1e200 0 1e200` overflowed to
/// an infinite length).
pub(crate) fn unit_direction(path: &Path, line: usize, v: [f64; 3]) -> Result<DVec3> {
    unit_light(v).map_err(|why| Error::parse(path, line, format!("light direction {why}")))
}

/// `v` as a unit vector, or why it has no direction: "is zero", "is not finite (inf)".
pub(crate) fn unit_light(v: [f64; 3]) -> std::result::Result<DVec3, String> {
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("is not finite ({bad})"));
    }
    let largest = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if largest == 0.0 {
        return Err("is zero".into());
    }
    let d = DVec3::from_array(v);
    // Directly when the squares neither overflow nor lose precision (so ordinary lights keep
    // `normalize`'s unit vectors, bit for bit), else after scaling by the largest component.
    let n = if (1e-150..=1e150).contains(&largest) {
        d.normalize()
    } else {
        (d / largest).normalize()
    };
    if !n.is_finite() {
        return Err("cannot be normalised".into());
    }
    Ok(n)
}

/// Reads light directions alone (e.g. the lights to relight under), from either an `.lp`-style
/// file (the count `N` on the first line, then `N` lines `<name> <lx> <ly> <lz>` or `<lx> <ly>
/// <lz>`; the names are ignored and need not exist) or a table of `x y z` rows (DiLiGenT
/// `light_directions.txt`). The form is told by the first meaningful line: one integer means
/// `.lp`. Directions are normalised; rows as `parse_lp` reads them; errors name the file and
/// line.
pub fn read_light_directions(path: &Path) -> Result<Vec<DVec3>> {
    let mut lines = TextLines::open(path)?;
    let Some((first_line, first)) = lines.next_content()? else {
        return Err(Error::invalid(path, "no light directions in the file"));
    };
    let mut tokens = [""; 1];
    if fields(first, &mut tokens) != 1 {
        if matches!(lp_row(first), Ok(LpRow::Light(name, _)) if name.parse::<f64>().is_err()) {
            return Err(Error::parse(path, first_line, count_expected(first)));
        }
        return parse_directions(path);
    }
    let count: usize = tokens[0].parse().map_err(|_| {
        Error::parse(
            path,
            first_line,
            format!(
                "expected the number of lights or 'x y z', found '{}'",
                quoted(first)
            ),
        )
    })?;
    check_declared(path, first_line, count)?;
    let (entries, extra) = declared_entries(&mut lines, count)?;
    if extra.is_some() || entries.len() != count || count == 0 {
        let found = extra.map_or(entries.len().to_string(), |(_, f)| f);
        return Err(Error::invalid(
            path,
            format!("{count} lights declared on line {first_line} but {found} entries found"),
        ));
    }
    entries
        .iter()
        .map(|(line, text)| {
            let numbers = match lp_row(text) {
                Ok(LpRow::Light(_, numbers) | LpRow::Nameless(numbers)) => numbers,
                Ok(LpRow::FourNumbers { name, .. }) => {
                    return Err(Error::parse(path, *line, four_numbers(name)))
                }
                Err(e) => return Err(Error::parse(path, *line, e.message("<name>", None))),
            };
            let v = parse_triple(path, *line, 3, &numbers, "light direction")?;
            unit_direction(path, *line, v)
        })
        .collect()
}

/// Parses a DiLiGenT `filenames.txt`: one image filename per line, relative to `dir`.
pub(crate) fn parse_filenames(path: &Path, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut images = Vec::new();
    read_list(path, "a light file", "image filenames", |line, text| {
        let img = dir.join(text);
        if let Some(why) = not_a_file(&img) {
            return Err(image_problem(path, line, why));
        }
        images.push(img);
        Ok(())
    })?;
    if images.is_empty() {
        return Err(Error::invalid(path, "no image filenames"));
    }
    Ok(images)
}

/// Parses a table of `x y z` light directions (DiLiGenT `light_directions.txt`), normalised.
pub(crate) fn parse_directions(path: &Path) -> Result<Vec<DVec3>> {
    parse_rows(path, ["light directions", "light direction"], |line, v| {
        unit_direction(path, line, v)
    })
}

/// Parses a table of `r g b` light intensities (DiLiGenT `light_intensities.txt`); each must be
/// finite and positive since images are divided by them.
pub(crate) fn parse_intensities(path: &Path) -> Result<Vec<[f32; 3]>> {
    parse_rows(path, ["light intensities", "light intensity"], |line, v| {
        let out = v.map(|x| x as f32);
        if out.iter().any(|x| !x.is_finite() || *x <= 0.0) {
            return Err(Error::parse(
                path,
                line,
                "light intensity must be finite and greater than zero",
            ));
        }
        Ok(out)
    })
}

/// Parses a table of `x y z` light positions (`light_positions.txt`, camera frame, any length
/// unit): finite numbers, kept as written.
pub(crate) fn parse_positions(path: &Path) -> Result<Vec<DVec3>> {
    parse_rows(path, ["light positions", "light position"], |line, v| {
        if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
            return Err(Error::parse(
                path,
                line,
                format!("light position is not finite ({bad})"),
            ));
        }
        Ok(DVec3::from_array(v))
    })
}

/// Parses a table of `x y z` LED principal directions (`light_principal_directions.txt`, from
/// the LED into the scene), normalised.
pub(crate) fn parse_principal_directions(path: &Path) -> Result<Vec<DVec3>> {
    parse_rows(
        path,
        ["principal directions", "principal direction"],
        |line, v| {
            unit_light(v)
                .map_err(|why| Error::parse(path, line, format!("principal direction {why}")))
        },
    )
}

/// Parses `K.txt`: three rows of three numbers, the pinhole intrinsics in OpenCV's convention;
/// a fourth row or a matrix that is not a pinhole's is refused naming the line or the file.
pub(crate) fn parse_k(path: &Path) -> Result<[[f64; 3]; 3]> {
    let mut lines = TextLines::open_as(path, "an intrinsics file")?;
    let mut k = [[0.0; 3]; 3];
    let mut rows = 0;
    while let Some((line, text)) = lines.next_content()? {
        if rows == 3 {
            return Err(Error::parse(
                path,
                line,
                "K holds 3 rows of 3 numbers; this is a fourth row",
            ));
        }
        let mut tokens = [""; 3];
        let n = fields(text, &mut tokens);
        k[rows] = parse_triple(path, line, n, &tokens[..n.min(3)], "row of K")?;
        rows += 1;
    }
    if rows < 3 {
        return Err(Error::invalid(
            path,
            format!("K holds 3 rows of 3 numbers, found {rows} rows"),
        ));
    }
    Ok(k)
}

/// Parses a column of LED falloff exponents (`light_mu.txt`): one finite number of at least 0 a
/// line.
pub(crate) fn parse_mu(path: &Path) -> Result<Vec<f64>> {
    let mut lines = TextLines::open(path)?;
    let mut out = Vec::new();
    while let Some((line, text)) = lines.next_content()? {
        if out.len() == MAX_LIGHTS {
            return Err(too_many(path, line, "falloff exponents"));
        }
        let mut tokens = [""; 1];
        let n = fields(text, &mut tokens);
        if n != 1 {
            return Err(Error::parse(
                path,
                line,
                format!("expected 1 number for the falloff exponent, found {n}"),
            ));
        }
        let mu = tokens[0]
            .parse::<f64>()
            .ok()
            .filter(|m| m.is_finite() && *m >= 0.0);
        match mu {
            Some(m) => out.push(m),
            None => {
                return Err(Error::parse(
                    path,
                    line,
                    format!(
                        "falloff exponent '{}' is not a finite number of at least 0",
                        quoted(tokens[0])
                    ),
                ))
            }
        }
    }
    Ok(out)
}

/// The rows of a table of three numbers a line (`[rows, row]`: "light directions", "light
/// direction"), each made a value by `row(line, numbers)`; at most [`MAX_LIGHTS`] rows.
fn parse_rows<T>(
    path: &Path,
    [what, one]: [&str; 2],
    row: impl Fn(usize, [f64; 3]) -> Result<T>,
) -> Result<Vec<T>> {
    let mut lines = TextLines::open(path)?;
    let mut out = Vec::new();
    while let Some((line, text)) = lines.next_content()? {
        if out.len() == MAX_LIGHTS {
            return Err(too_many(path, line, what));
        }
        let mut tokens = [""; 3];
        let n = fields(text, &mut tokens);
        let v = parse_triple(path, line, n, &tokens[..n.min(3)], one)?;
        out.push(row(line, v)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::lp::{is_windows_path, vector_length, windows_file_name};
    use super::text::parse_content_lines;
    use super::*;

    #[test]
    fn image_paths_with_spaces_are_read_as_rtibuilder_writes_them() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("my photos");
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("IMG 0001.jpg"), b"x").unwrap();
        std::fs::write(dir.join("b.jpg"), b"x").unwrap();
        let lp = d.path().join("s.lp");
        std::fs::write(
            &lp,
            "2\nmy photos/IMG 0001.jpg  0.1 -0.2 0.97\nmy photos/b.jpg 0 0 1\n",
        )
        .unwrap();
        let LpFile { images, lights, .. } = parse_lp(&lp).unwrap();
        assert_eq!(images[0], d.path().join("my photos/IMG 0001.jpg"));
        assert!((lights[0] - DVec3::new(0.1, -0.2, 0.97).normalize()).length() < 1e-12);
        assert_eq!(images[1], d.path().join("my photos/b.jpg"));
        // Windows paths with spaces, as RTIBuilder writes them: found by file name.
        std::fs::write(&lp, "1\nC:\\Users\\me\\My Photos\\IMG 0001.jpg 0 0 1\n").unwrap();
        std::fs::write(d.path().join("IMG 0001.jpg"), b"x").unwrap();
        let images = parse_lp(&lp).unwrap().images;
        assert_eq!(images[0], d.path().join("IMG 0001.jpg"));
        assert_eq!(lp_path_convention(&lp).unwrap(), LpPaths::Windows);
        // Not three numbers after the path: the row is refused, naming the line.
        std::fs::write(&lp, "1\nmy photos/b.jpg 0 0\n").unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(e.contains("s.lp:2: light direction"), "{e}");
        // Directions alone (relighting): names with spaces too.
        std::fs::write(&lp, "1\nlight one 0 0 1\n").unwrap();
        assert_eq!(read_light_directions(&lp).unwrap(), vec![DVec3::Z]);
    }

    #[test]
    fn light_directions_from_lp_or_table() {
        let d = tempfile::tempdir().unwrap();
        let lp = d.path().join("new.lp");
        std::fs::write(&lp, "# relight\n2\nnone.png 0 0 2\nx 1 0 1 # comment\n").unwrap();
        let l = read_light_directions(&lp).unwrap();
        assert_eq!(l.len(), 2);
        assert!((l[0] - DVec3::Z).length() < 1e-12);
        assert!((l[1].x - 0.5f64.sqrt()).abs() < 1e-12);
        let table = d.path().join("dirs.txt");
        std::fs::write(&table, "0 0 1\n0 1 1\n").unwrap();
        assert_eq!(read_light_directions(&table).unwrap().len(), 2);
        std::fs::write(&lp, "2\nnone.png 0 0 1\n").unwrap();
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(e.contains("new.lp"), "{e}");
        std::fs::write(&lp, "1\nnone.png 0 zero 1\n").unwrap();
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(e.contains("new.lp:2"), "{e}");
        std::fs::write(&lp, "1\nnone.png 0 0 0\n").unwrap();
        assert!(read_light_directions(&lp).is_err());
    }

    /// A byte-order mark is skipped, not read into the count ("expected the number of lights,
    /// found '2'").
    #[test]
    fn a_utf8_bom_is_ignored() {
        let d = tempfile::tempdir().unwrap();
        let lp = d.path().join("bom.lp");
        std::fs::write(&lp, "\u{feff}2\nnone.png 0 0 2\nx 1 0 1\n").unwrap();
        assert_eq!(read_light_directions(&lp).unwrap().len(), 2);
        let table = d.path().join("dirs.txt");
        std::fs::write(&table, "\u{feff}0 0 1\n0 1 1\n").unwrap();
        assert_eq!(parse_directions(&table).unwrap().len(), 2);
        let int = d.path().join("int.txt");
        std::fs::write(&int, "\u{feff}1 1 1\n").unwrap();
        assert_eq!(parse_intensities(&int).unwrap(), vec![[1.0; 3]]);
        // Only at the start: elsewhere it is content.
        std::fs::write(&table, "0 0 1\n\u{feff}0 1 1\n").unwrap();
        let e = parse_directions(&table).unwrap_err().to_string();
        assert!(e.contains("dirs.txt:2"), "{e}");
    }

    #[test]
    fn windows_paths_are_matched_next_to_the_lp() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("jpeg-exports")).unwrap();
        std::fs::write(d.path().join("img_0000.jpg"), b"x").unwrap();
        std::fs::write(d.path().join("jpeg-exports/img_0001.jpg"), b"x").unwrap();
        let lp = d.path().join("capture.lp");
        std::fs::write(
            &lp,
            "2\nC:\\capture\\jpeg-exports\\img_0000.jpg 0 0 1\njpeg-exports\\img_0001.jpg 0 1 1\n",
        )
        .unwrap();
        let LpFile { images, lights, .. } = parse_lp(&lp).unwrap();
        assert_eq!(images[0], d.path().join("img_0000.jpg"));
        assert_eq!(images[1], d.path().join("jpeg-exports/img_0001.jpg"));
        assert_eq!(lights.len(), 2);
        assert_eq!(lp_path_convention(&lp).unwrap(), LpPaths::Windows);
        assert!(LpPaths::Windows.to_string().contains("Windows"));
        // Written the usual way: as written.
        std::fs::write(&lp, "1\nimg_0000.jpg 0 0 1\n").unwrap();
        assert_eq!(lp_path_convention(&lp).unwrap(), LpPaths::AsWritten);
        // A Windows path to a missing file names what was looked for.
        std::fs::write(&lp, "1\nD:\\x\\gone.jpg 0 0 1\n").unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(
            e.contains("capture.lp:2") && e.contains("gone.jpg") && e.contains("Windows"),
            "{e}"
        );
        assert_eq!(windows_file_name("C:img.png"), "img.png");
        assert!(!is_windows_path("a/b.png"));
    }

    /// `1e200 0 1e200` is a light, not "zero or not finite" (its length overflows as computed
    /// directly).
    #[test]
    fn huge_and_tiny_finite_lights_are_normalised() {
        let s = 0.5f64.sqrt();
        let n = unit_light([1e200, 0.0, 1e200]).unwrap();
        assert!((n - DVec3::new(s, 0.0, s)).length() < 1e-15, "{n}");
        let n = unit_light([f64::MAX, -f64::MAX, 0.0]).unwrap();
        assert!((n - DVec3::new(s, -s, 0.0)).length() < 1e-15, "{n}");
        assert_eq!(unit_light([0.0, 5e-324, 0.0]).unwrap(), DVec3::Y);
        assert_eq!(unit_light([0.0, -0.0, 0.0]).unwrap_err(), "is zero");
        assert_eq!(
            unit_light([1.0, f64::INFINITY, 0.0]).unwrap_err(),
            "is not finite (inf)"
        );
        let d = tempfile::tempdir().unwrap();
        let lp = d.path().join("big.lp");
        std::fs::write(&lp, "2\na 1e200 0 1e200\nb 0 0 0\n").unwrap();
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(e.ends_with("big.lp:3: light direction is zero"), "{e}");
        std::fs::write(&lp, "1\na 1e200 0 1e200\n").unwrap();
        assert!(read_light_directions(&lp).unwrap()[0].is_finite());
    }

    /// A file with CR-only line ends has as many lines as a file with LF ones, not one (whose
    /// errors would quote the whole file as "line 1").
    #[test]
    fn cr_only_line_ends_are_line_ends() {
        let lines = |text: &str| {
            let mut l = TextLines::new(Path::new("t"), text.as_bytes());
            let mut v = Vec::new();
            while let Some((n, t)) = l.next_line().unwrap() {
                v.push((n, t.to_string()));
            }
            v
        };
        let s = |v: &[(usize, &str)]| -> Vec<(usize, String)> {
            v.iter().map(|&(n, t)| (n, t.to_string())).collect()
        };
        assert_eq!(
            lines("a\rb\r\nc\n\rd"),
            s(&[(1, "a"), (2, "b"), (3, "c"), (4, ""), (5, "d")])
        );
        assert_eq!(lines("a\n"), s(&[(1, "a")]));
        assert_eq!(lines(""), s(&[]));
        // A CR at the end of one buffer and the LF at the start of the next are one line end.
        let mut l = TextLines::new(
            Path::new("t"),
            std::io::BufReader::with_capacity(2, "ab\r\ncd\r".as_bytes()),
        );
        assert_eq!(l.next_line().unwrap(), Some((1, "ab")));
        assert_eq!(l.next_line().unwrap(), Some((2, "cd")));
        assert_eq!(l.next_line().unwrap(), None);
        let d = tempfile::tempdir().unwrap();
        let lp = d.path().join("mac.lp");
        std::fs::write(&lp, "2\rnone.png 0 0 1\rx 1 0 1 # c\r").unwrap();
        assert_eq!(read_light_directions(&lp).unwrap().len(), 2);
        std::fs::write(&lp, "2\rnone.png 0 0 1\rx 1 zero 1\r").unwrap();
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(
            e.ends_with("mac.lp:3: light direction: cannot parse 'zero' as a number"),
            "{e}"
        );
        // What an error quotes is cut short.
        std::fs::write(&lp, format!("{}\n", "y".repeat(5000))).unwrap();
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(e.len() < 200 && e.contains("yyy..."), "{e}");
    }

    /// Light files are read a row at a time up to the cap, never whole (a huge one would cost
    /// memory and seconds first: docs/performance.md, "Memory model"): a table of exactly
    /// [`MAX_LIGHTS`] rows is read, one more is refused at the row that passes the cap; so are the
    /// other tables, and an `.lp` that declares more lights.
    #[test]
    fn light_files_hold_at_most_max_lights() {
        let d = tempfile::tempdir().unwrap();
        let table = d.path().join("light_directions.txt");
        let rows = "0 0 1\n".repeat(MAX_LIGHTS);
        std::fs::write(&table, format!("# lights\n{rows}")).unwrap();
        assert_eq!(parse_directions(&table).unwrap().len(), MAX_LIGHTS);
        assert_eq!(read_light_directions(&table).unwrap().len(), MAX_LIGHTS);
        std::fs::write(&table, format!("# lights\n{rows}\n0 1 1\n0 0 1\n")).unwrap();
        let over = MAX_LIGHTS + 3;
        let want = format!(
            "light_directions.txt:{over}: more than 100000 light directions: a light file \
             holds at most 100000 lights"
        );
        let e = parse_directions(&table).unwrap_err().to_string();
        assert!(e.ends_with(&want), "{e}");
        let e = read_light_directions(&table).unwrap_err().to_string();
        assert!(e.ends_with(&want), "{e}");
        let int = d.path().join("light_intensities.txt");
        std::fs::write(&int, "1 1 1\n".repeat(MAX_LIGHTS + 1)).unwrap();
        let e = parse_intensities(&int).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "light_intensities.txt:100001: more than 100000 light intensities: a \
                 light file holds at most 100000 lights"
            ),
            "{e}"
        );
        std::fs::write(d.path().join("a.png"), b"x").unwrap();
        let names = d.path().join("filenames.txt");
        std::fs::write(&names, "a.png\n".repeat(MAX_LIGHTS + 1)).unwrap();
        let e = parse_filenames(&names, d.path()).unwrap_err().to_string();
        assert!(
            e.contains("filenames.txt:100001: more than 100000 image filenames"),
            "{e}"
        );

        // An .lp: a count above the cap is refused at its line, before any entry is read.
        let lp = d.path().join("many.lp");
        std::fs::write(&lp, format!("\n{}\na.png 0 0 1\n", MAX_LIGHTS + 1)).unwrap();
        for e in [
            parse_lp(&lp).unwrap_err().to_string(),
            read_light_directions(&lp).unwrap_err().to_string(),
        ] {
            assert!(
                e.ends_with(
                    "many.lp:2: 100001 lights declared: a light file holds at most \
                     100000 lights"
                ),
                "{e}"
            );
        }
        // Exactly the cap, names not checked: read.
        let entries = "a.png 0 0 1\n".repeat(MAX_LIGHTS);
        std::fs::write(&lp, format!("{MAX_LIGHTS}\n{entries}")).unwrap();
        assert_eq!(read_light_directions(&lp).unwrap().len(), MAX_LIGHTS);
        // More entries than declared: the extra ones are counted up to the cap, not kept.
        std::fs::write(&lp, format!("2\n{entries}a.png 0 0 1\n")).unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "many.lp:4: more entries than the 2 lights declared on line 1 (more \
                 than 100000 found)"
            ),
            "{e}"
        );
        let e = read_light_directions(&lp).unwrap_err().to_string();
        assert!(
            e.ends_with("many.lp: 2 lights declared on line 1 but more than 100000 entries found"),
            "{e}"
        );
        std::fs::write(&lp, "1\na.png 0 0 1\na.png 0 1 1\n").unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(e.ends_with("(2 found)"), "{e}");
    }

    /// A line that is not UTF-8 is refused, wherever it is; a byte-order mark is dropped from
    /// the first line only.
    #[test]
    fn lines_are_utf8_and_a_bom_starts_only_the_file() {
        let d = tempfile::tempdir().unwrap();
        let table = d.path().join("dirs.txt");
        std::fs::write(&table, b"0 0 1\n0 1 1\n\xff\xfe 1\n").unwrap();
        let e = parse_directions(&table).unwrap_err();
        assert!(e.to_string().ends_with("dirs.txt: cannot decode"), "{e}");
        let cause = std::error::Error::source(&e).map(|c| c.to_string());
        assert_eq!(cause.as_deref(), Some("not a UTF-8 text file"));
        let mut l = TextLines::new(Path::new("t"), "\u{feff}# c\n\u{feff}x".as_bytes());
        assert_eq!(l.next_line().unwrap(), Some((1, "# c")));
        assert_eq!(l.next_line().unwrap(), Some((2, "\u{feff}x")));
    }

    // The row variants of the tools that write or read `.lp` files, one test each, naming the
    // tool and (in a comment) the source read.

    /// Writes `text` as `dir/name` and an empty file for each of `images`; the `.lp` path.
    fn lp_file(dir: &Path, name: &str, text: &str, images: &[&str]) -> PathBuf {
        for i in images {
            let p = dir.join(i);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, b"x").unwrap();
        }
        let lp = dir.join(name);
        std::fs::write(&lp, text).unwrap();
        lp
    }

    fn near(a: DVec3, b: [f64; 3]) -> bool {
        (a - DVec3::from_array(b).normalize()).length() < 1e-12
    }

    /// relight (cnr-isti-vclab/relight 5cca5c3e, src/project.cpp `Project::saveLP`): the count,
    /// then `<file> x y z` rows through a QTextStream, whose default notation writes small
    /// components with an exponent (`-1.2e-05`); LF line ends, none after the last row (as
    /// sungam94/NeuralRTI's data/dirs.lp). Its reader (src/lp.cpp `parseLP`) normalises rows.
    #[test]
    fn relight_rows_with_exponents_are_read() {
        let d = tempfile::tempdir().unwrap();
        let text = "3\na.jpg 0.5 -1.2e-05 0.866025\nb.jpg 1e-06 0 1\nc.jpg -0.6 1E-3 8.0e-01";
        let lp = lp_file(d.path(), "relight.lp", text, &["a.jpg", "b.jpg", "c.jpg"]);
        let f = parse_lp(&lp).unwrap();
        assert_eq!(f.images[2], d.path().join("c.jpg"));
        assert!(near(f.lights[0], [0.5, -1.2e-5, 0.866025]));
        assert!(near(f.lights[1], [1e-6, 0.0, 1.0]));
        assert!(near(f.lights[2], [-0.6, 1e-3, 0.8]));
        assert!(
            f.lengths.iter().all(|l| (l - 1.0).abs() < 1e-5),
            "{:?}",
            f.lengths
        );
        assert_eq!(f.paths, LpPaths::AsWritten);
        assert_eq!(read_light_directions(&lp).unwrap(), f.lights);
    }

    /// RTIBuilder (Cultural Heritage Imaging, Java, 2008-11; its reader
    /// Plugin/helpers/LPparser/LPparser.java `parseLPFileStrict` joins the words before the
    /// last three numbers into the path): absolute Windows paths to `jpeg-exports`, with
    /// spaces, and Windows line ends (CR LF).
    #[test]
    fn rtibuilder_windows_paths_with_spaces_and_crlf_are_read() {
        let d = tempfile::tempdir().unwrap();
        let text = "2\r\nC:\\RTI\\My Coin\\jpeg-exports\\coin 01.jpg 0.01813509 -0.33164996 \
                    0.9432282\r\nC:\\RTI\\My Coin\\jpeg-exports\\coin 02.jpg -0.040955737 \
                    0.32322052 0.945437\r\n";
        let lp = lp_file(d.path(), "coin.lp", text, &["coin 01.jpg", "coin 02.jpg"]);
        let f = parse_lp(&lp).unwrap();
        assert_eq!(
            f.images,
            [d.path().join("coin 01.jpg"), d.path().join("coin 02.jpg")]
        );
        assert!(near(f.lights[1], [-0.040955737, 0.32322052, 0.945437]));
        assert_eq!(f.paths, LpPaths::Windows);
        assert_eq!(lp_path_convention(&lp).unwrap(), LpPaths::Windows);
    }

    /// The PTM fitter's sample light files (HP; quoted in lpgen.py, M. Hodgson 2011:
    /// `../Samplexx/xx-001.tga<TAB>-0.015760 0.196076 0.980462`) put a tab after the path;
    /// NeuralRTI's reader (univr-GRAIL/NeuralRTI a1b276f9, modules/dataset/datasetwmask.py)
    /// takes rows with tabs between all fields.
    #[test]
    fn ptm_fitter_tab_separated_rows_are_read() {
        let d = tempfile::tempdir().unwrap();
        let text = "3\nSample 01/xx-001.tga\t-0.015760 0.196076 0.980462\n\
                    xx-002.tga\t0\t0\t1\n xx-003.tga \t 0.6\t\t0 0.8 \n";
        let images = ["Sample 01/xx-001.tga", "xx-002.tga", "xx-003.tga"];
        let lp = lp_file(d.path(), "ptm.lp", text, &images);
        let f = parse_lp(&lp).unwrap();
        assert_eq!(f.images[0], d.path().join("Sample 01/xx-001.tga"));
        assert!(near(f.lights[0], [-0.015760, 0.196076, 0.980462]));
        assert!(near(f.lights[1], [0.0, 0.0, 1.0]));
        assert!(near(f.lights[2], [0.6, 0.0, 0.8]));
    }

    /// SpectralRTI_Toolkit (thanneken/SpectralRTI_Toolkit 86d185eb,
    /// src/main/java/toolkit/SpectralRTI_Toolkit.java) rewrites an RTIBuilder `.lp` after
    /// splitting it on LF, appending the platform's line separator: on Windows each line ends
    /// CR CR LF. The extra CR ends an empty line, skipped; errors count it as a line.
    #[test]
    fn spectral_rti_toolkit_cr_cr_lf_line_ends_are_read() {
        let d = tempfile::tempdir().unwrap();
        let text = "2\r\r\nAccurateColorRTI\\AccurateColor_01.jpg 0.1 0.2 0.97\r\r\n\
                    AccurateColorRTI\\AccurateColor_02.jpg 0 0 1\r\r\n";
        let images = [
            "AccurateColorRTI/AccurateColor_01.jpg",
            "AccurateColorRTI/AccurateColor_02.jpg",
        ];
        let lp = lp_file(d.path(), "spectral.lp", text, &images);
        let f = parse_lp(&lp).unwrap();
        assert_eq!(f.images[1], d.path().join(images[1]));
        assert_eq!(f.paths, LpPaths::Windows);
        std::fs::write(&lp, text.replace("0 0 1", "0 O 1")).unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(
            e.ends_with("spectral.lp:5: light direction: cannot parse 'O' as a number"),
            "{e}"
        );
    }

    /// psmImages' lights.txt (the photometric stereo test set, e.g. xiumingzhang/
    /// photometric-stereo 5327958b, psmImages/lights.txt, read by run_ps.m past one header
    /// line): the count, then `x y z` rows without names; NeuralRTI's reader (datasetwmask.py
    /// above) takes such rows too, pairing them with the folder's images sorted by name.
    /// Lights to render under; as a capture, refused naming the row (the pairing is a guess).
    #[test]
    fn nameless_rows_under_a_count_are_lights_not_a_capture() {
        let d = tempfile::tempdir().unwrap();
        let text = "3\n0.403259 0.480808 0.778592\n0.0982272 0.163712 0.981606\n\
                    -0.0654826 0.180077 0.98147\n";
        let lights = lp_file(d.path(), "lights.txt", text, &[]);
        let l = read_light_directions(&lights).unwrap();
        assert_eq!(l.len(), 3);
        assert!(near(l[2], [-0.0654826, 0.180077, 0.98147]));
        let lp = lp_file(d.path(), "lights.lp", text, &[]);
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(
            e.contains("lights.lp:2: 3 numbers and no image") && e.contains("filenames.txt"),
            "{e}"
        );
    }

    /// A fourth number after the image is not read silently: relight's reader (src/lp.cpp)
    /// joins all but the last three fields into the file name, so `a.jpg 0.1 0.2 0.9 1.0`
    /// would be the light (0.2, 0.9, 1.0) of an image `a.jpg 0.1`. No
    /// tool surveyed (RTIBuilder, relight, the PTM and HSH fitters, SpectralRTI_Toolkit,
    /// NeuralRTI) writes a 4th or an r g b column: refused naming the line, unless the image's
    /// name ends in that number.
    #[test]
    fn extra_columns_are_refused_never_read_as_the_direction() {
        let d = tempfile::tempdir().unwrap();
        let lp = lp_file(d.path(), "x.lp", "1\na.jpg 0.1 0.2 0.9 1.0\n", &["a.jpg"]);
        for e in [
            parse_lp(&lp).unwrap_err().to_string(),
            read_light_directions(&lp).unwrap_err().to_string(),
        ] {
            assert!(
                e.contains("x.lp:2: 4 numbers after the image 'a.jpg'")
                    && e.contains("light_intensities.txt"),
                "{e}"
            );
        }
        // The image `scan 2` (a name ending in a number, as relight reads the row): read.
        std::fs::write(d.path().join("scan 2"), b"x").unwrap();
        std::fs::write(&lp, "1\nscan 2 0 0.6 0.8\n").unwrap();
        let f = parse_lp(&lp).unwrap();
        assert_eq!(f.images[0], d.path().join("scan 2"));
        assert!(near(f.lights[0], [0.0, 0.6, 0.8]));
        // An image named by a number, the row all numbers: read.
        std::fs::write(d.path().join("0001"), b"x").unwrap();
        std::fs::write(&lp, "1\n0001 0 0.6 0.8\n").unwrap();
        assert_eq!(parse_lp(&lp).unwrap().images[0], d.path().join("0001"));
        assert!(near(
            read_light_directions(&lp).unwrap()[0],
            [0.0, 0.6, 0.8]
        ));
        // r g b after x y z; five numbers; numbers only.
        let refused = [
            (
                "a.jpg 0 0 1 1 0.9 0.8",
                "6 numbers after the image 'a.jpg' (x y z and r g b",
            ),
            ("a.jpg 0 0 1 1 1", "5 numbers after the image 'a.jpg'"),
            ("0.5 0 0 1 1", "5 numbers and no image"),
            (
                "a.jpg 30 45",
                "2 numbers after the image: a row holds x y z toward the light, not angles",
            ),
            (
                "a.jpg 0,1 0,2 0,97",
                "cannot parse '0,97' as a number (a decimal comma?",
            ),
            (
                "a.jpg,0.1,0.2,0.97",
                "not commas or semicolons), found 1 fields",
            ),
        ];
        for (row, want) in refused {
            std::fs::write(&lp, format!("1\n{row}\n")).unwrap();
            for e in [
                parse_lp(&lp).unwrap_err().to_string(),
                read_light_directions(&lp).unwrap_err().to_string(),
            ] {
                assert!(e.contains("x.lp:2: ") && e.contains(want), "{row}: {e}");
            }
        }
    }

    /// An `.lp` without its count line (relight crashes on one, cnr-isti-vclab/relight issue
    /// #19) gets an error naming the light row and asking for the count, not "expected the
    /// number of lights".
    #[test]
    fn a_missing_count_line_is_named() {
        let d = tempfile::tempdir().unwrap();
        let lp = lp_file(
            d.path(),
            "n.lp",
            "a.jpg 0 0 1\nb.jpg 0 1 1\n",
            &["a.jpg", "b.jpg"],
        );
        for e in [
            parse_lp(&lp).unwrap_err().to_string(),
            read_light_directions(&lp).unwrap_err().to_string(),
        ] {
            assert!(
                e.contains(
                    "n.lp:1: expected the number of lights, found the light row 'a.jpg 0 0 1'"
                ) && e.contains("add the count as the first line"),
                "{e}"
            );
        }
        // A DiLiGenT table stays a table.
        std::fs::write(&lp, "0 0 1\n0 1 1\n").unwrap();
        assert_eq!(read_light_directions(&lp).unwrap().len(), 2);
    }

    /// Quoted image paths (no RTI tool writes them; a spreadsheet's CSV export or a hand edit
    /// does): the name without its quotes when the quoted one is not a file.
    #[test]
    fn quoted_image_paths_are_unquoted() {
        let d = tempfile::tempdir().unwrap();
        let text = "2\n\"my photos/a.jpg\" 0 0 1\n'b.jpg' 0 1 1\n";
        let lp = lp_file(d.path(), "q.lp", text, &["my photos/a.jpg", "b.jpg"]);
        let f = parse_lp(&lp).unwrap();
        assert_eq!(
            f.images,
            [d.path().join("my photos/a.jpg"), d.path().join("b.jpg")]
        );
        std::fs::write(&lp, "1\n\"gone.jpg\" 0 0 1\n").unwrap();
        let e = parse_lp(&lp).unwrap_err().to_string();
        assert!(
            e.contains("q.lp:2: image") && e.contains("does not exist"),
            "{e}"
        );
    }

    /// Lengths as written are kept for the near-light warning, however large.
    #[test]
    fn lengths_as_written_are_kept() {
        assert_eq!(vector_length([3.0, 0.0, 4.0]), 5.0);
        assert!((vector_length([1e200, 0.0, 1e200]) / 1e200 - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(vector_length([0.0; 3]), 0.0);
        let d = tempfile::tempdir().unwrap();
        let lp = lp_file(
            d.path(),
            "mm.lp",
            "2\na 300 0 400\nb 0 0 250\n",
            &["a", "b"],
        );
        assert_eq!(parse_lp(&lp).unwrap().lengths, [500.0, 250.0]);
    }

    proptest::proptest! {
        /// Line numbers follow every line end (LF, CR LF, lone CR); no input panics.
        #[test]
        fn content_lines_number_every_line_end(
            bytes in proptest::collection::vec(
                proptest::prop_oneof![
                    proptest::strategy::Just(b'\r'),
                    proptest::strategy::Just(b'\n'),
                    proptest::strategy::Just(b'#'),
                    proptest::strategy::Just(b' '),
                    proptest::strategy::Just(b'1'),
                    proptest::prelude::any::<u8>(),
                ],
                0..64,
            )
        ) {
            if let Ok(lines) = parse_content_lines(Path::new("f.lp"), &bytes) {
                let text = String::from_utf8(bytes).unwrap();
                let ends = text.matches('\n').count() + text.matches('\r').count()
                    - text.matches("\r\n").count();
                for w in lines.windows(2) {
                    proptest::prop_assert!(w[0].0 < w[1].0);
                }
                for (n, l) in &lines {
                    proptest::prop_assert!(*n <= ends + 1);
                    proptest::prop_assert!(!l.contains(['\r', '\n']));
                }
            }
        }

        /// No row panics the row reader; a row written as `<name> x y z` reads back so.
        #[test]
        fn lp_rows_never_panic_and_written_rows_read_back(
            row in "[ \t#,a-z0-9.eE+-]{0,40}",
            name in "[a-z_][a-z0-9_. ]{0,12}\\.jpg",
            v in proptest::array::uniform3(-1e3f64..1e3),
        ) {
            let _ = lp_row(&row);
            let text = format!("{name} {} {}\t{}", v[0], v[1], v[2]);
            let (x, y, z) = (v[0].to_string(), v[1].to_string(), v[2].to_string());
            proptest::prop_assert_eq!(
                lp_row(&text),
                Ok(LpRow::Light(name.trim(), [x.as_str(), y.as_str(), z.as_str()]))
            );
        }

        /// Any finite light other than zero has a unit direction.
        #[test]
        fn every_finite_nonzero_light_is_normalised(
            x in proptest::prelude::any::<f64>(),
            y in proptest::prelude::any::<f64>(),
            z in proptest::prelude::any::<f64>(),
        ) {
            let v = [x, y, z];
            match unit_light(v) {
                Ok(n) => proptest::prop_assert!((n.length() - 1.0).abs() < 1e-12, "{n}"),
                Err(_) => proptest::prop_assert!(
                    v.iter().any(|c| !c.is_finite()) || v.iter().all(|&c| c == 0.0)
                ),
            }
        }
    }
}
