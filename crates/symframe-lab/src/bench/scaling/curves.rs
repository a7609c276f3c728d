//! `scaling.png`: the measured curves with the model's.

use std::collections::BTreeMap;

use anyhow::Result;

use super::model::Point;
use super::{Figures, Job};
use crate::experiment::plot;

/// The three panels: estimation time per pixel against lights, time against image size,
/// speed-up against threads; measured points with the model's.
pub(super) fn plot_curves(
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
