//! PIZ decompression of OpenEXR blocks: Huffman decoding, the inverse Haar-like wavelet and the
//! value lookup, as OpenEXR's `ImfPizCompressor.cpp` and `ImfHuf.cpp` define them.
//!
//! Written here rather than taken from the `exr` crate because that crate's decoder rebuilds
//! tables over the whole 65,537-symbol alphabet for every block and keeps a heap vector per
//! table entry, several times OpenEXR's time on small images. This one touches only the
//! symbols a block uses, reads the bit stream a word at a time and keeps the decoded samples as
//! 16-bit planes, which the caller converts straight into its output (no interleaved copy of
//! the block): about OpenEXR's time (docs/performance.md, "Decoding, every compression").
//!
//! Every length, code and count read from the file is checked: a forged block gives an error,
//! never a panic, and allocations are bounded by the block's pixel count.

/// A symbol's code length: 0 (unused) to 58 bits.
const MAX_CODE_LEN: usize = 58;
/// Bits of the direct decoding table: codes up to this long are looked up at once, longer
/// ones by length. OpenEXR's `hufDecode` uses 14 bits; 11 keep the table (8 KB) in the L1
/// cache, which decodes faster (docs/performance.md, "Decoding, every compression").
const DEC_BITS: u32 = 11;
const DEC_SIZE: usize = 1 << DEC_BITS;
/// Code lengths 59 to 62 stand for 2 to 5 unused symbols, 63 for 6 to 261 (8 bits follow).
const SHORT_ZEROCODE_RUN: u64 = 59;
const LONG_ZEROCODE_RUN: u64 = 63;
const SHORTEST_LONG_RUN: u64 = 2 + LONG_ZEROCODE_RUN - SHORT_ZEROCODE_RUN;
/// The alphabet: every 16-bit value, and one more for the run-length code.
const ENC_SIZE: usize = (1 << 16) + 1;

/// What went wrong in a block (the caller names the file and the compression).
pub(super) type PizError = &'static str;

/// The decoded samples of one PIZ block, as 16-bit words: channel after channel (in the
/// part's channel order), each channel's lines one after the other, a float or uint sample as
/// two words (low half first).
pub(super) fn decompress(
    input: &[u8],
    channel_words: &[usize],
    (width, height): (usize, usize),
) -> Result<Vec<u16>, PizError> {
    let total: usize = channel_words.iter().map(|w| w * width * height).sum();
    let mut r = input;
    let min_non_zero = usize::from(read_u16(&mut r)?);
    let max_non_zero = usize::from(read_u16(&mut r)?);
    const BITMAP_SIZE: usize = 8192;
    if max_non_zero >= BITMAP_SIZE || min_non_zero >= BITMAP_SIZE {
        return Err("bitmap range");
    }
    let mut bitmap = [0u8; BITMAP_SIZE];
    if min_non_zero <= max_non_zero {
        let n = max_non_zero - min_non_zero + 1;
        let bytes = r.get(..n).ok_or("truncated bitmap")?;
        bitmap[min_non_zero..=max_non_zero].copy_from_slice(bytes);
        r = &r[n..];
    }
    let lut = reverse_lut(&bitmap, min_non_zero, max_non_zero);
    let max_value = (lut.len() - 1) as u16;
    let length = read_u32(&mut r)? as usize;
    let huf = r.get(..length).ok_or("truncated Huffman data")?;
    let mut words = vec![0u16; total];
    huf_decompress(huf, &mut words)?;
    let mut at = 0;
    for &cw in channel_words {
        let n = cw * width * height;
        let plane = &mut words[at..at + n];
        wav2_decode_plane(plane, width, height, cw, max_value);
        at += n;
    }
    apply_lut(&mut words, &lut);
    Ok(words)
}

fn read_u16(r: &mut &[u8]) -> Result<u16, PizError> {
    let (b, rest) = r.split_first_chunk::<2>().ok_or("truncated header")?;
    *r = rest;
    Ok(u16::from_le_bytes(*b))
}

fn read_u32(r: &mut &[u8]) -> Result<u32, PizError> {
    let (b, rest) = r.split_first_chunk::<4>().ok_or("truncated header")?;
    *r = rest;
    Ok(u32::from_le_bytes(*b))
}

/// The values the bitmap marks (0 always), in increasing order, as a lookup from their rank
/// (OpenEXR's `reverseLutFromBitmap`; ranks past the last give 0 there, and are refused by
/// [`apply_lut`] here); only bytes `lo..=hi` of the bitmap can be non-zero.
fn reverse_lut(bitmap: &[u8; 8192], lo: usize, hi: usize) -> Vec<u16> {
    let mut lut = vec![0u16];
    for (byte, &b) in bitmap.iter().enumerate().take(hi + 1).skip(lo) {
        for bit in 0..8 {
            let v = byte * 8 + bit;
            if b & (1 << bit) != 0 && v != 0 {
                lut.push(v as u16);
            }
        }
    }
    lut
}

/// Replaces each word by the value of its rank; a rank the bitmap does not have gives 0, as in
/// OpenEXR (whose table is zero past the last rank).
fn apply_lut(words: &mut [u16], lut: &[u16]) {
    if lut.iter().enumerate().all(|(i, &v)| usize::from(v) == i) {
        // Every value up to the largest is used: ranks are values, except beyond it.
        let max = lut.len() - 1;
        for w in words {
            if usize::from(*w) > max {
                *w = 0;
            }
        }
        return;
    }
    for w in words {
        *w = lut.get(usize::from(*w)).copied().unwrap_or(0);
    }
}

/// One step of the 14-bit inverse wavelet (values that fit in 14 bits, so no wrap-around).
#[inline(always)]
fn wdec14(l: u16, h: u16) -> (u16, u16) {
    let ls = l as i16 as i32;
    let hi = h as i16 as i32;
    let ai = ls + (hi & 1) + (hi >> 1);
    (ai as i16 as u16, (ai - hi) as i16 as u16)
}

/// One step of the 16-bit inverse wavelet (modulo 2^16).
#[inline(always)]
fn wdec16(l: u16, h: u16) -> (u16, u16) {
    const A_OFFSET: i32 = 1 << 15;
    const MOD_MASK: i32 = 0xffff;
    let m = i32::from(l);
    let d = i32::from(h);
    let bb = (m - (d >> 1)) & MOD_MASK;
    let aa = (d + bb - A_OFFSET) & MOD_MASK;
    (aa as u16, bb as u16)
}

/// The inverse 2D wavelet of one channel's plane of `nx` x `ny` samples of `cw` words each:
/// OpenEXR's `wav2Decode` of each word of the sample (`cw` interleaved transforms); `mx`, the
/// largest value, picks the 14- or 16-bit form.
fn wav2_decode_plane(plane: &mut [u16], nx: usize, ny: usize, cw: usize, mx: u16) {
    match (mx < (1 << 14), cw) {
        (true, 1) => wav2_plane::<1>(plane, nx, ny, wdec14),
        (true, 2) => wav2_plane::<2>(plane, nx, ny, wdec14),
        (false, 1) => wav2_plane::<1>(plane, nx, ny, wdec16),
        (false, 2) => wav2_plane::<2>(plane, nx, ny, wdec16),
        // No sample type has other sizes; the general form for completeness.
        (w14, _) => {
            let dec = if w14 { wdec14 } else { wdec16 };
            for j in 0..cw {
                if let Some(buf) = plane.get_mut(j..) {
                    wav2_decode_with(buf, nx, cw, ny, cw * nx, 2, dec);
                }
            }
            if nx.min(ny) >= 2 {
                wav2_finest(plane, nx, cw, dec);
            }
        }
    }
}

/// [`wav2_decode_plane`] for samples of `CW` words: the coarse levels by index, then the
/// finest level (three quarters of the work) by rows, without index checks.
#[inline(always)]
fn wav2_plane<const CW: usize>(
    plane: &mut [u16],
    nx: usize,
    ny: usize,
    dec: impl Fn(u16, u16) -> (u16, u16) + Copy,
) {
    for j in 0..CW {
        if let Some(buf) = plane.get_mut(j..) {
            wav2_decode_with(buf, nx, CW, ny, CW * nx, 2, dec);
        }
    }
    if nx.min(ny) >= 2 {
        wav2_finest(plane, nx, CW, dec);
    }
}

/// The finest level of the inverse wavelet (OpenEXR's `wav2Decode` with `p` = 1) on a plane
/// of `nx`-sample rows of `cw` words: each 2 x 2 block of samples, then the odd column and the
/// odd row.
#[inline(always)]
fn wav2_finest(plane: &mut [u16], nx: usize, cw: usize, dec: impl Fn(u16, u16) -> (u16, u16)) {
    let oy = nx * cw;
    let mut pairs = plane.chunks_exact_mut(2 * oy);
    for rows in pairs.by_ref() {
        let (top, bottom) = rows.split_at_mut(oy);
        let mut quads = top
            .chunks_exact_mut(2 * cw)
            .zip(bottom.chunks_exact_mut(2 * cw));
        for (a, b) in quads.by_ref() {
            for j in 0..cw {
                let (i00, i10) = dec(a[j], b[j]);
                let (i01, i11) = dec(a[cw + j], b[cw + j]);
                (a[j], a[cw + j]) = dec(i00, i01);
                (b[j], b[cw + j]) = dec(i10, i11);
            }
        }
        if nx & 1 != 0 {
            let (a, b) = (&mut top[oy - cw..], &mut bottom[oy - cw..]);
            for j in 0..cw {
                (a[j], b[j]) = dec(a[j], b[j]);
            }
        }
    }
    // An odd row left over (the plane holds whole rows).
    for a in pairs.into_remainder().chunks_exact_mut(2 * cw) {
        for j in 0..cw {
            (a[j], a[cw + j]) = dec(a[j], a[cw + j]);
        }
    }
}

/// The levels of OpenEXR's `wav2Decode` down to `p` = `finest` (1: all of them) on `nx` x `ny`
/// values of `buf`, `ox` apart in x and `oy` in y.
#[inline(always)]
fn wav2_decode_with(
    buf: &mut [u16],
    nx: usize,
    ox: usize,
    ny: usize,
    oy: usize,
    finest: usize,
    dec: impl Fn(u16, u16) -> (u16, u16),
) {
    let n = nx.min(ny);
    if n == 0 {
        return;
    }
    let mut p = 1usize;
    while p <= n {
        p <<= 1;
    }
    p >>= 1;
    let mut p2 = p;
    p >>= 1;
    while p >= finest {
        let (oy1, oy2, ox1, ox2) = (oy * p, oy * p2, ox * p, ox * p2);
        let ey = oy * (ny - p2);
        let ex = ox * (nx - p2);
        let mut py = 0;
        while py <= ey {
            let mut px = py;
            while px <= py + ex {
                let (p01, p10) = (px + ox1, px + oy1);
                let p11 = p10 + ox1;
                let (i00, i10) = dec(buf[px], buf[p10]);
                let (i01, i11) = dec(buf[p01], buf[p11]);
                (buf[px], buf[p01]) = dec(i00, i01);
                (buf[p10], buf[p11]) = dec(i10, i11);
                px += ox2;
            }
            if nx & p != 0 {
                let p10 = px + oy1;
                (buf[px], buf[p10]) = dec(buf[px], buf[p10]);
            }
            py += oy2;
        }
        if ny & p != 0 {
            let mut px = py;
            while px <= py + ex {
                let p01 = px + ox1;
                (buf[px], buf[p01]) = dec(buf[px], buf[p01]);
                px += ox2;
            }
        }
        p2 = p;
        p >>= 1;
    }
}

/// Reads `n` bits (at most 8) from a byte stream, most significant first, as OpenEXR's
/// table unpacking does (`getBits`).
struct TableBits<'a> {
    bytes: &'a [u8],
    pos: usize,
    c: u64,
    lc: u32,
}

impl TableBits<'_> {
    fn get(&mut self, n: u32) -> Result<u64, PizError> {
        while self.lc < n {
            let b = *self.bytes.get(self.pos).ok_or("truncated code table")?;
            self.c = (self.c << 8) | u64::from(b);
            self.pos += 1;
            self.lc += 8;
        }
        self.lc -= n;
        Ok((self.c >> self.lc) & ((1 << n) - 1))
    }
}

/// OpenEXR's `hufUncompress` into `out` (its length is the symbol count the block must hold):
/// PIZ's Huffman code, which DWA's AC coefficients use too.
pub(super) fn huf_decompress(input: &[u8], out: &mut [u16]) -> Result<(), PizError> {
    if input.is_empty() {
        return if out.is_empty() {
            Ok(())
        } else {
            Err("no Huffman data")
        };
    }
    let mut r = input;
    let im = read_u32(&mut r)? as usize;
    let i_max = read_u32(&mut r)? as usize;
    let _table_length = read_u32(&mut r)?;
    let n_bits = u64::from(read_u32(&mut r)?);
    let _reserved = read_u32(&mut r)?;
    if im >= ENC_SIZE || i_max >= ENC_SIZE || im > i_max {
        return Err("Huffman table size");
    }
    // The code lengths of symbols im..=i_max, then their canonical codes (`len | code << 6`).
    // The symbols that have a code, in increasing order, as `symbol << 8 | length`: only
    // these are visited below (a block's table spans up to 65,537 symbols, most unused).
    let n_symbols = i_max - im + 1;
    let mut used: Vec<u32> = Vec::new();
    let mut bits = TableBits {
        bytes: r,
        pos: 0,
        c: 0,
        lc: 0,
    };
    let mut i = 0;
    while i < n_symbols {
        let l = bits.get(6)?;
        if l == LONG_ZEROCODE_RUN {
            let run = (bits.get(8)? + SHORTEST_LONG_RUN) as usize;
            if i + run > n_symbols {
                return Err("Huffman table too long");
            }
            i += run;
        } else if l >= SHORT_ZEROCODE_RUN {
            let run = (l - SHORT_ZEROCODE_RUN + 2) as usize;
            if i + run > n_symbols {
                return Err("Huffman table too long");
            }
            i += run;
        } else {
            if l > 0 {
                used.push((((im + i) as u32) << 8) | l as u32);
            }
            i += 1;
        }
    }
    let data = &r[bits.pos..];
    if n_bits > 8 * data.len() as u64 {
        return Err("Huffman bit count beyond the block");
    }
    // Canonical codes (OpenEXR's `hufCanonicalCodeTable`): longest codes first, numbered up.
    let mut next = [0u64; MAX_CODE_LEN + 1];
    for &u in &used {
        next[(u & 0xff) as usize] += 1;
    }
    let mut c = 0u64;
    for l in (1..=MAX_CODE_LEN).rev() {
        let nc = (c + next[l]) >> 1;
        next[l] = c;
        c = nc;
    }
    // The decoding tables: codes of up to `DEC_BITS` bits through a direct table (as OpenEXR's
    // `hufBuildDecTable`), longer ones canonically, by length (as OpenEXR's `FastHufDecoder`):
    // a length's codes are consecutive numbers from `first[l]`, given to its symbols in
    // increasing order, and a longer code's first `l` bits are below `first[l]`.
    let mut table = vec![0u32; DEC_SIZE];
    let mut long = LongCodes {
        first: [0; MAX_CODE_LEN + 1],
        count: [0; MAX_CODE_LEN + 1],
        at: [0; MAX_CODE_LEN + 1],
        symbols: Vec::new(),
        max_len: 0,
    };
    for &u in &used {
        let (symbol, l) = (u >> 8, u & 0xff);
        let code = next[l as usize];
        next[l as usize] += 1;
        if code >> l != 0 {
            return Err("invalid Huffman code");
        }
        if l > DEC_BITS {
            let lu = l as usize;
            if long.count[lu] == 0 {
                long.first[lu] = code;
            }
            long.count[lu] += 1;
            long.max_len = long.max_len.max(l);
        } else {
            let start = (code << (DEC_BITS - l)) as usize;
            let entries = &mut table[start..start + (1 << (DEC_BITS - l))];
            if entries.iter().any(|&e| e != 0) {
                return Err("invalid Huffman code");
            }
            entries.fill(l | (symbol << 8));
        }
    }
    if long.max_len > 0 {
        let mut n = 0;
        for l in 0..=MAX_CODE_LEN {
            long.at[l] = n;
            n += long.count[l] as usize;
        }
        long.symbols = vec![0; n];
        let mut next = long.at;
        for &u in &used {
            let l = (u & 0xff) as usize;
            if l > DEC_BITS as usize {
                long.symbols[next[l]] = u >> 8;
                next[l] += 1;
            }
        }
    }
    let n_bytes = n_bits.div_ceil(8) as usize;
    decode(&table, &long, &data[..n_bytes], n_bits, i_max as u32, out)
}

/// The codes longer than the direct table's `DEC_BITS` bits, by length: the first code, how many
/// there are, and where their symbols start in `symbols`.
struct LongCodes {
    first: [u64; MAX_CODE_LEN + 1],
    count: [u64; MAX_CODE_LEN + 1],
    at: [usize; MAX_CODE_LEN + 1],
    symbols: Vec<u32>,
    max_len: u32,
}

impl LongCodes {
    /// The symbol and length of the code at the top of the `lc` low bits of `c`.
    #[inline]
    fn find(&self, c: u64, lc: u32) -> Option<(u32, u32)> {
        for l in DEC_BITS + 1..=self.max_len.min(lc) {
            let lu = l as usize;
            if self.count[lu] == 0 {
                continue;
            }
            let v = (c >> (lc - l)) & ((1u64 << l) - 1);
            if v >= self.first[lu] {
                let i = v - self.first[lu];
                return (i < self.count[lu]).then(|| (self.symbols[self.at[lu] + i as usize], l));
            }
        }
        None
    }
}

/// Decodes the bit stream (OpenEXR's `hufDecode`): `rlc`, the run-length symbol, repeats the
/// previous value as many times as the next 8 bits say.
#[allow(clippy::too_many_arguments)]
fn decode(
    table: &[u32],
    long: &LongCodes,
    data: &[u8],
    n_bits: u64,
    rlc: u32,
    out: &mut [u16],
) -> Result<(), PizError> {
    // The bit buffer: the low `lc` bits of `c` are the next bits of the stream (most
    // significant first); `pos` is the next byte of `data`.
    let mut c: u64 = 0;
    let mut lc: u32 = 0;
    let mut pos = 0usize;
    let mut o = 0usize;
    let end = out.len();

    // Emits symbol `s` (or a run of the previous value).
    macro_rules! emit {
        ($s:expr) => {{
            let s: u32 = $s;
            if s == rlc {
                if lc < 8 {
                    let b = *data.get(pos).ok_or("truncated Huffman run")?;
                    c = (c << 8) | u64::from(b);
                    pos += 1;
                    lc += 8;
                }
                lc -= 8;
                let run = ((c >> lc) & 0xff) as usize;
                if o == 0 || o + run > end {
                    return Err("Huffman run outside the block");
                }
                let v = out[o - 1];
                out[o..o + run].fill(v);
                o += run;
            } else if o < end {
                out[o] = s as u16;
                o += 1;
            } else {
                return Err("more Huffman symbols than samples");
            }
        }};
    }

    // Decodes the code at the top of the buffer (at least `DEC_BITS` bits in it).
    macro_rules! step {
        () => {{
            let e = table[((c >> (lc - DEC_BITS)) as usize) & (DEC_SIZE - 1)];
            let len = e & 0x7f;
            if len != 0 {
                lc -= len;
                emit!(e >> 8);
            } else {
                // A long code: as many bits as the longest code where the data has them.
                while lc < long.max_len && lc <= 56 && pos < data.len() {
                    c = (c << 8) | u64::from(data[pos]);
                    pos += 1;
                    lc += 8;
                }
                let (s, l) = long.find(c, lc).ok_or("invalid Huffman code")?;
                lc -= l;
                emit!(s);
            }
        }};
    }

    // While eight bytes are left: refill to 56 bits or more in one read, then decode while
    // 22 bits are there (a table code and a run's 8 bits).
    while let Some(b) = data.get(pos..pos + 8) {
        let w = u64::from_be_bytes(b.try_into().unwrap_or([0; 8]));
        let take = (64 - lc) / 8;
        c = if take == 8 {
            w
        } else {
            (c << (8 * take)) | (w >> (64 - 8 * take))
        };
        pos += take as usize;
        lc += 8 * take;
        while lc >= 22 {
            step!();
        }
    }
    // The last bytes, one at a time.
    loop {
        while lc <= 56 && pos < data.len() {
            c = (c << 8) | u64::from(data[pos]);
            pos += 1;
            lc += 8;
        }
        if lc < DEC_BITS {
            break;
        }
        while lc >= DEC_BITS {
            step!();
            if lc < 22 && pos < data.len() {
                break;
            }
        }
    }
    // The last bits: drop the padding of the last byte, then decode what is left.
    let pad = (n_bits.wrapping_neg() & 7) as u32;
    if pad > lc {
        return Err("Huffman bit count");
    }
    c >>= pad;
    lc -= pad;
    while lc > 0 {
        let e = table[((c << (DEC_BITS - lc.min(DEC_BITS))) >> (lc - lc.min(DEC_BITS))) as usize
            & (DEC_SIZE - 1)];
        let len = e & 0x7f;
        if len == 0 || len > lc {
            return Err("invalid Huffman code");
        }
        lc -= len;
        emit!(e >> 8);
    }
    if o != end {
        return Err("fewer Huffman symbols than samples");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Compressed blocks, words per sample of each channel, block size, decoded words.
    type Fixture = (Vec<Vec<u8>>, Vec<usize>, (usize, usize), Vec<u16>);

    /// The compressed blocks of a PIZ file written by the `exr` crate: float R, G, B whose
    /// low halves are noise (thousands of distinct words: codes longer than the direct table)
    /// and a half channel; 125 x 32 pixels, one block.
    /// Also returns the channels' words as PIZ lays them out (planes A, B, G, R; a float as
    /// its low then its high half).
    fn piz_blocks() -> Fixture {
        use exr::prelude::*;
        let (w, h) = (125usize, 32usize);
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut noise = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut f = |c: usize| -> Vec<f32> {
            (0..w * h)
                .map(|i| 1.0 + (i % w + c) as f32 * 0.01 + (noise() % 4096) as f32 * 1e-7)
                .collect()
        };
        let (r, g, b) = (f(0), f(1), f(2));
        let a: Vec<f16> = f(3).iter().map(|&x| f16::from_f32(x)).collect();
        let mut expected: Vec<u16> = a.iter().map(|v| v.to_bits()).collect();
        for c in [&b, &g, &r] {
            for v in c.iter() {
                expected.extend([v.to_bits() as u16, (v.to_bits() >> 16) as u16]);
            }
        }
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
            AnyChannel::new("A", FlatSamples::F16(a)),
            AnyChannel::new("B", FlatSamples::F32(b)),
            AnyChannel::new("G", FlatSamples::F32(g)),
            AnyChannel::new("R", FlatSamples::F32(r)),
        ]);
        let enc = Encoding {
            compression: Compression::PIZ,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        };
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            enc,
            AnyChannels::sort(list),
        );
        let mut bytes = Vec::new();
        Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(std::io::Cursor::new(&mut bytes))
            .unwrap();
        let chunks = exr::block::read(std::io::Cursor::new(&bytes), false)
            .unwrap()
            .all_chunks(false)
            .unwrap();
        let blocks = chunks
            .map(|c| match c.unwrap().compressed_block {
                exr::block::chunk::CompressedBlock::ScanLine(b) => b.compressed_pixels_le,
                _ => unreachable!(),
            })
            .collect();
        (blocks, vec![1, 2, 2, 2], (w, h), expected)
    }

    /// A block the `exr` crate wrote decodes to the words of the samples it was given.
    #[test]
    fn blocks_decode_to_the_written_samples() {
        let (blocks, words, size, expected) = piz_blocks();
        assert_eq!(blocks.len(), 1);
        assert!(
            blocks[0].len() < 2 * expected.len(),
            "stored uncompressed: {} bytes",
            blocks[0].len()
        );
        assert_eq!(decompress(&blocks[0], &words, size).unwrap(), expected);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]
        /// A PIZ block with bytes changed, cut short or extended gives words or an error,
        /// never a panic, whatever block size it is said to have.
        #[test]
        fn forged_blocks_do_not_panic(
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
            cut in any::<usize>(),
            extra in proptest::collection::vec(any::<u8>(), 0..16),
            w in 0usize..40,
            h in 0usize..40,
        ) {
            let (blocks, words, _, _) = piz_blocks();
            let mut b = blocks[0].clone();
            for (i, v) in edits {
                let n = b.len();
                b[i % n] = v;
            }
            b.truncate(cut % (b.len() + 1));
            b.extend(extra);
            let _ = decompress(&b, &words, (w, h));
            let _ = decompress(&b, &words, (125, 32));
        }
    }
}
