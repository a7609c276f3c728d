//! Regression tests of the output folder's boundary: whatever was planted inside it (staging
//! plans, symbolic and hard links, folders named like the tool's), no file outside it is
//! deleted, renamed or written, and no output replaces an input of the same run.

use std::fs;
use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};

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
    fs::create_dir_all(&out).unwrap();
    let (victim, _) = victims(tmp.path());
    for name in ["normals.npy", "report.json", "source.png"] {
        symlink(&victim, out.join(name)).unwrap();
    }
    ok(&estimate(&lp, &out));
    assert_kept(&[&victim]);
    for name in ["normals.npy", "report.json", "source.png"] {
        assert!(
            fs::symlink_metadata(out.join(name)).unwrap().is_file(),
            "{name}"
        );
    }
    symframe_job::check_output_set(&out, "report.json").unwrap();
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
