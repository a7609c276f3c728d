//! Integer caches (`u8`, `u16`): the images' own codes are stored, and each light's record of
//! how they become the samples a float cache would hold (transfer curve, saturation level,
//! intensity) is kept in a table at the file's end, applied when a tile is read so that the
//! values equal the float path's bit for bit.

use crate::codecs::SampleKind;

/// Bytes of one light's record in the table: kind, first saturated code, whether there is an
/// intensity, the intensity's three `f32`, zero padding (little-endian).
pub(super) const LIGHT_RECORD_BYTES: usize = 32;

/// How one light's codes become linear samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LightCodes {
    /// The image's sample kind: its transfer curve (an integer kind).
    pub(super) kind: SampleKind,
    /// The first code at or above the saturation level: a pixel with any code at or above it
    /// reads `+inf` (divided by the intensity).
    pub(super) first_saturated: u32,
    /// The light's intensity, when the dataset has intensities: samples are divided by it.
    pub(super) intensity: Option<[f32; 3]>,
}

/// A kind's code in the table (0: no record written).
fn kind_code(k: SampleKind) -> u32 {
    match k {
        SampleKind::Linear8 => 1,
        SampleKind::Srgb8 => 2,
        SampleKind::U16 => 3,
        SampleKind::Srgb16 => 4,
        SampleKind::Float => 0,
    }
}

impl LightCodes {
    /// The record's bytes.
    pub(super) fn encode(&self) -> [u8; LIGHT_RECORD_BYTES] {
        let mut b = [0u8; LIGHT_RECORD_BYTES];
        b[..4].copy_from_slice(&kind_code(self.kind).to_le_bytes());
        b[4..8].copy_from_slice(&self.first_saturated.to_le_bytes());
        if let Some(k) = self.intensity {
            b[8..12].copy_from_slice(&1u32.to_le_bytes());
            for (c, v) in k.iter().enumerate() {
                b[12 + 4 * c..16 + 4 * c].copy_from_slice(&v.to_bits().to_le_bytes());
            }
        }
        b
    }

    /// Reads a record; `None` when it is not one an integer cache of `max_bits`-bit codes
    /// (8 or 16) can hold (an 8-bit cache holds only 8-bit kinds).
    pub(super) fn decode(b: &[u8], max_bits: u32) -> Option<Self> {
        let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        if b.len() != LIGHT_RECORD_BYTES {
            return None;
        }
        let kind = match u(0) {
            1 => SampleKind::Linear8,
            2 => SampleKind::Srgb8,
            3 if max_bits == 16 => SampleKind::U16,
            4 if max_bits == 16 => SampleKind::Srgb16,
            _ => return None,
        };
        let intensity = match u(8) {
            0 => None,
            1 => Some([0, 1, 2].map(|c| f32::from_bits(u(12 + 4 * c)))),
            _ => return None,
        };
        Some(Self {
            kind,
            first_saturated: u(4),
            intensity,
        })
    }
}

/// What reading one light needs: its table of linear values, saturation level and intensity.
#[derive(Debug, Clone, Copy)]
struct LightDecode {
    table: usize,
    first_saturated: u32,
    intensity: Option<[f32; 3]>,
}

/// The decoding of an integer cache's codes: one table of linear values per sample kind
/// present (built once when the cache is opened: 256 entries for `u8`, 65,536 for `u16`), and
/// each light's.
#[derive(Debug, Clone)]
pub(crate) struct CodeTables {
    tables: Vec<Vec<f32>>,
    lights: Vec<LightDecode>,
}

impl CodeTables {
    /// The tables of these lights' records, for codes below `codes` (256 or 65,536).
    pub(super) fn new(records: &[LightCodes], codes: usize) -> Self {
        let mut kinds: Vec<SampleKind> = Vec::new();
        let lights = records
            .iter()
            .map(|r| {
                let table = kinds.iter().position(|&k| k == r.kind).unwrap_or_else(|| {
                    kinds.push(r.kind);
                    kinds.len() - 1
                });
                LightDecode {
                    table,
                    first_saturated: r.first_saturated,
                    intensity: r.intensity,
                }
            })
            .collect();
        let tables = kinds
            .iter()
            .map(|&k| crate::codecs::linear_table(k, codes))
            .collect();
        Self { tables, lights }
    }

    /// Light `light`'s RGB sample from its three codes, as the float path computes it: `+inf`
    /// on all three when any code is saturated, else each code's linear value; divided by the
    /// intensity when there is one.
    #[inline]
    pub(super) fn rgb<T: Copy + Into<u32>>(&self, light: usize, codes: &[T], out: &mut [f32]) {
        let d = &self.lights[light];
        let table = &self.tables[d.table];
        let c: [u32; 3] = [codes[0].into(), codes[1].into(), codes[2].into()];
        let mut v = if c.iter().any(|&c| c >= d.first_saturated) {
            [f32::INFINITY; 3]
        } else {
            c.map(|c| table[c as usize])
        };
        if let Some(k) = d.intensity {
            for (v, k) in v.iter_mut().zip(k) {
                *v /= k;
            }
        }
        out[..3].copy_from_slice(&v);
    }
}
