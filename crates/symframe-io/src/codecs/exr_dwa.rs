//! DWAA/DWAB blocks: decoded here where every channel is lossy (colour as OpenEXR writes it),
//! by the `exr` crate otherwise, with their Huffman-coded AC section decoded here first.
//!
//! A DWA block holds four sections (unknown channels, AC and DC coefficients, RLE channels)
//! after a header of eleven 64-bit counters and the channel rules. OpenEXR codes the AC
//! coefficients with PIZ's Huffman code in scan-line files and tiled DWAB files, and with zlib
//! in tiled DWAA files. The `exr` crate rebuilds its Huffman tables over the whole
//! 65,537-symbol alphabet for each block (most of its time on small scan-line DWAA files), and
//! its DCT path converts samples one by one (most of what is left once the Huffman part is
//! ours). [`decode`] does what it does, in the same arithmetic order, so its values are
//! OpenEXR's to the bit (`tests/openexr.rs`), in about OpenEXR's time (docs/performance.md,
//! "Decoding, every compression").
//!
//! Blocks with other channels (alpha, depth: the unknown and RLE sections) go to the `exr`
//! crate, [`recode_ac`] having replaced their Huffman-coded AC section by the same values
//! stored as zlib, the format's other AC coding, which it reads at memory speed.

/// The header's counters: version, unknown sizes (raw, compressed), AC, DC and RLE compressed
/// sizes, RLE sizes (unpacked, raw), AC and DC value counts, AC coding (0 Huffman, 1 zlib).
const COUNTERS: usize = 11;
const AC_SIZE: usize = 3;
const AC_COUNT: usize = 8;
const AC_CODING: usize = 10;

/// `block` with its Huffman-coded AC section replaced by the same values stored as zlib, or
/// `None` where there is nothing to gain or the block does not parse (the `exr` crate then
/// decodes or refuses the block as it is). `max_values`: the most AC values the block's pixels
/// can have (one per sample), which bounds what a forged count allocates.
pub(super) fn recode_ac(block: &[u8], max_values: usize) -> Option<Vec<u8>> {
    let counter = |i: usize| -> Option<u64> {
        let b = block.get(8 * i..8 * i + 8)?;
        Some(u64::from_le_bytes(b.try_into().ok()?))
    };
    let mut h = [0u64; COUNTERS];
    for (i, v) in h.iter_mut().enumerate() {
        *v = counter(i)?;
    }
    let ac_count = usize::try_from(h[AC_COUNT]).ok()?;
    if h[AC_CODING] != 0 || ac_count == 0 || ac_count > max_values {
        return None;
    }
    // The channel rules (version 2 and later): a 16-bit size that counts itself, then rules.
    let mut at = 8 * COUNTERS;
    if h[0] >= 2 {
        let size = u16::from_le_bytes(block.get(at..at + 2)?.try_into().ok()?);
        at = at.checked_add(usize::from(size).max(2))?;
    }
    let ac_start = at.checked_add(usize::try_from(h[2]).ok()?)?;
    let ac_end = ac_start.checked_add(usize::try_from(h[AC_SIZE]).ok()?)?;
    let ac = block.get(ac_start..ac_end)?;
    let mut values = vec![0u16; ac_count];
    super::exr_piz::huf_decompress(ac, &mut values).ok()?;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let stored = zlib_stored(&bytes);
    h[AC_SIZE] = stored.len() as u64;
    h[AC_CODING] = 1;
    let mut out = Vec::with_capacity(block.len() - ac.len() + stored.len());
    for v in h {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&block[8 * COUNTERS..ac_start]);
    out.extend_from_slice(&stored);
    out.extend_from_slice(&block[ac_end..]);
    Some(out)
}

/// What [`decode`] needs of a channel: the part of its name after the last `.` and before it,
/// its sample type and whether it is quantised linearly (`pLinear`).
pub(super) struct DwaChannel {
    pub(super) prefix: String,
    pub(super) suffix: String,
    pub(super) sample_type: exr::meta::attribute::SampleType,
    pub(super) linear: bool,
}

/// How [`decode`] reads a DWA block whose channels are all lossy: the header's counters, where
/// its AC and DC sections lie, and the groups of channels decoded together (each Y'CbCr
/// triplet, then each other channel), with whether the group skips the transfer curve.
pub(super) struct Plan {
    h: [usize; COUNTERS],
    ac: std::ops::Range<usize>,
    dc: std::ops::Range<usize>,
    groups: Vec<(Vec<usize>, bool)>,
}

/// The [`Plan`] of a DWAA/DWAB block of `width` x `height` pixels whose channels are all lossy
/// (R, G, B, Y, BY, RY in half or float, as OpenEXR writes colour); `None` where the block
/// holds anything else (other channels, stored in its "unknown" or RLE sections; a version 1
/// block), which the `exr` crate then decodes; an error where its counts cannot be right.
pub(super) fn plan(
    block: &[u8],
    channels: &[DwaChannel],
    (width, height): (usize, usize),
) -> Option<Result<Plan, &'static str>> {
    use exr::meta::attribute::SampleType;
    let counter = |i: usize| -> Option<usize> {
        let b = block.get(8 * i..8 * i + 8)?;
        usize::try_from(u64::from_le_bytes(b.try_into().ok()?)).ok()
    };
    let mut h = [0usize; COUNTERS];
    for (i, v) in h.iter_mut().enumerate() {
        *v = counter(i)?;
    }
    // Version 2 or later, nothing in the unknown or RLE sections.
    if h[0] < 2 || h[1] != 0 || h[2] != 0 || h[5] != 0 || h[7] != 0 {
        return None;
    }
    let mut at = 8 * COUNTERS;
    let size = usize::from(u16::from_le_bytes(block.get(at..at + 2)?.try_into().ok()?));
    let rules = parse_rules(block.get(at + 2..at.checked_add(size.max(2))?)?)?;
    at += size.max(2);
    // Every channel lossy (by the block's own rules), of half or float samples.
    let mut slots: Vec<(&str, [Option<usize>; 3])> = Vec::new();
    for (i, c) in channels.iter().enumerate() {
        if !slots.iter().any(|(p, _)| *p == c.prefix) {
            slots.push((&c.prefix, [None; 3]));
        }
        let mut lossy = false;
        for r in rules.iter().filter(|r| r.matches(&c.suffix, c.sample_type)) {
            lossy = r.lossy;
            if let Some(k) = r.csc {
                if let Some((_, s)) = slots.iter_mut().find(|(p, _)| *p == c.prefix) {
                    s[k] = Some(i);
                }
            }
        }
        if !lossy || c.sample_type == SampleType::U32 {
            return None;
        }
    }
    let triplets: Vec<usize> = slots
        .iter()
        .filter_map(|(_, s)| Some([s[0]?, s[1]?, s[2]?]))
        .flatten()
        .collect();
    let groups: Vec<(Vec<usize>, bool)> = triplets
        .chunks(3)
        .map(|g| (g.to_vec(), false))
        .chain(
            (0..channels.len())
                .filter(|i| !triplets.contains(i))
                .map(|i| (vec![i], channels[i].linear)),
        )
        .collect();
    let blocks = width.div_ceil(8) * height.div_ceil(8);
    // At most one AC value per sample, one DC value per 8 x 8 block and channel.
    if h[AC_COUNT] > channels.len() * blocks * 64 || h[9] > channels.len() * blocks {
        return Some(Err("DWA coefficient counts beyond the block"));
    }
    let ac_end = at.checked_add(h[AC_SIZE])?;
    let dc_end = ac_end.checked_add(h[4])?;
    if dc_end > block.len() {
        return Some(Err("truncated DWA sections"));
    }
    Some(Ok(Plan {
        h,
        ac: at..ac_end,
        dc: ac_end..dc_end,
        groups,
    }))
}

/// Decodes a block as its [`Plan`] says, giving the samples to `sink` a row of a group of
/// channels at a time: `sink(channels, y, rows)`, `rows[i]` the whole row `y` of the block for
/// channel `channels[i]`. Follows the
/// `exr` crate's decoder step for step (the AC run lengths, the zig-zag, [`idct_8x8`], the
/// Y'CbCr inverse, the transfer curve), whose values equal OpenEXR 3.1's, but without its
/// per-block buffers and sample-by-sample conversions, and straight into the caller's image:
/// faster than it (docs/performance.md, "Decoding, every compression").
pub(super) fn decode(
    block: &[u8],
    plan: &Plan,
    (width, height): (usize, usize),
    mut sink: impl FnMut(&[usize], usize, &[&[f32]]),
) -> Result<(), &'static str> {
    use half::slice::HalfFloatSliceExt;
    let h = &plan.h;
    let (ac, dc) = (&block[plan.ac.clone()], &block[plan.dc.clone()]);
    let blocks = width.div_ceil(8) * height.div_ceil(8);
    let mut ac_values = vec![0u16; h[AC_COUNT]];
    if !ac_values.is_empty() {
        match h[AC_CODING] {
            0 => super::exr_piz::huf_decompress(ac, &mut ac_values)?,
            1 => {
                let bytes = inflate(ac, 2 * ac_values.len())?;
                for (v, b) in ac_values.iter_mut().zip(bytes.chunks_exact(2)) {
                    *v = u16::from_le_bytes([b[0], b[1]]);
                }
            }
            _ => return Err("unknown DWA AC coding"),
        }
    }
    let mut dc_values = vec![0u16; h[9]];
    if !dc_values.is_empty() {
        let bytes = undo_zip_predictor(inflate(dc, 2 * dc_values.len())?);
        for (v, b) in dc_values.iter_mut().zip(bytes.chunks_exact(2)) {
            *v = u16::from_le_bytes([b[0], b[1]]);
        }
    }
    let (mut ac_at, mut dc_at) = (0usize, 0usize);
    let (bx_n, by_n) = (width.div_ceil(8), height.div_ceil(8));
    for (group, linear) in &plan.groups {
        let k = group.len();
        // Nonlinear half to the float the channel holds: through the transfer curve, or
        // (channels quantised linearly) as it is.
        let to_float = if *linear {
            half_table()
        } else {
            to_linear_table()
        };
        let dc_group = dc_values
            .get(dc_at..dc_at + k * blocks)
            .ok_or("truncated DWA DC data")?;
        // A band of 8 rows of the group's channels, given to `sink` row by row once full.
        let mut band = vec![0.0f32; k * 8 * width];
        for by in 0..by_n {
            let rows = 8.min(height - by * 8);
            for bx in 0..bx_n {
                let b = by * bx_n + bx;
                let mut data = [[0.0f32; 64]; 3];
                for (c, data) in data.iter_mut().enumerate().take(k) {
                    // The block's coefficients in raster order: the AC values are put in
                    // place as they are read (most are zero), not gathered afterwards.
                    let mut raster = [0u16; 64];
                    raster[0] = dc_group[c * blocks + b];
                    let last = un_rle_ac(&ac_values, &mut ac_at, &mut raster)?;
                    if last == 0 {
                        let v =
                            half::f16::from_bits(raster[0]).to_f32() * 0.353_553_6 * 0.353_553_6;
                        data.fill(v);
                    } else {
                        // Converted 64 at a time (F16C): converting each coefficient on its
                        // own is a noticeable share of the decoding time
                        // (docs/performance.md, "Decoding, every compression").
                        use half::slice::HalfBitsSliceExt;
                        raster
                            .reinterpret_cast::<half::f16>()
                            .convert_to_f32_slice(data);
                        idct_8x8(data);
                    }
                }
                if k == 3 {
                    let [r, g, b] = &mut data;
                    for ((r, g), b) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
                        let (y, ry, by) = (*r, *g, *b);
                        *r = y + 1.5747 * by;
                        *g = y - 0.1873 * ry - 0.4682 * by;
                        *b = y + 1.8556 * ry;
                    }
                }
                // To half floats (nonlinear), then through the transfer curve, cropped to
                // the block's pixels, into the band.
                let cols = 8.min(width - bx * 8);
                for (c, data) in data.iter().enumerate().take(k) {
                    let mut halves = [half::f16::ZERO; 64];
                    halves.convert_from_f32_slice(data);
                    for y in 0..rows {
                        let row = &mut band[(c * 8 + y) * width + bx * 8..][..cols];
                        for (o, hv) in row.iter_mut().zip(&halves[y * 8..y * 8 + cols]) {
                            *o = to_float[usize::from(hv.to_bits())];
                        }
                    }
                }
            }
            for y in 0..rows {
                let row = |c: usize| &band[(c * 8 + y) * width..][..width];
                let all = [row(0), row(k.min(2) - 1), row(k - 1)];
                sink(group, by * 8 + y, &all[..k.min(3)]);
            }
        }
        dc_at += k * blocks;
    }
    Ok(())
}

/// The zig-zag order: raster position `i` of an 8 x 8 block holds coefficient `ZIGZAG[i]`.
const ZIGZAG: [usize; 64] = [
    0, 1, 5, 6, 14, 15, 27, 28, 2, 4, 7, 13, 16, 26, 29, 42, 3, 8, 12, 17, 25, 30, 41, 43, 9, 11,
    18, 24, 31, 40, 44, 53, 10, 19, 23, 32, 39, 45, 52, 54, 20, 22, 33, 38, 46, 51, 55, 60, 21, 34,
    37, 47, 50, 56, 59, 61, 35, 36, 48, 49, 57, 58, 62, 63,
];

/// Where coefficient `p` of the zig-zag order goes in raster order.
const UNZIGZAG: [u8; 64] = {
    let mut inv = [0; 64];
    let mut i = 0;
    while i < 64 {
        inv[ZIGZAG[i]] = i as u8;
        i += 1;
    }
    inv
};

/// Reads one block's AC values from `ac` at `*at` into `raster` (raster order; coefficient 0,
/// the DC, is not touched): a value `0xffNN` skips `NN` zeros (`0xff00`: the rest of the
/// block), any other is the next coefficient. Returns the zig-zag position of the last
/// coefficient (0: none).
fn un_rle_ac(ac: &[u16], at: &mut usize, raster: &mut [u16; 64]) -> Result<usize, &'static str> {
    let mut last = 0;
    let mut pos = 1;
    // Without branches on the token: a run writes a zero at its first position (which is
    // zero anyway) and steps over the run; a coefficient writes itself and steps by one.
    for &v in ac.get(*at..).unwrap_or_default() {
        *at += 1;
        let run = v & 0xff00 == 0xff00;
        let n = usize::from(v & 0xff);
        raster[usize::from(UNZIGZAG[pos])] = if run { 0 } else { v };
        last = if run { last } else { pos };
        pos += if !run {
            1
        } else if n == 0 {
            64
        } else {
            n
        };
        if pos >= 64 {
            return Ok(last);
        }
    }
    Err("truncated DWA AC data")
}

/// OpenEXR's inverse 8 x 8 DCT as its AVX kernel computes it (`dctInverse8x8_avx`, as the
/// `exr` crate ports it): the same products and sums in the same order, so the same bits.
/// Written on plain 8-wide arrays (one lane per row, then per column), which the compiler
/// vectorises; Rust never fuses a multiply and an add, so every step rounds as there.
fn idct_8x8(data: &mut [f32; 64]) {
    const A: f32 = 3.535_536e-1;
    const B: f32 = 4.903_927e-1;
    const C: f32 = 4.619_398e-1;
    const D: f32 = 4.157_349e-1;
    const E: f32 = 2.777_855e-1;
    const F: f32 = 1.913_422e-1;
    const G: f32 = 9.754_573e-2;
    type L = [f32; 8];
    fn mul(a: L, k: f32) -> L {
        a.map(|x| x * k)
    }
    fn add(a: L, b: L) -> L {
        std::array::from_fn(|i| a[i] + b[i])
    }
    fn sub(a: L, b: L) -> L {
        std::array::from_fn(|i| a[i] - b[i])
    }
    // Rows: lane r is row r; `i[k]` its coefficient k.
    let i: [L; 8] = std::array::from_fn(|k| std::array::from_fn(|r| data[r * 8 + k]));
    let even0 = add(
        add(mul(i[4], A), mul(i[6], F)),
        add(mul(i[0], A), mul(i[2], C)),
    );
    let even1 = add(
        add(mul(i[4], -A), mul(i[6], -C)),
        add(mul(i[0], A), mul(i[2], F)),
    );
    let even2 = add(
        add(mul(i[4], -A), mul(i[6], C)),
        add(mul(i[0], A), mul(i[2], -F)),
    );
    let even3 = add(
        add(mul(i[4], A), mul(i[6], -F)),
        add(mul(i[0], A), mul(i[2], -C)),
    );
    let odd0 = add(
        add(mul(i[5], E), mul(i[7], G)),
        add(mul(i[1], B), mul(i[3], D)),
    );
    let odd1 = add(
        add(mul(i[5], -B), mul(i[7], -E)),
        add(mul(i[1], D), mul(i[3], -G)),
    );
    let odd2 = add(
        add(mul(i[5], G), mul(i[7], D)),
        add(mul(i[1], E), mul(i[3], -B)),
    );
    let odd3 = add(
        add(mul(i[5], D), mul(i[7], -B)),
        add(mul(i[1], G), mul(i[3], -E)),
    );
    let o = [
        add(even0, odd0),
        add(even1, odd1),
        add(even2, odd2),
        add(even3, odd3),
        sub(even3, odd3),
        sub(even2, odd2),
        sub(even1, odd1),
        sub(even0, odd0),
    ];
    // Columns: lane c is column c; `i[r]` the row pass's row r.
    let i: [L; 8] = std::array::from_fn(|r| std::array::from_fn(|c| o[c][r]));
    let beta0 = add(
        add(mul(i[7], G), mul(i[5], E)),
        add(mul(i[3], D), mul(i[1], B)),
    );
    let beta1 = sub(
        sub(mul(i[1], D), add(mul(i[5], B), mul(i[3], G))),
        mul(i[7], E),
    );
    let beta2 = add(
        mul(i[7], D),
        add(mul(i[5], G), sub(mul(i[1], E), mul(i[3], B))),
    );
    let beta3 = sub(
        add(mul(i[5], D), mul(i[1], G)),
        add(mul(i[7], B), mul(i[3], E)),
    );
    let theta0 = add(mul(i[4], A), mul(i[0], A));
    let theta3 = sub(mul(i[0], A), mul(i[4], A));
    let theta1 = add(mul(i[6], F), mul(i[2], C));
    let gamma0 = add(theta1, theta0);
    let gamma3 = sub(theta0, theta1);
    let theta2 = sub(mul(i[2], F), mul(i[6], C));
    let gamma1 = add(theta3, theta2);
    let gamma2 = sub(theta3, theta2);
    let rows = [
        add(gamma0, beta0),
        add(gamma1, beta1),
        add(gamma2, beta2),
        add(gamma3, beta3),
        sub(gamma3, beta3),
        sub(gamma2, beta2),
        sub(gamma1, beta1),
        sub(gamma0, beta0),
    ];
    for (r, row) in rows.iter().enumerate() {
        data[r * 8..r * 8 + 8].copy_from_slice(row);
    }
}

/// A channel rule of a DWA block: the channels whose name ends in `suffix` (compared without
/// case where `nocase`) and whose samples are of `sample_type` are `lossy` or not, and take
/// slot `csc` (0 R, 1 G, 2 B) of their layer's Y'CbCr triplet.
struct Rule {
    suffix: Vec<u8>,
    nocase: bool,
    lossy: bool,
    csc: Option<usize>,
    sample_type: exr::meta::attribute::SampleType,
}

impl Rule {
    fn matches(&self, suffix: &str, t: exr::meta::attribute::SampleType) -> bool {
        self.sample_type == t
            && if self.nocase {
                suffix.as_bytes().eq_ignore_ascii_case(&self.suffix)
            } else {
                suffix.as_bytes() == self.suffix
            }
    }
}

/// The rules a block carries: each a NUL-terminated suffix (at most 128 bytes), a flags byte
/// (Y'CbCr slot + 1 in the high nibble, the scheme in bits 2-3, no case in bit 0) and the
/// sample type; `None` if they do not parse (the `exr` crate then reports it).
fn parse_rules(mut data: &[u8]) -> Option<Vec<Rule>> {
    use exr::meta::attribute::SampleType;
    let mut rules = Vec::new();
    while !data.is_empty() {
        let n = data.iter().position(|&b| b == 0).filter(|&n| n <= 128)?;
        let suffix = data[..n].to_vec();
        let [flags, ty] = *data.get(n + 1..n + 3)?.first_chunk::<2>()?;
        data = &data[n + 3..];
        let csc = match flags >> 4 {
            0 => None,
            k @ 1..=3 => Some(usize::from(k) - 1),
            _ => return None,
        };
        let lossy = match (flags >> 2) & 3 {
            1 => true,
            0 | 2 => false,
            _ => return None,
        };
        let sample_type = match ty {
            0 => SampleType::U32,
            1 => SampleType::F16,
            2 => SampleType::F32,
            _ => return None,
        };
        rules.push(Rule {
            suffix,
            nocase: flags & 1 != 0,
            lossy,
            csc,
            sample_type,
        });
    }
    Some(rules)
}

/// Inflates a zlib stream that must give exactly `n` bytes.
fn inflate(data: &[u8], n: usize) -> Result<Vec<u8>, &'static str> {
    let mut out = vec![0u8; n];
    let mut z = flate2::Decompress::new(true);
    match z.decompress(data, &mut out, flate2::FlushDecompress::Finish) {
        Ok(flate2::Status::StreamEnd) if z.total_out() as usize == n => Ok(out),
        _ => Err("DWA zlib data"),
    }
}

/// Undoes the predictor and the byte split of DWA's DC section (as ZIP's): each byte the
/// running sum of differences less 128, then the first half's bytes interleaved with the
/// second's.
fn undo_zip_predictor(mut d: Vec<u8>) -> Vec<u8> {
    for i in 1..d.len() {
        d[i] = d[i - 1].wrapping_add(d[i]).wrapping_sub(128);
    }
    let (a, b) = d.split_at(d.len().div_ceil(2));
    let mut out = Vec::with_capacity(d.len());
    for (i, _) in d.iter().enumerate() {
        out.push(if i % 2 == 0 { a[i / 2] } else { b[i / 2] });
    }
    out
}

/// OpenEXR's DWA transfer curve, nonlinear half to linear half, for every half (as the `exr`
/// crate computes it: `x^2.2` up to 1, `e^(2.2 (x - 1))` above, sign kept, non-finite to 0),
/// as the float of that linear half: the channel's value (a float channel's DWA values are
/// halves too). One lookup instead of a lookup and a conversion per sample.
fn to_linear_table() -> &'static [f32; 65536] {
    static TABLE: std::sync::OnceLock<Box<[f32; 65536]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = Box::new([0.0f32; 65536]);
        for (bits, slot) in t.iter_mut().enumerate() {
            let v = half::f16::from_bits(bits as u16).to_f32();
            *slot = if !v.is_finite() {
                0.0
            } else {
                let sign = if v < 0.0 { -1.0f32 } else { 1.0 };
                let a = v.abs();
                let lin = if a <= 1.0 {
                    a.powf(2.2)
                } else {
                    #[allow(clippy::excessive_precision)]
                    9.025_013_291_56_f32.powf(a - 1.0)
                };
                half::f16::from_f32(sign * lin).to_f32()
            };
        }
        t
    })
}

/// Every half as a float (channels quantised linearly skip the transfer curve).
fn half_table() -> &'static [f32; 65536] {
    static TABLE: std::sync::OnceLock<Box<[f32; 65536]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = Box::new([0.0f32; 65536]);
        for (bits, slot) in t.iter_mut().enumerate() {
            *slot = half::f16::from_bits(bits as u16).to_f32();
        }
        t
    })
}

/// `data` as a zlib stream of stored (uncompressed) deflate blocks. Written out here because
/// `flate2`'s level 0 (`miniz_oxide`) goes through its compressor byte by byte, a noticeable
/// share of decoding small scan-line DWAA files, where this is a copy and a checksum
/// (docs/performance.md, "Decoding, every compression").
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    const MAX_BLOCK: usize = 65_535;
    let mut out = Vec::with_capacity(data.len() + data.len() / MAX_BLOCK * 5 + 11);
    out.extend_from_slice(&[0x78, 0x01]);
    let mut blocks = data.chunks(MAX_BLOCK).peekable();
    if blocks.peek().is_none() {
        out.extend_from_slice(&[1, 0, 0, 0xff, 0xff]);
    }
    while let Some(block) = blocks.next() {
        let last = blocks.peek().is_none();
        let len = block.len() as u16;
        out.push(u8::from(last));
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

/// The Adler-32 checksum (RFC 1950), summed 5,552 bytes at a time before each reduction (the
/// most that cannot overflow 32 bits).
fn adler32(data: &[u8]) -> u32 {
    const MOD: u32 = 65_521;
    let (mut a, mut b) = (1u32, 0u32);
    for part in data.chunks(5552) {
        for &x in part {
            a += u32::from(x);
            b += a;
        }
        a %= MOD;
        b %= MOD;
    }
    (b << 16) | a
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The scan-line DWAA block of the OpenEXR-written fixture (one block: 32 lines of 45).
    fn dwaa_block() -> Vec<u8> {
        let p = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/openexr/scan-half-dwaa.exr"
        );
        let bytes = std::fs::read(p).unwrap();
        let mut chunks = exr::block::read(std::io::Cursor::new(&bytes), false)
            .unwrap()
            .all_chunks(false)
            .unwrap();
        match chunks.next().unwrap().unwrap().compressed_block {
            exr::block::chunk::CompressedBlock::ScanLine(b) => b.compressed_pixels_le,
            _ => unreachable!(),
        }
    }

    /// Stored zlib streams inflate back to their data (`flate2` reads them), up to several
    /// blocks of 65,535 bytes and empty.
    #[test]
    fn stored_zlib_round_trips() {
        use std::io::Read;
        for n in [0usize, 1, 5551, 5553, 65_535, 65_536, 200_000] {
            let data: Vec<u8> = (0..n).map(|i| (i * 7 + i / 251) as u8).collect();
            let mut back = Vec::new();
            flate2::read::ZlibDecoder::new(&zlib_stored(&data)[..])
                .read_to_end(&mut back)
                .unwrap();
            assert_eq!(back, data, "{n} bytes");
        }
    }

    /// The recoded block says zlib, and is left alone once it does; a count of AC values
    /// beyond the block's samples is not believed. (Its values: tests/openexr.rs, which
    /// compares every DWA fixture with OpenEXR's decoding.)
    #[test]
    fn recoded_blocks_decode_alike() {
        let block = dwaa_block();
        let recoded = recode_ac(&block, 45 * 32 * 3).expect("a Huffman-coded AC section");
        assert_eq!(u64::from_le_bytes(recoded[80..88].try_into().unwrap()), 1);
        assert!(recode_ac(&recoded, 45 * 32 * 3).is_none(), "already zlib");
        assert!(recode_ac(&block, 10).is_none(), "more values than samples");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// A DWA block with bytes changed or cut short gives a block, an error or `None`,
        /// never a panic, whatever size it is said to have.
        #[test]
        fn forged_blocks_do_not_panic(
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..6),
            cut in any::<usize>(),
        ) {
            let mut b = dwaa_block();
            for (i, v) in edits {
                let n = b.len();
                b[i % n] = v;
            }
            b.truncate(cut % (b.len() + 1));
            let _ = recode_ac(&b, 45 * 32 * 3);
            let channels: Vec<DwaChannel> = ["B", "G", "R"]
                .into_iter()
                .map(|n| DwaChannel {
                    prefix: String::new(),
                    suffix: n.into(),
                    sample_type: exr::meta::attribute::SampleType::F16,
                    linear: false,
                })
                .collect();
            for size in [(45, 32), (7, 300)] {
                if let Some(Ok(p)) = plan(&b, &channels, size) {
                    let _ = decode(&b, &p, size, |_, _, _| {});
                }
            }
        }
    }
}
