//! Making a decoded image's samples linear, one run of pixels at a time (a whole image, a band
//! of rows, one row): every reader (whole images, row by row) converts through [`Convert`], so
//! they agree bit for bit.

use std::path::Path;

use super::{srgb_to_linear, DecodeOptions, SampleKind};
use crate::error::{Error, Result};

/// Decoded samples in the file's own type, a run of whole pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) enum RawRun<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
    F32(&'a [f32]),
}

/// The sample type of a decoded image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SampleType {
    U8,
    U16,
    F32,
}

/// How one image's samples become linear `f32`: grey or RGB kept (alpha dropped), integer
/// samples made linear by the transfer curve `opts.gamma` picks, a pixel with any kept sample
/// at or above the saturation level all `+inf`, a float pixel with any non-finite sample all
/// `NaN`.
#[derive(Debug, Clone)]
pub(crate) struct Convert {
    /// Samples per pixel in the file (1 to 4).
    ch: usize,
    /// Samples kept per pixel: 1 (grey) or 3 (RGB).
    take: usize,
    /// What the file stored and how it is made linear.
    kind: SampleKind,
    /// 8-bit codes made linear.
    lut8: [f32; 256],
    /// Raw value at or above which an integer sample is saturated.
    sat: f32,
    /// 16-bit samples are sRGB-decoded.
    srgb16: bool,
}

impl Convert {
    /// The conversion of an image of `ch` samples per pixel of type `ty` (`integer`: a
    /// format whose integer samples may be gamma-encoded, decoded by `opts.gamma`).
    pub(crate) fn new(
        path: &Path,
        ch: usize,
        ty: SampleType,
        integer: bool,
        opts: &DecodeOptions,
    ) -> Result<Self> {
        let take = match ch {
            1 | 2 => 1,
            3 | 4 => 3,
            _ => return Err(Error::unsupported(path, format!("{ch}-channel image"))),
        };
        let (srgb8, srgb16) = (
            integer && opts.gamma.srgb(8),
            integer && opts.gamma.srgb(16),
        );
        let kind = match ty {
            SampleType::U8 if srgb8 => SampleKind::Srgb8,
            SampleType::U8 => SampleKind::Linear8,
            SampleType::U16 if srgb16 => SampleKind::Srgb16,
            SampleType::U16 => SampleKind::U16,
            SampleType::F32 => SampleKind::Float,
        };
        let mut lut8 = [0.0f32; 256];
        for (i, v) in lut8.iter_mut().enumerate() {
            *v = linear_value(srgb8, 8, i as u32);
        }
        let sat = match ty {
            SampleType::U8 => opts.saturation * 255.0,
            SampleType::U16 => opts.saturation * 65535.0,
            SampleType::F32 => f32::INFINITY,
        };
        Ok(Self {
            ch,
            take,
            kind,
            lut8,
            sat,
            srgb16,
        })
    }

    /// Samples per pixel in the file.
    pub(crate) fn channels(&self) -> usize {
        self.ch
    }

    /// Samples kept per pixel: 1 (grey) or 3 (RGB).
    pub(crate) fn take(&self) -> usize {
        self.take
    }

    /// What the file stored and how it is made linear.
    pub(crate) fn kind(&self) -> SampleKind {
        self.kind
    }

    /// Converts the whole pixels of `src` into `out`, `out_ch` samples a pixel: [`Self::take`],
    /// or 3 with grey replicated. Returns how many kept samples are negative (a grey one
    /// counted once).
    pub(crate) fn run(&self, src: RawRun, out: &mut [f32], out_ch: usize) -> usize {
        debug_assert!(out_ch == self.take || out_ch == 3);
        match src {
            RawRun::U8(v) => {
                self.each(v, out, out_ch, |px, o| {
                    if px.iter().any(|&s| s as f32 >= self.sat) {
                        o.fill(f32::INFINITY);
                    } else {
                        for (o, &s) in o.iter_mut().zip(px) {
                            *o = self.lut8[s as usize];
                        }
                    }
                });
                0
            }
            RawRun::U16(v) => {
                let linear = |s: u16| linear_value(self.srgb16, 16, s as u32);
                self.each(v, out, out_ch, |px, o| {
                    if px.iter().any(|&s| s as f32 >= self.sat) {
                        o.fill(f32::INFINITY);
                    } else {
                        for (o, &s) in o.iter_mut().zip(px) {
                            *o = linear(s);
                        }
                    }
                });
                0
            }
            // Nothing dropped or replicated: one copy, then a check that is vectorised
            // while every sample is finite (the usual case).
            RawRun::F32(v) if out_ch == self.ch => {
                let n = v.len().min(out.len());
                let out = &mut out[..n];
                out.copy_from_slice(&v[..n]);
                if out.iter().all(|s| s.is_finite()) {
                    return out.iter().filter(|&&s| s < 0.0).count();
                }
                out.chunks_exact_mut(out_ch).map(mark_non_finite).sum()
            }
            RawRun::F32(v) => {
                let mut negative = 0;
                self.each(v, out, out_ch, |px, o| {
                    o.copy_from_slice(px);
                    negative += mark_non_finite(o);
                });
                negative
            }
        }
    }

    /// The first integer code at or above the saturation level (a pixel with any kept sample
    /// at or above it is saturated); `2^bits` when none is, `0` for float samples (unused).
    pub(crate) fn first_saturated(&self) -> u32 {
        let max: u32 = match self.kind {
            SampleKind::Srgb8 | SampleKind::Linear8 => 255,
            SampleKind::U16 | SampleKind::Srgb16 => 65535,
            SampleKind::Float => return 0,
        };
        // `s as f32` grows with `s`: the codes at or above the level are one final range.
        let (mut lo, mut hi) = (0u32, max + 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if mid as f32 >= self.sat {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    }

    /// Copies the kept integer samples of the whole pixels of `src` into `out`, 3 a pixel
    /// (grey replicated), as the file stores them: what an integer tile cache keeps, made
    /// linear when read ([`linear_table`]). Float samples are refused (`false`).
    pub(crate) fn codes(&self, src: RawRun, out: &mut [u16]) -> bool {
        fn copy<T: Copy + Into<u16>>(ch: usize, take: usize, src: &[T], out: &mut [u16]) {
            for (px, o) in src.chunks_exact(ch).zip(out.chunks_exact_mut(3)) {
                if take == 3 {
                    for (o, &s) in o.iter_mut().zip(&px[..3]) {
                        *o = s.into();
                    }
                } else {
                    o.fill(px[0].into());
                }
            }
        }
        match src {
            RawRun::U8(v) => copy(self.ch, self.take, v, out),
            RawRun::U16(v) => copy(self.ch, self.take, v, out),
            RawRun::F32(_) => return false,
        }
        true
    }

    /// Calls `one(kept samples, their linear values)` for each pixel of `src`, then writes the
    /// values into `out` (`out_ch` a pixel, grey replicated).
    fn each<T: Copy>(
        &self,
        src: &[T],
        out: &mut [f32],
        out_ch: usize,
        mut one: impl FnMut(&[T], &mut [f32]),
    ) {
        let take = self.take;
        for (px, o) in src.chunks_exact(self.ch).zip(out.chunks_exact_mut(out_ch)) {
            let mut v = [0.0f32; 3];
            one(&px[..take], &mut v[..take]);
            if take == out_ch {
                o.copy_from_slice(&v[..take]);
            } else {
                o.fill(v[0]);
            }
        }
    }
}

/// The linear value of the integer code `s` of a `bits`-bit sample (8 or 16), sRGB-decoded
/// or not: the one definition of [`Convert`]'s curves, so that tables built from it
/// ([`linear_table`]) give its values bit for bit.
fn linear_value(srgb: bool, bits: u32, s: u32) -> f32 {
    let x = s as f32 / if bits == 8 { 255.0 } else { 65535.0 };
    if srgb {
        srgb_to_linear(x)
    } else {
        x
    }
}

/// The linear values of every code of samples of `kind` (an integer kind), `len` entries:
/// codes past the kind's largest (none in a file this crate wrote) read as `NaN`.
pub(crate) fn linear_table(kind: SampleKind, len: usize) -> Vec<f32> {
    let (srgb, bits) = match kind {
        SampleKind::Srgb8 => (true, 8),
        SampleKind::Linear8 => (false, 8),
        SampleKind::Srgb16 => (true, 16),
        SampleKind::U16 | SampleKind::Float => (false, 16),
    };
    let codes = 1usize << bits;
    (0..len)
        .map(|s| {
            if s < codes {
                linear_value(srgb, bits, s as u32)
            } else {
                f32::NAN
            }
        })
        .collect()
}

/// Sets a float pixel's samples all `NaN` when any is not finite; returns how many of them
/// are negative (after marking).
pub(crate) fn mark_non_finite(px: &mut [f32]) -> usize {
    if !px.iter().all(|s| s.is_finite()) {
        px.fill(f32::NAN);
        return 0;
    }
    px.iter().filter(|&&v| v < 0.0).count()
}
