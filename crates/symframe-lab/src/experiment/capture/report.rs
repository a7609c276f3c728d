//! The capture experiment's section of docs/validation.md: the sweep's tables (each
//! method's figures per set, the calibrated confidence), its plots and the reading of them.

use super::*;
use crate::experiment::plot::{self, md_table};
use crate::experiment::{Ctx, Section};

fn deg(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "–".into()
    }
}

fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{:.0}%", 100.0 * v)
    } else {
        "–".into()
    }
}

/// The estimator's cell as `normal (tangent share, tangent error)`.
fn ours(c: &Cell, anisotropic: bool) -> String {
    if anisotropic {
        format!(
            "{} (t {} at {} [{}])",
            deg(c.normal_mean),
            pct(c.tangent_share),
            deg(c.tangent_mean),
            deg(c.tangent_swap_free)
        )
    } else {
        format!("{} (t {})", deg(c.normal_mean), pct(c.tangent_share))
    }
}

/// The estimator's sources as `lobe 90% · symmetry 8% · …` (those above 0.5%).
fn sources(c: &Cell) -> String {
    let names = ["none", "symmetry", "lambertian", "highlight", "lobe"];
    let mut v: Vec<(f64, &str)> = c.sources.iter().copied().zip(names).collect();
    v.sort_by(|a, b| b.0.total_cmp(&a.0));
    v.iter()
        .filter(|(s, _)| *s >= 0.005)
        .map(|(s, n)| format!("{n} {:.0}%", 100.0 * s))
        .collect::<Vec<_>>()
        .join(" · ")
}

fn name_of(r: &Row) -> String {
    if r.held_out {
        format!("{} (held out)", r.material)
    } else {
        r.material.to_string()
    }
}

/// The reading of the tables, from the numbers: where a baseline beats the estimator, and
/// where an anisotropic material keeps a tangent on fewer than 90% of its pixels.
fn reading(rows: &[Row]) -> String {
    let mut losses = Vec::new();
    let mut few_tangents = Vec::new();
    let mut cells = 0;
    for r in rows {
        let ours = &r.cells[0];
        cells += 1;
        for (m, c) in METHODS.iter().zip(&r.cells).skip(1) {
            if c.normal_mean < ours.normal_mean || !ours.normal_mean.is_finite() {
                losses.push(format!(
                    "{} / {} / {}: {m} {} vs {}",
                    name_of(r),
                    r.condition.label(),
                    r.rig,
                    deg(c.normal_mean),
                    deg(ours.normal_mean)
                ));
            }
        }
        if r.anisotropic && r.rig != "narrow" && ours.tangent_share < 0.9 {
            few_tangents.push(format!(
                "{} / {} / {}: {}",
                name_of(r),
                r.condition.label(),
                r.rig,
                pct(ours.tangent_share)
            ));
        }
    }
    let list = |v: &[String]| {
        if v.is_empty() {
            "none.\n\n".to_string()
        } else {
            format!(
                "\n\n{}\n\n",
                v.iter()
                    .map(|l| format!("- {l}"))
                    .collect::<Vec<_>>()
                    .join("\n")
            )
        }
    };
    format!(
        "### Reading\n\nOf {cells} sets, those where a baseline's mean normal error is below the \
         estimator's: {}Anisotropic materials under the dense and sparse rigs with a tangent on \
         fewer than 90% of the estimated pixels: {}",
        list(&losses),
        list(&few_tangents)
    )
}

/// Runs the experiment; returns the markdown section.
pub fn run(ctx: &Ctx) -> Result<Section<Vec<Row>>> {
    let size = if ctx.quick { 20 } else { 48 };
    let rows = compute(ctx.quick, size)?;
    let mut md = String::from(
        "## Real-capture conditions: quantisation, JPEG, clipping, noise, light error\n\n",
    );
    md += &format!(
        "Set-up: a {size} x {size} sphere (circular tangents) of each material, rendered by \
         symframe's renderer and degraded as a camera and a calibration degrade it: the \
         exposure set so that the given share of the object's samples reach the white level \
         and clip there, shot noise of the given full well (electrons at the white level), \
         quantisation (8-bit in the sRGB-encoded domain as a PNG or JPEG stores it, 12 and 16 \
         bits linear), for JPEG captures the 8-bit image encoded at the given quality by the \
         `image` crate's encoder (4:4:4, no chroma subsampling) and decoded by symframe's \
         reader, the reader's saturation rule (a pixel with a raw value at 99.5% of the \
         maximum is unknown under that light; a float capture's clip level is found from the \
         plateau of its samples at one value, docs/method.md \"Noise model\"), and light \
         directions given to every method \
         each off by the stated angle in a random direction. The estimator's noise model (shot \
         and read noise; a float capture's clip level) is estimated as `estimate` estimates \
         it, from four of the capture's images, rendered for that at {noise} x {noise} pixels \
         with the same degradation: on the {size}-pixel sphere itself the estimate reads the \
         shading's curvature per pixel as noise, where a real capture's object spans hundreds \
         of pixels. The reference capture is {}, \
         stored losslessly (as a PNG). Rigs: dense = {} lights uniform over the 65-degree cone (a 130-degree cap), sparse = \
         200, narrow = the DiLiGenT-like 96-light grid within 45 degrees. The estimator runs \
         with its defaults. Cells: mean normal error in degrees over pixels within 60 degrees \
         of the view; for the estimator also the share of estimated pixels with a tangent (t), \
         the tangents' mean axis error and in brackets the same where tangent and binormal may \
         swap (the frame's error, without the rule that picks which axis is the tangent). Materials marked held out were not looked at while \
         the estimator's rules were chosen.\n\n",
        REFERENCE.label(),
        if ctx.quick { 300 } else { 1000 },
        noise = NOISE_SCALE * size,
    );
    let header = |first: &str| -> Vec<String> {
        let mut h = vec!["material".to_string(), first.to_string()];
        h.extend(METHODS.iter().map(|m| m.to_string()));
        h
    };
    let line = |r: &Row, second: String| -> Vec<String> {
        let mut v = vec![name_of(r), second];
        v.push(ours(&r.cells[0], r.anisotropic));
        v.extend(r.cells[1..].iter().map(|c| deg(c.normal_mean)));
        v
    };
    let reference: Vec<Vec<String>> = rows
        .iter()
        .filter(|r| r.sweep == "reference")
        .map(|r| {
            let mut v = line(r, r.rig.to_string());
            v.push(sources(&r.cells[0]));
            v
        })
        .collect();
    let mut h = header("rig");
    h.push("estimator's sources".into());
    let t = md_table(&h, &reference);
    println!("Reference capture ({}):\n{t}", REFERENCE.label());
    md += &format!(
        "### The reference capture\n\n{}\n\n{t}\n",
        REFERENCE.label()
    );
    let clean: Vec<Vec<String>> = rows
        .iter()
        .filter(|r| r.sweep == "clean")
        .map(|r| {
            let mut v = line(r, r.rig.to_string());
            v.push(sources(&r.cells[0]));
            v
        })
        .collect();
    let t = md_table(&h, &clean);
    println!("Clean float renders:\n{t}");
    md += &format!("### Clean float renders (the same materials)\n\n{t}\n");
    for (sweep, title) in [
        ("bits", "Bit depth"),
        ("noise", "Shot noise"),
        ("clipped", "Clipped share"),
        ("lights", "Light-direction error"),
        ("jpeg", "JPEG quality"),
    ] {
        let mut set: Vec<&Row> = rows
            .iter()
            .filter(|r| r.sweep == sweep || (r.sweep == "reference" && r.rig == "dense"))
            .collect();
        if !set.iter().any(|r| r.sweep == sweep) {
            continue;
        }
        set.sort_by(|a, b| a.material.cmp(b.material));
        let table: Vec<Vec<String>> = set.iter().map(|r| line(r, r.condition.label())).collect();
        let t = md_table(&header("condition (dense rig)"), &table);
        println!("{title}:\n{t}");
        md += &format!("### {title}\n\n{t}\n");
        // One plot per sweep: the estimator's normal error per material over the axis.
        let mut labels: Vec<String> = Vec::new();
        let mut conds: Vec<Condition> = Vec::new();
        for r in &set {
            if !conds.contains(&r.condition) {
                conds.push(r.condition);
                labels.push(match sweep {
                    "bits" => match (r.condition.bits, r.condition.srgb) {
                        (None, _) => "float".into(),
                        (Some(b), s) => format!("{b}{}", if s { " sRGB" } else { "" }),
                    },
                    "noise" => r
                        .condition
                        .full_well
                        .map_or("none".into(), |e| format!("{e:.0} e-")),
                    "clipped" => format!("{:.1}%", 100.0 * r.condition.clipped),
                    "jpeg" => r
                        .condition
                        .jpeg_quality
                        .map_or("lossless".into(), |q| format!("q{q}")),
                    _ => format!("{}°", r.condition.light_error_deg),
                });
            }
        }
        let mut names: Vec<&'static str> = set.iter().map(|r| r.material).collect();
        names.dedup();
        let series: Vec<(String, Vec<Option<f64>>)> = names
            .iter()
            .map(|&m| {
                let v = conds
                    .iter()
                    .map(|c| {
                        set.iter()
                            .find(|r| r.material == m && r.condition == *c)
                            .map(|r| r.cells[0].normal_mean)
                            .filter(|v| v.is_finite())
                    })
                    .collect();
                (m.to_string(), v)
            })
            .collect();
        let pic = plot::line_plot(
            &format!("{title}: the estimator's normal error"),
            title,
            "mean normal error (°, log)",
            &labels,
            &series,
            true,
        )?;
        md += &ctx.save(&pic, &format!("capture_{sweep}.png"), title)?;
        md += "\n";
    }
    md += &reading(&rows);
    // Calibrated confidence: per set, the share of confident pixels within 1 degree.
    let mut conf_rows = Vec::new();
    let (mut all_confident, mut all_within) = (0usize, 0.0f64);
    let (mut all_t, mut all_t_within) = (0usize, 0.0f64);
    // Sets with confident pixels, and those where 95% of them are within 1 degree.
    let (mut sets, mut sets_calibrated) = (0usize, 0usize);
    for r in &rows {
        let c = &r.cells[0];
        if c.confident > 0 {
            sets += 1;
            sets_calibrated += usize::from(c.confident_within_1 >= 0.95);
        }
        all_confident += c.confident;
        all_within += c.confident_within_1 * c.confident as f64;
        all_t += c.tangent_confident;
        all_t_within += c.tangent_confident_within * c.tangent_confident as f64;
        conf_rows.push(vec![
            name_of(r),
            r.condition.label(),
            r.rig.to_string(),
            c.confident.to_string(),
            pct(if c.confident > 0 {
                c.confident_within_1
            } else {
                f64::NAN
            }),
            if r.anisotropic {
                c.tangent_confident.to_string()
            } else {
                "–".into()
            },
            pct(if c.tangent_confident > 0 {
                c.tangent_confident_within
            } else {
                f64::NAN
            }),
        ]);
    }
    let t = md_table(
        &[
            "material",
            "condition",
            "rig",
            "pixels with confidence ≥ 0.9",
            "of those within 1°",
            "tangents with tangent confidence ≥ 0.9",
            "of those within 2.5° (axes)",
        ]
        .map(String::from),
        &conf_rows,
    );
    md += &format!(
        "### Does confidence mean something?\n\nOver every set above: {} pixels with \
         confidence ≥ 0.9, {:.1}% of them within 1° of the truth ({sets_calibrated} of the \
         {sets} sets with such pixels at 95% or more); {} tangents (anisotropic materials) with \
         tangent confidence ≥ 0.9 (`tangent_confidence.npy`), {} of them with their axes \
         within {TANGENT_WITHIN_DEG}° of the truth's.\n\n{t}\n",
        all_confident,
        100.0 * all_within / all_confident.max(1) as f64,
        all_t,
        pct(all_t_within / all_t.max(1) as f64)
    );
    println!(
        "confidence >= 0.9: {all_confident} pixels, {} within 1 degree; tangent confidence >= \
         0.9: {all_t} tangents, {} within {TANGENT_WITHIN_DEG} degrees",
        pct(all_within / all_confident.max(1) as f64),
        pct(all_t_within / all_t.max(1) as f64)
    );
    Ok(Section {
        markdown: md,
        figures: rows,
    })
}
