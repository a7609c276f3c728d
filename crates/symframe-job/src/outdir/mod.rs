//! Output folders that are never left half-written: files are written into a hidden staging
//! folder beside the destination and moved into place only when all of them are complete.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{Context, Result};

use crate::{Checkpoint, Control, Interrupted};

mod plan;

#[cfg(any(test, feature = "fuzzing"))]
pub use plan::check_switch_plan;
use plan::Plan;

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
        // A fresh name (the process id and a random token): a folder already there, whoever
        // made it, is never removed or written into.
        let staging = parent.join(format!(
            ".{name}.partial-{}-{:016x}",
            std::process::id(),
            new_token()
        ));
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
/// Prefix of the staging folders inside an output folder (`.symframe-staging-PID-TOKEN`).
const STAGING_PREFIX: &str = ".symframe-staging-";
/// Inside a staging folder: the switch plan, written once every file of the new set is staged.
const READY: &str = ".ready";
/// The most bytes a lock file or a switch plan is read to (a forged one may be a device).
const MAX_PLAN_BYTES: u64 = 16 << 20;

/// An output folder locked for one job: a second job into the same folder is refused at once
/// (`OUT is in use by process N`) while this one runs. Taking the lock also finishes what a
/// killed job left: a staged output set that was complete is switched in, an incomplete one
/// removed, and only when the staging folder carries the token of the job that held the lock
/// before (so a planted folder or plan is left alone, with a warning). Nothing inside the
/// folder is followed through a symbolic link: the lock file, the tile and cache folders and
/// staging folders that are links are refused or left alone. Remembers which of the folder and
/// its working subfolders this job created, so a failed job removes only those, and only when
/// they hold nothing a rerun could resume from.
pub struct OutputDir {
    dir: PathBuf,
    created: bool,
    existed: Vec<String>,
    /// This job's lock token: names its staging folders and signs its switch plans.
    token: u64,
    /// What the recovery left alone (planted or foreign staging folders), for the job's report.
    warnings: Vec<String>,
    /// The run's input files (canonical paths), which no output may replace.
    inputs: std::sync::Mutex<Vec<PathBuf>>,
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
        let token = new_token();
        let (file, previous) = match lock_file(&path, token) {
            Ok(Locked::Held(f, previous)) => (f, previous),
            Ok(Locked::Busy) => {
                let holder = read_own_file(&path).unwrap_or_default();
                let holder = holder.split_whitespace().next().unwrap_or_default();
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
        let mut existed = Vec::new();
        for name in [
            crate::TILES_DIR,
            crate::tiles::EVIDENCE_DIR,
            crate::CACHE_DIR,
        ] {
            let p = dir.join(name);
            match fs::symlink_metadata(&p) {
                Ok(m) if m.file_type().is_symlink() => anyhow::bail!(
                    "{}: is a symbolic link; symframe makes none inside its output folder and \
                     follows none there: remove it (give --cache DIR to keep the cache elsewhere)",
                    p.display()
                ),
                Ok(m) if !m.is_dir() => anyhow::bail!(
                    "{}: is not a folder; symframe keeps its working files there: remove it",
                    p.display()
                ),
                Ok(_) => existed.push(name.to_string()),
                Err(_) => {}
            }
        }
        let mut out = Self {
            dir: dir.to_path_buf(),
            created,
            existed,
            token,
            warnings: Vec::new(),
            inputs: std::sync::Mutex::new(Vec::new()),
            _file: file,
        };
        out.recover(previous)?;
        Ok(out)
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// What taking the lock left alone and the user should hear of (a staging folder or plan
    /// that no earlier holder of the lock wrote), one line each.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Records the run's input files (`inputs`: paths as given; those that do not exist are
    /// skipped) so that no output replaces one of them, and refuses at once when a file in the
    /// folder that the job may write or remove (`writes(name)`) is one of them, or when a file
    /// it replaces (`writes` but for the files it only removes, `removes_only`) is not a file
    /// of the output set that the folder's `report` names (a user's own `report.json` or
    /// `normals.png` there): a clear error instead of a file overwritten.
    pub fn guard_inputs<P: AsRef<Path>>(
        &self,
        inputs: impl IntoIterator<Item = P>,
        report: &str,
        writes: &dyn Fn(&str) -> bool,
        removes_only: &dyn Fn(&str) -> bool,
    ) -> Result<()> {
        let mut guarded = self.inputs.lock().unwrap_or_else(|e| e.into_inner());
        guarded.extend(
            inputs
                .into_iter()
                .filter_map(|p| p.as_ref().canonicalize().ok()),
        );
        guarded.sort();
        guarded.dedup();
        drop(guarded);
        let names: Vec<String> = fs::read_dir(&self.dir)
            .with_context(|| format!("{}: cannot read folder", self.dir.display()))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| writes(n))
            .collect();
        self.refuse_inputs(&names)?;
        let replaced: Vec<String> = names.into_iter().filter(|n| !removes_only(n)).collect();
        self.refuse_foreign(report, &replaced)
    }

    /// An error naming the first of `names` that is a file in the folder but neither `report`
    /// (a report of this tool's: it names an output set) nor a file of the set it names:
    /// symframe replaces only its own files. Folders are left to the folder check.
    fn refuse_foreign(&self, report: &str, names: &[String]) -> Result<()> {
        let present: Vec<&String> = names
            .iter()
            .filter(|n| fs::symlink_metadata(self.dir.join(n)).is_ok_and(|m| !m.is_dir()))
            .collect();
        if present.is_empty() {
            return Ok(());
        }
        let listed: Option<Vec<String>> = read_own_file(&self.dir.join(report))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| {
                let files = v.get("output_set")?.get("files")?.as_array()?.clone();
                Some(
                    files
                        .iter()
                        .filter_map(|f| f["name"].as_str().map(String::from))
                        .collect(),
                )
            });
        for n in present {
            let ours = listed
                .as_ref()
                .is_some_and(|l| n.as_str() == report || l.contains(n));
            if !ours {
                anyhow::bail!(
                    "{}: exists and is not a file of the output set that {report} there names \
                     (symframe replaces only its own files); move it away or write the results \
                     into another folder (-o)",
                    self.dir.join(n).display()
                );
            }
        }
        Ok(())
    }

    /// An error naming the first of `names` (files of this folder) that is an input of the run.
    fn refuse_inputs(&self, names: &[String]) -> Result<()> {
        let guarded = self.inputs.lock().unwrap_or_else(|e| e.into_inner());
        if guarded.is_empty() {
            return Ok(());
        }
        for n in names {
            let p = self.dir.join(n);
            if let Ok(c) = p.canonicalize() {
                if guarded.binary_search(&c).is_ok() {
                    anyhow::bail!(
                        "{}: is an input of this run, and the output would replace it; write \
                         the results into another folder (-o)",
                        p.display()
                    );
                }
            }
        }
        Ok(())
    }

    /// Staging folders left by killed jobs (no other job can be writing: we hold the lock).
    /// Only a folder named with the token of the lock's previous holder (`previous`, read from
    /// the lock file it left) is this tool's: a complete one (a verified plan) is switched in,
    /// an incomplete one removed. Anything else named like a staging folder is left alone and
    /// reported.
    fn recover(&mut self, previous: Option<u64>) -> Result<()> {
        let entries: Vec<_> = fs::read_dir(&self.dir)
            .with_context(|| format!("{}: cannot read folder", self.dir.display()))?
            .flatten()
            .collect();
        for e in entries {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(rest) = name.strip_prefix(STAGING_PREFIX) else {
                continue;
            };
            let staging = e.path();
            let ours = staging_token(rest).is_some_and(|t| Some(t) == previous);
            let real_dir = fs::symlink_metadata(&staging).is_ok_and(|m| m.is_dir());
            if !ours || !real_dir {
                self.warnings.push(format!(
                    "{}: left alone: not a staging folder of the job that held this folder's \
                     lock before",
                    staging.display()
                ));
                continue;
            }
            let ready = staging.join(READY);
            if fs::symlink_metadata(&ready).is_ok() {
                let plan = read_own_file(&ready)
                    .and_then(|text| Plan::parse(&text, previous.unwrap_or(0)))
                    .with_context(|| format!("{}: bad switch plan", ready.display()));
                match plan {
                    Ok(plan) => plan.apply(&staging, &self.dir, &|_| {})?,
                    Err(err) => {
                        self.warnings.push(format!("{err:#}; left alone"));
                    }
                }
            } else {
                fs::remove_dir_all(&staging)
                    .with_context(|| format!("{}: cannot remove", staging.display()))?;
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
            remove_real_dir(&tiles);
        }
        let cache = self.dir.join(crate::CACHE_DIR);
        if !self.existed.iter().any(|n| n == crate::CACHE_DIR)
            && !symframe_io::cache_holds_work(&cache)
        {
            remove_real_dir(&cache);
        }
        let (dir, created) = (self.dir.clone(), self.created);
        drop(self);
        if created {
            let _ = fs::remove_dir(&dir);
        }
    }
}

/// Removes `dir` with its contents when it is a real folder (a link is left alone).
fn remove_real_dir(dir: &Path) {
    if fs::symlink_metadata(dir).is_ok_and(|m| m.is_dir()) {
        let _ = fs::remove_dir_all(dir);
    }
}

/// The token in a staging folder's name after the prefix: `PID-TOKEN` (16 hex digits).
fn staging_token(rest: &str) -> Option<u64> {
    let (pid, token) = rest.split_once('-')?;
    let digits = |s: &str, hex: bool| {
        !s.is_empty()
            && s.bytes().all(|b| {
                if hex {
                    b.is_ascii_hexdigit()
                } else {
                    b.is_ascii_digit()
                }
            })
    };
    if !digits(pid, false) || token.len() != 16 || !digits(token, true) {
        return None;
    }
    u64::from_str_radix(token, 16).ok().filter(|&t| t != 0)
}

/// A fresh lock token: 64 random bits (from the standard library's per-process random hash
/// keys, mixed with the process id and the time), never zero.
pub(crate) fn new_token() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    h.write_u128(now.as_nanos());
    h.finish().max(1)
}

/// Reads a small file of this tool's (a lock file, a plan) that must not be a link, at most
/// [`MAX_PLAN_BYTES`] (through [`symframe_io::read_text_bounded`]: a device or a huge file is
/// an error).
fn read_own_file(path: &Path) -> Result<String> {
    if fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
        anyhow::bail!(
            "{}: is a symbolic link (symframe makes none there)",
            path.display()
        );
    }
    Ok(symframe_io::read_text_bounded(
        path,
        "a file of symframe's own",
        MAX_PLAN_BYTES,
    )?)
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

/// The outcome of trying to take the lock.
enum Locked {
    /// Held, with the token the previous holder left in the file (a job that was killed).
    Held(fs::File, Option<u64>),
    /// Another process holds it.
    Busy,
}

/// Takes an exclusive `flock` on `path` without waiting. The lock file must be a regular file
/// with one link (a symbolic or hard link planted there is refused, never truncated). The
/// holder writes `PID TOKEN` into it; the token the last holder left there is returned.
#[cfg(unix)]
fn lock_file(path: &Path, token: u64) -> Result<Locked> {
    use std::io::{Read, Seek, Write};
    use std::os::unix::fs::MetadataExt;
    use std::os::unix::io::AsRawFd;
    loop {
        if let Ok(m) = fs::symlink_metadata(path) {
            if m.file_type().is_symlink() {
                anyhow::bail!(
                    "{}: is a symbolic link; symframe makes none there and follows none: \
                     remove it",
                    path.display()
                );
            }
        }
        let mut file = symframe_io::open_no_follow(
            fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false),
            path,
        )
        .with_context(|| format!("{}: cannot create lock file", path.display()))?;
        let held = file.metadata()?;
        if !held.is_file() || held.nlink() != 1 {
            anyhow::bail!(
                "{}: is not a lock file of symframe's (not a regular file, or linked elsewhere); \
                 remove it",
                path.display()
            );
        }
        // SAFETY: flock on a file descriptor we own.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = std::io::Error::last_os_error();
            match e.kind() {
                std::io::ErrorKind::Interrupted => continue,
                std::io::ErrorKind::WouldBlock => return Ok(Locked::Busy),
                _ => return Err(e).with_context(|| format!("{}: cannot lock", path.display())),
            }
        }
        // The holder removes the file before releasing it: the lock counts only if the file
        // we hold is still the one at the path.
        match fs::symlink_metadata(path) {
            Ok(now) if now.ino() == held.ino() && now.dev() == held.dev() => {}
            _ => continue,
        }
        let mut before = String::new();
        let _ = (&mut file).take(4096).read_to_string(&mut before);
        let previous = before
            .split_whitespace()
            .nth(1)
            .and_then(|t| u64::from_str_radix(t, 16).ok());
        file.set_len(0)?;
        file.rewind()?;
        write!(file, "{} {token:016x}", std::process::id())
            .with_context(|| format!("{}: cannot write", path.display()))?;
        return Ok(Locked::Held(file, previous));
    }
}

#[cfg(not(unix))]
fn lock_file(path: &Path, token: u64) -> Result<Locked> {
    use std::io::Write;
    let mut file = fs::OpenOptions::new()
        .create(true)
        .truncate(true)
        .write(true)
        .open(path)
        .with_context(|| format!("{}: cannot create lock file", path.display()))?;
    write!(file, "{} {token:016x}", std::process::id())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(Locked::Held(file, None))
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
    /// A fresh staging folder in `out`, named with the lock's token.
    pub fn new(out: &'a OutputDir, owned: fn(&str) -> bool) -> Result<Self> {
        let staging = out.path().join(format!(
            "{STAGING_PREFIX}{}-{:016x}",
            std::process::id(),
            out.token
        ));
        // A folder of this name can only be this job's own (the token is fresh): one left by
        // an earlier set of the same job goes.
        remove_real_dir(&staging);
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
            if fs::symlink_metadata(&dest).is_ok_and(|m| m.is_dir()) {
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
        // No input of the run is replaced or removed, nor a file this tool did not write.
        self.out.refuse_inputs(&names)?;
        self.out.refuse_foreign(report_name, &names)?;
        self.out.refuse_inputs(&remove)?;
        let plan = Plan::new(names, remove, self.out.token);
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
            remove_real_dir(&self.staging);
        }
    }
}

/// Checks that the files of the output set that `report` (a report written through
/// [`OutputSet`]) names are in `dir` with their recorded sizes and checksums: `Ok(id)` of the
/// set, else an error naming the first file that differs.
pub fn check_output_set(dir: &Path, report: &str) -> Result<String> {
    let rp = dir.join(report);
    let text =
        symframe_io::read_text_bounded(&rp, "a report", symframe_io::limits::MAX_TEXT_FILE_BYTES)?;
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

/// Runs a job's `run` into the output folder `output`, locked for the whole job: the warnings
/// (the folder's recovery's first) collected for the job's report and told through `ctl`; on
/// an error other than an interruption, what this job created and holds nothing to resume from
/// is removed again.
pub(crate) fn in_locked_output<T>(
    output: &Path,
    ctl: &Control,
    run: impl FnOnce(&Control, &OutputDir, &Mutex<Vec<String>>) -> Result<T>,
) -> Result<T> {
    let out = OutputDir::lock(output)?;
    (ctl.checkpoint)(Checkpoint::OutputLocked);
    let warnings = Mutex::new(Vec::new());
    let warn = |line: &str| {
        lock_warnings(&warnings).push(line.to_string());
        ctl.warn(line);
    };
    let counted = Control {
        warning: &warn,
        ..*ctl
    };
    for w in out.warnings() {
        warn(w);
    }
    let result = run(&counted, &out, &warnings);
    if let Err(e) = &result {
        if !e.is::<Interrupted>() {
            out.discard_unfinished();
        }
    }
    result
}

/// The warnings collected so far (a poisoned lock still holds them).
pub(crate) fn lock_warnings(w: &Mutex<Vec<String>>) -> std::sync::MutexGuard<'_, Vec<String>> {
    w.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staging_folder_names_carry_a_token() {
        assert_eq!(staging_token("12-00000000000000ff"), Some(255));
        for bad in [
            "12",
            "notes",
            "12-ff",
            "x-00000000000000ff",
            "12-0000000000000000",
        ] {
            assert_eq!(staging_token(bad), None, "{bad}");
        }
    }
}
