//! `symframe-lab bench scaling`: scaling curves of the estimation job. Sweeps the image size
//! at a fixed light count, the light count at a fixed size, the threads at a fixed job and the
//! decoding batch at a fixed job (datasets as `bench` renders them, each run cold: the
//! tile cache deleted first), fits a cost model by least squares, and writes `scaling.json`
//! (every run, the model, its error), `scaling.md` (tables and the formula) and `scaling.png`
//! (the curves with the model).
//!
//! The model is linear in its coefficients, one part per stage, each fitted to that stage's
//! measured seconds with relative residuals and non-negative coefficients (a term the data
//! do not support is dropped): with N pixels in the image, P in the mask, L lights, T cores
//! (threads on an idle machine; measured as CPU / wall seconds here),
//! `wall = other(N, L) + decode(N, L, T) + P (c + d min(L, 512) + e L) / T`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use serde_json::{json, Value};

use symframe_console::flags::CacheFormatArg;

mod curves;
mod model;

use super::{dataset, remove_dir, run_estimate, symmetry_config, Figures};
use crate::cli::ScalingArgs;
use crate::experiment::plot;
use curves::plot_curves;
use model::{errors, fit, fmt_part, parts, predict, Point, SAMPLE_BYTES};

/// The shape of one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Job {
    size: usize,
    lights: usize,
    threads: usize,
    decode_memory_mib: usize,
}

/// The sweeps: (name, jobs). A job in several sweeps runs once.
fn plan(args: &ScalingArgs) -> Vec<(&'static str, Vec<Job>)> {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let mib = args.decode_memory;
    let job = |size, lights, threads, decode_memory_mib| Job {
        size,
        lights,
        threads,
        decode_memory_mib,
    };
    if args.quick {
        return vec![
            (
                "size",
                vec![job(16, 40, cores, mib), job(24, 40, cores, mib)],
            ),
            (
                "lights",
                [20, 40, 80].map(|l| job(16, l, cores, mib)).to_vec(),
            ),
            ("threads", [1, 2].map(|t| job(24, 40, t, mib)).to_vec()),
            ("batch", vec![job(16, 80, cores, 1)]),
        ];
    }
    let mut sizes = vec![128, 256, 512];
    if args.large {
        sizes.push(1024);
    }
    vec![
        (
            "size",
            sizes.iter().map(|&s| job(s, 380, cores, mib)).collect(),
        ),
        (
            "lights",
            [96, 190, 380, 760, 1512, 3000]
                .map(|l| job(128, l, cores, mib))
                .to_vec(),
        ),
        ("threads", [1, 2].map(|t| job(256, 380, t, mib)).to_vec()),
        // A small decoding batch on the same stack: separates the batch from the cache size
        // in the memory model.
        ("batch", vec![job(128, 1512, cores, 64)]),
    ]
}

/// The machine's load averages over 1, 5 and 15 minutes (Linux), as text.
fn load_average() -> String {
    fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

/// Runs the sweeps and writes the results.
pub fn run(args: &ScalingArgs) -> Result<()> {
    fs::create_dir_all(&args.dir)
        .with_context(|| format!("{}: cannot create folder", args.dir.display()))?;
    let load_start = load_average();
    let sweeps = plan(args);
    // Each distinct job once, in order of its dataset (rendered once, kept for later runs).
    let mut jobs: BTreeMap<Job, Vec<&str>> = BTreeMap::new();
    for (name, list) in &sweeps {
        for j in list {
            jobs.entry(*j).or_default().push(name);
        }
    }
    let json_path = args.dir.join("scaling.json");
    let (runs, load_start, load_end) = if args.refit {
        recorded(&json_path)?
    } else {
        let runs = measure(args, &jobs)?;
        (runs, load_start, load_average())
    };
    let jobs: BTreeMap<Job, Vec<String>> = if args.refit {
        recorded_sweeps(&json_path)?
    } else {
        jobs.into_iter()
            .map(|(j, v)| (j, v.into_iter().map(String::from).collect()))
            .collect()
    };
    let points: Vec<Point> = runs.iter().map(|(j, f)| Point::of(j, f)).collect();
    let parts = parts();
    let coefs: Vec<Vec<f64>> = parts
        .iter()
        .map(|part| {
            let rows: Vec<Vec<f64>> = points
                .iter()
                .map(|x| part.terms.iter().map(|t| (t.value)(x)).collect())
                .collect();
            let y: Vec<f64> = runs.iter().map(|(_, f)| (part.measured)(f)).collect();
            fit(&rows, &y)
        })
        .collect();
    let pred = |k: usize, x: &Point| predict(&parts[k], &coefs[k], x);
    let wall_pred = |x: &Point| pred(0, x) + pred(1, x) + pred(2, x);
    let formula = format!(
        "wall ≈ {} (decode) + {} (estimate) + {} (other)",
        fmt_part(&parts[1], &coefs[1]),
        fmt_part(&parts[2], &coefs[2]),
        fmt_part(&parts[0], &coefs[0])
    );
    let memory_formula = format!("peak RSS ≈ {}", fmt_part(&parts[3], &coefs[3]));
    let err_of = |predicted: &dyn Fn(&Point) -> f64, measured: fn(&Figures) -> f64| {
        let p: Vec<f64> = points.iter().map(predicted).collect();
        let m: Vec<f64> = runs.iter().map(|(_, f)| measured(f)).collect();
        errors(&p, &m)
    };
    let wall_err = err_of(&wall_pred, |f| f.wall_s);
    let decode_err = err_of(&|x| pred(1, x), |f| f.decode_s);
    let est_err = err_of(&|x| pred(2, x), |f| f.estimate_s);
    let mem_err = err_of(&|x| pred(3, x), |f| f.peak_rss_bytes);

    // scaling.json
    let run_values: Vec<Value> = runs
        .iter()
        .zip(&points)
        .map(|((job, f), x)| {
            let terms: serde_json::Map<String, Value> = parts
                .iter()
                .flat_map(|part| {
                    part.terms
                        .iter()
                        .enumerate()
                        .map(move |(i, t)| (format!("{}.{i}", part.name), json!((t.value)(x))))
                })
                .collect();
            json!({
                "sweeps": jobs[job],
                "size": job.size,
                "lights": job.lights,
                "threads": job.threads,
                "decode_memory_mib": job.decode_memory_mib,
                "image_pixels": x.n,
                "cores_busy": x.t,
                "mask_pixels": f.mask_pixels,
                "estimated_pixels": f.estimated,
                "wall_s": f.wall_s,
                "decode_s": f.decode_s,
                "estimate_s": f.estimate_s,
                "other_s": (parts[0].measured)(f),
                "cpu_s": f.cpu_s,
                "pixels_per_s": f.pixels_per_s(),
                "peak_rss_bytes": f.peak_rss_bytes,
                "cache_bytes": f.cache_bytes,
                "batch_images": f.batch_images,
                "batch_bytes": x.b,
                "terms": terms,
                "predicted": {
                    "wall_s": wall_pred(x),
                    "other_s": pred(0, x),
                    "decode_s": pred(1, x),
                    "estimate_s": pred(2, x),
                    "peak_rss_bytes": pred(3, x),
                },
            })
        })
        .collect();
    let err_json = |(rms, max): (f64, f64)| json!({"rms_relative": rms, "max_relative": max});
    let model_parts: serde_json::Map<String, Value> = parts
        .iter()
        .zip(&coefs)
        .map(|(part, c)| {
            let terms: Vec<Value> = part
                .terms
                .iter()
                .zip(c)
                .map(|(t, c)| json!({"term": t.name, "coefficient": c}))
                .collect();
            (
                part.name.to_string(),
                json!({"terms": terms, "formula": fmt_part(part, c), "wrap": [part.wrap.0, part.wrap.1]}),
            )
        })
        .collect();
    let mask_fraction = runs.iter().map(|(_, f)| f.mask_pixels).sum::<f64>()
        / points.iter().map(|x| x.n).sum::<f64>();
    let document = json!({
        "cores": std::thread::available_parallelism().map_or(1, |c| c.get()),
        "load_average_start": load_start,
        "load_average_end": load_end,
        "runs": run_values,
        "model": {
            "formula": formula,
            "memory_formula": memory_formula,
            "parts": model_parts,
            "errors": {
                "wall": err_json(wall_err),
                "decode": err_json(decode_err),
                "estimate": err_json(est_err),
                "peak_rss": err_json(mem_err),
            },
        },
    });
    fs::write(&json_path, serde_json::to_string_pretty(&document)? + "\n")
        .with_context(|| format!("{}: cannot write", json_path.display()))?;

    // scaling.md
    let mib = |b: f64| format!("{:.0}", b / f64::from(1u32 << 20));
    let header: Vec<String> = [
        "sweeps",
        "size",
        "lights",
        "threads",
        "pixels in mask",
        "decode",
        "estimate",
        "wall",
        "CPU",
        "T (CPU / wall)",
        "pixels/s",
        "peak RSS MiB",
        "cache MiB",
        "model wall",
        "model error",
        "model RSS MiB",
    ]
    .map(String::from)
    .to_vec();
    let rows: Vec<Vec<String>> = runs
        .iter()
        .zip(&points)
        .map(|((job, f), x)| {
            let w = wall_pred(x);
            vec![
                jobs[job].join(", ")
                    + &if job.decode_memory_mib != args.decode_memory {
                        format!(" ({} MiB batch)", job.decode_memory_mib)
                    } else {
                        String::new()
                    },
                format!("{0}x{0}", job.size),
                job.lights.to_string(),
                job.threads.to_string(),
                format!("{:.0}", f.mask_pixels),
                format!("{:.2} s", f.decode_s),
                format!("{:.2} s", f.estimate_s),
                format!("{:.2} s", f.wall_s),
                format!("{:.2} s", f.cpu_s),
                format!("{:.2}", x.t),
                format!("{:.0}", f.pixels_per_s()),
                mib(f.peak_rss_bytes),
                mib(f.cache_bytes),
                format!("{w:.2} s"),
                format!("{:+.0}%", 100.0 * (w - f.wall_s) / f.wall_s),
                mib(pred(3, x)),
            ]
        })
        .collect();
    let mut md = String::new();
    writeln!(
        md,
        "# Scaling of `symframe estimate`\n\n{} cores, load average {load_start} (1, 5, 15 min) \
         at the start, {load_end} at the end. Every run cold (tile cache deleted first); \
         decoding batch {} MiB unless given. CPU: seconds of all threads (user + system); CPU / \
         wall below the thread count means the cores were shared.\n",
        document["cores"], args.decode_memory
    )?;
    md += &plot::md_table(&header, &rows);
    let pct = |(rms, max): (f64, f64)| format!("{:.0}% rms, {:.0}% max", 100.0 * rms, 100.0 * max);
    writeln!(
        md,
        "\n## Model\n\nN pixels in the image, P in the mask, L lights, T cores the job has (its \
         threads on an idle machine; fitted with each run's CPU / wall), B bytes of one decoding \
         batch (12·N·min(L, batch images)), C bytes of the cache (12·N·L):\n\n\
         ```text\n{formula}\n{memory_formula}\n```\n\n\
         Error on the measured points: wall {}; decoding {}; estimation {}; peak RSS {}.\n",
        pct(wall_err),
        pct(decode_err),
        pct(est_err),
        pct(mem_err)
    )?;
    let sizes = [256usize, 512, 1024, 2048];
    let lights = [96usize, 380, 1512, 3000];
    let mut ph: Vec<String> = vec!["size \\ lights".into()];
    ph.extend(lights.iter().map(|l| l.to_string()));
    let prows: Vec<Vec<String>> = sizes
        .iter()
        .map(|&s| {
            let mut r = vec![format!("{s}x{s}")];
            for &l in &lights {
                let n = (s * s) as f64;
                let at = |t: f64| Point {
                    n,
                    p: mask_fraction * n,
                    l: l as f64,
                    t,
                    b: (args.decode_memory as f64 * f64::from(1u32 << 20)).min(n * l as f64 * 12.0),
                };
                r.push(format!(
                    "{} / {} ({:.1} GiB)",
                    fmt_minutes(wall_pred(&at(1.0))),
                    fmt_minutes(wall_pred(&at(2.0))),
                    n * l as f64 * SAMPLE_BYTES / f64::from(1u32 << 30)
                ));
            }
            r
        })
        .collect();
    writeln!(
        md,
        "## Predicted wall time: 1 core / 2 cores (cache size)\n\nThe model at T = 1 and T = 2 \
         free cores and P = {:.3}·N (this sphere's mask); sizes and light counts beyond the \
         measured ones are extrapolations.\n",
        mask_fraction
    )?;
    md += &plot::md_table(&ph, &prows);
    let md_path = args.dir.join("scaling.md");
    fs::write(&md_path, md).with_context(|| format!("{}: cannot write", md_path.display()))?;

    // scaling.png
    plot_curves(&jobs, &runs, &points, &|x| pred(2, x), &wall_pred)?
        .save(&args.dir.join("scaling.png"))?;
    println!("{formula}\n{memory_formula}");
    println!(
        "model error: wall {}, decoding {}, estimation {}, peak RSS {}",
        pct(wall_err),
        pct(decode_err),
        pct(est_err),
        pct(mem_err)
    );
    println!("wrote {}, scaling.md and scaling.png", json_path.display());
    Ok(())
}

/// Runs every job cold on its own thread pool; returns their figures in the order of `jobs`.
fn measure(args: &ScalingArgs, jobs: &BTreeMap<Job, Vec<&str>>) -> Result<Vec<(Job, Figures)>> {
    let mut runs = Vec::new();
    for (i, job) in jobs.keys().enumerate() {
        let tag = format!("{}px-{}lights", job.size, job.lights);
        let lp = dataset(&args.dir.join(format!("data-{tag}")), job.size, job.lights)?;
        let cache = args.dir.join("cache");
        let config = symmetry_config(
            &lp,
            args.dir.join("out"),
            cache.clone(),
            true,
            job.decode_memory_mib,
            CacheFormatArg::F32,
        )?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(job.threads)
            .build()
            .context("cannot start the thread pool")?;
        let f = pool.install(|| run_estimate(&config))?;
        // Only the figures are kept: the cache and the maps are removed (disk).
        remove_dir(&cache)?;
        remove_dir(&config.output)?;
        println!(
            "scaling {}/{}: {size}x{size}, {} lights, {} threads, batch {} MiB: wall {:.1} s \
             (CPU {:.1} s), decode {:.1} s, estimate {:.1} s, {:.0} pixels/s, peak RSS {:.0} MiB",
            i + 1,
            jobs.len(),
            job.lights,
            job.threads,
            job.decode_memory_mib,
            f.wall_s,
            f.cpu_s,
            f.decode_s,
            f.estimate_s,
            f.pixels_per_s(),
            f.peak_rss_bytes / f64::from(1u32 << 20),
            size = job.size,
        );
        runs.push((*job, f));
    }
    Ok(runs)
}

/// The recorded document of `--refit`.
fn read_json(path: &Path) -> Result<Value> {
    let text = symframe_io::read_text_bounded(
        path,
        "a scaling JSON",
        symframe_io::limits::MAX_TEXT_FILE_BYTES,
    )?;
    serde_json::from_str(&text).with_context(|| format!("{}: not scaling JSON", path.display()))
}

/// The job of a recorded run.
fn recorded_job(r: &Value) -> Job {
    let u = |k: &str| r[k].as_u64().unwrap_or(0) as usize;
    Job {
        size: u("size"),
        lights: u("lights"),
        threads: u("threads"),
        decode_memory_mib: u("decode_memory_mib"),
    }
}

/// Recorded runs with the load averages at the start and at the end.
type Recorded = (Vec<(Job, Figures)>, String, String);

/// The runs and load averages recorded in a `scaling.json`, for `--refit`.
fn recorded(path: &Path) -> Result<Recorded> {
    let doc = read_json(path)?;
    let runs = doc["runs"]
        .as_array()
        .with_context(|| format!("{}: no runs", path.display()))?
        .iter()
        .map(|r| {
            let num = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
            let f = Figures {
                wall_s: num("wall_s"),
                decode_s: num("decode_s"),
                estimate_s: num("estimate_s"),
                mask_pixels: num("mask_pixels"),
                estimated: num("estimated_pixels"),
                peak_rss_bytes: num("peak_rss_bytes"),
                load_peak_rss_bytes: num("load_peak_rss_bytes"),
                cache_bytes: num("cache_bytes"),
                cache_hit: false,
                batch_images: num("batch_images"),
                cache_decode_s: f64::NAN,
                cache_scatter_s: f64::NAN,
                cpu_s: num("cpu_s"),
            };
            (recorded_job(r), f)
        })
        .collect();
    let text = |k: &str| doc[k].as_str().unwrap_or("unknown").to_string();
    Ok((runs, text("load_average_start"), text("load_average_end")))
}

/// The sweeps of each recorded run, for `--refit`.
fn recorded_sweeps(path: &Path) -> Result<BTreeMap<Job, Vec<String>>> {
    let doc = read_json(path)?;
    Ok(doc["runs"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or_default()
        .iter()
        .map(|r| {
            let sweeps = r["sweeps"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_str().map(String::from))
                        .collect()
                })
                .unwrap_or_default();
            (recorded_job(r), sweeps)
        })
        .collect())
}

/// Seconds as `12.3 s`, `4.5 min` or `2.1 h`.
fn fmt_minutes(s: f64) -> String {
    if s < 120.0 {
        format!("{s:.1} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}
