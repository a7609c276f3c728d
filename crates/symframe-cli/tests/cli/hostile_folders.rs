//! Regression tests of the output folder's boundary: whatever was planted inside it (staging
//! plans, symbolic and hard links, folders named like the tool's), no file outside it is
//! deleted, renamed or written, and no output replaces an input of the same run.

use std::fs;
use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{self, assert_one_line_error, ok, report, s, stderr, ward_sphere};

/// A small capture: a 16-pixel Ward sphere under 30 lights.
fn capture(dir: &Path) -> PathBuf {
    ward_sphere(dir, 16, 30)
}

/// `symframe estimate LP -o OUT --method woodham` (fast; the folder rules are the same for
/// every method).
fn estimate(lp: &Path, out: &Path) -> std::process::Output {
    common::estimate(lp, out, &["--method", "woodham"])
}

/// Files outside the output folder a planted plan aims at, each holding `keep`.
fn victims(dir: &Path) -> (PathBuf, PathBuf) {
    let (abs, up) = (dir.join("victim-abs.txt"), dir.join("victim-up.txt"));
    fs::write(&abs, "keep").unwrap();
    fs::write(&up, "keep").unwrap();
    (abs, up)
}

fn assert_kept(paths: &[&Path]) {
    for p in paths {
        assert_eq!(fs::read_to_string(p).unwrap(), "keep", "{p:?} was touched");
    }
}

/// A switch plan aimed outside `out`: `files` moves `out/victim-up.txt` (planted) over
/// `../victim-up.txt`, `remove` names an absolute path.
fn plant_plan(staging: &Path, abs: &Path, token: &str) {
    fs::create_dir_all(staging).unwrap();
    let plan = serde_json::json!({
        "files": ["../victim-up.txt", "report.json"],
        "remove": [abs.to_str().unwrap()],
        "token": token,
        "checksum": "0000000000000000",
    });
    fs::write(staging.join(".ready"), plan.to_string()).unwrap();
}

#[test]
fn a_planted_staging_plan_never_touches_a_file_outside_the_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let (abs, up) = victims(tmp.path());
    fs::write(out.join("victim-up.txt"), "planted").unwrap();
    // The old name form, and the current one with a token no holder of the lock had.
    let old = out.join(".symframe-staging-999");
    let forged = out.join(".symframe-staging-999-0123456789abcdef");
    plant_plan(&old, &abs, "0123456789abcdef");
    plant_plan(&forged, &abs, "0123456789abcdef");
    for cmd in [["--method", "woodham"], ["--method", "highlight-centroid"]] {
        let o = common::estimate(&lp, &out, &cmd);
        ok(&o);
        assert_kept(&[&abs, &up]);
        assert!(old.join(".ready").is_file() && forged.join(".ready").is_file());
        let e = stderr(&o);
        assert!(e.contains(".symframe-staging-999: left alone"), "{e}");
        let warnings = report(&out)["warnings"].to_string();
        assert!(warnings.contains("left alone"), "{warnings}");
    }
    // A plan in a folder named with the token the killed holder of the lock left, but not
    // the plan it wrote (the checksum is wrong): left alone too.
    let signed = out.join(crate::outdir::killed_holding_the_lock(&lp, &out));
    let token = signed
        .to_string_lossy()
        .rsplit('-')
        .next()
        .unwrap()
        .to_string();
    plant_plan(&signed, &abs, &token);
    let o = estimate(&lp, &out);
    ok(&o);
    assert_kept(&[&abs, &up]);
    assert!(stderr(&o).contains("bad switch plan"), "{}", stderr(&o));
    assert!(signed.join(".ready").is_file());
}

#[test]
fn a_users_folder_named_like_a_staging_folder_is_left_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    let notes = out.join(".symframe-staging-notes");
    fs::create_dir_all(&notes).unwrap();
    fs::write(notes.join("notes.txt"), "keep").unwrap();
    let o = estimate(&lp, &out);
    ok(&o);
    assert_kept(&[&notes.join("notes.txt")]);
    assert!(stderr(&o).contains("left alone"), "{}", stderr(&o));
}

#[test]
fn a_lock_file_that_is_a_link_is_refused_and_its_target_untouched() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    fs::create_dir_all(&out).unwrap();
    let (victim, _) = victims(tmp.path());
    let lock = out.join(symframe_job::LOCK_FILE);
    symlink(&victim, &lock).unwrap();
    let o = estimate(&lp, &out);
    assert_one_line_error(&o, ".symframe-lock: is a symbolic link");
    assert_kept(&[&victim]);
    // A hard link to a file elsewhere is not truncated either.
    fs::remove_file(&lock).unwrap();
    fs::hard_link(&victim, &lock).unwrap();
    let o = estimate(&lp, &out);
    assert_one_line_error(&o, "is not a lock file of symframe's");
    assert_kept(&[&victim]);
    // Once removed, the folder is usable again.
    fs::remove_file(&lock).unwrap();
    ok(&estimate(&lp, &out));
}

#[test]
fn tile_and_cache_folders_that_are_links_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    for name in [".symframe-tiles", ".symframe-cache"] {
        let out = tmp.path().join(format!("out{name}"));
        let elsewhere = tmp.path().join(format!("elsewhere{name}"));
        fs::create_dir_all(&out).unwrap();
        fs::create_dir_all(&elsewhere).unwrap();
        symlink(&elsewhere, out.join(name)).unwrap();
        let o = common::estimate(&lp, &out, &["--method", "woodham", "--tile-size", "8"]);
        assert_one_line_error(&o, &format!("{name}: is a symbolic link"));
        assert_eq!(fs::read_dir(&elsewhere).unwrap().count(), 0, "{name}");
        assert!(!out.join("report.json").exists());
    }
}

#[test]
fn links_at_output_names_are_replaced_not_written_through() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let (victim, _) = victims(tmp.path());
    // Files of the set the report names, replaced by links: the rerun replaces the links.
    for name in ["normals.npy", "source.png"] {
        fs::remove_file(out.join(name)).unwrap();
        symlink(&victim, out.join(name)).unwrap();
    }
    ok(&estimate(&lp, &out));
    assert_kept(&[&victim]);
    for name in ["normals.npy", "source.png"] {
        let meta = fs::symlink_metadata(out.join(name)).unwrap();
        assert!(meta.is_file(), "{name}");
    }
    symframe_job::check_output_set(&out, "report.json").unwrap();
}

/// A file at an output's name that no report of the tool's names (a user's `report.json`, a
/// link planted in a fresh folder) is never replaced without a word.
#[test]
fn files_the_tool_did_not_write_are_never_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("report.json"), "keep").unwrap();
    let o = estimate(&lp, &out);
    assert_one_line_error(
        &o,
        "report.json: exists and is not a file of the output set",
    );
    assert_kept(&[&out.join("report.json")]);
    fs::remove_file(out.join("report.json")).unwrap();
    let (victim, _) = victims(tmp.path());
    symlink(&victim, out.join("normals.npy")).unwrap();
    let o = estimate(&lp, &out);
    assert_one_line_error(
        &o,
        "normals.npy: exists and is not a file of the output set",
    );
    assert_kept(&[&victim]);
    fs::remove_file(out.join("normals.npy")).unwrap();
    ok(&estimate(&lp, &out));
}

/// A capture whose first image is named like an output (`normals.exr`).
fn capture_with_an_image_named_normals(dir: &Path) -> PathBuf {
    let lp = capture(dir);
    let text = fs::read_to_string(&lp).unwrap();
    let first = text
        .lines()
        .nth(1)
        .and_then(|l| l.split_whitespace().next())
        .unwrap()
        .to_string();
    fs::rename(dir.join(&first), dir.join("normals.exr")).unwrap();
    fs::write(&lp, text.replacen(&first, "normals.exr", 1)).unwrap();
    lp
}

#[test]
fn an_estimate_into_its_input_folder_never_replaces_an_input_image() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = capture_with_an_image_named_normals(&data);
    let image = fs::read(data.join("normals.exr")).unwrap();
    let o = common::estimate(&lp, &data, &[]);
    assert_one_line_error(&o, "normals.exr: is an input of this run");
    assert_eq!(fs::read(data.join("normals.exr")).unwrap(), image);
    assert!(!data.join("report.json").exists());
    // Into another folder it runs.
    ok(&estimate(&lp, &tmp.path().join("out")));
}

#[test]
fn fit_and_view_never_replace_their_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let est = tmp.path().join("est");
    ok(&estimate(&lp, &est));
    let normals = fs::read(est.join("normals.npy")).unwrap();
    // `fit -o` the frames folder would replace normals.npy with the fit's.
    let o = common::symframe(&["fit", s(&lp), "--frames", s(&est), "-o", s(&est), "--quiet"]);
    assert_one_line_error(&o, "normals.npy: is an input of this run");
    assert_eq!(fs::read(est.join("normals.npy")).unwrap(), normals);
    // `view -o` a fit's map (or any file it did not write) is refused.
    crate::view::fit_folder(tmp.path());
    let kd = tmp.path().join("fit").join("kd.npy");
    let before = fs::read(&kd).unwrap();
    let o = common::symframe(&["view", s(&tmp.path().join("fit")), "-o", s(&kd)]);
    assert_one_line_error(&o, "is not a viewer page written by symframe view");
    assert_eq!(fs::read(&kd).unwrap(), before);
    // A page it wrote is replaced.
    let page = tmp.path().join("page.html");
    ok(&common::symframe(&[
        "view",
        s(&tmp.path().join("fit")),
        "-o",
        s(&page),
    ]));
    ok(&common::symframe(&[
        "view",
        s(&tmp.path().join("fit")),
        "-o",
        s(&page),
    ]));
}

#[test]
fn a_cache_file_that_is_a_link_is_never_written_through() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let cache = out.join(".symframe-cache");
    let stack = fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "stack"))
        .expect("a cache file");
    let (victim, _) = victims(tmp.path());
    fs::remove_file(&stack).unwrap();
    symlink(&victim, &stack).unwrap();
    // The cache is rebuilt beside the link and renamed over it: the link goes, its target
    // stays as it was.
    ok(&estimate(&lp, &out));
    assert_kept(&[&victim]);
    assert!(fs::symlink_metadata(&stack).unwrap().is_file());
}

/// Replaces `path` by a FIFO.
fn plant_fifo(path: &Path) {
    let _ = fs::remove_file(path);
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a NUL-terminated path we own.
    let r = unsafe { libc::mkfifo(c.as_ptr(), 0o644) };
    assert_eq!(r, 0, "mkfifo {path:?}");
}

/// Plants, as tiles 1, 2 and 3 of the folder `tiles` (created if need be), a link to
/// `/dev/zero`, a FIFO and a sparse 1 GB file (a tile's file is under a kilobyte); returns
/// their paths.
fn plant_hostile_tiles(tiles: &Path) -> Vec<PathBuf> {
    fs::create_dir_all(tiles).unwrap();
    let planted: Vec<PathBuf> = [1, 2, 3]
        .iter()
        .map(|t| tiles.join(format!("tile-{t:06}.bin")))
        .collect();
    for (k, p) in planted.iter().enumerate() {
        plant_hostile_tile(p, k);
    }
    planted
}

/// Replaces `p` by a link to `/dev/zero` (`kind` 0), a FIFO (1) or a sparse 1 GB file (2).
fn plant_hostile_tile(p: &Path, kind: usize) {
    let _ = fs::remove_file(p);
    match kind {
        0 => symlink("/dev/zero", p).unwrap(),
        1 => plant_fifo(p),
        _ => fs::File::create(p).unwrap().set_len(1 << 30).unwrap(),
    }
}

/// The `.npy` maps of an output folder, by name.
fn npy_maps(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut maps: Vec<(String, Vec<u8>)> = fs::read_dir(out)
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "npy"))
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    maps.sort();
    assert!(!maps.is_empty(), "no maps in {out:?}");
    maps
}

/// A tile result that is a link to `/dev/zero`, a FIFO or a sparse 1 GB file (where a
/// 688-byte tile belongs) is never opened, nor read beyond a tile's length, by a resumed run
/// or a merge (read, it would cost gigabytes or wait forever: docs/performance.md, "Memory model").
/// The resumed run recomputes those tiles with a warning naming each, its maps equal to a
/// clean run's, peaking under 600 MB; a merge of such a shard fails naming the file.
#[test]
#[cfg(target_os = "linux")]
fn tile_results_that_are_devices_fifos_or_huge_are_never_read() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let flags = ["--tile-size", "8", "--method", "woodham", "--quiet"];
    let clean = tmp.path().join("clean");
    ok(&common::estimate(&lp, &clean, &flags));
    let out = tmp.path().join("out");
    ok(&common::estimate(&lp, &out, &flags));
    // As a resumed run finds them in its tile folder (kept only while a run is unfinished).
    let args = [&["estimate", s(&lp), "-o", s(&out)], &flags[..]].concat();
    let planted = plant_hostile_tiles(&out.join(".symframe-tiles"));
    // A hang would show as a test that never ends: time out instead.
    let o = common::run_with_timeout(&args, 60);
    ok(&o);
    let warned = [report_warnings_of(&out), vec![stderr(&o)]]
        .concat()
        .join("\n");
    for p in &planted {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(warned.contains(&name), "no warning about {name}: {warned}");
    }
    assert_eq!(npy_maps(&out), npy_maps(&clean));
    plant_hostile_tiles(&out.join(".symframe-tiles"));
    let (o, kib) = common::run_measuring_rss(&args);
    ok(&o);
    assert!(
        kib < 600 * 1024,
        "the resumed run peaked at {} MB",
        kib / 1024
    );
    assert_eq!(npy_maps(&out), npy_maps(&clean));

    // A shard folder holding such a file: the merge names the file, never waits or reads it.
    let shard = tmp.path().join("shard");
    ok(&common::estimate(
        &lp,
        &shard,
        &[&flags[..], &["--tiles", "1/1"]].concat(),
    ));
    let tiles = shard.join(".symframe-tiles");
    let saved = tmp.path().join("saved");
    fs::create_dir_all(&saved).unwrap();
    for t in 1..=3 {
        let name = format!("tile-{t:06}.bin");
        fs::copy(tiles.join(&name), saved.join(&name)).unwrap();
    }
    for kind in 0..3 {
        let name = format!("tile-{:06}.bin", kind + 1);
        plant_hostile_tile(&tiles.join(&name), kind);
        let merged = tmp.path().join(format!("merged-{kind}"));
        let margs = ["merge", s(&shard), "-o", s(&merged)];
        let o = common::run_with_timeout(&margs, 60);
        assert_one_line_error(&o, &name);
        let (o, kib) = common::run_measuring_rss(&margs);
        assert_one_line_error(&o, &name);
        assert!(!merged.exists());
        assert!(kib < 600 * 1024, "merge peaked at {} MB", kib / 1024);
        fs::remove_file(tiles.join(&name)).unwrap();
        fs::copy(saved.join(&name), tiles.join(&name)).unwrap();
    }
    ok(&common::symframe(&[
        "merge",
        s(&shard),
        "-o",
        s(&tmp.path().join("merged")),
    ]));
    assert_eq!(npy_maps(&tmp.path().join("merged")), npy_maps(&clean));
}

/// The report's warnings of `out`, or none without a report.
fn report_warnings_of(out: &Path) -> Vec<String> {
    if out.join("report.json").is_file() {
        common::report_warnings(out)
    } else {
        Vec::new()
    }
}

/// `fit` resumes from its own tile folder: a tile file there that is a FIFO (opening it would
/// wait forever) or a link to `/dev/zero` is never opened: the tiles are recomputed, the fit
/// equal to a clean one's.
#[test]
#[cfg(target_os = "linux")]
fn fit_tile_results_that_are_fifos_or_devices_are_never_opened() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let est = tmp.path().join("est");
    ok(&common::estimate(
        &lp,
        &est,
        &["--tile-size", "8", "--quiet"],
    ));
    let fit = |out: &Path| {
        let args = ["fit", s(&lp), "--frames", s(&est), "-o", s(out), "--quiet"];
        common::run_with_timeout(&args, 60)
    };
    let clean = tmp.path().join("clean");
    ok(&fit(&clean));
    let out = tmp.path().join("fit");
    ok(&fit(&out));
    // As a resumed fit finds them in its tile folder.
    plant_hostile_tiles(&out.join(".symframe-tiles"));
    ok(&fit(&out));
    assert_eq!(npy_maps(&out), npy_maps(&clean));
}

/// A tile cache file (`OUT/.symframe-cache/*.stack`, or in `--cache DIR`) that is a FIFO is
/// never opened (the run would wait forever), and rebuilt like a stale cache.
#[test]
#[cfg(target_os = "linux")]
fn a_cache_file_that_is_a_fifo_is_rebuilt_not_waited_on() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let stack_in = |cache: &Path| {
        fs::read_dir(cache)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "stack"))
            .expect("a cache file")
    };
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let stack = stack_in(&out.join(".symframe-cache"));
    plant_fifo(&stack);
    let args = ["estimate", s(&lp), "-o", s(&out), "--method", "woodham"];
    ok(&common::run_with_timeout(&args, 60));
    assert!(fs::symlink_metadata(&stack).unwrap().is_file());

    let cache = tmp.path().join("cache");
    let flags = ["--method", "woodham", "--cache", s(&cache)];
    ok(&common::estimate(&lp, &tmp.path().join("a"), &flags));
    let stack = stack_in(&cache);
    plant_fifo(&stack);
    let b = tmp.path().join("b");
    let args = [&["estimate", s(&lp), "-o", s(&b)], &flags[..]].concat();
    ok(&common::run_with_timeout(&args, 60));
    assert!(fs::symlink_metadata(&stack).unwrap().is_file());
}

/// A finished job removes only its tile results from its tile folder, never a user's file in
/// it: the folder stays while anything else is in it.
#[test]
fn a_finished_job_removes_only_its_own_tile_files() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    let tiles = out.join(".symframe-tiles");
    fs::create_dir_all(&tiles).unwrap();
    fs::write(tiles.join("notes.txt"), "keep").unwrap();
    ok(&common::estimate(
        &lp,
        &out,
        &["--method", "woodham", "--tile-size", "8"],
    ));
    assert_kept(&[&tiles.join("notes.txt")]);
    let left: Vec<_> = fs::read_dir(&tiles).unwrap().flatten().collect();
    assert_eq!(left.len(), 1, "only the user's file is left");
    // Without one, the folder goes.
    fs::remove_file(tiles.join("notes.txt")).unwrap();
    ok(&common::estimate(&lp, &out, &["--tile-size", "8"]));
    assert!(!tiles.exists());
}

/// A MERL file that is /dev/zero is refused, not read until memory runs out
/// (docs/performance.md, "Memory model").
#[cfg(target_os = "linux")]
#[test]
fn a_merl_file_that_is_a_device_is_refused_unread() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("c");
    let (o, peak_kib) = common::run_measuring_rss(&[
        "synth",
        "-o",
        s(&out),
        "--model",
        "merl:path=/dev/zero",
        "--size",
        "16",
        "--rig",
        "cone:10",
        "-q",
    ]);
    assert_one_line_error(&o, "/dev/zero");
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
}

/// `calibrate lights.lp -o lights.lp` replaced the `.lp` it read with the calibrated one.
#[test]
fn calibrate_never_replaces_the_lp_it_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    common::chrome_sphere_capture(&data, false);
    let lp = data.join("lights.lp");
    let before = fs::read(&lp).unwrap();
    let o = common::symframe(&["calibrate", s(&lp), "-o", s(&lp), "--quiet"]);
    assert_one_line_error(&o, "lights.lp: is an input of this run");
    assert_eq!(fs::read(&lp).unwrap(), before);
}

/// A FIFO planted at the tile cache's lock file does not make the next run wait forever.
#[cfg(target_os = "linux")]
#[test]
fn a_fifo_at_the_cache_lock_is_an_error_not_a_wait() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let lock = fs::read_dir(out.join(".symframe-cache"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "lock"))
        .expect("a cache lock file");
    fs::remove_file(&lock).unwrap();
    let status = Command::new("mkfifo").arg(&lock).status().unwrap();
    assert!(status.success());
    let args = ["estimate", s(&lp), "-o", s(&out), "--method", "woodham"];
    let o = common::run_with_timeout(&args, 60);
    assert_one_line_error(&o, ".lock");
}

/// `integrate` (and `synth`) staged into `.NAME.partial-PID` beside the output folder and
/// removed a folder already there by that name, outside the output folder.
#[test]
fn a_folder_beside_the_output_is_never_removed() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let est = tmp.path().join("est");
    ok(&estimate(&lp, &est));
    let par = tmp.path().join("par");
    fs::create_dir_all(&par).unwrap();
    // The process id is the shell's, which `exec` hands to symframe.
    let script = format!(
        "mkdir -p {par}/.shape.partial-$$/mine && printf keep > {par}/.shape.partial-$$/mine/k \
         && echo $$ > {par}/pid && exec {bin} integrate {est} -o {par}/shape --solver poisson -q",
        par = s(&par),
        bin = common::bin().display(),
        est = s(&est),
    );
    let o = Command::new("bash").args(["-c", &script]).output().unwrap();
    ok(&o);
    let pid = fs::read_to_string(par.join("pid")).unwrap();
    let mine = par.join(format!(".shape.partial-{}", pid.trim()));
    assert_kept(&[&mine.join("mine").join("k")]);
    assert!(par.join("shape").join("depth.npy").is_file());
}

/// A corrupt block of a cache file with other hard links (a backup made with `cp -al`, outside
/// the output folder) is not repaired in place, which would change the backup too, nor does it
/// fail the run: the cache is rebuilt as a new file, with a warning, and the other link keeps
/// its bytes.
#[test]
fn a_hard_linked_cache_file_is_not_repaired_in_place() {
    use std::io::{Seek, SeekFrom, Write};
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out));
    let normals = fs::read(out.join("normals.npy")).unwrap();
    let stack = fs::read_dir(out.join(".symframe-cache"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "stack"))
        .expect("a cache file");
    let backup = tmp.path().join("backup.stack");
    fs::hard_link(&stack, &backup).unwrap();
    let mut f = fs::OpenOptions::new().write(true).open(&stack).unwrap();
    f.seek(SeekFrom::Start(5000)).unwrap();
    f.write_all(&[0x5a; 64]).unwrap();
    drop(f);
    let before = fs::read(&backup).unwrap();
    let o = estimate(&lp, &out);
    ok(&o);
    let warning = "other hard links to the file: rebuilt as a new file rather than repaired in \
                   place (the other links keep the old content)";
    assert!(
        stderr(&o)
            .lines()
            .any(|l| l.starts_with("warning: ") && l.contains(warning)),
        "{}",
        stderr(&o)
    );
    assert_eq!(fs::read(&backup).unwrap(), before, "the backup changed");
    assert_ne!(fs::read(&stack).unwrap(), before);
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        assert_eq!(fs::metadata(&stack).unwrap().nlink(), 1);
        assert_eq!(fs::metadata(&backup).unwrap().nlink(), 1);
    }
    assert_eq!(fs::read(out.join("normals.npy")).unwrap(), normals);
    let report = common::report(&out);
    assert_eq!(report["cache"]["hit"], false, "{report}");
    assert!(
        report["cache"]["blocks_corrupt"].as_u64().unwrap() > 0,
        "{report}"
    );
}

/// `integrate -o EST` replaced a user's `depth.npy` there (integrate wrote without the output
/// folder's rules), removed a user's folder named `depth.png`, and wrote into a folder a
/// running estimate held.
#[test]
fn integrate_replaces_only_its_own_files_and_respects_the_lock() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let est = tmp.path().join("est");
    ok(&estimate(&lp, &est));
    fs::write(est.join("depth.npy"), "keep").unwrap();
    let integrate = |out: &Path| {
        common::symframe(&[
            "integrate",
            s(&est),
            "-o",
            s(out),
            "--solver",
            "poisson",
            "-q",
        ])
    };
    let o = integrate(&est);
    assert_one_line_error(&o, "depth.npy: exists and is not a file of the output set");
    assert_kept(&[&est.join("depth.npy")]);
    assert!(!est.join("mesh.ply").exists());
    fs::remove_file(est.join("depth.npy")).unwrap();
    // A user's folder at an output name is never replaced.
    fs::create_dir_all(est.join("depth.png")).unwrap();
    fs::write(est.join("depth.png").join("k"), "keep").unwrap();
    assert_one_line_error(&integrate(&est), "depth.png: is a folder");
    assert_kept(&[&est.join("depth.png").join("k")]);
    fs::remove_dir_all(est.join("depth.png")).unwrap();
    // Its own earlier set is replaced.
    ok(&integrate(&est));
    ok(&integrate(&est));
    symframe_job::check_output_set(&est, "integrate.json").unwrap();
    // A folder another job holds is refused at once.
    let held = std::process::Command::new(common::bin())
        .args([
            "estimate",
            s(&lp),
            "-o",
            s(&est),
            "--method",
            "woodham",
            "-q",
        ])
        .env("SYMFRAME_TEST_HOLD_LOCK_S", "4")
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let o = integrate(&est);
    let mut held = held;
    held.wait().unwrap();
    assert_one_line_error(&o, "in use by process");
}

/// `synth --rig lp:cap/lights.lp -o cap` rewrote the light file it read its rig from.
#[test]
fn synth_never_replaces_its_rig_file() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    ok(&common::symframe(&[
        "synth",
        "-o",
        s(&cap),
        "--size",
        "16",
        "--rig",
        "cone:12",
        "-q",
    ]));
    let lp = cap.join("lights.lp");
    let before = fs::read(&lp).unwrap();
    let rig = format!("lp:{}", s(&lp));
    let o = common::symframe(&["synth", "-o", s(&cap), "--size", "16", "--rig", &rig, "-q"]);
    assert_one_line_error(&o, "lights.lp: is an input of this run");
    assert_eq!(fs::read(&lp).unwrap(), before);
    // Into another folder it runs.
    let other = tmp.path().join("other");
    ok(&common::symframe(&[
        "synth",
        "-o",
        s(&other),
        "--size",
        "16",
        "--rig",
        &rig,
        "-q",
    ]));
}

/// A real (sparse) 11000 x 11000 normal map under an address-space limit gets a one-line
/// error with the figures from `integrate`, not an abort on a failed allocation (exit 134).
#[cfg(target_os = "linux")]
#[test]
fn integrate_refuses_a_map_too_large_for_the_memory_it_may_use() {
    use std::io::Write;
    let tmp = tempfile::tempdir().unwrap();
    let est = tmp.path().join("est");
    fs::create_dir_all(&est).unwrap();
    let mut header =
        b"{'descr': '<f4', 'fortran_order': False, 'shape': (11000, 11000, 3), }".to_vec();
    while !(header.len() + 11).is_multiple_of(64) {
        header.push(b' ');
    }
    header.push(b'\n');
    let mut f = fs::File::create(est.join("normals.npy")).unwrap();
    f.write_all(b"\x93NUMPY\x01\x00").unwrap();
    f.write_all(&(header.len() as u16).to_le_bytes()).unwrap();
    f.write_all(&header).unwrap();
    f.set_len(10 + header.len() as u64 + 11000 * 11000 * 12)
        .unwrap();
    drop(f);
    let out = tmp.path().join("shape");
    let o =
        common::run_with_address_space_cap(&["integrate", s(&est), "-o", s(&out), "-q"], 2 << 30);
    assert_one_line_error(
        &o,
        "normals.npy: integrating a map of about 121.0 megapixels needs",
    );
    assert!(!out.join("depth.npy").exists());
}

/// What taking the output folder's lock left alone (a user's folder named like a staging
/// folder) is recorded as well as printed by `fit` and `relight`: `fit.json` and
/// `relight.json` carry it in `warnings`, as `report.json` of an estimate does.
#[test]
fn fit_and_relight_record_what_the_lock_left_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = capture(&tmp.path().join("data"));
    let est = tmp.path().join("est");
    ok(&estimate(&lp, &est));
    let plant = |out: &Path| {
        let notes = out.join(".symframe-staging-notes");
        fs::create_dir_all(&notes).unwrap();
        fs::write(notes.join("notes.txt"), "keep").unwrap();
        notes.join("notes.txt")
    };
    let recorded = |report: &Path| -> String {
        let v: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(report).unwrap()).unwrap();
        v["warnings"].to_string()
    };
    let fit = tmp.path().join("fit");
    let kept = plant(&fit);
    let o = common::symframe(&[
        "fit",
        s(&lp),
        "--frames",
        s(&est),
        "-o",
        s(&fit),
        "--model",
        "ward",
        "--holdout",
        "3",
    ]);
    ok(&o);
    assert!(stderr(&o).contains("left alone"), "{}", stderr(&o));
    assert!(
        recorded(&fit.join("fit.json")).contains("left alone"),
        "{}",
        recorded(&fit.join("fit.json"))
    );
    assert_kept(&[&kept]);
    // Without anything left alone, the record is there and empty.
    let clean = tmp.path().join("fit2");
    ok(&common::symframe(&[
        "fit",
        s(&lp),
        "--frames",
        s(&est),
        "-o",
        s(&clean),
        "--model",
        "ward",
        "--holdout",
        "3",
        "--quiet",
    ]));
    assert_eq!(recorded(&clean.join("fit.json")), "[]");

    let relit = tmp.path().join("relit");
    let kept = plant(&relit);
    let o = common::symframe(&["relight", s(&fit), "-o", s(&relit), "--light", "0,0,1"]);
    ok(&o);
    assert!(stderr(&o).contains("left alone"), "{}", stderr(&o));
    let r = recorded(&relit.join("relight.json"));
    assert!(r.contains("left alone"), "{r}");
    assert_kept(&[&kept]);
}
