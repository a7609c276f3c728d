//! End-to-end regression tests of the output folder's guarantees: one job at a time (a second
//! is refused while the first holds the lock), nothing finished is thrown away on an error
//! (tiles and cache kept, a rerun resumes; only half-written maps go, never a folder symframe
//! did not create), and the output switched as one set (a job killed between moves is finished
//! by the next job into the folder).

use std::fs;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    self, estimate_tiled as estimate, ok, report, sphere_dataset, stderr, ward_sphere, Truth,
};

use symframe::brdf::Ward;
use symframe_io::{read_npy_f32, ImageFormat};
use symframe_job::check_output_set;

/// 8-pixel tiles over 32x32: 16 tiles.
const TILES: usize = 16;

fn dataset(dir: &Path) -> PathBuf {
    ward_sphere(dir, 32, 60)
}

/// `symframe estimate LP -o OUT --tile-size 8 EXTRA...` with environment `env`.
fn estimate_cmd(lp: &Path, out: &Path, extra: &[&str], env: &[(&str, &str)]) -> Command {
    let mut c = Command::new(crate::common::bin());
    c.args([
        "estimate",
        common::s(lp),
        "-o",
        common::s(out),
        "--tile-size",
        "8",
    ])
    .args(extra)
    .envs(env.iter().copied());
    c
}

fn normals(out: &Path) -> Vec<u32> {
    let (_, v) = read_npy_f32(&out.join("normals.npy")).unwrap();
    v.iter().map(|x| x.to_bits()).collect()
}

/// Names in `dir` starting with `prefix`.
fn entries(dir: &Path, prefix: &str) -> Vec<String> {
    fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(prefix))
        .collect()
}

#[test]
fn a_second_job_into_a_busy_folder_is_refused_and_the_first_finishes() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    // The first job holds the folder's lock for 4 s before it starts working.
    let first = estimate_cmd(&lp, &out, &[], &[("SYMFRAME_TEST_HOLD_LOCK_S", "4")])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lock = out.join(symframe_job::LOCK_FILE);
    let t = Instant::now();
    while lock_holder(&lock) != first.id().to_string() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "the first job never took the lock"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // The second is refused at once, naming the holder, and touches nothing.
    let o = estimate(&lp, &out, &["--method", "woodham"]);
    common::assert_one_line_error(&o, &format!("is in use by process {}", first.id()));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(common::s(&out)), "{}", stderr(&o));
    let first = first.wait_with_output().unwrap();
    ok(&first);
    assert_eq!(report(&out)["method"], "symmetry");
    check_output_set(&out, "report.json").unwrap();
    // The lock is gone with its job; the next job runs.
    assert!(!lock.exists());
    ok(&estimate(&lp, &out, &["--method", "woodham"]));
    assert_eq!(report(&out)["method"], "woodham");
}

/// The process id in a lock file (`PID TOKEN`), empty when there is none.
pub fn lock_holder(lock: &Path) -> String {
    let text = fs::read_to_string(lock).unwrap_or_default();
    text.split_whitespace()
        .next()
        .unwrap_or_default()
        .to_string()
}

/// Kills (SIGKILL) an estimate into `out` while it holds the folder's lock, before it stages
/// anything; returns the name a staging folder of that job would have
/// (`.symframe-staging-PID-TOKEN`, the token read from the lock file it left).
pub fn killed_holding_the_lock(lp: &Path, out: &Path) -> String {
    let mut held = estimate_cmd(lp, out, &[], &[("SYMFRAME_TEST_HOLD_LOCK_S", "20")])
        .spawn()
        .unwrap();
    wait_for_lock(out, &held);
    held.kill().unwrap();
    held.wait().unwrap();
    let lock = fs::read_to_string(out.join(symframe_job::LOCK_FILE)).unwrap();
    let token = lock.split_whitespace().nth(1).unwrap().to_string();
    format!(".symframe-staging-{}-{token}", held.id())
}

/// Waits until `child` holds the output lock of `dir` (its process id in the lock file).
pub fn wait_for_lock(dir: &Path, child: &std::process::Child) {
    let lock = dir.join(symframe_job::LOCK_FILE);
    let t = Instant::now();
    while lock_holder(&lock) != child.id().to_string() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "the job never took the lock"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `synth -o DIR` and `eval` hold the output lock like estimate and fit do, so they cannot
/// interleave with each other or with those: a second job into the folder is refused while
/// they run.
#[test]
fn synth_and_eval_hold_the_output_folder_lock() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let synth = |env: &[(&str, &str)]| {
        let mut c = Command::new(crate::common::bin());
        c.args(["--quiet", "synth", "-o", common::s(&data)])
            .args(["--size", "16", "--rig", "cone:40"])
            .envs(env.iter().copied())
            .stderr(Stdio::piped());
        c
    };
    let first = synth(&[("SYMFRAME_TEST_HOLD_LOCK_S", "3")])
        .spawn()
        .unwrap();
    wait_for_lock(&data, &first);
    let busy = format!("is in use by process {}", first.id());
    common::assert_one_line_error(&synth(&[]).output().unwrap(), &busy);
    let lp = data.join("lights.lp");
    let est = tmp.path().join("est");
    common::assert_one_line_error(&estimate(&lp, &data, &[]), &busy);
    ok(&first.wait_with_output().unwrap());
    assert!(lp.is_file() && data.join("gt_normals.npy").is_file());
    ok(&estimate(&lp, &est, &["--quiet"]));

    let eval = |env: &[(&str, &str)]| {
        let mut c = Command::new(crate::common::bin());
        c.args(["eval", common::s(&data), common::s(&est)])
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c
    };
    let first = eval(&[("SYMFRAME_TEST_HOLD_LOCK_S", "3")]).spawn().unwrap();
    wait_for_lock(&est, &first);
    let busy = format!("is in use by process {}", first.id());
    common::assert_one_line_error(&eval(&[]).output().unwrap(), &busy);
    common::assert_one_line_error(&estimate(&lp, &est, &[]), &busy);
    ok(&first.wait_with_output().unwrap());
    assert!(est.join("eval.json").is_file());
    assert!(!est.join(symframe_job::LOCK_FILE).exists());
    check_output_set(&est, "report.json").unwrap();
}

#[test]
fn a_late_failure_keeps_tiles_and_cache_and_the_rerun_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let clean = tmp.path().join("clean");
    ok(&estimate(&lp, &clean, &[]));

    // The maps cannot be moved into place: a folder (the user's) is in the way.
    let out = tmp.path().join("out");
    let blocker = out.join("normals.npy");
    fs::create_dir_all(&blocker).unwrap();
    fs::write(blocker.join("mine.txt"), b"keep me").unwrap();
    let o = estimate(&lp, &out, &[]);
    common::assert_one_line_error(&o, "normals.npy: is a folder");
    // Nothing of the user's is gone, no map was half switched, no staging folder is left;
    // every finished tile and the cache are kept.
    assert_eq!(fs::read(blocker.join("mine.txt")).unwrap(), b"keep me");
    assert!(!out.join("report.json").exists() && !out.join("normals.exr").exists());
    assert!(entries(&out, ".symframe-staging").is_empty());
    assert_eq!(entries(&out.join(".symframe-tiles"), "tile-").len(), TILES);
    assert!(out.join(".symframe-cache").is_dir());

    fs::remove_dir_all(&blocker).unwrap();
    let o = estimate(&lp, &out, &[]);
    ok(&o);
    let r = report(&out);
    assert_eq!(r["tiles"]["reused"], TILES, "{r}");
    assert_eq!(r["tiles"]["computed"], 0, "{r}");
    assert_eq!(r["cache"]["hit"], true, "{r}");
    assert_eq!(normals(&out), normals(&clean));
}

#[test]
fn an_error_in_a_fresh_folder_keeps_only_what_a_rerun_resumes_from() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    // Failing before anything is decoded: no folder is left behind.
    let out = tmp.path().join("new/out");
    let o = estimate(Path::new("/no/such/data.lp"), &out, &[]);
    common::assert_one_line_error(&o, "/no/such/data.lp");
    assert!(!out.exists());
    // A mask of the wrong size is found before the images are decoded: nothing left either.
    let small = tmp.path().join("small.png");
    symframe_io::write_png8_rgb(&small, 5, 5, &[1.0; 75], false).unwrap();
    let o = estimate(&lp, &out, &["--mask", common::s(&small)]);
    common::assert_one_line_error(&o, "small.png: mask is 5x5");
    assert!(!out.exists());
    // Failing after the cache is built (fit with frames of the wrong size): the cache stays
    // for the rerun, no maps.
    let frames = tmp.path().join("frames");
    ok(&estimate(&lp, &frames, &["--quiet", "--no-keep-cache"]));
    let wrong = tmp.path().join("wrong");
    fs::create_dir_all(&wrong).unwrap();
    for name in ["normals.npy", "tangents.npy"] {
        symframe_io::write_npy_f32(&wrong.join(name), &[4, 4, 3], &[0.0; 48]).unwrap();
    }
    let fit = |frames: &Path| {
        common::symframe(&[
            "fit",
            "--quiet",
            common::s(&lp),
            "--frames",
            common::s(frames),
            "-o",
            common::s(&out),
        ])
    };
    common::assert_one_line_error(&fit(&wrong), "normals.npy: shape [4, 4, 3]");
    assert!(out.join(".symframe-cache").is_dir());
    assert!(!out.join("kd.npy").exists() && !out.join(".symframe-tiles").exists());
    ok(&fit(&frames));
    let r: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
    assert_eq!(r["cache"]["hit"], true, "{r}");
}

#[test]
fn a_job_killed_between_moves_is_finished_by_the_next_job_into_the_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out, &["--method", "woodham"]));
    let old = check_output_set(&out, "report.json").unwrap();

    // Killed (SIGKILL) after 3 of the new set's 12 files were moved in.
    let o = estimate_cmd(&lp, &out, &[], &[("SYMFRAME_TEST_KILL_AFTER_MOVES", "3")])
        .output()
        .unwrap();
    assert_eq!(o.status.signal(), Some(9), "{}", stderr(&o));
    // The old report still names the old set, and a reader can tell it is no longer whole.
    assert_eq!(report(&out)["method"], "woodham");
    let e = check_output_set(&out, "report.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("not the file of output set"), "{e}");
    assert_eq!(entries(&out, ".symframe-staging").len(), 1);

    // Any job into the folder finishes the switch first, even one that then fails.
    let o = estimate(Path::new("/no/such/data.lp"), &out, &[]);
    common::assert_one_line_error(&o, "/no/such/data.lp");
    let new = check_output_set(&out, "report.json").unwrap();
    assert_ne!(new, old);
    assert_eq!(report(&out)["method"], "symmetry");
    assert!(entries(&out, ".symframe-staging").is_empty());

    // A staging folder of a job killed before its switch began (named with the token that
    // job left in the lock file) is removed; the set stays.
    let stray = out.join(killed_holding_the_lock(&lp, &out));
    fs::create_dir(&stray).unwrap();
    fs::write(stray.join("normals.npy"), b"half written").unwrap();
    let o = estimate(&lp, &out, &[]);
    ok(&o);
    assert!(!stray.exists());
    check_output_set(&out, "report.json").unwrap();
    let clean = tmp.path().join("clean");
    ok(&estimate(&lp, &clean, &[]));
    assert_eq!(normals(&out), normals(&clean));
}

#[test]
fn progress_summary_and_warnings_reach_a_log_and_quiet_silences_them() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    // stderr captured: not a terminal, as under Slurm, cron, CI or `2>log`.
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &[]);
    ok(&o);
    let e = stderr(&o);
    // Each line says how far, the share, the time spent and (past the first second) the time
    // left: `estimating 16/64 tiles (25%), 0:10 elapsed, about 0:30 left`.
    assert!(
        e.lines()
            .any(|l| l.starts_with("decoding 60/60 images (100%), ") && l.ends_with(" elapsed")),
        "{e}"
    );
    assert!(
        e.lines()
            .any(|l| l.starts_with(&format!("estimating {TILES}/{TILES} tiles (100%), "))),
        "{e}"
    );
    assert!(
        e.lines().filter(|l| l.starts_with("estimating ")).count() <= 12,
        "{e}"
    );
    assert!(
        e.lines()
            .any(|l| l.starts_with("symframe: answered by ") && l.contains("report.json in ")),
        "{e}"
    );
    assert!(
        e.lines().any(|l| l.starts_with("symframe (symmetry): ")),
        "{e}"
    );
    assert_eq!(report(&out)["warnings"], serde_json::json!([]));

    let o = estimate(&lp, &tmp.path().join("quiet"), &["--quiet"]);
    ok(&o);
    assert_eq!(stderr(&o), "");

    // A light cone too narrow for the rig: most normals from the fallbacks, a loud warning
    // (also with --quiet) counted in report.json.
    let narrow = tmp.path().join("narrow");
    let o = estimate(&lp, &narrow, &["--quiet", "--theta-d-max", "20"]);
    ok(&o);
    let e = stderr(&o);
    assert!(
        e.lines()
            .any(|l| l.starts_with("warning: most pixels beyond the rig's reach")),
        "{e}"
    );
    let w = report(&narrow)["warnings"].clone();
    assert_eq!(w.as_array().unwrap().len(), 1, "{w}");

    // Nothing estimated (black images): a loud warning.
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    let black = sphere_dataset(
        &tmp.path().join("black"),
        16,
        60,
        &brdf,
        ImageFormat::Exr,
        0.0,
        truth,
    )
    .1;
    let o = estimate(&black, &tmp.path().join("dark"), &["--quiet"]);
    let e = stderr(&o);
    assert!(
        e.lines()
            .any(|l| l.starts_with("warning: 0 pixels estimated")),
        "{e}"
    );
}

#[test]
fn forged_shard_manifests_are_one_line_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let shard = |k: usize| tmp.path().join(format!("shard_{k}"));
    for k in 1..=2 {
        ok(&estimate(
            &lp,
            &shard(k),
            &["--quiet", "--tiles", &format!("{k}/2")],
        ));
    }
    let manifest = shard(2).join("shard.json");
    let good = fs::read_to_string(&manifest).unwrap();
    let merged = tmp.path().join("merged");
    let merge = || {
        common::symframe(&[
            "merge",
            "--quiet",
            common::s(&shard(1)),
            common::s(&shard(2)),
            "-o",
            common::s(&merged),
        ])
    };
    let forged: [(&str, serde_json::Value); 8] = [
        ("of", 0.into()),
        ("shard", 0.into()),
        ("shard", 3.into()),
        ("tile_size", 0.into()),
        ("width", 100_000_000_000u64.into()),
        ("height", 0.into()),
        ("n_tiles", 1_000_000_000_000u64.into()),
        ("tiles", serde_json::json!([0, 1, 99999999999u64])),
    ];
    for (field, value) in forged {
        let mut m: serde_json::Value = serde_json::from_str(&good).unwrap();
        m[field] = value;
        fs::write(&manifest, m.to_string()).unwrap();
        let o = merge();
        common::assert_one_line_error(&o, "shard_2/shard.json: not a valid shard manifest");
        assert_eq!(o.status.code(), Some(1), "{field}: {}", stderr(&o));
        assert!(!merged.exists(), "{field}");
    }
    fs::write(&manifest, good).unwrap();
    ok(&merge());
    check_output_set(&merged, "report.json").unwrap();
}

#[test]
fn a_rerun_removes_the_files_of_the_earlier_set_it_does_not_write() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let frames = tmp.path().join("frames");
    ok(&estimate(&lp, &frames, &["--quiet"]));
    let fit = tmp.path().join("fit");
    let run_fit = |extra: &[&str]| {
        let mut a = vec![
            "fit",
            "--quiet",
            common::s(&lp),
            "--frames",
            common::s(&frames),
        ];
        a.extend_from_slice(&["-o", common::s(&fit)]);
        a.extend_from_slice(extra);
        common::symframe(&a)
    };
    ok(&run_fit(&["--holdout", "6"]));
    assert!(fit.join("holdout_residual.npy").is_file());
    ok(&run_fit(&[]));
    assert!(!fit.join("holdout_residual.npy").exists());
    assert!(!fit.join("holdout_residual.exr").exists());
    check_output_set(&fit, "fit.json").unwrap();

    let relit = tmp.path().join("relit");
    let relight = |lights: &[&str], extra: &[&str]| {
        let mut a = vec![
            "relight",
            "--quiet",
            common::s(&fit),
            "-o",
            common::s(&relit),
        ];
        for l in lights {
            a.extend_from_slice(&["--light", l]);
        }
        a.extend_from_slice(extra);
        common::symframe(&a)
    };
    ok(&relight(
        &["0,0,1", "0.3,0,1", "0,0.3,1"],
        &["--rotate-tangents", "30"],
    ));
    assert!(relit.join("relit_002.png").is_file() && relit.join("tangents_edited.png").is_file());
    ok(&relight(&["0,0,1"], &[]));
    let left = entries(&relit, "relit_");
    assert_eq!(left.len(), 2, "{left:?}");
    assert!(!relit.join("tangents_edited.png").exists());
    check_output_set(&relit, "relight.json").unwrap();
}

#[test]
fn the_first_ctrl_c_ends_a_wait_on_another_process_cache_lock() {
    use std::os::unix::io::AsRawFd;
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let cache = tmp.path().join("cache");
    ok(&estimate(
        &lp,
        &tmp.path().join("a"),
        &["--quiet", "--cache", common::s(&cache)],
    ));
    // Another process (this test) holds the cache's lock as a builder would.
    let lock = cache.join(
        entries(&cache, "")
            .into_iter()
            .find(|n| n.ends_with(".lock"))
            .unwrap(),
    );
    let f = fs::File::open(&lock).unwrap();
    // SAFETY: flock on a file descriptor we own.
    assert_eq!(unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) }, 0);
    let mut waiting = estimate_cmd(
        &lp,
        &tmp.path().join("b"),
        &["--cache", common::s(&cache)],
        &[],
    )
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: signalling the child we started.
    unsafe { libc::kill(waiting.id() as i32, libc::SIGINT) };
    let t = Instant::now();
    let status = loop {
        if let Some(s) = waiting.try_wait().unwrap() {
            break s;
        }
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "Ctrl-C was ignored while waiting"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(status.code(), Some(130));
    drop(f);
}
