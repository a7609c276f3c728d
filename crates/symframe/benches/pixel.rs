//! Per-pixel estimation cost at the paper's light counts (172, 380, 743, 1512 lights over the
//! 65-degree cone), anisotropic Ward, a normal 30 degrees from the view.
//! `cargo bench -p symframe --bench pixel`.
#![allow(
    missing_docs,
    reason = "criterion_group! defines a public function without documentation"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use glam::DVec3;
use symframe::brdf::Ward;
use symframe::render::Scene;
use symframe::{
    uniform_cone_lights, Estimator, EstimatorParams, Interpolation, PixelScratch, Rig, RigOptions,
};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("estimate_pixel");
    group.sample_size(20);
    let ward = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let normal = DVec3::new(0.5f64.sin(), 0.0, 0.5f64.cos());
    let scene = Scene::plane(1, 1, normal, DVec3::new(0.3, 1.0, 0.0));
    for n in [172, 380, 743, 1512] {
        let lights = uniform_cone_lights(n, 65.0);
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        let stack = scene.render_stack(&ward, &lights);
        // The pixel's samples in rig order.
        let all = stack.pixel(0);
        let slice: Vec<f32> = rig
            .input_index()
            .iter()
            .flat_map(|&i| all[3 * i..3 * i + 3].iter().copied())
            .collect();
        for (name, interpolation) in [
            ("fast", Interpolation::Fast),
            ("exact", Interpolation::Exact),
        ] {
            let params = EstimatorParams {
                interpolation,
                ..EstimatorParams::default()
            };
            let est = Estimator::new(&rig, params);
            let mut scratch = PixelScratch::new(&rig);
            group.bench_with_input(BenchmarkId::new(name, n), &slice, |b, s| {
                b.iter(|| est.estimate_pixel_with(std::hint::black_box(s), &mut scratch))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
