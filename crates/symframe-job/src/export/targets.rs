//! The files an export may replace: never one of its inputs (by path or by file identity), and
//! only files an earlier export wrote.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::Value;

/// The files of the input folder an export may read (its `.npy` maps and `.json` records).
pub(super) fn input_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("{}: cannot read", dir.display()))? {
        let p = e
            .with_context(|| format!("{}: cannot read", dir.display()))?
            .path();
        if p.extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("npy") || x.eq_ignore_ascii_case("json"))
        {
            v.push(p);
        }
    }
    Ok(v)
}

/// A path with its folder resolved (links included): the directory entry it names.
fn entry(p: &Path) -> Option<PathBuf> {
    let dir = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    Some(dir.canonicalize().ok()?.join(p.file_name()?))
}

/// The device and inode of the file `p` names (links followed), where the platform has them.
fn file_id(p: &Path) -> Option<(u64, u64)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = p;
        None
    }
}

/// Refuses, before anything is written, targets that are folders (the move would fail half-way)
/// and targets that would replace one of the export's inputs: the same directory entry, a
/// symbolic link to the input, or a hard link to it (the same file under another name).
pub(super) fn check_targets(targets: &[PathBuf], inputs: &[PathBuf]) -> Result<()> {
    let inputs: Vec<_> = inputs
        .iter()
        .map(|p| (p.clone(), entry(p), p.canonicalize().ok(), file_id(p)))
        .collect();
    for t in targets {
        let meta = std::fs::symlink_metadata(t).ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            bail!(
                "{}: a folder is in the way of the exported file; move it or choose another \
                 output name",
                t.display()
            );
        }
        let (t_entry, t_file, t_id) = (entry(t), t.canonicalize().ok(), file_id(t));
        for (p, p_entry, p_file, p_id) in &inputs {
            let same_entry = t_entry.is_some() && t_entry == *p_entry;
            let same_file = t_file.is_some() && t_file == *p_file;
            let same_inode = t_id.is_some() && t_id == *p_id;
            if same_entry || same_file || same_inode {
                bail!(
                    "{}: is {}, one of the export's inputs: refusing to replace it; write the \
                     asset elsewhere or under another name",
                    t.display(),
                    p.display()
                );
            }
        }
    }
    Ok(())
}

/// The JSON of the glTF asset at `path` (a `.gltf`, or a `.glb`'s JSON chunk), read no
/// further than its first 64 MiB; `None` when it is not one (not a regular file, not JSON).
fn asset_json(path: &Path) -> Option<Value> {
    use std::io::Read;
    let meta = std::fs::symlink_metadata(path).ok()?;
    if !meta.is_file() {
        return None;
    }
    let cap = symframe_io::limits::MAX_TEXT_FILE_BYTES;
    let mut f = std::fs::File::open(path).ok()?;
    let mut head = [0u8; 20];
    let glb = f.read_exact(&mut head).is_ok() && &head[..4] == b"glTF" && &head[16..20] == b"JSON";
    let bytes = if glb {
        let len = u32::from_le_bytes([head[12], head[13], head[14], head[15]]) as u64;
        symframe_io::read_at_most(f, path, len.min(cap)).ok()?
    } else {
        symframe_io::read_bounded(path, "a glTF file", cap).ok()?
    };
    serde_json::from_slice(&bytes).ok()
}

/// Refuses, before anything is written, to replace a file that this tool did not write: the
/// asset at `output` must be absent or a glTF asset symframe wrote (its `asset.generator`), and
/// each of its companion files there (the `.bin` and textures) absent or named by that asset.
/// A user's `scene.gltf`, or a `scene.bin` beside a new asset, is never replaced without a word.
pub(super) fn check_own_files(targets: &[PathBuf], output: &Path) -> Result<()> {
    let exists = |p: &Path| std::fs::symlink_metadata(p).is_ok();
    let ours = asset_json(output).filter(|doc| {
        doc["asset"]["generator"]
            .as_str()
            .is_some_and(|g| g.starts_with("symframe"))
    });
    if exists(output) && ours.is_none() {
        bail!(
            "{}: exists and is not a glTF asset written by symframe export (symframe replaces \
             only its own files); remove it or choose another output name",
            output.display()
        );
    }
    let named: Vec<String> = ours
        .iter()
        .flat_map(|doc| {
            ["buffers", "images"]
                .iter()
                .flat_map(|k| doc[*k].as_array().cloned().unwrap_or_default())
                .filter_map(|e| e["uri"].as_str().map(str::to_string))
                .collect::<Vec<_>>()
        })
        .collect();
    for t in targets
        .iter()
        .filter(|t| t.as_path() != output && exists(t))
    {
        let name = t.file_name().map(|n| n.to_string_lossy().into_owned());
        if !name.is_some_and(|n| named.contains(&n)) {
            bail!(
                "{}: exists and is not a file of a glTF asset symframe export wrote at {} \
                 (symframe replaces only its own files); remove it or choose another output \
                 name",
                t.display(),
                output.display()
            );
        }
    }
    Ok(())
}
