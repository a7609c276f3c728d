//! Colour tags embedded in image files (PNG `sRGB`, `gAMA` and `iCCP` chunks; the ICC profile
//! of JPEG and TIFF files), read so that a file whose tag disagrees with how it is decoded can be
//! warned about. Nothing is converted: the samples are still decoded by
//! [`super::DecodeOptions::gamma`].

/// What a file's colour tag says about its encoding.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColourTag {
    /// Where the tag was found (`PNG sRGB chunk`, `PNG gAMA chunk`, `ICC profile`).
    pub source: String,
    /// The profile's description (ICC), or a description of the chunk.
    pub name: String,
    /// Whether the tag names the sRGB colour space (primaries and curve).
    pub srgb: bool,
    /// The transfer curve's exponent when the tag gives one (1 linear, about 2.2 sRGB-like).
    pub gamma: Option<f32>,
}

impl ColourTag {
    /// Whether the tag says the samples are linear (a transfer exponent near 1).
    pub fn says_linear(&self) -> bool {
        self.gamma.is_some_and(|g| (g - 1.0).abs() < 0.05)
    }

    /// Whether the tag says the samples are gamma-encoded as sRGB is (sRGB, or an exponent
    /// near 2.2).
    pub fn says_srgb_curve(&self) -> bool {
        self.srgb || self.gamma.is_some_and(|g| (g - 2.2).abs() < 0.2)
    }
}

/// What the chunks of a PNG file before its image data say about its colour: an `sRGB`
/// chunk, else the exponent of a `gAMA` chunk (the ICC profile comes from the decoder).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum PngChunks {
    /// An `sRGB` chunk.
    Srgb,
    /// No `sRGB` chunk; a `gAMA` chunk's exponent, if any.
    Gamma(Option<f32>),
    /// A chunk's length runs past the end of the file: no tag is read.
    Cut,
}

impl PngChunks {
    /// Walks the chunks of the PNG file `bytes` before its image data, decoding nothing.
    pub(super) fn read(bytes: &[u8]) -> Self {
        Self::walk(bytes).unwrap_or(PngChunks::Cut)
    }

    fn walk(bytes: &[u8]) -> Option<Self> {
        let mut gama = None;
        let mut pos = 8;
        while pos + 8 <= bytes.len() {
            let len = u32::from_be_bytes(bytes[pos..pos + 4].try_into().ok()?) as usize;
            let kind = &bytes[pos + 4..pos + 8];
            let data = bytes.get(pos + 8..pos.checked_add(8)?.checked_add(len)?)?;
            match kind {
                b"sRGB" => return Some(PngChunks::Srgb),
                b"gAMA" if data.len() == 4 => {
                    let v = u32::from_be_bytes(data.try_into().ok()?);
                    if v > 0 {
                        // The chunk stores the encoding exponent times 100000 (45455 for 1/2.2).
                        gama = Some(100_000.0 / v as f32);
                    }
                }
                b"IDAT" | b"IEND" => break,
                _ => {}
            }
            pos = pos.checked_add(12)?.checked_add(len)?;
        }
        Some(PngChunks::Gamma(gama))
    }

    /// The file's colour tag: its `sRGB` chunk, else its ICC profile (`iCCP`, decompressed by
    /// the decoder: `icc`), else its `gAMA` chunk; `None` without any.
    pub(super) fn tag(self, icc: Option<&[u8]>) -> Option<ColourTag> {
        let gama = match self {
            PngChunks::Srgb => {
                return Some(ColourTag {
                    source: "PNG sRGB chunk".into(),
                    name: "sRGB".into(),
                    srgb: true,
                    gamma: None,
                })
            }
            PngChunks::Cut => return None,
            PngChunks::Gamma(g) => g,
        };
        if let Some(tag) = icc.and_then(icc_tag) {
            return Some(tag);
        }
        gama.map(|g| ColourTag {
            source: "PNG gAMA chunk".into(),
            name: format!("gamma {g:.2}"),
            srgb: false,
            gamma: Some(g),
        })
    }
}

/// The colour tag of the PNG file `bytes` whose decompressed ICC profile is `icc` (see
/// [`PngChunks::tag`]).
pub(super) fn png_tag(bytes: &[u8], icc: Option<&[u8]>) -> Option<ColourTag> {
    PngChunks::read(bytes).tag(icc)
}

/// Reads an ICC profile's description (`desc` tag, v2 `desc` or v4 `mluc` type) and red
/// transfer curve (`rTRC`, a `curv` of 0 or 1 entries, or a `para` curve): whether it names
/// sRGB, and its exponent. `None` when the bytes are no ICC profile.
pub(super) fn icc_tag(icc: &[u8]) -> Option<ColourTag> {
    if icc.len() < 132 || &icc[36..40] != b"acsp" {
        return None;
    }
    let be32 =
        |o: usize| -> Option<u32> { Some(u32::from_be_bytes(icc.get(o..o + 4)?.try_into().ok()?)) };
    let count = be32(128)? as usize;
    let mut desc = None;
    let mut gamma = None;
    for k in 0..count.min(256) {
        let e = 132 + 12 * k;
        let (sig, off, size) = (
            icc.get(e..e + 4)?,
            be32(e + 4)? as usize,
            be32(e + 8)? as usize,
        );
        let Some(data) = icc.get(off..off.checked_add(size)?) else {
            continue;
        };
        match sig {
            b"desc" => desc = icc_text(data),
            b"rTRC" => gamma = icc_curve_gamma(data),
            _ => {}
        }
    }
    let name = desc.unwrap_or_else(|| "unnamed ICC profile".into());
    Some(ColourTag {
        source: "ICC profile".into(),
        srgb: name.to_ascii_lowercase().contains("srgb"),
        name,
        gamma,
    })
}

/// The text of an ICC `desc` (ASCII) or `mluc` (first record, UTF-16BE) tag.
fn icc_text(data: &[u8]) -> Option<String> {
    let be32 = |o: usize| -> Option<usize> {
        Some(u32::from_be_bytes(data.get(o..o + 4)?.try_into().ok()?) as usize)
    };
    let text = match data.get(0..4)? {
        b"desc" => {
            let n = be32(8)?;
            let s = data.get(12..12 + n)?;
            String::from_utf8_lossy(s)
                .trim_end_matches('\0')
                .to_string()
        }
        b"mluc" => {
            let (len, off) = (be32(20)?, be32(24)?);
            let s = data.get(off..off.checked_add(len)?)?;
            let units: Vec<u16> = s
                .chunks_exact(2)
                .map(|c| u16::from_be_bytes([c[0], c[1]]))
                .collect();
            String::from_utf16_lossy(&units)
                .trim_end_matches('\0')
                .to_string()
        }
        _ => return None,
    };
    Some(text.trim().to_string()).filter(|t| !t.is_empty())
}

/// The exponent of an ICC `curv` (no entry: 1; one entry: u8.8 fixed) or `para` (s15.16
/// first parameter) curve; `None` for a sampled curve.
fn icc_curve_gamma(data: &[u8]) -> Option<f32> {
    match data.get(0..4)? {
        b"curv" => {
            let n = u32::from_be_bytes(data.get(8..12)?.try_into().ok()?);
            match n {
                0 => Some(1.0),
                1 => Some(u16::from_be_bytes(data.get(12..14)?.try_into().ok()?) as f32 / 256.0),
                _ => None,
            }
        }
        b"para" => Some(i32::from_be_bytes(data.get(12..16)?.try_into().ok()?) as f32 / 65536.0),
        _ => None,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A minimal ICC profile with a v2 `desc` tag and an `rTRC` `curv` of one exponent.
    pub(crate) fn icc_profile(description: &str, gamma: f32) -> Vec<u8> {
        let mut desc = b"desc\0\0\0\0".to_vec();
        desc.extend((description.len() as u32 + 1).to_be_bytes());
        desc.extend(description.as_bytes());
        desc.push(0);
        while !desc.len().is_multiple_of(4) {
            desc.push(0);
        }
        let mut curv = b"curv\0\0\0\0".to_vec();
        curv.extend(1u32.to_be_bytes());
        curv.extend(((gamma * 256.0).round() as u16).to_be_bytes());
        curv.extend([0, 0]);
        let mut icc = vec![0u8; 128];
        icc[36..40].copy_from_slice(b"acsp");
        icc.extend(2u32.to_be_bytes());
        let desc_off = 128 + 4 + 24;
        let curv_off = desc_off + desc.len();
        for (sig, off, len) in [
            (b"desc", desc_off, desc.len()),
            (b"rTRC", curv_off, curv.len()),
        ] {
            icc.extend(sig);
            icc.extend((off as u32).to_be_bytes());
            icc.extend((len as u32).to_be_bytes());
        }
        icc.extend(desc);
        icc.extend(curv);
        let n = icc.len() as u32;
        icc[0..4].copy_from_slice(&n.to_be_bytes());
        icc
    }

    #[test]
    fn icc_profiles_name_their_space_and_curve() {
        let t = icc_tag(&icc_profile("Adobe RGB (1998)", 2.2)).unwrap();
        assert_eq!(t.name, "Adobe RGB (1998)");
        assert!(!t.srgb && (t.gamma.unwrap() - 2.2).abs() < 0.01);
        let t = icc_tag(&icc_profile("sRGB IEC61966-2.1", 2.4)).unwrap();
        assert!(t.srgb && t.says_srgb_curve());
        let t = icc_tag(&icc_profile("Linear Rec.709", 1.0)).unwrap();
        assert!(t.says_linear() && !t.srgb);
        assert_eq!(icc_tag(b"not a profile"), None);
        assert_eq!(icc_tag(&[0u8; 200]), None);
    }

    /// CRC-32 (ISO-HDLC), as PNG chunks use.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0xedb8_8320
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    /// `png` with a chunk of `kind` holding `data` inserted after its header chunk.
    pub(crate) fn with_chunk(png: &[u8], kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
        let at = 8 + 8 + 13 + 4;
        let mut chunk = (data.len() as u32).to_be_bytes().to_vec();
        let mut body = kind.to_vec();
        body.extend(data);
        chunk.extend(&body);
        chunk.extend(crc32(&body).to_be_bytes());
        [&png[..at], &chunk[..], &png[at..]].concat()
    }

    /// An `iCCP` chunk's data: name, method 0, and the profile in a zlib stream of stored
    /// blocks (no compression needed to be valid).
    pub(crate) fn iccp(profile: &[u8]) -> Vec<u8> {
        let mut d = b"icc\0\0".to_vec();
        d.extend([0x78, 0x01]);
        let blocks: Vec<&[u8]> = profile.chunks(65_535).collect();
        for (k, b) in blocks.iter().enumerate() {
            d.push((k + 1 == blocks.len()) as u8);
            let n = b.len() as u16;
            d.extend(n.to_le_bytes());
            d.extend((!n).to_le_bytes());
            d.extend(*b);
        }
        let (mut a, mut b) = (1u32, 0u32);
        for &x in profile {
            a = (a + x as u32) % 65_521;
            b = (b + a) % 65_521;
        }
        d.extend(((b << 16) | a).to_be_bytes());
        d
    }

    /// A 2 x 1 16-bit PNG of the given samples.
    fn png16(values: &[f32; 6]) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        crate::write_png16_rgb(&p, 2, 1, values).unwrap();
        std::fs::read(p).unwrap()
    }

    fn decode(bytes: &[u8], gamma: crate::Gamma) -> crate::Image {
        let opts = crate::DecodeOptions {
            gamma,
            ..Default::default()
        };
        crate::decode_image(std::path::Path::new("a.png"), bytes, &opts).unwrap()
    }

    #[test]
    fn sixteen_bit_samples_follow_the_gamma_option() {
        let v = [0.5f32, 0.25, 0.1, 0.8, 0.0, 0.04];
        let bytes = png16(&v);
        let auto = decode(&bytes, crate::Gamma::Auto);
        assert_eq!(auto.kind, crate::SampleKind::U16);
        let srgb = decode(&bytes, crate::Gamma::Srgb);
        assert_eq!(srgb.kind, crate::SampleKind::Srgb16);
        for (k, &x) in v.iter().enumerate() {
            let q = (x * 65535.0).round() / 65535.0;
            assert!((auto.data[k] - q).abs() < 1e-7);
            assert!((srgb.data[k] - crate::srgb_to_linear(q)).abs() < 1e-6);
        }
        // 0.5 sRGB-encoded is 0.214 linear.
        assert!((srgb.data[0] - 0.2140).abs() < 1e-3);
        assert_eq!(decode(&bytes, crate::Gamma::Linear).data, auto.data);
        assert_eq!(auto.colour, None);
    }

    #[test]
    fn png_chunks_are_read_as_tags() {
        let bytes = png16(&[0.5; 6]);
        let t = decode(&with_chunk(&bytes, b"sRGB", &[0]), crate::Gamma::Auto)
            .colour
            .unwrap();
        assert!(t.srgb && t.says_srgb_curve() && t.source == "PNG sRGB chunk");
        let t = decode(
            &with_chunk(&bytes, b"gAMA", &100_000u32.to_be_bytes()),
            crate::Gamma::Auto,
        )
        .colour
        .unwrap();
        assert!(t.says_linear() && !t.srgb);
        let t = decode(
            &with_chunk(&bytes, b"gAMA", &45_455u32.to_be_bytes()),
            crate::Gamma::Auto,
        )
        .colour
        .unwrap();
        assert!(t.says_srgb_curve() && (t.gamma.unwrap() - 2.2).abs() < 0.01);
        let adobe = icc_profile("Adobe RGB (1998)", 2.2);
        let img = decode(
            &with_chunk(&bytes, b"iCCP", &iccp(&adobe)),
            crate::Gamma::Auto,
        );
        let t = img.colour.unwrap();
        assert_eq!(
            (t.source.as_str(), t.name.as_str()),
            ("ICC profile", "Adobe RGB (1998)")
        );
        // The tag is only read: the samples are decoded as without it.
        assert_eq!(img.data, decode(&bytes, crate::Gamma::Auto).data);
    }
}
