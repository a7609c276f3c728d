//! End-to-end regression tests of what symframe guarantees about its own files: a corrupt tile
//! result or tile cache is never trusted (recomputed or repaired, with a warning; `merge` names
//! it), and a changed image is noticed by content even with its size and time kept.

use crate::common::{
    self, estimate_tiled as estimate, ok, report, sphere_dataset, stderr, symframe, ward_sphere,
    Truth,
};
use std::fs;
use std::path::{Path, PathBuf};

use symframe::brdf::Ward;
use symframe_io::{read_npy_f32, ImageFormat};

const SIZE: usize = 40;
const LIGHTS: usize = 60;
/// 8-pixel tiles over 40x40: 25 tiles.
const TILES: usize = 25;

fn dataset(dir: &Path) -> PathBuf {
    ward_sphere(dir, SIZE, LIGHTS)
}

/// The normal maps of two output folders are identical, bit for bit.
fn same_normals(a: &Path, b: &Path) -> bool {
    let (sa, va) = read_npy_f32(&a.join("normals.npy")).unwrap();
    let (sb, vb) = read_npy_f32(&b.join("normals.npy")).unwrap();
    sa == sb && va.iter().zip(&vb).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Tile result files: 48-byte header, then 40-byte records (status, normal, ...).
const HEADER: usize = 48;
const RECORD: usize = 40;

#[test]
fn corrupt_tile_results_are_recomputed_with_a_warning_and_named_by_merge() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let whole = tmp.path().join("whole");
    ok(&estimate(&lp, &whole, &[]));

    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &["--stop-after-tiles", "6", "--threads", "1"]);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    let tiles = out.join(".symframe-tiles");
    // Tile 0: every normal overwritten with (1, 0, 0), length and header kept.
    let t0 = tiles.join("tile-000000.bin");
    let mut b = fs::read(&t0).unwrap();
    let len = b.len();
    for k in 0..64 {
        let o = HEADER + k * RECORD + 4;
        for (j, v) in [1.0f32, 0.0, 0.0].iter().enumerate() {
            b[o + 4 * j..o + 4 * j + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    assert_eq!(b.len(), len);
    fs::write(&t0, &b).unwrap();
    // Tile 1: one bad status byte (it must not block every rerun).
    let t1 = tiles.join("tile-000001.bin");
    let mut b = fs::read(&t1).unwrap();
    b[HEADER + 3 * RECORD] = 200;
    fs::write(&t1, &b).unwrap();

    let o = estimate(&lp, &out, &[]);
    ok(&o);
    let e = stderr(&o);
    for t in ["tile-000000.bin", "tile-000001.bin"] {
        assert!(
            e.lines().any(|l| l.starts_with("warning: ")
                && l.contains(&format!("{t}: corrupt tile result (checksum mismatch)"))
                && l.ends_with("recomputing the tile")),
            "{e}"
        );
    }
    let r = report(&out);
    assert_eq!(r["tiles"]["reused"], 4, "{r}");
    assert_eq!(r["tiles"]["computed"], TILES - 4, "{r}");
    assert!(same_normals(&out, &whole));

    // Shards: a corrupt tile file is named by merge, not merged.
    let shard = |k: usize| tmp.path().join(format!("shard_{k}"));
    for k in 1..=2 {
        ok(&estimate(&lp, &shard(k), &["--tiles", &format!("{k}/2")]));
    }
    let f = shard(2).join(".symframe-tiles/tile-000003.bin");
    let mut b = fs::read(&f).unwrap();
    b[HEADER + 4] ^= 0x40;
    fs::write(&f, &b).unwrap();
    let merged = tmp.path().join("merged");
    let o = symframe(&[
        "merge",
        shard(1).to_str().unwrap(),
        shard(2).to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("tile-000003.bin: corrupt tile result (checksum mismatch)"),
        "{e}"
    );
    assert!(!merged.exists());
}

/// The one cache file of an output folder.
fn cache_file(out: &Path) -> PathBuf {
    fs::read_dir(out.join(".symframe-cache"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "stack"))
        .unwrap()
}

#[test]
fn a_corrupt_cache_is_rebuilt_or_repaired_never_trusted() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let whole = tmp.path().join("whole");
    ok(&estimate(&lp, &whole, &[]));

    // Batches of fewer than the 60 images in 1 MiB (each EXR costs its band and a row of its
    // blocks, about 36 KB): several light blocks per tile.
    let out = tmp.path().join("out");
    let small = ["--decode-memory", "1"];
    ok(&estimate(&lp, &out, &small));
    assert!(same_normals(&out, &whole));
    let batch = report(&out)["cache"]["batch_images"].as_u64().unwrap();
    assert!((2..LIGHTS as u64 / 2).contains(&batch), "{batch}");
    let file = cache_file(&out);

    // The header's light-block field (the 8th field after 16 bytes): the whole cache rebuilt.
    let mut b = fs::read(&file).unwrap();
    let at = 16 + 8 * 7;
    let block = u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    b[at..at + 8].copy_from_slice(&(block + 1).to_le_bytes());
    fs::write(&file, &b).unwrap();
    ok(&estimate(&lp, &out, &small));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false, "{r}");
    assert_eq!(r["cache"]["images_decoded"], LIGHTS, "{r}");
    assert!(same_normals(&out, &whole));

    // 3,000 floats of pixel data: the blocks holding them decoded again and rewritten.
    let mut b = fs::read(&file).unwrap();
    for k in 0..3000 {
        let o = 4096 + 40_000 + 4 * k;
        b[o..o + 4].copy_from_slice(&0.5f32.to_ne_bytes());
    }
    fs::write(&file, &b).unwrap();
    ok(&estimate(&lp, &out, &small));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false, "{r}");
    // (12 KB of a 1.2 MB cache: the two or three blocks they fall in, not the whole.)
    let repaired = r["cache"]["blocks_repaired"].as_u64().unwrap();
    assert!((1..=3).contains(&repaired), "{r}");
    assert!(same_normals(&out, &whole));
    // Repaired for good.
    ok(&estimate(&lp, &out, &small));
    assert_eq!(report(&out)["cache"]["hit"], true);
}

#[test]
fn an_image_replaced_with_the_same_size_and_time_is_noticed() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = dataset(&data);
    // The same dataset as uncompressed PFM images (a changed sample keeps the file's size).
    let text = fs::read_to_string(&lp).unwrap().replace(".exr", ".pfm");
    let pfm_lp = data.join("pfm.lp");
    fs::write(&pfm_lp, text).unwrap();
    let mut names = Vec::new();
    for e in fs::read_dir(data.join("images")).unwrap() {
        let p = e.unwrap().path();
        let img = symframe_io::read_image(&p, &Default::default()).unwrap();
        let q = p.with_extension("pfm");
        symframe_io::write_pfm(&q, img.width, img.height, img.channels, &img.data).unwrap();
        names.push(q);
    }
    names.sort();
    let out = tmp.path().join("out");
    ok(&estimate(&pfm_lp, &out, &[]));
    let first = fs::read(out.join("normals.npy")).unwrap();

    // Another image's pixels under this image's name, size and modification time (cp -p).
    let (victim, donor) = (&names[10], &names[30]);
    let meta = fs::metadata(victim).unwrap();
    let (len, mtime) = (meta.len(), meta.modified().unwrap());
    fs::copy(donor, victim).unwrap();
    fs::File::options()
        .write(true)
        .open(victim)
        .unwrap()
        .set_modified(mtime)
        .unwrap();
    let meta = fs::metadata(victim).unwrap();
    assert_eq!((meta.len(), meta.modified().unwrap()), (len, mtime));

    // --trust-mtime: the documented blind spot (a cache of that kind built first).
    let trusting = tmp.path().join("trusting");
    let o = estimate(&pfm_lp, &trusting, &["--trust-mtime"]);
    ok(&o);
    ok(&estimate(&pfm_lp, &trusting, &["--trust-mtime"]));
    assert_eq!(report(&trusting)["cache"]["hit"], true);

    // By default: rebuilt, and the maps are those of a fresh run.
    ok(&estimate(&pfm_lp, &out, &[]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false, "{r}");
    assert_eq!(r["cache"]["images_decoded"], LIGHTS, "{r}");
    assert_ne!(fs::read(out.join("normals.npy")).unwrap(), first);
    let fresh = tmp.path().join("fresh");
    ok(&estimate(&pfm_lp, &fresh, &[]));
    assert!(same_normals(&out, &fresh));
}

#[test]
fn synth_never_replaces_a_folder_it_did_not_write() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("photos");
    fs::create_dir_all(dir.join("images")).unwrap();
    let raw = dir.join("images/IMG_0001.CR2");
    fs::write(&raw, b"a user's raw file").unwrap();
    let synth = |extra: &[&str]| {
        let mut args = vec![
            "synth",
            "-o",
            dir.to_str().unwrap(),
            "--size",
            "8",
            "--rig",
            "cone:10",
        ];
        args.extend_from_slice(extra);
        symframe(&args)
    };
    let o = synth(&[]);
    common::assert_one_line_error(&o, "photos: not written by symframe synth");
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
    assert_eq!(fs::read(&raw).unwrap(), b"a user's raw file");
    assert!(!dir.join("lights.lp").exists());
    // --force replaces it; then the folder is synth's own and is rewritten without it.
    ok(&synth(&["--force"]));
    assert!(dir.join("lights.lp").is_file() && dir.join(".symframe-synth").is_file());
    ok(&synth(&[]));
}

/// An EXR whose header claims 100000 x 100000 pixels (a 1 KB file) is a one-line error, not an
/// abort of `estimate` with "memory allocation of 40000000000 bytes failed".
#[test]
fn a_forged_image_header_is_a_one_line_error() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let img = tmp.path().join("data/images/img_0007.exr");
    let mut b = fs::read(&img).unwrap();
    let at = b
        .windows(17)
        .position(|w| w == b"dataWindow\0box2i\0")
        .unwrap()
        + 21;
    for (k, v) in [0i32, 0, 99_999, 99_999].iter().enumerate() {
        b[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    b.truncate(1024);
    fs::write(&img, &b).unwrap();
    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &[]);
    common::assert_one_line_error(
        &o,
        "img_0007.exr: exceeds limits: EXR header declares 100000x100000 pixels",
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

/// `eval ... | head` panicked with "failed printing to stdout: Broken pipe".
#[cfg(unix)]
#[test]
fn eval_into_a_closed_pipe_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::{Command, Stdio};
    let tmp = tempfile::tempdir().unwrap();
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let truth = Truth {
        normals: true,
        tangents: true,
    };
    let data = tmp.path().join("data");
    let lp = sphere_dataset(&data, 16, 40, &brdf, ImageFormat::Exr, 1.0, truth).1;
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out, &[]));
    let mut child = Command::new(crate::common::bin())
        .args(["eval", data.to_str().unwrap(), out.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert!(!e.contains("panicked") && !e.contains("Broken pipe"), "{e}");
    assert!(
        o.status.success() || o.status.signal() == Some(13),
        "{:?} {e}",
        o.status
    );
}

/// `--threads 100000` spawned threads for minutes on a 16x16 input.
#[test]
fn absurd_thread_counts_are_refused() {
    for n in ["100000", "0"] {
        let o = symframe(&["--threads", n, "eval", "nowhere", "nowhere"]);
        common::assert_one_line_error(&o, &format!("--threads {n}: give 1 to"));
        assert_eq!(o.status.code(), Some(2));
    }
}

/// `--decode-memory` is checked before it is shifted into bytes (a huge value would wrap
/// around: 2^44 MiB, a zero-byte batch): out of range is a one-line error naming the flag.
#[test]
fn huge_decode_memory_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    for n in ["17592186044416", "18446744073709551615", "1048577", "0"] {
        let out = tmp.path().join("out");
        let o = symframe(&[
            "estimate",
            "nowhere.lp",
            "-o",
            common::s(&out),
            "--decode-memory",
            n,
        ]);
        common::assert_fails_naming(
            &o,
            &format!("--decode-memory must be in [1, 1048576] MiB (at most 1 TiB), got {n}"),
            &out,
        );
    }
}

/// The mask is not read only after every image is decoded into the cache: a wrong-size or empty
/// `mask.png` fails after the first image, before the cache file is created.
#[test]
fn a_bad_mask_fails_before_the_cache_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let mask = lp.parent().unwrap().join("mask.png");
    let cache = tmp.path().join("cache");
    let cache_files = || -> Vec<String> {
        fs::read_dir(&cache)
            .map(|rd| {
                rd.flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.contains(".stack"))
                    .collect()
            })
            .unwrap_or_default()
    };
    let run = |extra: &[&str]| {
        let out = tmp.path().join("out");
        let o = estimate(
            &lp,
            &out,
            &[&["--cache", common::s(&cache)], extra].concat(),
        );
        (o, out)
    };
    // The dataset's own mask.png of the wrong size.
    symframe_io::write_png8_rgb(&mask, 5, 7, &[1.0; 105], false).unwrap();
    let (o, out) = run(&[]);
    common::assert_fails_naming(&o, "mask.png: mask is 5x7 but the images are 40x40", &out);
    assert_eq!(cache_files(), Vec::<String>::new());
    // An empty one given with --mask.
    let empty = tmp.path().join("empty.png");
    symframe_io::write_png8_rgb(&empty, SIZE, SIZE, &vec![0.0; SIZE * SIZE * 3], false).unwrap();
    let (o, out) = run(&["--mask", common::s(&empty)]);
    common::assert_fails_naming(&o, "empty.png: mask is empty", &out);
    assert_eq!(cache_files(), Vec::<String>::new());
    // A right one: the cache is built and the job runs.
    let full = tmp.path().join("full.png");
    symframe_io::write_png8_rgb(&full, SIZE, SIZE, &vec![1.0; SIZE * SIZE * 3], false).unwrap();
    let (o, _) = run(&["--mask", common::s(&full), "--method", "woodham"]);
    ok(&o);
    assert_eq!(cache_files().len(), 1, "{:?}", cache_files());
}
