//! The page: its template, script and shaders filled in with the data block, the textures'
//! encoding, and the page written whole and only over a page this tool wrote.

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Serialize;

/// The page template; `{{NAME}}` marks are filled in by [`render_page`].
const PAGE: &str = include_str!("viewer.html");
/// The page's script.
const SCRIPT: &str = include_str!("viewer.js");
/// The vertex shader (one tile's rectangle on the canvas).
const VERTEX_SHADER: &str = include_str!("viewer.vert");
/// The fragment shader: relighting and the map views.
const FRAGMENT_SHADER: &str = include_str!("viewer.frag");

/// The data block of the page (JSON in a `<script>` element).
#[derive(Serialize)]
pub(super) struct PageData {
    /// Version of the data layout, checked by the script.
    pub(super) format: u32,
    pub(super) title: String,
    pub(super) width: usize,
    pub(super) height: usize,
    /// The coarsest level's textures (the whole maps without a pyramid).
    pub(super) textures: Textures,
    /// The pyramid the page loads tiles of, if any.
    pub(super) pyramid: Option<PagePyramid>,
    pub(super) views: Vec<&'static str>,
    /// Names of the source codes, by code.
    pub(super) sources: Vec<&'static str>,
    /// Their colours (as `source.png`).
    pub(super) source_colors: Vec<[u8; 3]>,
    /// What the page shades: `ward`, `gltf` or `estimate`.
    pub(super) model: &'static str,
    /// A glTF fit's light intensity (1 for Ward).
    pub(super) light_intensity: f64,
    /// The capture's samples for the view `samples`, if asked for.
    pub(super) samples: Option<super::samples::PageSamples>,
}

/// The pyramid as the page sees it.
#[derive(Serialize)]
pub(super) struct PagePyramid {
    /// The tile folder, relative to the page.
    pub(super) dir: String,
    pub(super) tile: usize,
    /// Levels below the page's: 0 (full resolution) to `levels - 1`, which is the page's.
    pub(super) levels: usize,
}

/// The encoded textures (see the module documentation).
#[derive(Serialize, Default)]
pub(super) struct Textures {
    pub(super) geom: Option<String>,
    pub(super) frame: Option<String>,
    pub(super) kd: Option<String>,
    pub(super) ks: Option<String>,
    pub(super) est: Option<String>,
}

/// Half floats, four a pixel, as the page takes them: the low bytes of all values then the
/// high bytes (which deflate far better than interleaved), zlib-compressed at `level`,
/// base64-encoded.
pub(super) fn encode_halves(halves: &[u16], level: u32) -> Result<String> {
    let n = halves.len();
    let mut bytes = vec![0u8; n * 2];
    let (lo, hi) = bytes.split_at_mut(n);
    for (i, h) in halves.iter().enumerate() {
        let [l, b] = h.to_le_bytes();
        lo[i] = l;
        hi[i] = b;
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(level));
    z.write_all(&bytes)?;
    Ok(base64(&z.finish()?))
}

/// Standard base64 with padding.
pub(super) fn base64(data: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ABC[(v >> (18 - 6 * i)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Escapes text for HTML element content.
fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The page: the template with its `{{NAME}}` marks replaced in one pass (so nothing inserted
/// is scanned again). The data is JSON with `<` escaped, so no string in it can end its
/// `<script>` element.
pub(super) fn render_page(title: &str, data: &PageData) -> Result<String> {
    let json = serde_json::to_string(data)?.replace('<', "\\u003c");
    let fills = [
        ("TITLE", html_escape(title)),
        ("VERTEX_SHADER", VERTEX_SHADER.to_string()),
        ("FRAGMENT_SHADER", FRAGMENT_SHADER.to_string()),
        ("SCRIPT", SCRIPT.to_string()),
        ("DATA", json),
    ];
    let mut out =
        String::with_capacity(PAGE.len() + fills.iter().map(|f| f.1.len()).sum::<usize>());
    let mut rest = PAGE;
    while let Some(start) = rest.find("{{") {
        let Some(len) = rest[start..].find("}}") else {
            break;
        };
        let name = &rest[start + 2..start + len];
        let Some((_, value)) = fills.iter().find(|f| f.0 == name) else {
            bail!("viewer template: unknown mark {{{{{name}}}}}");
        };
        out.push_str(&rest[..start]);
        out.push_str(value);
        rest = &rest[start + len + 2..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The first line of the page after the doctype: how a page this tool wrote is told apart.
const PAGE_MARK: &str = "<!-- symframe viewer:";

/// Refuses `path` as the page's destination unless it is missing or a viewer page written
/// by this tool: `view -o` never replaces a fit's map or any other file it did not write.
pub(super) fn check_replaceable(path: &Path) -> Result<()> {
    use std::io::Read;
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    let mut head = Vec::new();
    let ours = meta.is_file()
        && std::fs::File::open(path)
            .and_then(|f| f.take(256).read_to_end(&mut head))
            .is_ok()
        && String::from_utf8_lossy(&head)
            .lines()
            .take(2)
            .any(|l| l.starts_with(PAGE_MARK));
    if !ours {
        bail!(
            "{}: exists and is not a viewer page written by symframe view; refusing to replace \
             it (give another -o)",
            path.display()
        );
    }
    Ok(())
}

/// Writes `bytes` to `path` whole or not at all (a temporary file beside it, then renamed).
pub(super) fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot create folder", parent.display()))?;
    }
    check_replaceable(path)?;
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file name", path.display()))?;
    let tmp = path.with_file_name(format!(
        ".{}.partial-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    // A file (or link) left at the temporary name goes; the new one is created, never opened
    // through a link.
    if std::fs::symlink_metadata(&tmp).is_ok_and(|m| !m.is_dir()) {
        let _ = std::fs::remove_file(&tmp);
    }
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| std::io::Write::write_all(&mut f, bytes))
        .with_context(|| format!("{}: cannot write", tmp.display()))
        .and_then(|()| {
            std::fs::rename(&tmp, path).with_context(|| format!("{}: cannot write", path.display()))
        });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}
