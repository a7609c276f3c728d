//! Output folders that are never left half-written: files are written into a hidden staging
//! folder beside the destination and moved into place only when all of them are complete.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// A staging folder for the files of one output folder.
pub struct Staging {
    staging: PathBuf,
    target: PathBuf,
    done: bool,
}

impl Staging {
    /// Creates the hidden staging folder beside `target` (whose parent must exist or be
    /// creatable).
    pub fn new(target: &Path) -> Result<Self> {
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent)
            .with_context(|| format!("{}: cannot create folder", parent.display()))?;
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            fs::remove_dir_all(&staging).ok();
        }
        fs::create_dir(&staging)
            .with_context(|| format!("{}: cannot create folder", staging.display()))?;
        Ok(Self {
            staging,
            target: target.to_path_buf(),
            done: false,
        })
    }

    /// The staging folder itself (for writers that lay out several files and folders).
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// The path a file named `name` is written to while staging.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// Moves the staged files into the target folder (created if missing; same-named files
    /// replaced) and removes the staging folder.
    pub fn commit(mut self) -> Result<()> {
        if !self.target.exists() {
            fs::rename(&self.staging, &self.target).with_context(|| {
                format!("{}: cannot move results into place", self.target.display())
            })?;
        } else {
            if !self.target.is_dir() {
                anyhow::bail!("{}: exists and is not a folder", self.target.display());
            }
            for entry in fs::read_dir(&self.staging)? {
                let entry = entry?;
                let dest = self.target.join(entry.file_name());
                if dest.is_dir() {
                    fs::remove_dir_all(&dest).ok();
                }
                fs::rename(entry.path(), &dest)
                    .with_context(|| format!("{}: cannot move into place", dest.display()))?;
            }
            fs::remove_dir_all(&self.staging).ok();
        }
        self.done = true;
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.done {
            fs::remove_dir_all(&self.staging).ok();
        }
    }
}
