//! Pictures drawn with plotters into RGB buffers: the [`Picture`] type, the text style, the
//! vertical colour bar every scale shares ([`draw_bar`]), and error-map pictures (the map
//! coloured with viridis, enlarged when small, a colour bar in degrees, a title and a legend)
//! for [`crate::eval`], the estimate's legends ([`crate::pictures`]) and the experiments' plots.
//!
//! Text uses an embedded subset of DejaVu Sans (`assets/`, with its licence), so nothing depends
//! on the system's fonts.

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{anyhow, ensure, Context, Result};
use plotters::coord::Shift;
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

/// An RGB picture.
pub struct Picture {
    /// Interleaved RGB bytes.
    pub rgb: Vec<u8>,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl Picture {
    /// A white picture of `width x height` pixels.
    pub fn white(width: usize, height: usize) -> Self {
        Self {
            rgb: vec![255; width * height * 3],
            width,
            height,
        }
    }

    /// Writes the picture as an 8-bit PNG (atomically: never half-written).
    pub fn save(&self, path: &Path) -> Result<()> {
        symframe_io::write_png_rgb8(path, self.width, self.height, &self.rgb)
            .with_context(|| format!("{}: cannot write", path.display()))
    }

    /// The colour of pixel `(x, y)`.
    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let o = (y * self.width + x) * 3;
        [self.rgb[o], self.rgb[o + 1], self.rgb[o + 2]]
    }
}

/// Black text of `size` pixels in the embedded font.
pub fn text(size: i32) -> TextStyle<'static> {
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

/// A plotters error as this crate's.
pub(crate) fn draw_err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing a picture: {e}")
}

/// A vertical colour bar: its gradient fills columns `left..left + width` and rows
/// `top..=bottom` exactly (row `bottom` is the colour of `lo`, row `top` that of `hi`), framed
/// one pixel outside, with ticks and labels on the right.
pub struct Bar<'a> {
    /// Left column of the gradient.
    pub left: i32,
    /// Top row of the gradient (the colour of `hi`).
    pub top: i32,
    /// Bottom row of the gradient (the colour of `lo`).
    pub bottom: i32,
    /// Width of the gradient in pixels.
    pub width: i32,
    /// The value at the bottom.
    pub lo: f64,
    /// The value at the top.
    pub hi: f64,
    /// The colour of a value.
    pub colour: &'a dyn Fn(f64) -> [u8; 3],
    /// Tick values with their labels.
    pub ticks: &'a [(f64, String)],
    /// Label size in pixels.
    pub label_size: i32,
}

/// Draws `bar` on `root`.
pub fn draw_bar<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, bar: &Bar) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let (top, bottom, left) = (bar.top, bar.bottom, bar.left);
    let right = left + bar.width;
    let span = (bottom - top).max(1) as f64;
    let value = |y: i32| bar.lo + (bar.hi - bar.lo) * (bottom - y) as f64 / span;
    for y in top..=bottom {
        let c = (bar.colour)(value(y));
        for x in left..right {
            root.draw_pixel((x, y), &RGBColor(c[0], c[1], c[2]))
                .map_err(draw_err)?;
        }
    }
    root.draw(&Rectangle::new(
        [(left - 1, top - 1), (right, bottom + 1)],
        BLACK,
    ))
    .map_err(draw_err)?;
    let label = text(bar.label_size).pos(Pos::new(HPos::Left, VPos::Center));
    for (v, s) in bar.ticks {
        let y = bottom - ((v - bar.lo) / (bar.hi - bar.lo) * span).round() as i32;
        root.draw(&PathElement::new(vec![(right, y), (right + 5, y)], BLACK))
            .map_err(draw_err)?;
        root.draw(&Text::new(s.clone(), (right + 8, y), label.clone()))
            .map_err(draw_err)?;
    }
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

    /// The ticks with their labels (`unit` appended; the top one marked `≥` when `clipped`:
    /// larger values have its colour).
    pub fn labelled_ticks(&self, unit: &str, clipped: bool) -> Vec<(f64, String)> {
        self.ticks
            .iter()
            .map(|&v| {
                let mut s = format!("{v:.*}{unit}", self.decimals);
                if clipped && (v - self.max).abs() <= 1e-9 * self.max {
                    s.insert(0, '\u{2265}');
                }
                (v, s)
            })
            .collect()
    }

    /// The viridis colour of a value on this scale.
    pub fn colour(&self, v: f32) -> [u8; 3] {
        let rgb = symframe_io::gray_map_rgb8(&[v], 0.0, self.max as f32);
        [rgb[0], rgb[1], rgb[2]]
    }
}

/// Left margin of an error picture's map.
const PAD: usize = 12;
/// Height of an error picture's title band, above the map.
const TITLE_H: usize = 30;

/// Where [`error_picture`] puts a `width x height` map: its top-left corner `(x, y)` in the
/// picture and the whole factor it is enlarged by (map pixel `(i, j)` covers the picture's
/// pixels `(x + i * zoom.., y + j * zoom..)`).
pub fn error_map_layout(width: usize, height: usize) -> (usize, usize, usize) {
    (PAD, TITLE_H, (256 / width.max(height).max(1)).max(1))
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
    const LEGEND_H: usize = 26;
    const BAR_W: usize = 22;
    const LABELS_W: usize = 64;
    let (_, _, zoom) = error_map_layout(width, height);
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
        root.draw_text(title, &text(17), (PAD as i32, 7))
            .map_err(|e| err(&e))?;
        root.draw_text(
            "grey: no estimate    black: no ground truth",
            &text(13),
            (PAD as i32, (TITLE_H + body_h + 6) as i32),
        )
        .map_err(|e| err(&e))?;

        // The bar, its ticks and labels on the right.
        draw_bar(
            &root,
            &Bar {
                left: bar_x as i32,
                top: bar_y as i32 + 10,
                bottom: (bar_y + body_h) as i32 - 10,
                width: BAR_W as i32,
                lo: 0.0,
                hi: scale.max,
                colour: &|v| scale.colour(v as f32),
                ticks: &scale.labelled_ticks("", clipped),
                label_size: 14,
            },
        )?;
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
