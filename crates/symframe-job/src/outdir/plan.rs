//! The switch plan: how a staged output set is moved into the output folder, signed so that
//! only the next holder of the folder's lock carries it out, and only as written.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};

/// How a staged output set is switched in: the files in order (the report last) and the files
/// of an earlier set that the new one does not have. Signed with the writer's lock token and
/// a checksum over both lists, so a plan is carried out only by the next holder of the same
/// folder's lock, and only as written.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
pub(super) struct Plan {
    files: Vec<String>,
    remove: Vec<String>,
    /// The lock token of the job that wrote the plan (16 hex digits).
    token: String,
    /// XXH3-64 over the token and both lists (16 hex digits).
    checksum: String,
}

impl Plan {
    /// A signed plan of the job holding `token`.
    pub(super) fn new(files: Vec<String>, remove: Vec<String>, token: u64) -> Self {
        let token = format!("{token:016x}");
        let checksum = format!("{:016x}", plan_checksum(&token, &files, &remove));
        Self {
            files,
            remove,
            token,
            checksum,
        }
    }

    /// Parses a plan and checks it: written by the lock holder whose token is `token`, its
    /// checksum right, and every name a plain file name (no folder part, no `..`, not hidden
    /// but for this tool's own names), so that applying it touches only files directly in the
    /// output folder.
    pub(super) fn parse(text: &str, token: u64) -> Result<Self> {
        let plan: Plan = serde_json::from_str(text).context("not a switch plan")?;
        if plan.token != format!("{token:016x}") || token == 0 {
            anyhow::bail!("not written by the job that held this folder's lock");
        }
        if plan.checksum
            != format!(
                "{:016x}",
                plan_checksum(&plan.token, &plan.files, &plan.remove)
            )
        {
            anyhow::bail!("checksum mismatch");
        }
        for n in plan.files.iter().chain(&plan.remove) {
            if !plain_name(n) {
                anyhow::bail!("{n:?} is not a plain file name");
            }
        }
        Ok(plan)
    }

    /// Moves the staged files still in `staging` into `out`, removes the earlier set's extra
    /// files before the report (last) goes in, then removes the staging folder. Idempotent: a
    /// killed switch is finished by applying the plan again. Only plain names, only regular
    /// files are moved; a name in `out` that is a folder is never replaced or removed, and a
    /// link there is replaced or removed itself (never what it points to).
    pub(super) fn apply(
        &self,
        staging: &Path,
        out: &Path,
        after_move: &dyn Fn(usize),
    ) -> Result<()> {
        let n = self.files.len();
        for (i, name) in self.files.iter().enumerate() {
            if !plain_name(name) {
                anyhow::bail!("{}: {name:?} is not a plain file name", staging.display());
            }
            if i + 1 == n {
                for r in self.remove.iter().filter(|r| plain_name(r)) {
                    let p = out.join(r);
                    if fs::symlink_metadata(&p).is_ok_and(|m| !m.is_dir()) {
                        fs::remove_file(&p)
                            .with_context(|| format!("{}: cannot remove", p.display()))?;
                    }
                }
            }
            let from = staging.join(name);
            if fs::symlink_metadata(&from).is_ok_and(|m| m.is_file()) {
                let dest = out.join(name);
                if fs::symlink_metadata(&dest).is_ok_and(|m| m.is_dir()) {
                    anyhow::bail!(
                        "{}: is a folder; symframe replaces only its own files there",
                        dest.display()
                    );
                }
                fs::rename(&from, &dest)
                    .with_context(|| format!("{}: cannot move into place", dest.display()))?;
                after_move(i + 1);
            }
        }
        fs::remove_dir_all(staging).with_context(|| format!("{}: cannot remove", staging.display()))
    }
}

/// The checksum a plan carries.
fn plan_checksum(token: &str, files: &[String], remove: &[String]) -> u64 {
    let mut f = symframe_io::fingerprint::Fingerprint::new();
    f.str("symframe switch plan")
        .str(token)
        .u64(files.len() as u64);
    for n in files {
        f.str(n);
    }
    f.u64(remove.len() as u64);
    for n in remove {
        f.str(n);
    }
    f.finish()
}

/// Whether `name` is a file name of this folder that a plan may name: one component, not
/// `.`/`..`, no separator or NUL.
fn plain_name(name: &str) -> bool {
    !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', '\0'])
        && !name.contains(':')
        && Path::new(name).components().count() == 1
}

/// Parses and checks a switch plan as the recovery does (for the fuzz target): `Ok` only for
/// a plan signed with `token` whose names are all plain.
#[cfg(any(test, feature = "fuzzing"))]
pub fn check_switch_plan(text: &str, token: u64) -> Result<(usize, usize)> {
    Plan::parse(text, token).map(|p| (p.files.len(), p.remove.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signed_plan_naming_a_path_outside_the_folder_is_refused() {
        let token = 0x1234_5678_9abc_def0;
        let good = Plan::new(
            vec!["normals.npy".into(), "report.json".into()],
            vec![],
            token,
        );
        let text = serde_json::to_string(&good).unwrap();
        assert_eq!(check_switch_plan(&text, token).unwrap(), (2, 0));
        assert!(
            check_switch_plan(&text, token + 1).is_err(),
            "another holder's plan"
        );
        assert!(check_switch_plan(&text, 0).is_err(), "no holder");
        for bad in [
            "../.bashrc",
            "/etc/passwd",
            "a/b",
            "..",
            ".",
            "",
            "c:x",
            "a\\b",
        ] {
            let forged = Plan::new(vec![bad.into()], vec![], token);
            let text = serde_json::to_string(&forged).unwrap();
            assert!(check_switch_plan(&text, token).is_err(), "{bad:?} in files");
            let forged = Plan::new(vec!["report.json".into()], vec![bad.into()], token);
            let text = serde_json::to_string(&forged).unwrap();
            assert!(
                check_switch_plan(&text, token).is_err(),
                "{bad:?} in remove"
            );
        }
        // A list changed after signing.
        let mut changed = good;
        changed.remove.push("kd.npy".into());
        let text = serde_json::to_string(&changed).unwrap();
        assert!(check_switch_plan(&text, token).is_err());
    }

    /// The fuzz target's seed is a plan this code signs (kept in step with the format).
    #[test]
    fn the_fuzz_seed_is_a_valid_signed_plan() {
        let token = 0x0123_4567_89ab_cdef;
        let plan = Plan::new(
            vec!["normals.npy".into(), "report.json".into()],
            vec!["holdout_residual.npy".into()],
            token,
        );
        let seed = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fuzz/seeds/switch_plan/signed.json"
        );
        let text = std::fs::read_to_string(seed).unwrap();
        assert_eq!(text, serde_json::to_string(&plan).unwrap());
        assert_eq!(check_switch_plan(&text, token).unwrap(), (2, 1));
    }
}
