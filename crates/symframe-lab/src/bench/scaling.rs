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

use super::{dataset, remove_dir, run_estimate, symmetry_config, Figures};
use crate::cli::ScalingArgs;
use crate::experiment::plot;

/// The lobe fit reads at most this many lights per pixel (`EstimatorParams`' lobe subset).
const LOBE_LIGHTS: f64 = 512.0;
/// Bytes per pixel per light of the float32 tile cache and of a decoded RGB float image.
const SAMPLE_BYTES: f64 = 12.0;

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

/// What a model term is evaluated on: N image pixels, P mask pixels, L lights, T cores the job
/// had, B bytes of one decoding batch.
#[derive(Debug, Clone, Copy)]
struct Point {
    n: f64,
    p: f64,
    l: f64,
    t: f64,
    b: f64,
}

impl Point {
    /// The point of a measured run. T is the cores the run had, CPU seconds over wall seconds
    /// (at most its threads): the thread count on an idle machine, less on a shared one, where
    /// taking the thread count would charge the other jobs' load to the model.
    fn of(job: &Job, f: &Figures) -> Self {
        let n = (job.size * job.size) as f64;
        let threads = job.threads as f64;
        let busy = f.cpu_s / f.wall_s;
        Point {
            n,
            p: f.mask_pixels,
            l: job.lights as f64,
            t: if busy.is_finite() && busy > 0.0 {
                busy.min(threads)
            } else {
                threads
            },
            b: f.batch_images.min(job.lights as f64) * n * SAMPLE_BYTES,
        }
    }
}

/// One term of a part: its name in the formula and its value at a point.
struct Term {
    name: &'static str,
    value: fn(&Point) -> f64,
}

/// A part of the model, fitted to one measured figure.
struct Part {
    name: &'static str,
    /// The figure it predicts.
    measured: fn(&Figures) -> f64,
    /// Bytes (memory) rather than seconds.
    bytes: bool,
    /// Text around the sum in the formula (prefix, suffix).
    wrap: (&'static str, &'static str),
    terms: Vec<Term>,
}

/// The model's parts: three time stages (their sum is the wall time) and the peak memory.
/// Terms are in the order they are dropped when the data cannot tell them apart: last first.
fn parts() -> Vec<Part> {
    vec![
        Part {
            name: "other",
            measured: |f| (f.wall_s - f.decode_s - f.estimate_s).max(0.0),
            bytes: false,
            wrap: ("", ""),
            terms: vec![
                Term {
                    name: "",
                    value: |_| 1.0,
                },
                Term {
                    name: "N",
                    value: |x| x.n,
                },
                Term {
                    name: "L",
                    value: |x| x.l,
                },
            ],
        },
        Part {
            name: "decode",
            measured: |f| f.decode_s,
            bytes: false,
            wrap: ("", ""),
            terms: vec![
                Term {
                    name: "N·L/T",
                    value: |x| x.n * x.l / x.t,
                },
                Term {
                    name: "N·L",
                    value: |x| x.n * x.l,
                },
                Term {
                    name: "",
                    value: |_| 1.0,
                },
            ],
        },
        Part {
            name: "estimate",
            measured: |f| f.estimate_s,
            bytes: false,
            wrap: ("P·(", ")/T"),
            terms: vec![
                Term {
                    name: "",
                    value: |x| x.p / x.t,
                },
                Term {
                    name: "min(L, 512)",
                    value: |x| x.p * x.l.min(LOBE_LIGHTS) / x.t,
                },
                Term {
                    name: "L",
                    value: |x| x.p * x.l / x.t,
                },
            ],
        },
        Part {
            name: "peak_rss",
            measured: |f| f.peak_rss_bytes,
            bytes: true,
            wrap: ("", ""),
            terms: vec![
                Term {
                    name: "",
                    value: |_| 1.0,
                },
                Term {
                    name: "B",
                    value: |x| x.b,
                },
                Term {
                    name: "C",
                    value: |x| x.n * x.l * SAMPLE_BYTES,
                },
            ],
        },
    ]
}

/// Solves the square system `a x = b` (`a` with `b` as its last column) by Gaussian
/// elimination with partial pivoting; `None` when a pivot is below `1e-9` (the rows are
/// scaled so that the diagonal is 1: the terms are collinear on the data).
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    for c in 0..m {
        let p = (c..m).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-9 {
            return None;
        }
        a.swap(c, p);
        let (top, rest) = a.split_at_mut(c + 1);
        let pivot = &top[c];
        for row in rest {
            let f = row[c] / pivot[c];
            for (v, p) in row[c..].iter_mut().zip(&pivot[c..]) {
                *v -= f * p;
            }
        }
    }
    let mut x = vec![0.0; m];
    for c in (0..m).rev() {
        let s: f64 = (c + 1..m).map(|k| a[c][k] * x[k]).sum();
        x[c] = (a[c][m] - s) / a[c][c];
    }
    Some(x)
}

/// Least squares of `y ~ rows · coef` on relative residuals (`(pred - y) / y`: points from
/// a tenth of a second to minutes count alike) with non-negative coefficients: a term whose
/// coefficient comes out negative, or that the points cannot tell from the others, is
/// dropped (coefficient 0) and the rest refitted.
pub(crate) fn fit(rows: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let k = rows.first().map_or(0, |r| r.len());
    let mut active: Vec<bool> = (0..k).map(|j| rows.iter().any(|r| r[j] != 0.0)).collect();
    // Relative weights, floored at a thousandth of the largest (a stage that took no time).
    let top = y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let w: Vec<f64> = y
        .iter()
        .map(|v| 1.0 / v.abs().max(1e-3 * top).max(1e-300))
        .collect();
    loop {
        let idx: Vec<usize> = (0..k).filter(|&j| active[j]).collect();
        if idx.is_empty() {
            return vec![0.0; k];
        }
        let scale: Vec<f64> = idx
            .iter()
            .map(|&j| {
                let s: f64 = rows.iter().zip(&w).map(|(r, w)| (r[j] * w).powi(2)).sum();
                s.sqrt().max(1e-300)
            })
            .collect();
        let m = idx.len();
        let mut a = vec![vec![0.0; m + 1]; m];
        for (r, (&yy, &ww)) in rows.iter().zip(y.iter().zip(&w)) {
            let x: Vec<f64> = idx
                .iter()
                .zip(&scale)
                .map(|(&j, s)| r[j] * ww / s)
                .collect();
            for i in 0..m {
                for j in 0..m {
                    a[i][j] += x[i] * x[j];
                }
                a[i][m] += x[i] * yy * ww;
            }
        }
        let Some(x) = solve(a) else {
            active[idx[m - 1]] = false;
            continue;
        };
        let coef: Vec<f64> = x.iter().zip(&scale).map(|(x, s)| x / s).collect();
        let worst = (0..m)
            .filter(|&i| coef[i] < 0.0)
            .min_by(|&i, &j| coef[i].total_cmp(&coef[j]));
        if let Some(i) = worst {
            active[idx[i]] = false;
            continue;
        }
        let mut out = vec![0.0; k];
        for (i, &j) in idx.iter().enumerate() {
            out[j] = coef[i];
        }
        return out;
    }
}

/// A duration with three significant digits in s, ms, us or ns.
fn fmt_s(v: f64) -> String {
    let (v, unit) = if v >= 1.0 {
        (v, "s")
    } else if v >= 1e-3 {
        (v * 1e3, "ms")
    } else if v >= 1e-6 {
        (v * 1e6, "us")
    } else {
        (v * 1e9, "ns")
    };
    format!("{} {unit}", sig3(v))
}

/// A number with three significant digits.
fn sig3(v: f64) -> String {
    // Digits after the point: 2 - the exponent, at most 9 (0.00604 has 5).
    let d = if v > 0.0 {
        (2 - v.abs().log10().floor() as i32).clamp(0, 9) as usize
    } else {
        2
    };
    format!("{v:.d$}")
}

/// One fitted term of the formula, its coefficient formatted.
fn fmt_term(part: &Part, t: &Term, c: f64) -> String {
    let coef = if !part.bytes {
        fmt_s(c)
    } else if t.name.is_empty() {
        format!("{:.0} MiB", c / f64::from(1u32 << 20))
    } else {
        sig3(c)
    };
    if t.name.is_empty() {
        coef
    } else {
        format!("{coef}·{}", t.name)
    }
}

/// A part of the formula: its non-zero terms summed, wrapped.
fn fmt_part(part: &Part, coef: &[f64]) -> String {
    // The constant first, then the terms in their order.
    let mut fitted: Vec<(&Term, f64)> = part
        .terms
        .iter()
        .zip(coef.iter().copied())
        .filter(|&(_, c)| c > 0.0)
        .collect();
    fitted.sort_by_key(|(t, _)| !t.name.is_empty());
    let terms: Vec<String> = fitted
        .into_iter()
        .map(|(t, c)| fmt_term(part, t, c))
        .collect();
    if terms.is_empty() {
        return "0".into();
    }
    format!("{}{}{}", part.wrap.0, terms.join(" + "), part.wrap.1)
}

/// The model's prediction of a part at a point.
fn predict(part: &Part, coef: &[f64], x: &Point) -> f64 {
    part.terms
        .iter()
        .zip(coef)
        .map(|(t, c)| c * (t.value)(x))
        .sum()
}

/// The machine's load averages over 1, 5 and 15 minutes (Linux), as text.
fn load_average() -> String {
    fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

/// Root-mean-square and largest absolute relative error of `pred` against `meas`.
fn errors(pred: &[f64], meas: &[f64]) -> (f64, f64) {
    let rel: Vec<f64> = pred
        .iter()
        .zip(meas)
        .map(|(p, m)| ((p - m) / m).abs())
        .collect();
    let rms = (rel.iter().map(|e| e * e).sum::<f64>() / rel.len().max(1) as f64).sqrt();
    (rms, rel.iter().fold(0.0, |a: f64, &b| a.max(b)))
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

/// The three panels: estimation time per pixel against lights, time against image size,
/// speed-up against threads; measured points with the model's.
fn plot_curves(
    sweeps: &BTreeMap<Job, Vec<String>>,
    runs: &[(Job, Figures)],
    points: &[Point],
    estimate: &dyn Fn(&Point) -> f64,
    wall: &dyn Fn(&Point) -> f64,
) -> Result<plot::Picture> {
    // A sweep's runs, in the order of their jobs (size, lights, threads).
    let sweep = |name: &str| -> Vec<usize> {
        (0..runs.len())
            .filter(|&i| {
                sweeps
                    .get(&runs[i].0)
                    .is_some_and(|v| v.iter().any(|s| s == name))
            })
            .collect()
    };
    // Lights: CPU milliseconds per mask pixel (estimation time x cores the run had / pixels).
    let li = sweep("lights");
    let per_px = |i: usize, s: f64| s * points[i].t / runs[i].1.mask_pixels * 1e3;
    let lights_pic = plot::line_plot(
        "Estimation: CPU ms per pixel of the mask",
        "lights",
        "ms per pixel x T (CPU / wall)",
        &li.iter()
            .map(|&i| runs[i].0.lights.to_string())
            .collect::<Vec<_>>(),
        &[
            (
                "measured".into(),
                li.iter()
                    .map(|&i| Some(per_px(i, runs[i].1.estimate_s)))
                    .collect(),
            ),
            (
                "model".into(),
                li.iter()
                    .map(|&i| Some(per_px(i, estimate(&points[i]))))
                    .collect(),
            ),
        ],
        false,
    )?;
    let si = sweep("size");
    let col = |f: &dyn Fn(usize) -> f64| si.iter().map(|&i| Some(f(i))).collect::<Vec<_>>();
    let size_pic = plot::line_plot(
        "Time against image size",
        "image (pixels in the mask)",
        "seconds",
        &si.iter()
            .map(|&i| {
                let p = runs[i].1.mask_pixels;
                let p = if p >= 1e4 {
                    format!("{:.0}k", p / 1e3)
                } else {
                    format!("{p:.0}")
                };
                format!("{0}x{0} ({p})", runs[i].0.size)
            })
            .collect::<Vec<_>>(),
        &[
            ("wall".into(), col(&|i| runs[i].1.wall_s)),
            ("estimation".into(), col(&|i| runs[i].1.estimate_s)),
            ("decoding".into(), col(&|i| runs[i].1.decode_s)),
            ("model wall".into(), col(&|i| wall(&points[i]))),
        ],
        true,
    )?;
    let ti = sweep("threads");
    let base = ti.first().copied();
    let speed = |f: &dyn Fn(usize) -> f64| {
        ti.iter()
            .map(|&i| base.map(|b| f(b) / f(i)))
            .collect::<Vec<_>>()
    };
    let threads_pic = plot::line_plot(
        "Speed-up against threads",
        "threads",
        "speed-up over 1 thread",
        &ti.iter()
            .map(|&i| runs[i].0.threads.to_string())
            .collect::<Vec<_>>(),
        &[
            ("estimation".into(), speed(&|i| runs[i].1.estimate_s)),
            ("decoding".into(), speed(&|i| runs[i].1.decode_s)),
            ("wall".into(), speed(&|i| runs[i].1.wall_s)),
            (
                "T: cores had (CPU / wall)".into(),
                ti.iter().map(|&i| Some(points[i].t)).collect(),
            ),
            (
                "ideal".into(),
                ti.iter().map(|&i| Some(runs[i].0.threads as f64)).collect(),
            ),
        ],
        false,
    )?;
    let label = |j: Option<usize>, what: &str| {
        j.map_or(String::new(), |i| {
            let job = &runs[i].0;
            match what {
                "lights" => format!("{0}x{0}", job.size),
                "size" => format!("{} lights", job.lights),
                _ => format!("{0}x{0}, {1} lights", job.size, job.lights),
            }
        })
    };
    let pics = [lights_pic, size_pic, threads_pic];
    let (w, h) = (pics[0].width, pics[0].height);
    plot::grid(
        "symframe estimate: scaling (every run cold)",
        &[String::new()],
        &[
            label(li.first().copied(), "lights"),
            label(si.first().copied(), "size"),
            label(base, "threads"),
        ],
        &pics.into_iter().map(|p| p.rgb).collect::<Vec<_>>(),
        w,
        h,
        1,
        "regenerate: symframe-lab bench scaling --dir DIR",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_recovers_coefficients_and_drops_collinear_terms() {
        // y = 2 + 3 x exactly; the third column duplicates the second.
        let xs = [1.0, 2.0, 5.0, 10.0, 20.0];
        let rows: Vec<Vec<f64>> = xs.iter().map(|&x| vec![1.0, x, x]).collect();
        let y: Vec<f64> = xs.iter().map(|&x| 2.0 + 3.0 * x).collect();
        let c = fit(&rows, &y);
        assert!(
            (c[0] - 2.0).abs() < 1e-9 && (c[1] - 3.0).abs() < 1e-9,
            "{c:?}"
        );
        assert_eq!(c[2], 0.0, "{c:?}");
    }

    #[test]
    fn fit_drops_negative_terms() {
        let xs = [1.0, 2.0, 5.0, 10.0, 20.0];
        let rows: Vec<Vec<f64>> = xs.iter().map(|&x| vec![1.0, x, x * x]).collect();
        let y: Vec<f64> = xs.iter().map(|&x| 2.0 + 3.0 * x - 0.01 * x * x).collect();
        let c = fit(&rows, &y);
        assert_eq!(c[2], 0.0, "{c:?}");
        assert!(c[0] > 0.0 && c[1] > 0.0, "{c:?}");
    }

    #[test]
    fn formula_names_only_fitted_terms() {
        let p = &parts()[2];
        assert_eq!(fmt_part(p, &[1e-4, 0.0, 2e-8]), "P·(100 us + 20.0 ns·L)/T");
        let decode = &parts()[1];
        assert_eq!(
            fmt_part(decode, &[2e-8, 0.0, 0.5]),
            "500 ms + 20.0 ns·N·L/T"
        );
        assert_eq!(fmt_part(p, &[0.0; 3]), "0");
        assert_eq!(sig3(0.006041), "0.00604");
        assert_eq!(sig3(1.068), "1.07");
        assert_eq!(sig3(487.2), "487");
    }
}
