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

/// The lock file of an output folder, held by the job writing into it.
pub const LOCK_FILE: &str = symframe_io::OUTPUT_LOCK_FILE;
/// Prefix of the staging folders inside an output folder (`.symframe-staging-PID`).
const STAGING_PREFIX: &str = ".symframe-staging-";
/// Inside a staging folder: the switch plan, written once every file of the new set is staged.
const READY: &str = ".ready";

/// An output folder locked for one job: a second job into the same folder is refused at once
/// (`OUT is in use by process N`) while this one runs. Taking the lock also finishes what a
/// killed job left: a staged output set that was complete is switched in, an incomplete one
/// removed. Remembers which of the folder and its working subfolders this job created, so a
/// failed job removes only those, and only when they hold nothing a rerun could resume from.
pub struct OutputDir {
    dir: PathBuf,
    created: bool,
    existed: Vec<String>,
    _file: fs::File,
}

impl OutputDir {
    /// Locks `dir` (created if missing, with its parents).
    pub fn lock(dir: &Path) -> Result<Self> {
        if dir.exists() && !dir.is_dir() {
            anyhow::bail!("{}: exists and is not a folder", dir.display());
        }
        let created = !dir.exists();
        fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create folder", dir.display()))?;
        let path = dir.join(LOCK_FILE);
        let file = match lock_file(&path) {
            Ok(Some(f)) => f,
            Ok(None) => {
                let holder = fs::read_to_string(&path).unwrap_or_default();
                let holder = holder.trim();
                if holder.is_empty() {
                    anyhow::bail!("{} is in use by another process", dir.display());
                }
                anyhow::bail!("{} is in use by process {holder}", dir.display());
            }
            Err(e) => {
                if created {
                    let _ = fs::remove_dir(dir);
                }
                return Err(e);
            }
        };
        let existed = [crate::TILES_DIR, crate::CACHE_DIR]
            .iter()
            .filter(|n| dir.join(n).exists())
            .map(|n| n.to_string())
            .collect();
        let out = Self {
            dir: dir.to_path_buf(),
            created,
            existed,
            _file: file,
        };
        out.recover()?;
        Ok(out)
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Staging folders left by killed jobs (no other job can be writing: we hold the lock):
    /// a complete one is switched in, an incomplete one removed.
    fn recover(&self) -> Result<()> {
        for e in fs::read_dir(&self.dir)
            .with_context(|| format!("{}: cannot read folder", self.dir.display()))?
            .flatten()
        {
            let name = e.file_name().to_string_lossy().into_owned();
            if !name.starts_with(STAGING_PREFIX) || !e.path().is_dir() {
                continue;
            }
            let staging = e.path();
            match fs::read_to_string(staging.join(READY)) {
                Ok(text) => {
                    let plan: Plan = serde_json::from_str(&text).with_context(|| {
                        format!("{}: bad switch plan", staging.join(READY).display())
                    })?;
                    plan.apply(&staging, &self.dir, &|_| {})?;
                }
                Err(_) => {
                    fs::remove_dir_all(&staging)
                        .with_context(|| format!("{}: cannot remove", staging.display()))?;
                }
            }
        }
        Ok(())
    }

    /// After a failed job (not an interruption): removes the working subfolders (tile results,
    /// cache) this job created when they hold nothing to resume from, then the folder itself
    /// if this job created it and it is empty. Nothing else is touched.
    pub fn discard_unfinished(self) {
        let tiles = self.dir.join(crate::TILES_DIR);
        if !self.existed.iter().any(|n| n == crate::TILES_DIR) && !holds_tile_results(&tiles) {
            let _ = fs::remove_dir_all(&tiles);
        }
        let cache = self.dir.join(crate::CACHE_DIR);
        if !self.existed.iter().any(|n| n == crate::CACHE_DIR)
            && !symframe_io::cache_holds_work(&cache)
        {
            let _ = fs::remove_dir_all(&cache);
        }
        let (dir, created) = (self.dir.clone(), self.created);
        drop(self);
        if created {
            let _ = fs::remove_dir(&dir);
        }
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        // Removed while still held: a process that opened it before sees a lock file that is
        // no longer at the path and retries (see `lock_file`).
        let _ = fs::remove_file(self.dir.join(LOCK_FILE));
    }
}

/// Whether a tile folder holds any finished tile result.
fn holds_tile_results(dir: &Path) -> bool {
    fs::read_dir(dir).is_ok_and(|rd| {
        rd.flatten().any(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.starts_with("tile-") && n.ends_with(".bin")
        })
    })
}

/// Takes an exclusive `flock` on `path` without waiting: `None` when another process holds
/// it. The holder's process id is written into the file.
#[cfg(unix)]
fn lock_file(path: &Path) -> Result<Option<fs::File>> {
    use std::io::Write;
    use std::os::unix::fs::MetadataExt;
    use std::os::unix::io::AsRawFd;
    loop {
        let mut file = fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(path)
            .with_context(|| format!("{}: cannot create lock file", path.display()))?;
        // SAFETY: flock on a file descriptor we own.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = std::io::Error::last_os_error();
            match e.kind() {
                std::io::ErrorKind::Interrupted => continue,
                std::io::ErrorKind::WouldBlock => return Ok(None),
                _ => return Err(e).with_context(|| format!("{}: cannot lock", path.display())),
            }
        }
        // The holder removes the file before releasing it: the lock counts only if the file
        // we hold is still the one at the path.
        let held = file.metadata()?;
        match fs::metadata(path) {
            Ok(now) if now.ino() == held.ino() && now.dev() == held.dev() => {}
            _ => continue,
        }
        file.set_len(0)?;
        write!(file, "{}", std::process::id())
            .with_context(|| format!("{}: cannot write", path.display()))?;
        return Ok(Some(file));
    }
}

#[cfg(not(unix))]
fn lock_file(path: &Path) -> Result<Option<fs::File>> {
    Ok(Some(
        fs::OpenOptions::new()
            .create(true)
            .truncate(true)
            .write(true)
            .open(path)
            .with_context(|| format!("{}: cannot create lock file", path.display()))?,
    ))
}

/// How a staged output set is switched in: the files in order (the report last) and the files
/// of an earlier set that the new one does not have.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct Plan {
    files: Vec<String>,
    remove: Vec<String>,
}

impl Plan {
    /// Moves the staged files still in `staging` into `out`, removes the earlier set's extra
    /// files before the report (last) goes in, then removes the staging folder. Idempotent: a
    /// killed switch is finished by applying the plan again.
    fn apply(&self, staging: &Path, out: &Path, after_move: &dyn Fn(usize)) -> Result<()> {
        let n = self.files.len();
        for (i, name) in self.files.iter().enumerate() {
            if i + 1 == n {
                for r in &self.remove {
                    let p = out.join(r);
                    if p.is_file() {
                        fs::remove_file(&p)
                            .with_context(|| format!("{}: cannot remove", p.display()))?;
                    }
                }
            }
            let from = staging.join(name);
            if from.exists() {
                let dest = out.join(name);
                fs::rename(&from, &dest)
                    .with_context(|| format!("{}: cannot move into place", dest.display()))?;
                after_move(i + 1);
            }
        }
        fs::remove_dir_all(staging).with_context(|| format!("{}: cannot remove", staging.display()))
    }
}

/// The new output set of a job, written into a staging folder inside the (locked) output
/// folder and switched in by [`OutputSet::commit`]: every file moved in, the report last, the
/// report naming the set (an id, each file's size and XXH3-64 checksum; see
/// [`check_output_set`]). A job killed during the switch leaves a plan that the next job
/// into the folder finishes; one killed before leaves a staging folder that the next removes.
pub struct OutputSet<'a> {
    out: &'a OutputDir,
    staging: PathBuf,
    /// Names of files an earlier set of this kind of job may have had (replaced or removed).
    owned: fn(&str) -> bool,
    planned: bool,
}

impl<'a> OutputSet<'a> {
    /// A fresh staging folder in `out`.
    pub fn new(out: &'a OutputDir, owned: fn(&str) -> bool) -> Result<Self> {
        let staging = out
            .path()
            .join(format!("{STAGING_PREFIX}{}", std::process::id()));
        if staging.exists() {
            fs::remove_dir_all(&staging)
                .with_context(|| format!("{}: cannot remove", staging.display()))?;
        }
        fs::create_dir(&staging)
            .with_context(|| format!("{}: cannot create folder", staging.display()))?;
        Ok(Self {
            out,
            staging,
            owned,
            planned: false,
        })
    }

    /// Where the file `name` of the new set is written.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// Writes `report` as `report_name` with the set recorded under `output_set`, then switches
    /// the set in (`after_move(n)` is called after the n-th file is in place).
    pub fn commit(
        mut self,
        report_name: &str,
        mut report: serde_json::Value,
        after_move: &dyn Fn(usize),
    ) -> Result<()> {
        let mut names: Vec<String> = fs::read_dir(&self.staging)
            .with_context(|| format!("{}: cannot read folder", self.staging.display()))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != report_name)
            .collect();
        names.sort();
        let mut files = Vec::with_capacity(names.len());
        for n in &names {
            let p = self.staging.join(n);
            let bytes = fs::metadata(&p)
                .with_context(|| format!("{}: cannot read", p.display()))?
                .len();
            let hash = symframe_io::tile_cache::file_content_hash(&p)?;
            files.push(serde_json::json!({
                "name": n, "bytes": bytes, "xxh3": format!("{hash:016x}"),
            }));
        }
        let id = {
            let mut f = symframe_io::fingerprint::Fingerprint::new();
            f.str("symframe output set").u64(std::process::id() as u64);
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap_or_default();
            f.u64(now.as_nanos() as u64);
            format!("{:016x}", f.finish())
        };
        report["output_set"] = serde_json::json!({ "id": id, "files": files });
        let text = serde_json::to_string_pretty(&report)? + "\n";
        let report_path = self.staging.join(report_name);
        fs::write(&report_path, text)
            .with_context(|| format!("{}: cannot write", report_path.display()))?;
        names.push(report_name.to_string());
        // Folders are never replaced: refuse before anything moves.
        for n in &names {
            let dest = self.out.path().join(n);
            if dest.is_dir() {
                anyhow::bail!(
                    "{}: is a folder; symframe replaces only its own files there",
                    dest.display()
                );
            }
        }
        let remove: Vec<String> = fs::read_dir(self.out.path())
            .with_context(|| format!("{}: cannot read folder", self.out.path().display()))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| (self.owned)(n) && !names.contains(n))
            .collect();
        let plan = Plan {
            files: names,
            remove,
        };
        let tmp = self.staging.join(".ready.tmp");
        fs::write(&tmp, serde_json::to_string(&plan)?)
            .with_context(|| format!("{}: cannot write", tmp.display()))?;
        fs::rename(&tmp, self.staging.join(READY))
            .with_context(|| format!("{}: cannot write", self.staging.display()))?;
        // From here on a killed job's switch is finished by the next job into the folder.
        self.planned = true;
        plan.apply(&self.staging, self.out.path(), after_move)
    }
}

impl Drop for OutputSet<'_> {
    fn drop(&mut self) {
        if !self.planned {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

/// Checks that the files of the output set that `report` (a report written through
/// [`OutputSet`]) names are in `dir` with their recorded sizes and checksums: `Ok(id)` of the
/// set, else an error naming the first file that differs.
pub fn check_output_set(dir: &Path, report: &str) -> Result<String> {
    let rp = dir.join(report);
    let text = fs::read_to_string(&rp).with_context(|| format!("{}: cannot read", rp.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", rp.display()))?;
    let set = v
        .get("output_set")
        .with_context(|| format!("{}: names no output set", rp.display()))?;
    let id = set["id"].as_str().unwrap_or_default().to_string();
    for f in set["files"].as_array().into_iter().flatten() {
        let name = f["name"].as_str().unwrap_or_default();
        let p = dir.join(name);
        let bytes = fs::metadata(&p)
            .with_context(|| format!("{}: missing from output set {id}", p.display()))?
            .len();
        let hash = format!("{:016x}", symframe_io::tile_cache::file_content_hash(&p)?);
        if Some(bytes) != f["bytes"].as_u64() || Some(hash.as_str()) != f["xxh3"].as_str() {
            anyhow::bail!("{}: not the file of output set {id}", p.display());
        }
    }
    Ok(id)
}
