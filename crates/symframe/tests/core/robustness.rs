//! The estimator on arbitrary samples (NaN, infinities, negatives, huge and tiny values), with
//! and without a clip level: never a panic, and a normal is a unit vector facing the camera hemisphere or absent.

use proptest::prelude::*;
use symframe::{
    uniform_cone_lights, Estimator, EstimatorParams, NoiseModel, PixelScratch, Rig, RigOptions,
};

fn check(n_lights: usize, slice: &[f32]) {
    let rig = Rig::new(&uniform_cone_lights(n_lights, 65.0), RigOptions::default()).unwrap();
    // Without and with a clip level (censored samples read at it).
    let clipped = EstimatorParams {
        noise: NoiseModel {
            clip_level: Some(0.9),
            ..NoiseModel::default()
        },
        ..EstimatorParams::default()
    };
    for params in [EstimatorParams::default(), clipped] {
        let estimator = Estimator::new(&rig, params);
        let mut scratch = PixelScratch::new(&rig);
        let slice = &slice[..rig.n_used() * 3];
        let e = estimator.estimate_pixel_with(slice, &mut scratch);
        if let Some(n) = e.normal {
            assert!((n.length() - 1.0).abs() < 1e-6, "{n:?}");
        }
        if let Some(t) = e.tangent {
            assert!((t.length() - 1.0).abs() < 1e-6, "{t:?}");
        }
    }
}

/// A sample value: anything, or mostly plausible radiance with rare extremes.
fn sample() -> impl Strategy<Value = f32> {
    prop_oneof![
        prop::num::f32::ANY,
        0.0f32..2.0,
        Just(0.0f32),
        Just(f32::NAN),
        (0.0f32..1.0).prop_map(|v| v.powi(12) * 1e6),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn arbitrary_samples_never_panic_the_estimator(
        n_lights in prop::sample::select(vec![16usize, 80, 300]),
        slice in prop::collection::vec(sample(), 900),
    ) {
        check(n_lights, &slice);
    }
}
