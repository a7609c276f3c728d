//! `symframe-lab bench scaling --quick`: the sweep runs end to end, writes its JSON, report and
//! plot, and the fitted model is consistent with its own points. Timings are noisy, so only the
//! structure and the model's arithmetic are asserted, never a speed.

use std::fs;

use crate::common::{lab, ok, s};

/// Relative tolerance of a prediction recomputed from the JSON's coefficients and terms (the
/// same sums in another order: rounding only).
const RECOMPUTE_TOLERANCE: f64 = 1e-9;

#[test]
fn bench_scaling_quick_writes_a_consistent_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scaling");
    ok(&lab(&["bench", "scaling", "--quick", "--dir", s(&out)]));
    let doc: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("scaling.json")).unwrap()).unwrap();
    let runs = doc["runs"].as_array().unwrap();
    // Quick plan: 2 sizes, 3 light counts, 2 thread counts and a small batch, with the
    // shared jobs run once.
    assert!(runs.len() >= 6, "{} runs", runs.len());
    let sweeps: Vec<&str> = runs
        .iter()
        .flat_map(|r| r["sweeps"].as_array().unwrap())
        .map(|v| v.as_str().unwrap())
        .collect();
    for sweep in ["size", "lights", "threads", "batch"] {
        assert!(sweeps.contains(&sweep), "no {sweep} sweep: {sweeps:?}");
    }
    let parts = &doc["model"]["parts"];
    let predict = |run: &serde_json::Value, part: &str| -> f64 {
        parts[part]["terms"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let c = t["coefficient"].as_f64().unwrap();
                assert!(c >= 0.0 && c.is_finite(), "{part}: {t}");
                c * run["terms"][format!("{part}.{i}")].as_f64().unwrap()
            })
            .sum()
    };
    let close = |a: f64, b: f64| (a - b).abs() <= RECOMPUTE_TOLERANCE * b.abs().max(1e-12);
    let mut rel = Vec::new();
    for r in runs {
        for key in [
            "wall_s",
            "decode_s",
            "estimate_s",
            "mask_pixels",
            "pixels_per_s",
            "peak_rss_bytes",
            "cache_bytes",
        ] {
            let v = r[key].as_f64().unwrap_or(f64::NAN);
            assert!(v.is_finite() && v > 0.0, "{key} = {v} in {r}");
        }
        // The float32 cache holds 12 bytes per pixel per light, and a header.
        let samples = r["image_pixels"].as_f64().unwrap() * r["lights"].as_f64().unwrap() * 12.0;
        assert!(r["cache_bytes"].as_f64().unwrap() >= samples, "{r}");
        let p = &r["predicted"];
        let parts_sum: f64 = ["other", "decode", "estimate"]
            .iter()
            .map(|part| predict(r, part))
            .sum();
        assert!(close(parts_sum, p["wall_s"].as_f64().unwrap()), "{r}");
        for (part, key) in [
            ("decode", "decode_s"),
            ("estimate", "estimate_s"),
            ("peak_rss", "peak_rss_bytes"),
        ] {
            assert!(
                close(predict(r, part), p[key].as_f64().unwrap()),
                "{part}: {r}"
            );
        }
        let w = r["wall_s"].as_f64().unwrap();
        rel.push((p["wall_s"].as_f64().unwrap() - w) / w);
    }
    // The recorded error is the error of the recorded predictions.
    let max = rel.iter().fold(0.0f64, |a, e| a.max(e.abs()));
    let rms = (rel.iter().map(|e| e * e).sum::<f64>() / rel.len() as f64).sqrt();
    let err = &doc["model"]["errors"]["wall"];
    assert!(close(max, err["max_relative"].as_f64().unwrap()), "{err}");
    assert!(close(rms, err["rms_relative"].as_f64().unwrap()), "{err}");
    // The formula and the tables.
    let formula = doc["model"]["formula"].as_str().unwrap();
    assert!(formula.starts_with("wall ≈ "), "{formula}");
    let md = fs::read_to_string(out.join("scaling.md")).unwrap();
    for needle in [
        formula,
        "peak RSS ≈ ",
        "| sweeps |",
        "2048x2048",
        "load average",
    ] {
        assert!(md.contains(needle), "scaling.md lacks {needle:?}:\n{md}");
    }
    let png = fs::read(out.join("scaling.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    // Only the figures are kept: no cache or maps left behind.
    assert!(!out.join("cache").exists() && !out.join("out").exists());
}

/// `bench` of another layout and format writes that capture, runs on the cache its
/// images call for (`u8` for JPEG, `u16` for 16-bit PNG) and records its figures in
/// `bench.json`.
#[test]
fn bench_of_a_jpeg_or_png16_layout_writes_bench_json() {
    let dir = tempfile::tempdir().unwrap();
    for (format, bytes, baseline) in [("jpeg", 3.0, false), ("png16", 6.0, true)] {
        let d = dir.path().join(format);
        let mut args = vec![
            "bench",
            "--dir",
            s(&d),
            "--width",
            "40",
            "--height",
            "24",
            "--format",
            format,
            "--lights",
            "16",
            "--cold",
        ];
        if !baseline {
            args.push("--no-baseline");
        }
        ok(&lab(&args));
        let data = d.join(format!("data-40x24-16lights-{format}"));
        assert!(data.join("lights.lp").is_file());
        let doc: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(d.join("bench.json")).unwrap()).unwrap();
        assert_eq!(
            (
                &doc["width"],
                &doc["height"],
                &doc["lights"],
                &doc["format"]
            ),
            (&40.into(), &24.into(), &16.into(), &format.into()),
            "{doc}"
        );
        // (The header and tables add a little at this size.)
        let per_sample = doc["cache_bytes_per_pixel_per_light"].as_f64().unwrap();
        assert_eq!(per_sample.floor(), bytes, "{doc}");
        for k in ["total_s", "decode_s", "estimate_s", "cache_bytes"] {
            assert!(doc[k].as_f64().is_some_and(|v| v > 0.0), "{k}: {doc}");
        }
        assert_eq!(doc["woodham_s"].is_number(), baseline, "{doc}");
    }
}
