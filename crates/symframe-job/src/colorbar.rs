//! Error-map pictures: the map coloured with viridis (enlarged when small), a colour bar with
//! labelled ticks in degrees, a title and a legend, drawn with plotters into an RGB buffer
//! (for [`crate::eval`] and the experiments' plots).
//!
//! Text uses an embedded subset of DejaVu Sans (`assets/`, with its licence), so nothing depends
//! on the system's fonts.

use std::sync::OnceLock;

use anyhow::{anyhow, ensure, Result};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{register_font, FontStyle};

/// The embedded font: DejaVu Sans, printable ASCII plus a few signs.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans-subset.ttf");
/// The family name the embedded font is registered under.
pub const FAMILY: &str = "symframe-dejavu-sans";

/// Colour of pixels whose reference exists but that have no estimate.
const NO_ESTIMATE: [u8; 3] = [150, 150, 150];
/// Colour of pixels without a reference (outside the object).
const NO_REFERENCE: [u8; 3] = [0, 0, 0];

/// Registers the embedded font with plotters once per process.
pub fn font_ready() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    ensure!(ok, "the embedded font cannot be read");
    Ok(())
}

/// What one pixel of an error map shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cell {
    /// An error, degrees.
    Error(f32),
    /// The reference exists but there is no estimate.
    NoEstimate,
    /// No reference here.
    NoReference,
}

/// A colour scale from 0 to `max` degrees with its tick values.
#[derive(Debug, Clone, PartialEq)]
pub struct Scale {
    /// Top of the scale; larger errors get the top colour.
    pub max: f64,
    /// Tick values, ascending, from 0.
    pub ticks: Vec<f64>,
    /// Decimals the tick labels need.
    pub decimals: usize,
}

/// The 1-2-5 step nearest above `x > 0`.
fn nice_step(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&s| s >= x * (1.0 - 1e-9))
        .unwrap_or(10.0 * p)
}

impl Scale {
    /// A scale for errors whose typical top is `top` degrees (for instance their 95th
    /// percentile): a 1-2-5 step giving about five ticks, the top rounded up to a whole step.
    /// At least 0.01 degrees, so that exact results do not paint rounding noise.
    pub fn rounded(top: f64) -> Self {
        let top = if top.is_finite() { top.max(0.01) } else { 1.0 };
        let step = nice_step(top / 5.0);
        Self::with_step((top / step - 1e-9).ceil() * step, step)
    }

    /// This scale, or if its top is above `cap` (90 for axis errors) one ending at `cap`, with
    /// the smallest round step giving at most seven ticks that divides it.
    pub fn capped(self, cap: f64) -> Self {
        if self.max <= cap {
            return self;
        }
        let p = 10f64.powf((cap / 6.0).log10().floor());
        let step = [1.0, 1.5, 2.0, 2.5, 3.0, 5.0, 10.0]
            .into_iter()
            .map(|m| m * p)
            .find(|&s| {
                s >= cap / 6.0 * (1.0 - 1e-9) && ((cap / s).round() * s - cap).abs() < 1e-9 * cap
            })
            .unwrap_or(cap);
        Self::with_step(cap, step)
    }

    /// A scale with a fixed top (`--scale-max`), ticks at a 1-2-5 step below it.
    pub fn fixed(max: f64) -> Self {
        Self::with_step(max, nice_step(max / 5.0))
    }

    fn with_step(max: f64, step: f64) -> Self {
        let n = (max / step + 1e-9).floor() as usize;
        let ticks = (0..=n).map(|k| k as f64 * step).collect();
        let decimals = (-step.log10().floor()).max(0.0) as usize;
        Self {
            max,
            ticks,
            decimals,
        }
    }

    /// The viridis colour of a value on this scale.
    pub fn colour(&self, v: f32) -> [u8; 3] {
        let rgb = symframe_io::gray_map_rgb8(&[v], 0.0, self.max as f32);
        [rgb[0], rgb[1], rgb[2]]
    }
}

/// Draws an error map with its colour bar. Returns the picture's RGB bytes, width and height.
/// Maps under 256 pixels on their long side are enlarged by a whole factor (nearest neighbour).
pub fn error_picture(
    title: &str,
    cells: &[Cell],
    width: usize,
    height: usize,
    scale: &Scale,
) -> Result<(Vec<u8>, usize, usize)> {
    ensure!(cells.len() == width * height && width > 0 && height > 0);
    font_ready()?;
    const PAD: usize = 12;
    const TITLE_H: usize = 30;
    const LEGEND_H: usize = 26;
    const BAR_W: usize = 22;
    const LABELS_W: usize = 64;
    let zoom = (256 / width.max(height)).max(1);
    let (mw, mh) = (width * zoom, height * zoom);
    let body_h = mh.max(200);
    let (pw, ph) = (
        PAD + mw + 2 * PAD + BAR_W + LABELS_W,
        TITLE_H + body_h + LEGEND_H + PAD / 2,
    );
    let (bar_x, bar_y) = (PAD + mw + 2 * PAD, TITLE_H);
    let clipped = cells
        .iter()
        .any(|c| matches!(c, Cell::Error(e) if *e as f64 > scale.max * (1.0 + 1e-6)));

    let mut buf = vec![255u8; pw * ph * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (pw as u32, ph as u32)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| anyhow!("drawing the error picture: {e}");
        let text = |size: i32| TextStyle::from((FAMILY, size).into_font()).color(&BLACK);
        root.draw_text(title, &text(17), (PAD as i32, 7))
            .map_err(|e| err(&e))?;
        root.draw_text(
            "grey: no estimate    black: no ground truth",
            &text(13),
            (PAD as i32, (TITLE_H + body_h + 6) as i32),
        )
        .map_err(|e| err(&e))?;

        // The bar: the gradient one pixel row at a time, a frame, ticks and labels on the right.
        let (top, bottom) = (bar_y as i32 + 10, (bar_y + body_h) as i32 - 10);
        let (left, right) = (bar_x as i32, (bar_x + BAR_W) as i32);
        let span = (bottom - top) as f64;
        for y in top..=bottom {
            let c = scale.colour((scale.max * (bottom - y) as f64 / span) as f32);
            root.draw(&Rectangle::new(
                [(left, y), (right, y + 1)],
                RGBColor(c[0], c[1], c[2]).filled(),
            ))
            .map_err(|e| err(&e))?;
        }
        root.draw(&Rectangle::new([(left, top), (right, bottom + 1)], BLACK))
            .map_err(|e| err(&e))?;
        let label = text(14).pos(Pos::new(HPos::Left, VPos::Center));
        for &v in &scale.ticks {
            let y = bottom - (v / scale.max * span).round() as i32;
            root.draw(&PathElement::new(vec![(right, y), (right + 5, y)], BLACK))
                .map_err(|e| err(&e))?;
            let mut s = format!("{v:.*}", scale.decimals);
            if clipped && (v - scale.max).abs() <= 1e-9 * scale.max {
                s.insert(0, '\u{2265}');
            }
            root.draw(&Text::new(s, (right + 8, y), label.clone()))
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }

    // The map itself, written straight into the picture.
    for y in 0..mh {
        for x in 0..mw {
            let c = match cells[(y / zoom) * width + x / zoom] {
                Cell::Error(e) if e.is_finite() => scale.colour(e),
                Cell::Error(_) | Cell::NoEstimate => NO_ESTIMATE,
                Cell::NoReference => NO_REFERENCE,
            };
            let o = ((TITLE_H + y) * pw + PAD + x) * 3;
            buf[o..o + 3].copy_from_slice(&c);
        }
    }
    Ok((buf, pw, ph))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_have_round_ticks() {
        let s = Scale::rounded(3.7);
        assert_eq!(s.max, 4.0);
        assert_eq!(s.ticks, vec![0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.decimals, 0);
        let s = Scale::rounded(0.0);
        assert!((s.max - 0.01).abs() < 1e-12 && s.decimals == 3, "{s:?}");
        let s = Scale::rounded(27.0);
        assert_eq!(s.ticks, vec![0.0, 10.0, 20.0, 30.0]);
        let s = Scale::fixed(45.0);
        assert_eq!(s.ticks.last(), Some(&40.0));
        let s = Scale::rounded(89.0).capped(90.0);
        assert_eq!(s.ticks, vec![0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0]);
        assert_eq!(Scale::rounded(3.7).capped(90.0).max, 4.0);
    }

    #[test]
    fn picture_has_the_map_and_the_bar() {
        let cells: Vec<Cell> = (0..16)
            .map(|i| match i {
                0 => Cell::NoReference,
                1 => Cell::NoEstimate,
                _ => Cell::Error(i as f32),
            })
            .collect();
        let (rgb, w, h) = error_picture("t", &cells, 4, 4, &Scale::rounded(15.0)).unwrap();
        assert_eq!(rgb.len(), w * h * 3);
        // 4x4 enlarged by 64: the first cell's block is black, the second grey.
        let px = |x: usize, y: usize| &rgb[((30 + y) * w + 12 + x) * 3..][..3];
        assert_eq!(px(10, 10), &NO_REFERENCE);
        assert_eq!(px(70, 10), &NO_ESTIMATE);
    }
}
