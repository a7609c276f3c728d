//! The pictures an estimate writes beside its maps, for people rather than programs: the rig
//! seen from above (`lights.png`), a legend for each coloured map (`*_legend.png`), and one
//! page showing every picture with its legend and the run's summary (`index.html`).
//!
//! The maps' own pictures (`normals.png`, `tangents.png`, `confidence.png`, `source.png`,
//! `residual.png`) stay pixel-aligned data, one pixel per image pixel and nothing drawn on
//! them: they are read as maps (the viewer's views, a renderer's tangent map). Their legends
//! are separate pictures, shown beside them by `index.html`.

use anyhow::Result;
use glam::DVec3;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde_json::Value;
use symframe::PixelSource;

use crate::colorbar::{draw_bar, draw_err, font_ready, text, Bar, Picture, Scale};
use crate::outdir::OutputSet;

/// Top of `residual.png`'s colour scale: residuals at or above it get the top colour. A
/// slice whose mirror image about the normal misses a quarter of its signal is far from
/// symmetric (a well-explained pixel's residual is a few hundredths).
pub const RESIDUAL_MAX: f32 = 0.25;

/// Colours a residual map: viridis from 0 to [`RESIDUAL_MAX`], black where not measured.
pub fn residual_rgb8(values: &[f32]) -> Vec<u8> {
    symframe_io::gray_map_rgb8(values, 0.0, RESIDUAL_MAX)
}

/// Where a scalar legend's colour bar lies: its gradient fills columns `left..left + width`
/// and rows `top..=bottom`, the map's colour at 0 on row `bottom` and at the scale's top on
/// row `top` (see [`crate::colorbar::Bar`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BarRect {
    /// Left column.
    pub left: usize,
    /// Top row (the scale's top).
    pub top: usize,
    /// Bottom row (0).
    pub bottom: usize,
    /// Width.
    pub width: usize,
}

/// The colour bar of `confidence_legend.png` and `residual_legend.png`.
pub const LEGEND_BAR: BarRect = BarRect {
    left: 24,
    top: 64,
    bottom: 263,
    width: 28,
};

/// The colour wheel of `tangents_legend.png`: centre `(x, y)` and radius in pixels. The pixel
/// at `(x + r cos a, y - r sin a)` has the colour `tangents.png` gives a tangent at angle `a`
/// from the image's x axis.
pub const TANGENT_WHEEL: (usize, usize, usize) = (120, 160, 90);

/// Colour of the used lights in `lights.png`.
pub const LIGHT_USED: [u8; 3] = [31, 119, 180];
/// Colour of the dropped lights in `lights.png`.
pub const LIGHT_DROPPED: [u8; 3] = [214, 39, 40];
/// Colour of the cone's edge in `lights.png`.
const CONE: [u8; 3] = [44, 160, 44];
/// Centre of `lights.png`'s disc (the view direction) and the horizon's radius, pixels.
pub const LIGHTS_DISC: (i32, i32, i32) = (240, 250, 200);

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

/// Where `lights.png` draws a light of direction `l` (camera frame: x right, y up, z toward
/// the camera): its orthographic projection onto the image plane, the horizon the disc's edge.
pub fn light_position(l: DVec3) -> (i32, i32) {
    let l = l.try_normalize().unwrap_or(DVec3::Z);
    let (cx, cy, r) = LIGHTS_DISC;
    (
        cx + (l.x * r as f64).round() as i32,
        cy - (l.y * r as f64).round() as i32,
    )
}

/// The rig as `lights.png` shows it.
pub struct LightsPlot<'a> {
    /// Every input light, camera frame.
    pub lights: &'a [DVec3],
    /// Whether each light is used.
    pub used: &'a [bool],
    /// The symmetry method's cone (`theta_d` half-angle in halfway space, degrees); `None` for
    /// a baseline, which uses every light.
    pub theta_d_max_deg: Option<f64>,
}

/// Draws the rig from above: the light directions projected orthographically onto the image
/// plane (the unit circle is the horizon, grey rings 30 and 60 degrees from the view), used
/// and dropped lights in their colours (filled above the horizon, rings below it), the cone's
/// edge dashed, and a legend.
pub fn lights_picture(plot: &LightsPlot) -> Result<Picture> {
    font_ready()?;
    let (w, h) = (760usize, 500usize);
    let mut pic = Picture::white(w, h);
    let n_used = plot.used.iter().filter(|&&u| u).count();
    let n_dropped = plot.lights.len() - n_used;
    {
        let root =
            BitMapBackend::with_buffer(&mut pic.rgb, (w as u32, h as u32)).into_drawing_area();
        let (cx, cy, r) = LIGHTS_DISC;
        root.draw_text(
            "lights.png: the rig seen from above (x right, y up)",
            &text(16),
            (12, 8),
        )
        .map_err(draw_err)?;
        let grey = RGBColor(170, 170, 170);
        for deg in [30.0f64, 60.0] {
            let rr = (deg.to_radians().sin() * r as f64).round() as i32;
            root.draw(&Circle::new((cx, cy), rr, grey.stroke_width(1)))
                .map_err(draw_err)?;
            root.draw(&Text::new(
                format!("{deg:.0}°"),
                (cx + 3, cy - rr - 2),
                text(11)
                    .color(&grey)
                    .pos(Pos::new(HPos::Left, VPos::Bottom)),
            ))
            .map_err(draw_err)?;
        }
        root.draw(&Circle::new((cx, cy), r, BLACK.stroke_width(1)))
            .map_err(draw_err)?;
        root.draw(&Text::new(
            "90° (horizon)",
            (cx + 3, cy - r - 2),
            text(11).pos(Pos::new(HPos::Left, VPos::Bottom)),
        ))
        .map_err(draw_err)?;
        // The view direction.
        root.draw(&PathElement::new(vec![(cx - 6, cy), (cx + 6, cy)], BLACK))
            .map_err(draw_err)?;
        root.draw(&PathElement::new(vec![(cx, cy - 6), (cx, cy + 6)], BLACK))
            .map_err(draw_err)?;
        root.draw(&Text::new(
            "+x",
            (cx + r + 6, cy),
            text(12).pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(draw_err)?;
        // The cone: lights within 2 theta_d_max of the view (theta_d is half the angle between
        // light and view).
        let cone_deg = plot.theta_d_max_deg.map(|t| (2.0 * t).min(180.0));
        if let Some(c) = cone_deg.filter(|&c| c < 180.0) {
            let rr = (c.to_radians().sin() * r as f64).round() as i32;
            let n = 120;
            for k in (0..n).step_by(2) {
                let a0 = std::f64::consts::TAU * k as f64 / n as f64;
                let a1 = std::f64::consts::TAU * (k + 1) as f64 / n as f64;
                let p = |a: f64| {
                    (
                        cx + (rr as f64 * a.cos()).round() as i32,
                        cy - (rr as f64 * a.sin()).round() as i32,
                    )
                };
                root.draw(&PathElement::new(
                    vec![p(a0), p(a1)],
                    rgb(CONE).stroke_width(2),
                ))
                .map_err(draw_err)?;
            }
        }
        let size = match plot.lights.len() {
            0..=300 => 4,
            301..=2000 => 3,
            _ => 2,
        };
        // Used lights first, the dropped ones (usually few) over them.
        for want in [true, false] {
            let colour = rgb(if want { LIGHT_USED } else { LIGHT_DROPPED });
            for (l, _) in plot
                .lights
                .iter()
                .zip(plot.used)
                .filter(|(_, &u)| u == want)
            {
                let Some(l) = l.try_normalize() else {
                    continue;
                };
                let at = light_position(l);
                if l.z >= 0.0 {
                    root.draw(&Circle::new(at, size, colour.filled()))
                        .map_err(draw_err)?;
                } else {
                    root.draw(&Circle::new(at, size, colour.stroke_width(1)))
                        .map_err(draw_err)?;
                    root.draw_pixel(at, &colour).map_err(draw_err)?;
                }
            }
        }
        // The legend: a marker (a light's colour, or the cone's dash) and a line of text, or a
        // gap.
        enum Mark {
            Light([u8; 3]),
            Dash,
            Text,
            Gap,
        }
        let mut items = vec![(Mark::Light(LIGHT_USED), format!("used: {n_used}"))];
        items.push(match plot.theta_d_max_deg {
            Some(_) => (
                Mark::Light(LIGHT_DROPPED),
                format!("dropped: {n_dropped} (outside the cone)"),
            ),
            None => (Mark::Text, "(a baseline uses every light)".into()),
        });
        items.push((Mark::Text, "filled: above the horizon".into()));
        items.push((Mark::Text, "ring: below it (z < 0)".into()));
        items.push((Mark::Gap, String::new()));
        if let (Some(t), Some(c)) = (plot.theta_d_max_deg, cone_deg) {
            items.push((Mark::Dash, format!("cone: theta_d < {t:.0}°, i.e. lights")));
            let below = if c > 90.0 {
                " (edge below the horizon)"
            } else {
                ""
            };
            items.push((Mark::Text, format!("within {c:.0}° of the view{below}")));
            items.push((Mark::Gap, String::new()));
        }
        items.push((Mark::Text, "grey rings: 30° and 60° from the view".into()));
        items.push((Mark::Text, "+ : the view direction (0, 0, 1)".into()));
        let (lx, mut ly) = (470, 70);
        for (mark, s) in items {
            match mark {
                Mark::Light(c) => root
                    .draw(&Circle::new((lx + 6, ly + 8), 5, rgb(c).filled()))
                    .map_err(draw_err)?,
                Mark::Dash => root
                    .draw(&PathElement::new(
                        vec![(lx, ly + 8), (lx + 12, ly + 8)],
                        rgb(CONE).stroke_width(2),
                    ))
                    .map_err(draw_err)?,
                Mark::Text => {}
                Mark::Gap => {
                    ly += 10;
                    continue;
                }
            }
            root.draw_text(&s, &text(13), (lx + 18, ly))
                .map_err(draw_err)?;
            ly += 22;
        }
        root.present().map_err(draw_err)?;
    }
    Ok(pic)
}

/// A white `w` x `h` legend: `title` at its top left, then what `draw` adds.
fn legend(
    w: usize,
    h: usize,
    title: &str,
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<()>,
) -> Result<Picture> {
    font_ready()?;
    let mut pic = Picture::white(w, h);
    {
        let root =
            BitMapBackend::with_buffer(&mut pic.rgb, (w as u32, h as u32)).into_drawing_area();
        root.draw_text(title, &text(16), (12, 10))
            .map_err(draw_err)?;
        draw(&root)?;
        root.present().map_err(draw_err)?;
    }
    Ok(pic)
}

/// A legend with a colour bar from `lo` to `hi` at [`LEGEND_BAR`], a title and notes beside it.
fn scalar_legend(
    title: &str,
    notes: &[String],
    bar: (f64, f64),
    colour: &dyn Fn(f64) -> [u8; 3],
    ticks: &[(f64, String)],
) -> Result<Picture> {
    let (w, h) = (520usize, LEGEND_BAR.bottom + 30);
    legend(w, h, title, |root| {
        draw_bar(
            root,
            &Bar {
                left: LEGEND_BAR.left as i32,
                top: LEGEND_BAR.top as i32,
                bottom: LEGEND_BAR.bottom as i32,
                width: LEGEND_BAR.width as i32,
                lo: bar.0,
                hi: bar.1,
                colour,
                ticks,
                label_size: 13,
            },
        )?;
        for (k, s) in notes.iter().enumerate() {
            root.draw_text(s, &text(13), (130, (LEGEND_BAR.top + 22 * k) as i32))
                .map_err(draw_err)?;
        }
        Ok(())
    })
}

/// `confidence_legend.png`: the viridis bar from 0 to 1 of `confidence.png`.
pub fn confidence_legend(method: &str) -> Result<Picture> {
    let notes: Vec<String> = if method == "symmetry" {
        vec![
            "the chance that the normal is within".into(),
            "1° of the truth (the data's own".into(),
            "uncertainty, times the share of the".into(),
            "highlight the rig sees)".into(),
        ]
    } else {
        vec![format!("the {method} fit's goodness of fit")]
    };
    let notes: Vec<String> = notes
        .into_iter()
        .chain(["".into(), "black: no estimate".into()])
        .collect();
    let ticks: Vec<(f64, String)> = (0..=5)
        .map(|k| (k as f64 / 5.0, format!("{:.1}", k as f64 / 5.0)))
        .collect();
    let colour = |v: f64| {
        let c = symframe_io::gray_map_rgb8(&[v as f32], 0.0, 1.0);
        [c[0], c[1], c[2]]
    };
    scalar_legend(
        "confidence.png: confidence, 0 to 1",
        &notes,
        (0.0, 1.0),
        &colour,
        &ticks,
    )
}

/// `residual_legend.png`: the viridis bar from 0 to [`RESIDUAL_MAX`] of `residual.png`.
pub fn residual_legend() -> Result<Picture> {
    let notes = [
        "the symmetry distance about the normal:",
        "the share of the pixel's signal that its",
        "mirror image about the normal does not",
        "reproduce (0: perfectly symmetric)",
        "",
        "black: not measured (no estimate, a",
        "fallback beyond the rig's reach, or a",
        "baseline)",
    ]
    .map(String::from);
    let scale = Scale::fixed(RESIDUAL_MAX as f64);
    let colour = |v: f64| {
        let c = residual_rgb8(&[v as f32]);
        [c[0], c[1], c[2]]
    };
    scalar_legend(
        "residual.png: what the answer leaves unexplained",
        &notes,
        (0.0, RESIDUAL_MAX as f64),
        &colour,
        &scale.labelled_ticks("", true),
    )
}

/// `tangents_legend.png`: a wheel of the colours `tangents.png` gives each direction of the
/// tangent's projection onto the image plane.
pub fn tangents_legend() -> Result<Picture> {
    let (cx, cy, r) = TANGENT_WHEEL;
    let (w, h) = (560usize, cy + r + 40);
    let mut pic = legend(
        w,
        h,
        "tangents.png: the tangent's direction as a hue",
        |root| {
            let (cxi, cyi, ri) = (cx as i32, cy as i32, r as i32);
            let label = |s: &str, at: (i32, i32), hp: HPos, vp: VPos| {
                root.draw(&Text::new(
                    s.to_string(),
                    at,
                    text(12).pos(Pos::new(hp, vp)),
                ))
                .map_err(draw_err)
            };
            label("+x", (cxi + ri + 6, cyi), HPos::Left, VPos::Center)?;
            label("+y", (cxi, cyi - ri - 4), HPos::Center, VPos::Bottom)?;
            let notes = [
                "each direction in the wheel has the colour",
                "of a tangent pointing that way in the image",
                "(its projection onto the image plane)",
                "",
                "a tangent is an axis: t and -t are the same,",
                "so the hues go round twice",
                "",
                "black: no tangent (an isotropic slice,",
                "or no estimate)",
            ];
            for (k, s) in notes.iter().enumerate() {
                root.draw_text(s, &text(13), (250, 60 + 22 * k as i32))
                    .map_err(draw_err)?;
            }
            Ok(())
        },
    )?;
    // The wheel, pixel by pixel, through the map's own colouring.
    for y in cy - r..=cy + r {
        for x in cx - r..=cx + r {
            let (dx, dy) = (x as f64 - cx as f64, cy as f64 - y as f64);
            if dx.hypot(dy) > r as f64 || (dx == 0.0 && dy == 0.0) {
                continue;
            }
            let c = symframe_io::tangent_map_rgb8(&[dx as f32, dy as f32, 0.0]);
            let o = (y * w + x) * 3;
            pic.rgb[o..o + 3].copy_from_slice(&c);
        }
    }
    Ok(pic)
}

/// Splits `s` into lines of at most `width` characters at spaces.
fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in s.split_whitespace() {
        match lines.last_mut() {
            Some(l) if l.len() + 1 + word.len() <= width => {
                l.push(' ');
                l.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

/// Where `source_legend.png` draws the swatch of source `code`: its top-left corner; the
/// swatch is 28 x 18 pixels.
pub fn source_swatch(code: u8) -> (usize, usize) {
    (16, 48 + 60 * code as usize)
}

/// `source_legend.png`: the colour of each code of `source.png`, its name, meaning and pixel
/// count (`counts[code]`, from the report).
pub fn source_legend(counts: &[usize]) -> Result<Picture> {
    let n = PixelSource::ALL.len();
    let (w, h) = (600usize, source_swatch(n as u8).1 + 4);
    legend(
        w,
        h,
        "source.png: which measure gave each pixel's normal",
        |root| {
            for (code, name, what) in PixelSource::legend() {
                let (x, y) = source_swatch(code);
                let c = symframe_io::SOURCE_PALETTE[code as usize];
                root.draw(&Rectangle::new(
                    [(x as i32, y as i32), (x as i32 + 27, y as i32 + 17)],
                    rgb(c).filled(),
                ))
                .map_err(draw_err)?;
                root.draw(&Rectangle::new(
                    [(x as i32 - 1, y as i32 - 1), (x as i32 + 28, y as i32 + 18)],
                    RGBColor(120, 120, 120),
                ))
                .map_err(draw_err)?;
                let count = counts.get(code as usize).copied().unwrap_or(0);
                root.draw_text(
                    &format!("{code} {name}: {count} px"),
                    &text(14),
                    (x as i32 + 40, y as i32),
                )
                .map_err(draw_err)?;
                for (k, l) in wrap(what, 72).iter().take(2).enumerate() {
                    root.draw_text(l, &text(12), (x as i32 + 40, y as i32 + 19 + 15 * k as i32))
                        .map_err(draw_err)?;
                }
            }
            Ok(())
        },
    )
}

/// A picture of an estimate's output set, as `index.html` shows it.
struct Entry {
    file: &'static str,
    title: &'static str,
    what: &'static str,
    legend: Option<&'static str>,
    /// Pixel-aligned with the image (shown enlarged when small, without smoothing).
    map: bool,
}

/// Every picture an estimate may write, in the order `index.html` shows them.
const ENTRIES: [Entry; 7] = [
    Entry {
        file: "normals.png",
        title: "Normals",
        what: "The unit normal n as colour, (n + 1) / 2 per channel (16-bit; x right, y up unless \
               --normal-png directx, z toward the camera); black where there is no estimate.",
        legend: None,
        map: true,
    },
    Entry {
        file: "tangents.png",
        title: "Tangents",
        what: "The tangent's direction in the image as a hue (an axis: t and -t share a colour); \
               black where the slice is isotropic or there is no estimate.",
        legend: Some("tangents_legend.png"),
        map: true,
    },
    Entry {
        file: "confidence.png",
        title: "Confidence",
        what: "How sure the data are of each normal, 0 to 1 (viridis); black where there is no \
               estimate.",
        legend: Some("confidence_legend.png"),
        map: true,
    },
    Entry {
        file: "residual.png",
        title: "Residual",
        what: "How much of each pixel's data the answer leaves unexplained: the symmetry distance \
               about the normal (viridis, 0 to 0.25 and above); black where it was not measured.",
        legend: Some("residual_legend.png"),
        map: true,
    },
    Entry {
        file: "source.png",
        title: "Source",
        what: "Which measure gave each pixel's normal: the symmetry, a fitted lobe, a Lambertian \
               fit or the highlight.",
        legend: Some("source_legend.png"),
        map: true,
    },
    Entry {
        file: "tangents_gltf.png",
        title: "glTF anisotropy",
        what: "The tangents and anisotropy strength as KHR_materials_anisotropy's texture \
               (direction in red and green, strength in blue).",
        legend: None,
        map: true,
    },
    Entry {
        file: "lights.png",
        title: "Lights",
        what: "The rig seen from above: which lights the estimate used and which it dropped, and \
               the cone that decides.",
        legend: None,
        map: false,
    },
];

/// The files [`write_pictures`] writes (all of them in the estimate's output set).
#[cfg(test)]
pub(crate) const PICTURE_FILES: [&str; 6] = [
    "lights.png",
    "confidence_legend.png",
    "source_legend.png",
    "tangents_legend.png",
    "residual_legend.png",
    "index.html",
];

/// Text for HTML, escaped.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

/// A report value as a short text: numbers with at most three decimals.
fn show(v: &Value) -> String {
    match v {
        Value::Null => "-".into(),
        Value::String(s) => s.clone(),
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            let s = format!("{x:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        }
        other => other.to_string(),
    }
}

/// Rows `key: value` of a report object, as an HTML table.
fn table(v: &Value) -> String {
    let mut s = String::from("<table>");
    if let Some(o) = v.as_object() {
        for (k, x) in o {
            if x.is_object() || x.is_array() {
                continue;
            }
            s += &format!("<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&show(x)));
        }
    }
    s + "</table>"
}

/// `index.html`: every picture of the set that `present` says was written, each with its
/// title, a line saying what it shows and its legend, and the run's summary from `report`
/// (`report.json`'s value). Self-contained: pictures referenced by name from the same folder,
/// styles inline, no script.
pub fn index_html(report: &Value, present: &dyn Fn(&str) -> bool) -> String {
    let (w, h) = (
        report["width"].as_u64().unwrap_or(0),
        report["height"].as_u64().unwrap_or(0),
    );
    // Small maps are shown enlarged by a whole factor, without smoothing.
    let zoom = (256 / w.max(h).max(1)).max(1);
    let mut s = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>symframe estimate</title>\n<style>\n\
         body { font-family: sans-serif; margin: 1.5em; color: #222; max-width: 1400px; }\n\
         figure { margin: 0 0 2em 0; }\n\
         .row { display: flex; flex-wrap: wrap; gap: 1.5em; align-items: flex-start; }\n\
         img.map { image-rendering: pixelated; max-width: 100%; height: auto; \
         background: #000; }\n\
         table { border-collapse: collapse; margin: 0.5em 0 1em 0; }\n\
         th, td { text-align: left; padding: 0.15em 0.8em 0.15em 0; vertical-align: top; }\n\
         th { font-weight: normal; color: #555; }\n\
         .swatch { display: inline-block; width: 1em; height: 1em; vertical-align: middle; \
         border: 1px solid #888; }\n\
         </style>\n</head>\n<body>\n",
    );
    s += &format!(
        "<h1>symframe estimate: {} x {} pixels, method {}</h1>\n",
        w,
        h,
        esc(&show(&report["method"]))
    );
    s += &format!(
        "<p>Input: <code>{}</code>; symframe {}.</p>\n",
        esc(&show(&report["input"])),
        esc(&show(&report["version"]))
    );

    s += "<h2>Summary</h2>\n<div class=\"row\">\n<div><h3>Pixels</h3>";
    s += &table(&report["pixels"]);
    s += "</div>\n<div><h3>Lights</h3>";
    s += &table(&report["lights"]);
    if let Some(t) = report.pointer("/parameters/theta_d_max_deg") {
        s += &format!("<p>Cone: theta_d &lt; {}°</p>", esc(&show(t)));
    }
    s += "</div>\n<div><h3>Timings (s)</h3>";
    s += &table(&report["timings"]);
    s += "</div>\n</div>\n<h3>Sources</h3>\n<table>";
    for src in report["sources"].as_array().into_iter().flatten() {
        let code = src["code"].as_u64().unwrap_or(u64::MAX);
        let c = symframe_io::SOURCE_PALETTE
            .get(code as usize)
            .copied()
            .unwrap_or([255, 0, 255]);
        s += &format!(
            "<tr><td><span class=\"swatch\" style=\"background: rgb({}, {}, {})\"></span> \
             {}</td><td>{}</td><td>{} px</td><td>{}</td></tr>",
            c[0],
            c[1],
            c[2],
            esc(&show(&src["code"])),
            esc(&show(&src["name"])),
            esc(&show(&src["pixels"])),
            esc(&show(&src["description"]))
        );
    }
    s += "</table>\n<h3>Warnings</h3>\n";
    let warnings: Vec<&Value> = report["warnings"]
        .as_array()
        .into_iter()
        .flatten()
        .collect();
    if warnings.is_empty() {
        s += "<p>None.</p>\n";
    } else {
        s += "<ul>\n";
        for w in warnings {
            s += &format!("<li>{}</li>\n", esc(&show(w)));
        }
        s += "</ul>\n";
    }

    s += "<h2>Pictures</h2>\n";
    for e in ENTRIES.iter().filter(|e| present(e.file)) {
        s += &format!(
            "<figure id=\"{}\">\n<h3>{} <small><code>{}</code></small></h3>\n<p>{}</p>\n\
             <div class=\"row\">\n",
            esc(e.file),
            esc(e.title),
            esc(e.file),
            esc(e.what)
        );
        if e.map {
            s += &format!(
                "<img class=\"map\" src=\"{0}\" alt=\"{1}\" width=\"{2}\" height=\"{3}\">\n",
                esc(e.file),
                esc(e.title),
                w * zoom,
                h * zoom
            );
        } else {
            s += &format!("<img src=\"{}\" alt=\"{}\">\n", esc(e.file), esc(e.title));
        }
        if let Some(l) = e.legend.filter(|l| present(l)) {
            s += &format!(
                "<img src=\"{}\" alt=\"legend of {}\">\n",
                esc(l),
                esc(e.title)
            );
        }
        s += "</div>\n</figure>\n";
    }
    s += "<p>The maps themselves (<code>.npy</code>, <code>.exr</code>) and the whole report \
          (<code>report.json</code>) are in this folder.</p>\n</body>\n</html>\n";
    s
}

/// Writes the legends, the lights' picture (given `lights`) and `index.html` into the staged
/// output set, from the set's `report` (`report.json`'s value: the method and the source
/// counts). The maps' pictures must be staged already: the page shows the ones there.
pub(crate) fn write_pictures(
    staging: &OutputSet,
    report: &Value,
    lights: Option<&LightsPlot>,
) -> Result<()> {
    let method = report["method"].as_str().unwrap_or("symmetry");
    let mut counts = vec![0usize; PixelSource::ALL.len()];
    for src in report["sources"].as_array().into_iter().flatten() {
        if let (Some(code), Some(n)) = (src["code"].as_u64(), src["pixels"].as_u64()) {
            if let Some(c) = counts.get_mut(code as usize) {
                *c = n as usize;
            }
        }
    }
    confidence_legend(method)?.save(&staging.path("confidence_legend.png"))?;
    source_legend(&counts)?.save(&staging.path("source_legend.png"))?;
    tangents_legend()?.save(&staging.path("tangents_legend.png"))?;
    residual_legend()?.save(&staging.path("residual_legend.png"))?;
    if let Some(l) = lights {
        lights_picture(l)?.save(&staging.path("lights.png"))?;
    }
    let present = |name: &str| staging.path(name).is_file();
    let html = index_html(report, &present);
    let path = staging.path("index.html");
    symframe_io::write_bytes(&path, html.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_legend_bars_run_from_the_maps_colour_at_0_to_its_top() {
        let pic = confidence_legend("symmetry").unwrap();
        let x = LEGEND_BAR.left + LEGEND_BAR.width / 2;
        let at = |v: f32| {
            let c = symframe_io::gray_map_rgb8(&[v], 0.0, 1.0);
            [c[0], c[1], c[2]]
        };
        assert_eq!(pic.pixel(x, LEGEND_BAR.bottom), at(0.0));
        assert_eq!(pic.pixel(x, LEGEND_BAR.top), at(1.0));
        let pic = residual_legend().unwrap();
        assert_eq!(
            pic.pixel(x, LEGEND_BAR.top).to_vec(),
            residual_rgb8(&[RESIDUAL_MAX])
        );
    }

    #[test]
    fn the_tangent_wheel_has_the_maps_colours() {
        let pic = tangents_legend().unwrap();
        let (cx, cy, r) = TANGENT_WHEEL;
        for deg in [0.0f64, 30.0, 100.0, 200.0] {
            let a = deg.to_radians();
            let (x, y) = (
                (cx as f64 + 0.8 * r as f64 * a.cos()).round(),
                (cy as f64 - 0.8 * r as f64 * a.sin()).round(),
            );
            let (dx, dy) = (x - cx as f64, cy as f64 - y);
            let want = symframe_io::tangent_map_rgb8(&[dx as f32, dy as f32, 0.0]);
            assert_eq!(pic.pixel(x as usize, y as usize).to_vec(), want, "{deg}");
        }
    }

    #[test]
    fn the_pictures_are_files_of_the_output_set() {
        for name in PICTURE_FILES {
            assert!(crate::estimate::ESTIMATE_FILES.contains(&name), "{name}");
        }
    }

    #[test]
    fn html_is_escaped() {
        let report = serde_json::json!({
            "width": 4, "height": 4, "method": "symmetry", "input": "<a&b>",
            "warnings": ["x < y"],
        });
        let html = index_html(&report, &|n| n == "normals.png");
        assert!(html.contains("&lt;a&amp;b&gt;") && html.contains("x &lt; y"));
        assert!(html.contains("src=\"normals.png\"") && !html.contains("src=\"source.png\""));
    }
}
