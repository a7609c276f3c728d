//! Small plotting helpers for the experiments: heat maps with a colour bar, line plots with a
//! legend, and labelled picture grids, drawn with plotters into RGB buffers and saved as PNG.
//!
//! All text uses the embedded DejaVu subset of [`symframe_job::colorbar`] (printable ASCII plus `°`,
//! `−`, `≤`, `≥`), so nothing depends on the system's fonts.

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use symframe_job::colorbar::{draw_bar, font_ready, text, Bar, Scale};

pub use symframe_job::colorbar::Picture;

/// Colour of cells or pixels without an estimate.
pub const NO_ESTIMATE: [u8; 3] = [230, 60, 200];
/// Colour of pixels outside the object.
pub const BACKGROUND: [u8; 3] = [0, 0, 0];

fn err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing a plot: {e}")
}

/// A heat map of `values` (row-major, `rows x cols`; `None` = no estimate, drawn magenta) with
/// row and column labels, axis titles and a colour bar from 0 to `scale.max` (values above it
/// get the top colour).
pub fn heatmap(
    title: &str,
    row_title: &str,
    col_title: &str,
    row_labels: &[String],
    col_labels: &[String],
    values: &[Option<f64>],
    scale: &Scale,
) -> Result<Picture> {
    font_ready()?;
    let (rows, cols) = (row_labels.len(), col_labels.len());
    anyhow::ensure!(
        values.len() == rows * cols,
        "heat map: wrong number of values"
    );
    let cell = 22usize;
    let (left, top) = (70usize, 40usize);
    let (mw, mh) = (cols * cell, rows * cell);
    let (w, h) = (left + mw + 110, top + mh + 60);
    let mut rgb = vec![255u8; w * h * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
        root.draw_text(title, &text(15), (10, 8)).map_err(err)?;
        for (r, row) in values.chunks(cols).enumerate() {
            for (c, v) in row.iter().enumerate() {
                let col = match v {
                    Some(e) if e.is_finite() => scale.colour(*e as f32),
                    _ => NO_ESTIMATE,
                };
                let (x0, y0) = ((left + c * cell) as i32, (top + r * cell) as i32);
                root.draw(&Rectangle::new(
                    [(x0, y0), (x0 + cell as i32, y0 + cell as i32)],
                    RGBColor(col[0], col[1], col[2]).filled(),
                ))
                .map_err(err)?;
            }
        }
        let right_label = text(11).pos(Pos::new(HPos::Right, VPos::Center));
        for (r, l) in row_labels.iter().enumerate() {
            let y = (top + r * cell + cell / 2) as i32;
            root.draw(&Text::new(
                l.clone(),
                (left as i32 - 5, y),
                right_label.clone(),
            ))
            .map_err(err)?;
        }
        let centre_label = text(11).pos(Pos::new(HPos::Center, VPos::Top));
        for (c, l) in col_labels.iter().enumerate() {
            let x = (left + c * cell + cell / 2) as i32;
            root.draw(&Text::new(
                l.clone(),
                (x, (top + mh + 4) as i32),
                centre_label.clone(),
            ))
            .map_err(err)?;
        }
        root.draw(&Text::new(
            col_title.to_string(),
            ((left + mw / 2) as i32, (top + mh + 22) as i32),
            text(13).pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(err)?;
        root.draw(&Text::new(
            row_title.to_string(),
            (6, (top - 16) as i32),
            text(12),
        ))
        .map_err(err)?;
        root.draw_text(
            "magenta: no estimate",
            &text(11),
            (left as i32, (top + mh + 40) as i32),
        )
        .map_err(err)?;
        colour_bar(&root, left + mw + 16, top, mh, scale)?;
        root.present().map_err(err)?;
    }
    Ok(Picture {
        rgb,
        width: w,
        height: h,
    })
}

/// A vertical colour bar at `(x, y)`, `height` tall, with tick labels in degrees.
fn colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    x: usize,
    y: usize,
    height: usize,
    scale: &Scale,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    draw_bar(
        root,
        &Bar {
            left: x as i32,
            top: y as i32,
            bottom: (y + height) as i32 - 1,
            width: 16,
            lo: 0.0,
            hi: scale.max,
            colour: &|v| scale.colour(v as f32),
            ticks: &scale.labelled_ticks("°", true),
            label_size: 11,
        },
    )
}

/// Series colours of the line plots.
const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// A line plot of `series` (name, one value per x category; `None` = missing) over categorical
/// x labels, with a legend. With `log_y` the y axis is logarithmic (values floored at 0.01).
pub fn line_plot(
    title: &str,
    x_title: &str,
    y_title: &str,
    x_labels: &[String],
    series: &[(String, Vec<Option<f64>>)],
    log_y: bool,
) -> Result<Picture> {
    font_ready()?;
    let (w, h) = (640usize, 400usize);
    let n = x_labels.len().max(1);
    let floor = 0.01;
    let ymax = series
        .iter()
        .flat_map(|(_, v)| v.iter().flatten())
        .fold(0.0f64, |a, &b| if b.is_finite() { a.max(b) } else { a });
    let mut rgb = vec![255u8; w * h * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
        let labels = x_labels.to_vec();
        let fmt_x = move |x: &f64| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                labels[i as usize].clone()
            } else {
                String::new()
            }
        };
        let xr = -0.3..(n as f64 - 0.7);
        macro_rules! draw {
            ($chart:expr, $map:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .x_labels(n)
                    .x_label_formatter(&fmt_x)
                    .x_desc(x_title)
                    .y_desc(y_title)
                    .label_style(text(12))
                    .axis_desc_style(text(13))
                    .light_line_style(RGBColor(235, 235, 235))
                    .draw()
                    .map_err(err)?;
                for (k, (name, vals)) in series.iter().enumerate() {
                    let colour = COLOURS[k % COLOURS.len()];
                    let pts: Vec<(f64, f64)> = vals
                        .iter()
                        .enumerate()
                        .filter_map(|(i, v)| {
                            v.filter(|v| v.is_finite()).map(|v| (i as f64, $map(v)))
                        })
                        .collect();
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            pts.clone(),
                            colour.stroke_width(2),
                        )))
                        .map_err(err)?
                        .label(name.clone())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                        });
                    chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
                        .map_err(err)?;
                }
                chart
                    .configure_series_labels()
                    .label_font(text(12))
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()
                    .map_err(err)?;
            }};
        }
        macro_rules! builder {
            () => {
                ChartBuilder::on(&root)
                    .caption(title, text(15))
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(55)
            };
        }
        if log_y {
            let top = (ymax.max(floor) * 30.0).max(1.0);
            let chart = builder!()
                .build_cartesian_2d(xr, (floor..top).log_scale())
                .map_err(err)?;
            draw!(chart, |v: f64| v.max(floor));
        } else {
            let top = (ymax * 1.15).max(0.1);
            let chart = builder!().build_cartesian_2d(xr, 0.0..top).map_err(err)?;
            draw!(chart, |v: f64| v);
        }
        root.present().map_err(err)?;
    }
    Ok(Picture {
        rgb,
        width: w,
        height: h,
    })
}

/// A grid of equally sized tiles (`tiles[row * cols + col]`, RGB, `tile_w x tile_h`) enlarged by
/// `zoom`, with row labels on the left, column labels on top, a title and a footer line.
#[allow(clippy::too_many_arguments)]
pub fn grid(
    title: &str,
    row_labels: &[String],
    col_labels: &[String],
    tiles: &[Vec<u8>],
    tile_w: usize,
    tile_h: usize,
    zoom: usize,
    footer: &str,
) -> Result<Picture> {
    font_ready()?;
    let (rows, cols) = (row_labels.len(), col_labels.len());
    anyhow::ensure!(tiles.len() == rows * cols, "grid: wrong number of tiles");
    let (tw, th) = (tile_w * zoom, tile_h * zoom);
    let (left, top, gap) = (95usize, 52usize, 6usize);
    let w = left + cols * (tw + gap) + 6;
    let h = top + rows * (th + gap) + 30;
    let mut rgb = vec![255u8; w * h * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
        root.draw_text(title, &text(15), (8, 6)).map_err(err)?;
        let centre = text(12).pos(Pos::new(HPos::Center, VPos::Bottom));
        for (c, l) in col_labels.iter().enumerate() {
            let x = (left + c * (tw + gap) + tw / 2) as i32;
            root.draw(&Text::new(l.clone(), (x, top as i32 - 4), centre.clone()))
                .map_err(err)?;
        }
        let right = text(12).pos(Pos::new(HPos::Right, VPos::Center));
        for (r, l) in row_labels.iter().enumerate() {
            let y = (top + r * (th + gap) + th / 2) as i32;
            root.draw(&Text::new(l.clone(), (left as i32 - 6, y), right.clone()))
                .map_err(err)?;
        }
        root.draw_text(footer, &text(11), (8, (h - 22) as i32))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    for (k, tile) in tiles.iter().enumerate() {
        let (r, c) = (k / cols, k % cols);
        let (x0, y0) = (left + c * (tw + gap), top + r * (th + gap));
        for y in 0..th {
            for x in 0..tw {
                let s = ((y / zoom) * tile_w + x / zoom) * 3;
                let o = ((y0 + y) * w + x0 + x) * 3;
                rgb[o..o + 3].copy_from_slice(&tile[s..s + 3]);
            }
        }
    }
    Ok(Picture {
        rgb,
        width: w,
        height: h,
    })
}

/// An error map as RGB: viridis from 0 to `max` degrees, [`NO_ESTIMATE`] where the object has no
/// estimate (NaN), [`BACKGROUND`] outside `mask`.
pub fn error_tile(errors: &[f32], mask: &[bool], max: f64) -> Vec<u8> {
    let scale = Scale::fixed(max);
    errors
        .iter()
        .zip(mask)
        .flat_map(|(&e, &m)| {
            if !m {
                BACKGROUND
            } else if e.is_finite() {
                scale.colour(e)
            } else {
                NO_ESTIMATE
            }
        })
        .collect()
}

/// A normal map as RGB (`(n + 1) / 2`), [`NO_ESTIMATE`] where NaN inside `mask`, black outside.
pub fn normal_tile(normals: &[f32], mask: &[bool]) -> Vec<u8> {
    let rgb = symframe_io::normal_map_rgb8(normals);
    rgb.chunks_exact(3)
        .zip(normals.chunks_exact(3))
        .zip(mask)
        .flat_map(|((c, n), &m)| {
            if !m {
                BACKGROUND
            } else if n.iter().all(|v| v.is_finite()) {
                [c[0], c[1], c[2]]
            } else {
                NO_ESTIMATE
            }
        })
        .collect()
}

/// Formats an optional value with `d` decimals, `-` when missing.
pub fn fmt_opt(v: Option<f64>, d: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.d$}"),
        _ => "-".into(),
    }
}

/// A markdown table from a header and rows (also fine as plain text).
pub fn md_table(header: &[String], rows: &[Vec<String>]) -> String {
    let mut s = format!("| {} |\n", header.join(" | "));
    s += &format!("|{}\n", "---|".repeat(header.len()));
    for r in rows {
        s += &format!("| {} |\n", r.join(" | "));
    }
    s
}
