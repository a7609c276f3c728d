//! Decoding one image on one thread, by format and size: float RGB EXR (ZIP, as `symframe
//! synth` writes), 16-bit PNG and float TIFF, each 128 x 128 and 1024 x 1024, from bytes in
//! memory. Criterion reports the throughput in bytes of decoded `f32` samples (12 per pixel).
//! `cargo bench -p symframe-io --bench decode`; figures in docs/performance.md.
#![allow(
    missing_docs,
    reason = "criterion_group! defines a public function without documentation"
)]

use std::path::Path;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use symframe_io::{decode_image, write_exr_rgb, write_png16_rgb, DecodeOptions};

/// A shaded sphere filling the frame on a black background (smooth, like a synthetic render).
fn render(size: usize) -> Vec<f32> {
    let mut rgb = vec![0.0f32; size * size * 3];
    for y in 0..size {
        for x in 0..size {
            let u = (x as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let v = (y as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let r2 = u * u + v * v;
            if r2 < 1.0 {
                let nz = (1.0 - r2).sqrt();
                let shade = (0.3 * u + 0.2 * v + 0.93 * nz).max(0.0);
                let spec = shade.powi(40) * 4.0;
                let p = (y * size + x) * 3;
                rgb[p..p + 3].copy_from_slice(&[
                    0.6 * shade + spec,
                    0.5 * shade + spec,
                    0.4 * shade + spec,
                ]);
            }
        }
    }
    rgb
}

fn files(dir: &Path, size: usize) -> Vec<(&'static str, std::path::PathBuf)> {
    let rgb = render(size);
    let exr = dir.join(format!("{size}.exr"));
    write_exr_rgb(&exr, size, size, &rgb).unwrap();
    let png = dir.join(format!("{size}.png"));
    let clipped: Vec<f32> = rgb.iter().map(|v| v.min(0.99)).collect();
    write_png16_rgb(&png, size, size, &clipped).unwrap();
    let tif = dir.join(format!("{size}.tif"));
    tiff::encoder::TiffEncoder::new(std::fs::File::create(&tif).unwrap())
        .unwrap()
        .write_image::<tiff::encoder::colortype::RGB32Float>(size as u32, size as u32, &rgb)
        .unwrap();
    vec![("exr-zip-f32", exr), ("png16", png), ("tiff-f32", tif)]
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let opts = DecodeOptions::default();
    let mut g = c.benchmark_group("decode");
    for size in [128usize, 1024] {
        g.throughput(Throughput::Bytes((size * size * 12) as u64));
        if size > 512 {
            g.sample_size(20);
        }
        for (name, path) in files(dir.path(), size) {
            let bytes = std::fs::read(&path).unwrap();
            g.bench_with_input(BenchmarkId::new(name, size), &bytes, |b, bytes| {
                b.iter(|| decode_image(&path, bytes, &opts).unwrap())
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
