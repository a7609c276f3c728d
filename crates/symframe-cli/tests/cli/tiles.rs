//! End-to-end tests of the tiled pipeline: the tiled result equals the in-memory one bit for
//! bit; an interrupted run resumes to the same maps; the tile cache is reused and invalidated;
//! shards merge into the single run's maps; merge refuses incomplete or mismatched shards.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{estimate_tiled as estimate, ok, report, s, stderr, symframe, ward_sphere};

use symframe::{
    estimate_stack, Baseline, BaselineParams, CosineMode, EstimatorParams, NoiseModel, Rig,
    RigOptions,
};
use symframe_io::{read_npy_f32, DecodeOptions};

const SIZE: usize = 40;
const LIGHTS: usize = 100;
/// 8-pixel tiles over 40x40: 25 tiles.
const TILES: usize = 25;

/// A 40x40 anisotropic sphere under 100 lights (float EXR, so decoding is exact).
fn dataset(dir: &Path) -> PathBuf {
    ward_sphere(dir, SIZE, LIGHTS)
}

const MAPS: [&str; 5] = [
    "normals.npy",
    "tangents.npy",
    "confidence.npy",
    "anisotropy.npy",
    "tangent_confidence.npy",
];

/// Bitwise equality (NaN equals NaN).
fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The float maps of two output folders are identical.
fn same_maps(a: &Path, b: &Path) {
    for m in MAPS {
        let (sa, va) = read_npy_f32(&a.join(m)).unwrap();
        let (sb, vb) = read_npy_f32(&b.join(m)).unwrap();
        assert_eq!(sa, sb, "{m}");
        assert!(same_bits(&va, &vb), "{m} differs between {a:?} and {b:?}");
    }
    assert_eq!(report(a)["pixels"], report(b)["pixels"]);
    assert_eq!(report(a)["evals_per_pixel"], report(b)["evals_per_pixel"]);
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .map(|rd| {
            rd.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn tiled_result_equals_the_in_memory_result_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let ds = symframe_io::open_dataset(&lp).unwrap();
    let stack = symframe_io::load_stack(&ds, &DecodeOptions::default(), &|| {}).unwrap();
    let mask = symframe_io::read_mask(ds.mask.as_ref().unwrap(), SIZE, SIZE).unwrap();
    let rig = Rig::new(&ds.lights, RigOptions::default()).unwrap();
    for (k, (flags, params)) in [
        (vec![], EstimatorParams::default()),
        (
            vec!["--cosine", "compensated", "--min-confidence", "0.3"],
            EstimatorParams {
                cosine: CosineMode::Compensated(0.5),
                min_confidence: 0.3,
                ..EstimatorParams::default()
            },
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let out = tmp.path().join(format!("out{k}"));
        // The second run builds its cache in batches of what 1 MiB holds (some tens of images,
        // fewer with more threads' buffers): several light blocks.
        let mut flags = flags;
        if k == 1 {
            flags.extend(["--decode-memory", "1"]);
        }
        ok(&estimate(&lp, &out, &flags));
        // The job reads the capture's noise model from its images (report.json records it);
        // the in-memory run is given the same one (read back exactly: the workspace's serde_json
        // parses floats with `float_roundtrip`).
        let r = report(&out);
        let noise: NoiseModel = serde_json::from_value(r["parameters"]["noise"].clone()).unwrap();
        let params = EstimatorParams { noise, ..params };
        let maps = estimate_stack(&stack, &rig, Some(&mask), params, &|_| {}).unwrap();
        for (name, want) in MAPS.iter().zip([
            &maps.normals,
            &maps.tangents,
            &maps.confidence,
            &maps.anisotropy,
        ]) {
            let (_, got) = read_npy_f32(&out.join(name)).unwrap();
            assert!(same_bits(&got, want), "{name} ({flags:?})");
        }
        assert_eq!(r["pixels"], serde_json::to_value(maps.counts).unwrap());
        assert_eq!(r["tiles"]["size"], 8);
        assert_eq!(r["tiles"]["count"], TILES);
        assert_eq!(r["tiles"]["computed"], TILES);
        let batch = r["cache"]["batch_images"].as_u64().unwrap() as usize;
        if k == 0 {
            assert_eq!(batch, LIGHTS);
        } else {
            assert!((2..LIGHTS).contains(&batch), "{batch}");
        }
        let peak = r["timings"]["peak_rss_bytes"].as_u64().unwrap();
        let after_load = r["timings"]["load_peak_rss_bytes"].as_u64().unwrap();
        // The peak never falls: the run's is at least the one after decoding.
        assert!(after_load > 0 && after_load <= peak, "{r}");
        if k == 1 {
            assert!(
                maps.counts.culled > 0,
                "the threshold should cull some pixels"
            );
        }
        // The tile results are gone, the cache is kept.
        assert!(!out.join(".symframe-tiles").exists());
        let cache = names(&out.join(".symframe-cache"));
        assert!(cache.iter().any(|n| n.ends_with(".stack")), "{cache:?}");
    }
}

#[test]
fn tiled_baselines_equal_the_in_memory_baselines_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let ds = symframe_io::open_dataset(&lp).unwrap();
    let stack = symframe_io::load_stack(&ds, &DecodeOptions::default(), &|| {}).unwrap();
    let mask = symframe_io::read_mask(ds.mask.as_ref().unwrap(), SIZE, SIZE).unwrap();
    let cache = tmp.path().join("cache");
    for b in Baseline::ALL {
        let out = tmp.path().join(b.name());
        ok(&estimate(
            &lp,
            &out,
            &[
                "--method",
                b.name(),
                "--cache",
                cache.to_str().unwrap(),
                "--decode-memory",
                "1",
            ],
        ));
        let maps = b
            .estimate_stack(
                &stack,
                &ds.lights,
                Some(&mask),
                BaselineParams::default(),
                &|_| {},
            )
            .unwrap();
        for (name, want) in MAPS.iter().zip([
            &maps.normals,
            &maps.tangents,
            &maps.confidence,
            &maps.anisotropy,
        ]) {
            let (_, got) = read_npy_f32(&out.join(name)).unwrap();
            assert!(same_bits(&got, want), "{name} ({b})");
        }
        let r = report(&out);
        assert_eq!(r["method"], b.name());
        assert_eq!(r["pixels"], serde_json::to_value(maps.counts).unwrap());
    }
    // One cache served the three: decoded once.
    let r = report(&tmp.path().join("max-reflectance"));
    assert_eq!(r["cache"]["hit"], true, "{r}");
}

#[test]
fn an_interrupted_run_resumes_to_the_same_maps_and_changed_parameters_recompute() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let whole = tmp.path().join("whole");
    ok(&estimate(&lp, &whole, &[]));

    let out = tmp.path().join("out");
    let o = estimate(&lp, &out, &["--stop-after-tiles", "6", "--threads", "1"]);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("interrupted; run the same command again to resume"),
        "{}",
        stderr(&o)
    );
    assert!(!out.join("normals.npy").exists());
    let done = names(&out.join(".symframe-tiles"));
    assert_eq!(done.len(), 6, "{done:?}");
    assert!(done.iter().all(|n| n.starts_with("tile-")), "{done:?}");

    // Interrupt once more (2 more tiles), then finish.
    let o = estimate(&lp, &out, &["--stop-after-tiles", "2", "--threads", "1"]);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    ok(&estimate(&lp, &out, &[]));
    same_maps(&out, &whole);
    let r = report(&out);
    assert_eq!(r["tiles"]["reused"], 8, "{r}");
    assert_eq!(r["tiles"]["computed"], TILES - 8, "{r}");
    assert_eq!(r["cache"]["hit"], true, "{r}");
    assert!(!out.join(".symframe-tiles").exists());

    // Tiles of other parameters are stale: a rerun with new ones recomputes every tile.
    let out2 = tmp.path().join("out2");
    let o = estimate(&lp, &out2, &["--stop-after-tiles", "5", "--threads", "1"]);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    ok(&estimate(&lp, &out2, &["--min-anisotropy", "0.3"]));
    assert_eq!(report(&out2)["tiles"]["reused"], 0);
    let whole2 = tmp.path().join("whole2");
    ok(&estimate(&lp, &whole2, &["--min-anisotropy", "0.3"]));
    same_maps(&out2, &whole2);
}

#[test]
fn the_cache_is_reused_and_rebuilt_when_an_image_changes() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = dataset(&data);
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out, &[]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false, "{r}");
    assert_eq!(r["cache"]["images_decoded"], LIGHTS, "{r}");
    let first = r["cache"]["fingerprint"].clone();

    // Same command: nothing decoded.
    ok(&estimate(&lp, &out, &[]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], true, "{r}");
    assert_eq!(r["cache"]["images_decoded"], 0, "{r}");
    let before = fs::read(out.join("normals.npy")).unwrap();

    // A changed image: rebuilt, and the maps change with it.
    let img = data.join("images/img_0042.exr");
    symframe_io::write_exr_rgb(&img, SIZE, SIZE, &vec![0.25; SIZE * SIZE * 3]).unwrap();
    ok(&estimate(&lp, &out, &[]));
    let r = report(&out);
    assert_eq!(r["cache"]["hit"], false, "{r}");
    assert_eq!(r["cache"]["images_decoded"], LIGHTS, "{r}");
    assert_ne!(r["cache"]["fingerprint"], first);
    assert_ne!(fs::read(out.join("normals.npy")).unwrap(), before);
    assert_eq!(
        names(&out.join(".symframe-cache"))
            .iter()
            .filter(|n| n.contains(".stack"))
            .count(),
        1
    );

    // A shared cache folder serves another output; --no-keep-cache removes it at the end.
    let shared = tmp.path().join("shared-cache");
    let a = tmp.path().join("a");
    ok(&estimate(&lp, &a, &["--cache", shared.to_str().unwrap()]));
    assert_eq!(report(&a)["cache"]["hit"], false);
    assert!(!a.join(".symframe-cache").exists());
    let b = tmp.path().join("b");
    ok(&estimate(
        &lp,
        &b,
        &["--cache", shared.to_str().unwrap(), "--no-keep-cache"],
    ));
    assert_eq!(report(&b)["cache"]["hit"], true);
    assert_eq!(report(&b)["cache"]["kept"], false);
    assert!(!shared.exists(), "{:?}", names(&shared));
    same_maps(&a, &b);
}

#[test]
fn shards_merge_into_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let whole = tmp.path().join("whole");
    ok(&estimate(&lp, &whole, &[]));
    let cache = tmp.path().join("cache");
    let shard = |k: usize| tmp.path().join(format!("shard_{k}"));
    for k in 1..=3 {
        let spec = format!("{k}/3");
        ok(&estimate(
            &lp,
            &shard(k),
            &[
                "--tiles",
                &spec,
                "--cache",
                cache.to_str().unwrap(),
                "--decode-memory",
                "1",
            ],
        ));
        let m: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(shard(k).join("shard.json")).unwrap())
                .unwrap();
        assert_eq!(m["shard"], k);
        assert_eq!(m["of"], 3);
        assert!(!shard(k).join("normals.npy").exists());
        let tiles = names(&shard(k).join(".symframe-tiles"));
        assert_eq!(tiles.len(), m["tiles"].as_array().unwrap().len());
    }
    // `symframe merge SHARDS... -o OUT`.
    let merge = |shards: &[&Path], out: &Path| {
        let mut args = vec!["merge"];
        args.extend(shards.iter().map(|p| p.to_str().unwrap()));
        args.extend(["-o", out.to_str().unwrap()]);
        symframe(&args)
    };
    let out = tmp.path().join("merged");
    ok(&merge(&[&shard(1), &shard(2), &shard(3)], &out));
    same_maps(&out, &whole);
    for f in [
        "normals.png",
        "tangents.exr",
        "confidence.png",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert_eq!(report(&out)["shards"].as_array().unwrap().len(), 3);

    // Errors: a missing shard, a shard of another job, a folder that is no shard.
    let bad = tmp.path().join("bad");
    let o = merge(&[&shard(1), &shard(3)], &bad);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("missing tiles 1, 4, 7") && e.contains("shard 2/3 not given"),
        "{e}"
    );
    assert!(!bad.exists());

    let other = tmp.path().join("other_2");
    ok(&estimate(
        &lp,
        &other,
        &[
            "--tiles",
            "2/3",
            "--cache",
            cache.to_str().unwrap(),
            "--min-anisotropy",
            "0.2",
        ],
    ));
    let o = merge(&[&shard(1), &other, &shard(3)], &bad);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("other_2: belongs to another job than") && e.contains("shard_1"),
        "{e}"
    );
    assert!(!bad.exists());

    let o = merge(&[&shard(1), &whole], &bad);
    let e = stderr(&o);
    assert!(e.contains("whole: not a finished shard"), "{e}");

    // A shard whose tile file went missing: the file is named.
    fs::remove_file(shard(2).join(".symframe-tiles/tile-000004.bin")).unwrap();
    let o = merge(&[&shard(1), &shard(2), &shard(3)], &bad);
    let e = stderr(&o);
    assert!(e.contains("tile-000004.bin: cannot read"), "{e}");
    assert!(!bad.exists());
}

/// `--cache-format f16`: recorded in the report, reused while it matches, rebuilt when the
/// format changes; a rerun gives the same maps bit for bit, close to the float32 cache's.
#[test]
fn half_float_cache_is_recorded_reused_and_rebuilt_on_a_format_change() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = dataset(&tmp.path().join("data"));
    let cache = tmp.path().join("cache");
    let run = |out: &str, format: &str| {
        let out = tmp.path().join(out);
        let flags = ["--method", "woodham", "--cache", cache.to_str().unwrap()];
        ok(&estimate(
            &lp,
            &out,
            &[&flags[..], &["--cache-format", format]].concat(),
        ));
        let r = report(&out);
        (out, r)
    };
    let (a, r) = run("a", "f16");
    assert_eq!(
        (&r["cache"]["format"], &r["cache"]["hit"]),
        (&"f16".into(), &false.into())
    );
    let bytes16 = r["cache"]["bytes"].as_u64().unwrap();
    let (b, r) = run("b", "f16");
    assert_eq!(r["cache"]["hit"], true, "{r}");
    same_maps(&a, &b);
    let (c, r) = run("c", "f32");
    assert_eq!(
        (&r["cache"]["format"], &r["cache"]["hit"]),
        (&"f32".into(), &false.into())
    );
    assert!(
        r["cache"]["bytes"].as_u64().unwrap() > 2 * bytes16 - 10_000,
        "{r}"
    );
    let (_, n16) = read_npy_f32(&a.join("normals.npy")).unwrap();
    let (_, n32) = read_npy_f32(&c.join("normals.npy")).unwrap();
    let mut worst = 0.0f32;
    for (u, v) in n16.chunks_exact(3).zip(n32.chunks_exact(3)) {
        assert_eq!(u[0].is_nan(), v[0].is_nan());
        if !u[0].is_nan() {
            let d: f32 = u.iter().zip(v).map(|(x, y)| x * y).sum();
            worst = worst.max(d.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    assert!(worst < 0.1, "{worst} degrees");
}

/// 8-bit (PNG and JPEG) and 16-bit PNG captures: the automatic cache keeps the images' own
/// codes (3 or 6 bytes per pixel per light) and gives the maps of a float32 cache bit for bit.
#[test]
fn integer_caches_give_the_float_caches_maps_bit_for_bit() {
    use crate::common::{sphere_dataset, Truth};
    use symframe_io::ImageFormat;
    let tmp = tempfile::tempdir().unwrap();
    let brdf = symframe::brdf::Ward::new([0.4; 3], [0.3; 3], 0.15, 0.4);
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    let (size, n) = (24, 40);
    for (name, format, jpeg, want, bytes) in [
        ("png8", ImageFormat::Png8, false, "u8", 3),
        ("jpeg", ImageFormat::Png8, true, "u8", 3),
        ("png16", ImageFormat::Png16, false, "u16", 6),
    ] {
        let dir = tmp.path().join(name);
        let (_, mut lp) = sphere_dataset(&dir, size, n, &brdf, format, 1.5, truth);
        if jpeg {
            // The same pictures as baseline JPEG of quality 90.
            let text = fs::read_to_string(&lp).unwrap().replace(".png ", ".jpg ");
            for line in text.lines().skip(1) {
                let jpg = dir.join(line.split(' ').next().unwrap());
                let img = image::open(jpg.with_extension("png")).unwrap().to_rgb8();
                let f = std::io::BufWriter::new(fs::File::create(&jpg).unwrap());
                image::codecs::jpeg::JpegEncoder::new_with_quality(f, 90)
                    .encode_image(&img)
                    .unwrap();
            }
            lp = dir.join("jpeg.lp");
            fs::write(&lp, text).unwrap();
        }
        let run = |out: &str, format: &str| {
            let out = dir.join(out);
            let cache = dir.join(format!("cache-{format}"));
            ok(&estimate(
                &lp,
                &out,
                &["--cache", s(&cache), "--cache-format", format],
            ));
            let r = report(&out);
            (out, r)
        };
        let (a, r) = run("auto", "auto");
        assert_eq!(r["cache"]["format"], want, "{name}: {r}");
        // Header, samples, a checksum per tile (9 tiles of 8 pixels, one light block), a
        // record per light.
        let expect = 4096 + size * size * n * bytes + 9 * 8 + n * 32;
        assert_eq!(r["cache"]["bytes"], expect as u64, "{name}");
        let (b, r) = run("f32", "f32");
        assert_eq!(r["cache"]["format"], "f32", "{name}");
        same_maps(&a, &b);
        assert_eq!(
            fs::read(a.join("normals.npy")).unwrap(),
            fs::read(b.join("normals.npy")).unwrap(),
            "{name}"
        );
    }
}
