//! DWAA/DWAB blocks: their Huffman-coded AC section decoded with [`super::exr_piz`]'s Huffman
//! decoder, the rest by the `exr` crate.
//!
//! A DWA block holds four sections (unknown channels, AC and DC coefficients, RLE channels)
//! after a header of eleven 64-bit counters and the channel rules. OpenEXR codes the AC
//! coefficients with PIZ's Huffman code in scan-line files and tiled DWAB files, and with zlib
//! in tiled DWAA files. The `exr` crate's Huffman decoder rebuilds its tables over the whole
//! 65,537-symbol alphabet for each block: 70% of its time on 128 x 128 scan-line DWAA files,
//! which it decoded at 8.5-12x OpenEXR 3.1's time against 1.1-1.4x for the zlib-coded tiles
//! (docs/performance.md, "Decoding, every compression").
//!
//! [`recode_ac`] therefore decodes the AC section with our decoder and hands the `exr` crate
//! the same block with that section stored as zlib without compression (the format's other
//! AC coding, which it reads at memory speed): the DCT, colour and transfer-curve steps stay
//! the `exr` crate's, whose results equal OpenEXR's to the bit on every test file.

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

/// `data` as a zlib stream of stored (uncompressed) deflate blocks. Written out here because
/// `flate2`'s level 0 (`miniz_oxide`) goes through its compressor byte by byte: 13.5% of the
/// decoding time of 128 x 128 scan-line DWAA files, where this is a copy and a checksum.
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
        /// A DWA block with bytes changed or cut short gives a block or `None`, never a panic.
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
        }
    }
}
