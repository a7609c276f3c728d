//! End-to-end regression tests of hostile inputs: files beside the light file, never read (or
//! ignored) without a word; EXR layers and masks, read the right way; images whose declared
//! size could defeat `--decode-memory`; paths that are not regular files, never read without
//! bound.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{assert_one_line_error, estimate, ok, report, s, stderr, symframe, Truth};
use symframe::brdf::Lambertian;
use symframe_io::{read_image, read_npy_f32, write_exr_channels, DecodeOptions, ImageFormat};

/// A small Lambertian sphere as float EXR; returns the `.lp` path.
fn lambert(dir: &Path, size: usize, lights: usize) -> PathBuf {
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    let brdf = Lambertian::new([0.6; 3]);
    crate::common::sphere_dataset(dir, size, lights, &brdf, ImageFormat::Exr, 1.0, truth).1
}

/// `light_intensities.txt` is not silently ignored where a second `.lp` sits beside the first
/// (the normals would be off with nothing in report.json).
#[test]
fn light_intensities_beside_several_lp_files_are_never_silent() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = lambert(&data, 16, 20);
    let rows = "1 1 1\n".repeat(20);
    fs::write(data.join("light_intensities.txt"), &rows).unwrap();
    // A copy of the light file beside it: as many lights, so the rows fit both.
    fs::copy(&lp, data.join("copy.lp")).unwrap();
    let out = tmp.path().join("a");
    let o = estimate(&lp, &out, &["--method", "woodham"]);
    ok(&o);
    let want = "applied to lights.lp (its 20 rows match its 20 lights), but copy.lp";
    assert!(stderr(&o).contains(want), "{}", stderr(&o));
    assert!(
        crate::common::report_warnings(&out)
            .iter()
            .any(|w| w.contains(want)),
        "{:?}",
        crate::common::report_warnings(&out)
    );
    // Rows of another light file: not applied, said so.
    fs::write(data.join("light_intensities.txt"), "1 1 1\n".repeat(3)).unwrap();
    fs::write(
        data.join("copy.lp"),
        "3\nimages/img_0000.exr 0 0 1\nimages/img_0001.exr 0 1 1\nimages/img_0002.exr 1 0 1\n",
    )
    .unwrap();
    let out = tmp.path().join("b");
    let o = estimate(&lp, &out, &["--method", "woodham"]);
    ok(&o);
    let want =
        "not applied to lights.lp: its 3 rows are not lights.lp's 20 lights but those of copy.lp";
    assert!(stderr(&o).contains(want), "{}", stderr(&o));
    assert!(crate::common::report_warnings(&out)
        .iter()
        .any(|w| w.contains(want)));
    // Rows of no light file beside it: an error.
    fs::write(data.join("light_intensities.txt"), "1 1 1\n".repeat(7)).unwrap();
    let o = estimate(&lp, &tmp.path().join("c"), &["--method", "woodham"]);
    assert_one_line_error(&o, "light_intensities.txt: 7 light intensities but");
}

/// A layered EXR (`albedo.R/G/B`, `beauty.R/G/B`) is not read from the wrong layer without a
/// word (its normals would be far off); an EXR holding only a depth channel `Z` is not taken as
/// radiance.
#[test]
fn layered_exr_needs_exr_layer_and_depth_alone_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = lambert(&data, 16, 20);
    let plain = tmp.path().join("plain");
    ok(&estimate(&lp, &plain, &["--method", "woodham"]));
    let opts = DecodeOptions::default();
    let images: Vec<PathBuf> = (0..20)
        .map(|i| data.join(format!("images/img_{i:04}.exr")))
        .collect();
    for p in &images {
        let img = read_image(p, &opts).unwrap();
        let plane = |c: usize| img.data.iter().skip(c).step_by(3).copied().collect();
        let flat = vec![0.5f32; 16 * 16];
        let ch = vec![
            ("albedo.R", flat.clone()),
            ("albedo.G", flat.clone()),
            ("albedo.B", flat),
            ("beauty.R", plane(0)),
            ("beauty.G", plane(1)),
            ("beauty.B", plane(2)),
        ];
        write_exr_channels(p, 16, 16, ch).unwrap();
    }
    let o = estimate(&lp, &tmp.path().join("x"), &["--method", "woodham"]);
    assert_one_line_error(&o, "img_0000.exr: no default EXR layer");
    assert!(stderr(&o).contains("--exr-layer NAME (one of albedo, beauty)"));
    let picked = tmp.path().join("beauty");
    ok(&estimate(
        &lp,
        &picked,
        &["--method", "woodham", "--exr-layer", "beauty"],
    ));
    let bits = |dir: &Path| -> Vec<u32> {
        let (_, v) = read_npy_f32(&dir.join("normals.npy")).unwrap();
        v.iter().map(|x| x.to_bits()).collect()
    };
    assert_eq!(bits(&picked), bits(&plain));
    assert_eq!(report(&picked)["parameters"]["exr_layer"], "beauty");
    // The layer is part of the cache's fingerprint: another layer is decoded afresh.
    let o = estimate(
        &lp,
        &picked,
        &["--method", "woodham", "--exr-layer", "albedo"],
    );
    ok(&o);
    assert_eq!(report(&picked)["cache"]["hit"], false);
    // Depth only.
    write_exr_channels(&images[0], 16, 16, vec![("Z", vec![1.0; 256])]).unwrap();
    let o = estimate(&lp, &tmp.path().join("z"), &["--method", "woodham"]);
    assert_one_line_error(
        &o,
        "img_0000.exr: no radiance channel (R, G, B or Y) in the EXR (channels: default layer (Z))",
    );
}

/// Every channel of a mask counts, not only its first: a pure blue mask is not "empty".
#[test]
fn a_blue_mask_is_not_empty() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let lp = lambert(&data, 16, 20);
    let mask = tmp.path().join("blue.png");
    let rgb: Vec<f32> = (0..16 * 16)
        .flat_map(|i| {
            if i % 16 < 8 {
                [0.0, 0.0, 1.0]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    symframe_io::write_png8_rgb(&mask, 16, 16, &rgb, false).unwrap();
    let out = tmp.path().join("out");
    ok(&estimate(
        &lp,
        &out,
        &["--method", "woodham", "--mask", s(&mask)],
    ));
    let (_, n) = read_npy_f32(&out.join("normals.npy")).unwrap();
    let estimated = |half: bool| {
        (0..256)
            .filter(|&p| (p % 16 < 8) == half && n[p * 3].is_finite())
            .count()
    };
    assert!(estimated(true) > 0);
    assert_eq!(estimated(false), 0);
}

/// Writes an 8-bit grey PNG of `w x h` black pixels, compressed as deflate does (a literal
/// and then runs of 258 bytes): a real image of many pixels in a small file.
fn black_png(path: &Path, w: u32, h: u32) {
    black_png_of(path, w, h, Layout::Grey8);
}

/// The sample layouts of [`black_png_of`].
#[derive(Clone, Copy)]
enum Layout {
    Grey8,
    Rgb8,
    Grey1,
}

/// [`black_png`] of another sample layout.
fn black_png_of(path: &Path, w: u32, h: u32, layout: Layout) {
    fn crc32(data: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in data {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
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
    let (row, ihdr_tail) = match layout {
        Layout::Grey8 => (w as u64, [8, 0]),
        Layout::Rgb8 => (3 * w as u64, [8, 2]),
        Layout::Grey1 => ((w as u64).div_ceil(8), [1, 0]),
    };
    let raw = (row + 1) * h as u64; // a filter byte per row, all zero
    let mut z = Bits(vec![0x78, 0x01], 0, 0);
    z.put(1, 1); // final block
    z.put(1, 2); // fixed Huffman codes
    z.code(0x30, 8); // literal 0
    let mut left = raw - 1;
    while left >= 258 {
        z.code(0xc5, 8); // length 258 (code 285)
        z.code(0, 5); // distance 1
        left -= 258;
    }
    for _ in 0..left {
        z.code(0x30, 8);
    }
    z.code(0, 7); // end of block
    if z.2 > 0 {
        z.0.push(z.1 as u8);
    }
    let adler = ((raw % 65521) as u32) << 16 | 1;
    z.0.extend(adler.to_be_bytes());
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], body: &[u8]| {
        png.extend((body.len() as u32).to_be_bytes());
        let mut c = kind.to_vec();
        c.extend(body);
        png.extend(&c);
        png.extend(crc32(&c).to_be_bytes());
    };
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend(ihdr_tail);
    ihdr.extend([0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &z.0);
    chunk(b"IEND", &[]);
    fs::write(path, png).unwrap();
}

/// `--decode-memory` holds when an image's size disagrees with the first image's: that image is
/// refused from its header, not decoded whole before the comparison (four small PNGs of 8000 x 8000
/// pixels after a 16 x 16 one would cost gigabytes: docs/performance.md, "Memory model").
#[cfg(target_os = "linux")]
#[test]
fn an_image_of_another_size_is_refused_before_it_is_decoded() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    black_png(&d.join("a.png"), 16, 16);
    for i in 1..5 {
        black_png(&d.join(format!("b{i}.png")), 8000, 8000);
    }
    assert!(fs::metadata(d.join("b1.png")).unwrap().len() < 1 << 20);
    let names = ["a.png", "b1.png", "b2.png", "b3.png", "b4.png"];
    let mut lp = "5\n".to_string();
    for (i, n) in names.iter().enumerate() {
        lp += &format!("{n} {} 0.3 1\n", i as f64 * 0.1);
    }
    let big = d.join("big.lp");
    fs::write(&big, lp).unwrap();
    let out = d.join("out");
    let args = [
        "estimate",
        s(&big),
        "-o",
        s(&out),
        "--decode-memory",
        "16",
        "--method",
        "woodham",
    ];
    let (o, peak_kib) = crate::common::run_measuring_rss(&args);
    assert_one_line_error(&o, "b1.png: image is 8000x8000 but the first image");
    assert!(stderr(&o).contains("a.png) is 16x16"), "{}", stderr(&o));
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
}

/// A sparse 3 GB file holding a valid 16 x 16 PNG is not read whole (docs/performance.md, "Memory
/// model"): a file far longer than any encoding of the image its header declares is refused from
/// its header.
#[cfg(target_os = "linux")]
#[test]
fn a_padded_image_file_is_refused_before_it_is_read_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    black_png(&d.join("a.png"), 16, 16);
    black_png(&d.join("b.png"), 16, 16);
    let f = fs::OpenOptions::new()
        .write(true)
        .open(d.join("b.png"))
        .unwrap();
    f.set_len(3 << 30).unwrap();
    drop(f);
    let lp = d.join("l.lp");
    fs::write(&lp, "2\na.png 0.1 0.3 1\nb.png -0.2 0.1 1\n").unwrap();
    let out = d.join("out");
    let args = ["estimate", s(&lp), "-o", s(&out), "--method", "woodham"];
    let (o, peak_kib) = crate::common::run_measuring_rss(&args);
    assert_one_line_error(&o, "b.png: 3221225472 bytes, more than any encoding");
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
    // A sparse 3 GB file of zeros named like an EXR has no header where one must be: refused
    // from its first 16 MiB, never read whole.
    fs::remove_file(d.join("b.png")).unwrap();
    let f = fs::File::create(d.join("b.exr")).unwrap();
    f.set_len(3 << 30).unwrap();
    drop(f);
    fs::write(&lp, "2\na.png 0.1 0.3 1\nb.exr -0.2 0.1 1\n").unwrap();
    let (o, peak_kib) = crate::common::run_measuring_rss(&args);
    assert_one_line_error(&o, "b.exr");
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
}

/// A `--mask`, `.lp` or `relight --lights` file that is `/dev/zero` grew until memory ran out.
#[cfg(target_os = "linux")]
#[test]
fn paths_that_are_not_regular_files_are_refused_unread() {
    use crate::common::run_with_address_space_cap as capped;
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let lp = lambert(&d.join("data"), 8, 8);
    let zero_lp = d.join("zero.lp");
    std::os::unix::fs::symlink("/dev/zero", &zero_lp).unwrap();
    let zero_png = d.join("zero.png");
    std::os::unix::fs::symlink("/dev/zero", &zero_png).unwrap();
    let cap = 2 << 30;
    let o = capped(&["estimate", s(&zero_lp), "-o", s(&d.join("a"))], cap);
    assert_one_line_error(&o, "zero.lp: not a regular file (a character device)");
    let o = capped(
        &[
            "estimate",
            s(&lp),
            "-o",
            s(&d.join("b")),
            "--mask",
            s(&zero_png),
        ],
        cap,
    );
    assert_one_line_error(&o, "zero.png: not a regular file (a character device)");
    let o = capped(
        &[
            "relight",
            s(d),
            "-o",
            s(&d.join("c")),
            "--lights",
            "/dev/zero",
        ],
        cap,
    );
    assert_one_line_error(&o, "/dev/zero: not a regular file (a character device)");
}

/// A light `1e200 0 1e200` is not "zero or not finite"; an `.lp` with CR-only line ends has
/// one line per light, not one in all (whose error would quote the whole file).
#[test]
fn huge_finite_lights_and_cr_only_line_ends_are_read() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = lambert(&tmp.path().join("data"), 12, 12);
    let text = fs::read_to_string(&lp).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for l in lines.iter_mut().skip(1) {
        let t: Vec<&str> = l.split_whitespace().collect();
        let v: Vec<String> = t[1..]
            .iter()
            .map(|x| format!("{:e}", x.parse::<f64>().unwrap() * 1e200))
            .collect();
        *l = format!("{} {}", t[0], v.join(" "));
    }
    fs::write(&lp, lines.join("\r") + "\r").unwrap();
    ok(&estimate(
        &lp,
        &tmp.path().join("out"),
        &["--method", "woodham"],
    ));
    lines[3] = "images/img_0002.exr 0 zero 1".into();
    fs::write(&lp, lines.join("\r") + "\r").unwrap();
    let o = symframe(&["estimate", s(&lp), "-o", s(&tmp.path().join("x"))]);
    assert_one_line_error(
        &o,
        "lights.lp:4: light direction: cannot parse 'zero' as a number",
    );
}

/// Replaces `path` by a FIFO (opening it would wait for a writer).
#[cfg(unix)]
fn make_fifo(path: &Path) {
    let _ = fs::remove_file(path);
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a NUL-terminated path we own.
    let r = unsafe { libc::mkfifo(c.as_ptr(), 0o644) };
    assert_eq!(r, 0, "mkfifo {path:?}");
}

/// A capture of a few kilobytes (four 4096 x 4096 black PNGs of 16 KB) is estimated without holding
/// whole maps and four whole pictures, and a forged shard with one sparse 670 MB tile merged
/// without assembling maps first (either would cost hundreds of MB: docs/performance.md, "Memory
/// model"): the outputs are written from the tile results a band of tiles at a time, and a tile
/// file's header is checked before its records are read.
#[cfg(target_os = "linux")]
#[test]
fn a_forged_4096_square_capture_is_estimated_and_merged_in_bounded_memory() {
    use crate::common::run_measuring_rss;
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for n in ["a", "b", "c", "d"] {
        black_png(&d.join(format!("{n}.png")), 4096, 4096);
    }
    let lp = d.join("lights.lp");
    fs::write(
        &lp,
        "4\na.png 0 0 1\nb.png 0.5 0 0.866\nc.png 0 0.5 0.866\nd.png -0.5 0 0.866\n",
    )
    .unwrap();
    let limit_kib = 600 << 10;
    let out = d.join("out");
    let (o, peak) = run_measuring_rss(&[
        "estimate",
        s(&lp),
        "-o",
        s(&out),
        "--decode-memory",
        "16",
        "--quiet",
    ]);
    ok(&o);
    assert!(peak < limit_kib, "estimate: peak {peak} KiB");
    assert_eq!(report(&out)["pixels"]["no_data"], 4096 * 4096);
    assert_eq!(
        fs::metadata(out.join("normals.npy")).unwrap().len(),
        128 + 4096 * 4096 * 12
    );

    // A shard of the same job (the cache reused), merged.
    let shard = d.join("shard");
    let cache = out.join(".symframe-cache");
    ok(&symframe(&[
        "estimate",
        s(&lp),
        "-o",
        s(&shard),
        "--cache",
        s(&cache),
        "--tiles",
        "1/1",
        "--quiet",
    ]));
    let merged = d.join("merged");
    let (o, peak) = run_measuring_rss(&["merge", s(&shard), "-o", s(&merged), "--quiet"]);
    ok(&o);
    assert!(peak < limit_kib, "merge: peak {peak} KiB");
    assert_eq!(
        fs::read(merged.join("source.npy")).unwrap(),
        fs::read(out.join("source.npy")).unwrap()
    );

    // A forged shard: one tile of the whole image, a sparse file of its length.
    let forged = d.join("forged");
    let tiles = forged.join(".symframe-tiles");
    fs::create_dir_all(&tiles).unwrap();
    let manifest = serde_json::json!({
        "format": "symframe-shard", "version": 1, "job": "0123456789abcdef",
        "shard": 1, "of": 1, "width": 4096, "height": 4096, "tile_size": 4096,
        "n_tiles": 1, "tiles": [0], "report": {},
    });
    fs::write(forged.join("shard.json"), manifest.to_string()).unwrap();
    let tile = tiles.join("tile-000000.bin");
    let len = symframe_io::tile_results::tile_result_len(4096 * 4096);
    assert!(len > 600 << 20);
    fs::File::create(&tile).unwrap().set_len(len).unwrap();
    let (o, peak) = run_measuring_rss(&["merge", s(&forged), "-o", s(&d.join("m2"))]);
    assert_one_line_error(&o, "tile-000000.bin: not a symframe tile result");
    assert!(peak < limit_kib, "forged merge: peak {peak} KiB");
}

/// `calibrate` does not leave out an image of its folder that is a FIFO without a word: an
/// error names it, before anything is opened.
#[cfg(unix)]
#[test]
fn calibrate_refuses_an_image_that_is_a_fifo() {
    let tmp = tempfile::tempdir().unwrap();
    let images = tmp.path().join("images");
    fs::create_dir_all(&images).unwrap();
    black_png(&images.join("a.png"), 16, 16);
    make_fifo(&images.join("b.png"));
    let cal = tmp.path().join("cal.lp");
    let o = crate::common::run_with_timeout(&["calibrate", s(&images), "-o", s(&cal)], 60);
    assert_one_line_error(&o, "b.png: not a regular file (a FIFO)");
    assert!(!cal.exists());
    // Named in a list file, the same.
    let list = tmp.path().join("list.txt");
    fs::write(&list, "images/a.png\nimages/b.png\n").unwrap();
    let o = crate::common::run_with_timeout(&["calibrate", s(&list), "-o", s(&cal)], 60);
    assert_one_line_error(&o, "b.png: not a regular file (a FIFO)");
}

/// `relight` (of a glTF fit, which reads the exposure there) and `view` (which reads the
/// estimate folder there) given a `fit.json` that is a FIFO or `/dev/zero`: refused naming
/// it, never opened.
#[cfg(unix)]
#[test]
fn relight_and_view_refuse_a_fit_json_that_is_not_a_regular_file() {
    use crate::common::run_with_timeout;
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    crate::view::fit_folder(d);
    let ward = d.join("fit");
    // A glTF fit folder of the same frames.
    let gltf = d.join("gltf");
    fs::create_dir_all(&gltf).unwrap();
    let n = 12 * 12;
    let grey = |v: f32| vec![v; n];
    let rgb = |v: [f32; 3]| (0..n).flat_map(|_| v).collect::<Vec<f32>>();
    let write = |name: &str, shape: &[usize], v: &[f32]| {
        symframe_io::write_npy_f32(&gltf.join(name), shape, v).unwrap()
    };
    write("base_color.npy", &[12, 12, 3], &rgb([0.5; 3]));
    write("metallic.npy", &[12, 12], &grey(0.0));
    write("roughness.npy", &[12, 12], &grey(0.5));
    write("anisotropy_strength.npy", &[12, 12], &grey(0.0));
    write("normals.npy", &[12, 12, 3], &rgb([0.0, 0.0, 1.0]));
    write("tangents.npy", &[12, 12, 3], &rgb([1.0, 0.0, 0.0]));
    fs::write(gltf.join("fit.json"), r#"{"exposure": 1.0}"#).unwrap();
    let relight = |fit: &Path, out: &str| {
        run_with_timeout(
            &["relight", s(fit), "-o", s(&d.join(out)), "--light", "0,0,1"],
            60,
        )
    };
    ok(&relight(&gltf, "r0"));
    let view =
        |fit: &Path| run_with_timeout(&["view", s(fit), "-o", s(&d.join("v.html")), "--quiet"], 60);
    for (planted, what) in [(true, "a FIFO"), (false, "a character device")] {
        for fit in [&gltf, &ward] {
            let report = fit.join("fit.json");
            fs::remove_file(&report).unwrap();
            if planted {
                make_fifo(&report);
            } else {
                std::os::unix::fs::symlink("/dev/zero", &report).unwrap();
            }
        }
        let needle = format!("fit.json: not a regular file ({what})");
        assert_one_line_error(&relight(&gltf, "r1"), &needle);
        assert_one_line_error(&view(&ward), &needle);
    }
}

/// A DiLiGenT `light_directions.txt` of ten million rows (60 MB) is not read whole and parsed
/// (which would cost hundreds of MB and seconds: docs/performance.md, "Memory model"), nor an `.lp`
/// declaring seven million lights, each naming an existing image, every name checked: light
/// files are read a line at a time and refused at the line that passes the cap of 100,000
/// lights. The files are written a line at a time, so this
/// process's own peak (which the child's measure includes, see `own_peak_kib`) stays low.
#[cfg(target_os = "linux")]
#[test]
fn ten_million_light_directions_are_refused_in_bounded_memory() {
    use crate::common::{own_peak_kib, run_measuring_rss};
    use std::io::Write;
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let write_lines = |path: &Path, first: &str, line: &str, n: usize| {
        let mut f = std::io::BufWriter::new(fs::File::create(path).unwrap());
        f.write_all(first.as_bytes()).unwrap();
        for _ in 0..n {
            f.write_all(line.as_bytes()).unwrap();
        }
        f.flush().unwrap();
    };
    black_png(&d.join("a.png"), 4, 4);
    fs::write(d.join("filenames.txt"), "a.png\na.png\n").unwrap();
    write_lines(&d.join("light_directions.txt"), "", "0 0 1\n", 10_000_000);
    // 100 MB, or this process's own peak and 30 MB when that is higher (other tests).
    let limit_kib = |floor: u64| (100 << 10).max(floor + (30 << 10));
    let t = std::time::Instant::now();
    let floor = own_peak_kib();
    let (o, peak_kib) = run_measuring_rss(&["estimate", s(d), "-o", s(&d.join("out"))]);
    assert_one_line_error(
        &o,
        "light_directions.txt:100001: more than 100000 light directions: a light file holds \
         at most 100000 lights",
    );
    assert!(
        peak_kib < limit_kib(floor),
        "peak {peak_kib} KiB (own {floor})"
    );
    assert!(t.elapsed().as_secs() < 10, "{:?}", t.elapsed());

    let lp = d.join("many.lp");
    write_lines(&lp, "7000000\n", "a.png 0 0 1\n", 5_000_000);
    let t = std::time::Instant::now();
    let floor = own_peak_kib();
    let (o, peak_kib) = run_measuring_rss(&["estimate", s(&lp), "-o", s(&d.join("out"))]);
    assert_one_line_error(
        &o,
        "many.lp:1: 7000000 lights declared: a light file holds at most 100000 lights",
    );
    assert!(
        peak_kib < limit_kib(floor),
        "peak {peak_kib} KiB (own {floor})"
    );
    assert!(t.elapsed().as_secs() < 10, "{:?}", t.elapsed());
}

/// Four PNGs of a few KB declaring 8000 x 8000 pixels each are not decoded whole into the cache
/// builder's batch (`f32` RGB, 768 MB an image, beside their raw samples: docs/performance.md,
/// "Memory model"). Images are read a band of tile rows at a time (a PNG row by row), so what is
/// held is a band of each image of the batch, whatever the size they declare.
#[cfg(target_os = "linux")]
#[test]
fn large_declared_images_are_decoded_a_band_at_a_time() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    black_png_of(&d.join("rgb.png"), 8000, 8000, Layout::Rgb8);
    black_png_of(&d.join("bits.png"), 8000, 8000, Layout::Grey1);
    for n in ["rgb.png", "bits.png"] {
        assert!(fs::metadata(d.join(n)).unwrap().len() < 2 << 20);
    }
    fs::copy(d.join("bits.png"), d.join("bits2.png")).unwrap();
    let lp = d.join("lights.lp");
    fs::write(
        &lp,
        "3\nrgb.png 0 0 1\nbits.png 0.5 0 0.866\nbits2.png 0 0.5 0.866\n",
    )
    .unwrap();
    let out = d.join("out");
    // The cache alone is what is measured: the run stops after its first tile.
    let args = [
        "estimate",
        s(&lp),
        "-o",
        s(&out),
        "--decode-memory",
        "16",
        "--cache-format",
        "f16",
        "--stop-after-tiles",
        "1",
        "--quiet",
    ];
    let (o, peak_kib) = crate::common::run_measuring_rss(&args);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
    let cache: Vec<PathBuf> = fs::read_dir(out.join(".symframe-cache"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "stack"))
        .collect();
    assert_eq!(cache.len(), 1, "{cache:?}");
    let len = fs::metadata(&cache[0]).unwrap().len();
    assert!(len > 8000 * 8000 * 3 * 6, "{len}");
}

/// EXR, TIFF and Radiance HDR images are not decoded whole (415 KB of EXR, 6 KB of TIFF and 96
/// KB of HDR declaring 8000 x 8000 float RGB pixels would be 768 MB each as `f32`). They are
/// read from the file a row of blocks (a scan line) at a time; with `--decode-memory 16` the
/// run's peak memory stays under 600 MB.
#[cfg(target_os = "linux")]
#[test]
fn large_declared_float_images_are_read_a_band_at_a_time() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    crate::forged::exr_zeros(&d.join("a.exr"), 8000, 8000);
    crate::forged::tiff_zeros(&d.join("b.tif"), 8000, 8000);
    crate::forged::hdr_zeros(&d.join("c.hdr"), 8000, 8000);
    for (n, max) in [
        ("a.exr", 450 << 10),
        ("b.tif", 8 << 10),
        ("c.hdr", 100 << 10),
    ] {
        let len = fs::metadata(d.join(n)).unwrap().len();
        assert!(len < max, "{n}: {len} bytes");
    }
    let lp = d.join("lights.lp");
    fs::write(
        &lp,
        "3\na.exr 0 0 1\nb.tif 0.5 0 0.866\nc.hdr 0 0.5 0.866\n",
    )
    .unwrap();
    let out = d.join("out");
    // The cache alone is what is measured: the run stops after its first tile, every image
    // decoded. (Nothing is decoded here: this process's peak would count in the child's.)
    let args = [
        "estimate",
        s(&lp),
        "-o",
        s(&out),
        "--decode-memory",
        "16",
        "--cache-format",
        "f16",
        "--stop-after-tiles",
        "1",
        "--quiet",
    ];
    let (o, peak_kib) = crate::common::run_measuring_rss(&args);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(peak_kib < 600 << 10, "peak {peak_kib} KiB");
    let cache: Vec<PathBuf> = fs::read_dir(out.join(".symframe-cache"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "stack"))
        .collect();
    assert_eq!(cache.len(), 1, "{cache:?}");
    let len = fs::metadata(&cache[0]).unwrap().len();
    assert!(len > 8000 * 8000 * 3 * 6, "{len}");
}

/// Read a band at a time, every image of a decoding batch holds its file open: a batch of 300
/// EXR images failed with "Too many open files" under a limit of 200 open files (the common
/// default is 1,024, and a batch of 1,512 fits in the default `--decode-memory`). A batch holds
/// at most the limit less a margin.
#[cfg(target_os = "linux")]
#[test]
fn a_decoding_batch_holds_no_more_files_open_than_the_process_may() {
    use std::os::unix::process::CommandExt;
    let tmp = tempfile::tempdir().unwrap();
    let lp = lambert(&tmp.path().join("data"), 8, 300);
    let out = tmp.path().join("out");
    let mut cmd = std::process::Command::new(crate::common::bin());
    cmd.args([
        "estimate",
        s(&lp),
        "-o",
        s(&out),
        "--method",
        "woodham",
        "--quiet",
    ]);
    // SAFETY: the closure runs in the forked child before exec and only calls setrlimit,
    // which is async-signal-safe.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 200,
                rlim_max: 200,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = cmd.output().unwrap();
    ok(&o);
    let r = report(&out);
    assert_eq!(
        r["cache"]["batch_images"].as_u64(),
        Some(72),
        "{}",
        r["cache"]
    );
}

/// A mask is not decoded before its size is compared with the images' (a 415 KB EXR declaring
/// 8000 x 8000 float pixels as the mask of 16 x 16 images would cost hundreds of MB:
/// docs/performance.md, "Memory model"): the sizes their headers declare are compared first.
#[cfg(target_os = "linux")]
#[test]
fn a_mask_of_another_size_is_refused_before_it_is_decoded() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = lambert(&tmp.path().join("data"), 16, 12);
    let mask = tmp.path().join("mask.exr");
    crate::forged::exr_zeros(&mask, 8000, 8000);
    let out = tmp.path().join("out");
    let (o, peak_kib) = crate::common::run_measuring_rss(&[
        "estimate",
        s(&lp),
        "-o",
        s(&out),
        "--mask",
        s(&mask),
        "--method",
        "woodham",
    ]);
    assert_one_line_error(&o, "mask.exr");
    assert!(
        stderr(&o).contains("mask is 8000x8000 but the images are 16x16"),
        "{}",
        stderr(&o)
    );
    assert!(peak_kib < 100 << 10, "peak {peak_kib} KiB");
}

/// The `.lp` row variants other tools write, end to end: tabs after the path (the PTM
/// fitter's samples), CR LF line ends (RTIBuilder on Windows) and vectors of 300 (light
/// positions in mm, as ramamoorthyluxman/illumi-net reads `.lp` rows) give the same normals
/// as the plain file, the lengths warned about; a fourth number after the image (read by
/// relight as part of the name) is refused naming the line.
#[test]
fn lp_row_variants_of_other_tools_are_read_or_refused_naming_the_line() {
    let tmp = tempfile::tempdir().unwrap();
    let lp = lambert(&tmp.path().join("data"), 12, 12);
    let plain = tmp.path().join("plain");
    ok(&estimate(&lp, &plain, &["--method", "woodham", "-q"]));
    let text = fs::read_to_string(&lp).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let variant: Vec<String> = lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let t: Vec<&str> = l.split_whitespace().collect();
            if i == 0 {
                return t[0].to_string();
            }
            let v: Vec<String> = t[1..]
                .iter()
                .map(|x| format!("{}", x.parse::<f64>().unwrap() * 300.0))
                .collect();
            format!("{}\t{}", t[0], v.join(" "))
        })
        .collect();
    fs::write(&lp, variant.join("\r\n") + "\r\n").unwrap();
    let out = tmp.path().join("variant");
    let o = estimate(&lp, &out, &["--method", "woodham", "-q"]);
    ok(&o);
    let want = "12 of 12 lights are far from unit length";
    assert!(stderr(&o).contains(want), "{}", stderr(&o));
    assert!(crate::common::report_warnings(&out)
        .iter()
        .any(|w| w.contains(want)));
    let a = read_npy_f32(&plain.join("normals.npy")).unwrap().1;
    let b = read_npy_f32(&out.join("normals.npy")).unwrap().1;
    let worst = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(worst < 1e-5, "normals differ by {worst}");
    // A fourth number after the image: refused, naming the line.
    let mut rows: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    rows[2].push_str(" 1.0");
    fs::write(&lp, rows.join("\n") + "\n").unwrap();
    let o = symframe(&["estimate", s(&lp), "-o", s(&tmp.path().join("x"))]);
    assert_one_line_error(
        &o,
        "lights.lp:3: 4 numbers after the image 'images/img_0001.exr'",
    );
}
