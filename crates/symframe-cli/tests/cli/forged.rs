//! Small files declaring large float images, written by hand: an EXR of half-float zeros
//! (ZIP blocks), a float TIFF whose strips all point at one deflated strip of zeros, and a
//! Radiance file of old run-length scan lines. Each is a few KB to a few hundred KB (deflate
//! cannot pack more than about 1,000 bytes into one) and decodes to `width x height` RGB.

use std::fs;
use std::path::Path;

/// Bits written least significant first, as deflate packs them.
struct Bits(Vec<u8>, u32, u32);

impl Bits {
    /// `n` bits of `v`, least significant first.
    fn put(&mut self, v: u32, n: u32) {
        for k in 0..n {
            self.1 |= ((v >> k) & 1) << self.2;
            self.2 += 1;
            if self.2 == 8 {
                self.0.push(self.1 as u8);
                (self.1, self.2) = (0, 0);
            }
        }
    }
    /// A Huffman code of `n` bits, most significant first.
    fn code(&mut self, v: u32, n: u32) {
        for k in (0..n).rev() {
            self.put((v >> k) & 1, 1);
        }
    }
}

/// A zlib stream of `n` bytes: `first`, then `fill` repeated. One dynamic-Huffman block in
/// which a copy of 258 bytes at distance 1 costs two bits, so the stream is about `n / 1000`
/// bytes.
pub fn zlib_fill(first: u8, fill: u8, n: usize) -> Vec<u8> {
    assert!(n >= 2);
    // Literal/length codes: 285 (length 258) "0", `fill` "10", the other literal "110", end
    // of block "111"; distance codes 0 (distance 1) "0" and 1 "1".
    let other = if first == fill { fill ^ 1 } else { first };
    let mut lengths = vec![0u32; 286 + 2];
    lengths[285] = 1;
    lengths[fill as usize] = 2;
    lengths[other as usize] = 3;
    lengths[256] = 3;
    lengths[286] = 1;
    lengths[287] = 1;
    let mut z = Bits(vec![0x78, 0x01], 0, 0);
    z.put(1, 1); // final block
    z.put(2, 2); // dynamic Huffman codes
    z.put(286 - 257, 5);
    z.put(2 - 1, 5);
    z.put(19 - 4, 4);
    // Code length codes: 0, 1, 2, 3, 4, 5, 17 and 18 all of 3 bits, in deflate's order.
    let order = [
        16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15,
    ];
    for sym in order {
        z.put(
            if [0, 1, 2, 3, 4, 5, 17, 18].contains(&sym) {
                3
            } else {
                0
            },
            3,
        );
    }
    let cl_code = |sym: u32| match sym {
        0..=5 => sym,
        17 => 6,
        _ => 7,
    };
    let mut i = 0;
    while i < lengths.len() {
        let v = lengths[i];
        if v != 0 {
            z.code(cl_code(v), 3);
            i += 1;
            continue;
        }
        let run = lengths[i..].iter().take_while(|&&l| l == 0).count();
        if run >= 11 {
            let r = run.min(138);
            z.code(cl_code(18), 3);
            z.put((r - 11) as u32, 7);
            i += r;
        } else if run >= 3 {
            z.code(cl_code(17), 3);
            z.put((run - 3) as u32, 3);
            i += run;
        } else {
            z.code(cl_code(0), 3);
            i += 1;
        }
    }
    let literal = |z: &mut Bits, b: u8| {
        if b == fill {
            z.code(0b10, 2)
        } else {
            z.code(0b110, 3)
        }
    };
    literal(&mut z, first);
    let mut left = n - 1;
    if first != fill {
        literal(&mut z, fill);
        left -= 1;
    }
    while left >= 258 {
        z.code(0, 1); // length 258
        z.code(0, 1); // distance 1
        left -= 258;
    }
    for _ in 0..left {
        literal(&mut z, fill);
    }
    z.code(0b111, 3); // end of block
    if z.2 > 0 {
        z.0.push(z.1 as u8);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for k in 0..n {
        a = (a + if k == 0 { first } else { fill } as u32) % 65521;
        b = (b + a) % 65521;
    }
    z.0.extend((b << 16 | a).to_be_bytes());
    z.0
}

/// An EXR of `w x h` half-float RGB zeros in ZIP blocks of 16 scan lines.
pub fn exr_zeros(path: &Path, w: u32, h: u32) {
    fn attr(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
        out.extend(name.as_bytes());
        out.push(0);
        out.extend(kind.as_bytes());
        out.push(0);
        out.extend((value.len() as i32).to_le_bytes());
        out.extend(value);
    }
    let mut out = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    let mut channels = Vec::new();
    for name in ["B", "G", "R"] {
        channels.extend(name.as_bytes());
        channels.push(0);
        channels.extend(1i32.to_le_bytes()); // half
        channels.extend([0, 0, 0, 0]);
        channels.extend(1i32.to_le_bytes());
        channels.extend(1i32.to_le_bytes());
    }
    channels.push(0);
    attr(&mut out, "channels", "chlist", &channels);
    attr(&mut out, "compression", "compression", &[3]); // ZIP, 16 lines
    let window: Vec<u8> = [0, 0, w as i32 - 1, h as i32 - 1]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    attr(&mut out, "dataWindow", "box2i", &window);
    attr(&mut out, "displayWindow", "box2i", &window);
    attr(&mut out, "lineOrder", "lineOrder", &[0]);
    attr(&mut out, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attr(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
    attr(&mut out, "screenWindowWidth", "float", &1f32.to_le_bytes());
    out.push(0);
    let blocks = h.div_ceil(16);
    let table = out.len() + 8 * blocks as usize;
    let mut chunks = Vec::new();
    let mut offsets = Vec::new();
    let mut cached: Option<(u32, Vec<u8>)> = None;
    for b in 0..blocks {
        let lines = 16.min(h - 16 * b);
        // Zeros after ZIP's predictor: the first byte 0, every other 128.
        if cached.as_ref().is_none_or(|(l, _)| *l != lines) {
            cached = Some((lines, zlib_fill(0, 128, (lines * w * 6) as usize)));
        }
        let data = &cached.as_ref().unwrap().1;
        offsets.push((table + chunks.len()) as u64);
        chunks.extend((16 * b as i32).to_le_bytes());
        chunks.extend((data.len() as i32).to_le_bytes());
        chunks.extend(data);
    }
    for o in offsets {
        out.extend(o.to_le_bytes());
    }
    out.extend(chunks);
    fs::write(path, out).unwrap();
}

/// A TIFF of `w x h` (`h` a multiple of 16) 32-bit float RGB zeros in strips of 16 rows,
/// deflated, every strip's offset that of one stored strip.
pub fn tiff_zeros(path: &Path, w: u32, h: u32) {
    let rows = 16u32;
    assert_eq!(h % rows, 0);
    let strips = h.div_ceil(rows);
    let data = zlib_fill(0, 0, (rows * w * 12) as usize);
    let mut out = b"II*\0".to_vec();
    let ifd = 8 + data.len() as u32;
    out.extend(ifd.to_le_bytes());
    out.extend(&data);
    let entries: Vec<(u16, u16, Vec<u32>)> = vec![
        (256, 4, vec![w]),
        (257, 4, vec![h]),
        (258, 3, vec![32; 3]),
        (259, 3, vec![8]),
        (262, 3, vec![2]),
        (273, 4, vec![8; strips as usize]),
        (277, 3, vec![3]),
        (278, 4, vec![rows]),
        (279, 4, vec![data.len() as u32; strips as usize]),
        (284, 3, vec![1]),
        (339, 3, vec![3; 3]),
    ];
    let mut extra_at = ifd + 2 + 12 * entries.len() as u32 + 4;
    out.extend((entries.len() as u16).to_le_bytes());
    let mut extra = Vec::new();
    for (tag, ty, vals) in &entries {
        out.extend(tag.to_le_bytes());
        out.extend(ty.to_le_bytes());
        out.extend((vals.len() as u32).to_le_bytes());
        let mut bytes: Vec<u8> = Vec::new();
        for v in vals {
            if *ty == 3 {
                bytes.extend((*v as u16).to_le_bytes());
            } else {
                bytes.extend(v.to_le_bytes());
            }
        }
        if bytes.len() <= 4 {
            bytes.resize(4, 0);
            out.extend(bytes);
        } else {
            out.extend(extra_at.to_le_bytes());
            extra_at += bytes.len() as u32;
            extra.extend(bytes);
        }
    }
    out.extend(0u32.to_le_bytes());
    out.extend(extra);
    fs::write(path, out).unwrap();
}

/// A Radiance file of `w x h` (`w` at most 65,536) black pixels: each scan line one pixel and
/// two old run-length markers repeating it `w - 1` times.
pub fn hdr_zeros(path: &Path, w: u32, h: u32) {
    assert!((2..=65536).contains(&w));
    let mut out = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n").into_bytes();
    let n = w - 1;
    let mut line = vec![0u8, 0, 0, 0, 1, 1, 1, (n & 255) as u8];
    if n > 255 {
        line.extend([1, 1, 1, (n >> 8) as u8]);
    }
    for _ in 0..h {
        out.extend(&line);
    }
    fs::write(path, out).unwrap();
}
