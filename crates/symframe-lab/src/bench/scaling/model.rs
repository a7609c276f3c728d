//! The cost model: its parts (one a stage, and the peak memory) and their terms, the
//! non-negative least-squares fit on relative residuals, its predictions and errors, and the
//! formula as text.

use super::{Figures, Job};

/// The lobe fit reads at most this many lights per pixel (`EstimatorParams`' lobe subset).
const LOBE_LIGHTS: f64 = 512.0;
/// Bytes per pixel per light of the float32 tile cache and of a decoded RGB float image.
pub(super) const SAMPLE_BYTES: f64 = 12.0;

/// What a model term is evaluated on: N image pixels, P mask pixels, L lights, T cores the job
/// had, B bytes of one decoding batch.
#[derive(Debug, Clone, Copy)]
pub(super) struct Point {
    pub(super) n: f64,
    pub(super) p: f64,
    pub(super) l: f64,
    pub(super) t: f64,
    pub(super) b: f64,
}

impl Point {
    /// The point of a measured run. T is the cores the run had, CPU seconds over wall seconds
    /// (at most its threads): the thread count on an idle machine, less on a shared one, where
    /// taking the thread count would charge the other jobs' load to the model.
    pub(super) fn of(job: &Job, f: &Figures) -> Self {
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
pub(super) struct Term {
    pub(super) name: &'static str,
    pub(super) value: fn(&Point) -> f64,
}

/// A part of the model, fitted to one measured figure.
pub(super) struct Part {
    pub(super) name: &'static str,
    /// The figure it predicts.
    pub(super) measured: fn(&Figures) -> f64,
    /// Bytes (memory) rather than seconds.
    pub(super) bytes: bool,
    /// Text around the sum in the formula (prefix, suffix).
    pub(super) wrap: (&'static str, &'static str),
    pub(super) terms: Vec<Term>,
}

/// The model's parts: three time stages (their sum is the wall time) and the peak memory.
/// Terms are in the order they are dropped when the data cannot tell them apart: last first.
pub(super) fn parts() -> Vec<Part> {
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
pub(super) fn fit(rows: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
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
pub(super) fn fmt_part(part: &Part, coef: &[f64]) -> String {
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
pub(super) fn predict(part: &Part, coef: &[f64], x: &Point) -> f64 {
    part.terms
        .iter()
        .zip(coef)
        .map(|(t, c)| c * (t.value)(x))
        .sum()
}

/// Root-mean-square and largest absolute relative error of `pred` against `meas`.
pub(super) fn errors(pred: &[f64], meas: &[f64]) -> (f64, f64) {
    let rel: Vec<f64> = pred
        .iter()
        .zip(meas)
        .map(|(p, m)| ((p - m) / m).abs())
        .collect();
    let rms = (rel.iter().map(|e| e * e).sum::<f64>() / rel.len().max(1) as f64).sqrt();
    (rms, rel.iter().fold(0.0, |a: f64, &b| a.max(b)))
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
