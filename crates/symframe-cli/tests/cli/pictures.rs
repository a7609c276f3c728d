//! The pictures an estimate writes for people: `lights.png`, the legends, `residual.png` with
//! `residual.npy`, and `index.html`; and the demo's error pictures.

use std::collections::BTreeSet;
use std::fs;
use std::path::Path;

use glam::DVec3;
use symframe::brdf::Ward;
use symframe::render::{Scene, TangentField};
use symframe::{uniform_cone_lights, Estimator, EstimatorParams, Rig, RigOptions};
use symframe_io::{read_npy_f32, write_lp_dataset, ImageFormat};
use symframe_job::pictures::{
    light_position, LEGEND_BAR, LIGHTS_DISC, LIGHT_DROPPED, LIGHT_USED, RESIDUAL_MAX,
};

use crate::common::*;

/// An RGB picture read back.
fn rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// A 24-pixel Ward sphere under 150 lights over the 65-degree cone, as a float EXR `.lp`
/// dataset: estimated with a narrower cone, the lights far from the view are dropped.
fn sphere(dir: &Path) -> (Vec<DVec3>, std::path::PathBuf) {
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let scene = Scene::sphere(24, TangentField::Circular);
    let lights = uniform_cone_lights(150, 65.0);
    let images: Vec<Vec<f32>> = lights.iter().map(|&l| scene.render(&brdf, l)).collect();
    let lp = write_lp_dataset(
        dir,
        &lights,
        &images,
        24,
        24,
        ImageFormat::Exr,
        None,
        None,
        Some(&scene.mask),
    )
    .unwrap();
    (lights, lp)
}

/// A light of `lights` (by index) whose projection in `lights.png` is at least 10 pixels from
/// every other light's, used or not as asked.
fn isolated(lights: &[DVec3], used: &[bool], want_used: bool) -> usize {
    let at: Vec<(i32, i32)> = lights.iter().map(|&l| light_position(l)).collect();
    (0..lights.len())
        .find(|&i| {
            used[i] == want_used
                && at
                    .iter()
                    .enumerate()
                    .all(|(j, b)| j == i || (at[i].0 - b.0).pow(2) + (at[i].1 - b.1).pow(2) >= 100)
        })
        .unwrap_or_else(|| panic!("no isolated light (used: {want_used})"))
}

/// `lights.png` draws each light at its projected position, used and dropped ones in their
/// colours, as the report counts them; the legends' colour bars run from the map's colour at 0
/// to its colour at the top; `index.html` shows every picture of the folder and nothing else,
/// with the report's counts; `residual.npy` holds the symmetry distance the estimator finds at
/// a pixel.
#[test]
fn an_estimate_draws_its_lights_legends_residual_and_index() {
    let tmp = tempfile::tempdir().unwrap();
    let (lights, lp) = sphere(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    // theta_d < 40: lights up to 80 degrees from the view are used.
    ok(&estimate(&lp, &out, &["--theta-d-max", "40", "-q"]));
    let report = report(&out);

    // lights.png.
    let rig = Rig::new(
        &lights,
        RigOptions {
            theta_d_max_deg: 40.0,
        },
    )
    .unwrap();
    let mut used = vec![false; lights.len()];
    for &i in rig.input_index() {
        used[i] = true;
    }
    let dropped = used.iter().filter(|&&u| !u).count();
    assert!(dropped > 10, "{dropped}");
    assert_eq!(report["lights"]["dropped"].as_u64(), Some(dropped as u64));
    let pic = rgb(&out.join("lights.png"));
    for (want_used, colour) in [(true, LIGHT_USED), (false, LIGHT_DROPPED)] {
        let i = isolated(&lights, &used, want_used);
        let (x, y) = light_position(lights[i]);
        assert_eq!(
            pic.get_pixel(x as u32, y as u32).0,
            colour,
            "light {i} {:?} (used: {want_used})",
            lights[i]
        );
    }
    // Nothing is drawn in a light's colour where no light is: the disc's centre (the view).
    let (cx, cy, _) = LIGHTS_DISC;
    let centre = pic.get_pixel(cx as u32, cy as u32).0;
    assert!(centre != LIGHT_USED && centre != LIGHT_DROPPED);

    // The legends' bars: the map's colour at 0 on the bottom row, at the top on the top row.
    let x = (LEGEND_BAR.left + LEGEND_BAR.width / 2) as u32;
    let (top, bottom) = (LEGEND_BAR.top as u32, LEGEND_BAR.bottom as u32);
    let conf = rgb(&out.join("confidence_legend.png"));
    assert_eq!(
        conf.get_pixel(x, bottom).0.to_vec(),
        symframe_io::gray_map_rgb8(&[0.0], 0.0, 1.0)
    );
    assert_eq!(
        conf.get_pixel(x, top).0.to_vec(),
        symframe_io::gray_map_rgb8(&[1.0], 0.0, 1.0)
    );
    let res = rgb(&out.join("residual_legend.png"));
    assert_eq!(
        res.get_pixel(x, top).0.to_vec(),
        symframe_io::gray_map_rgb8(&[RESIDUAL_MAX], 0.0, RESIDUAL_MAX)
    );
    // The source legend shows each code's colour.
    let src = rgb(&out.join("source_legend.png"));
    for code in 0..5u8 {
        let (sx, sy) = symframe_job::pictures::source_swatch(code);
        assert_eq!(
            src.get_pixel(sx as u32 + 10, sy as u32 + 8).0,
            symframe_io::SOURCE_PALETTE[code as usize]
        );
    }
    // The data pictures stay pixel-aligned with the image.
    for name in [
        "confidence.png",
        "source.png",
        "tangents.png",
        "residual.png",
    ] {
        assert_eq!(rgb(&out.join(name)).dimensions(), (24, 24), "{name}");
    }

    // residual.npy: the estimator's symmetry distance at the answer, at a pixel near the
    // sphere's centre, as the library computes it from the same samples and parameters.
    let (shape, residual) = read_npy_f32(&out.join("residual.npy")).unwrap();
    assert_eq!(shape, vec![24, 24]);
    let ds = symframe_io::open_dataset(&lp).unwrap();
    let stack = symframe_io::load_stack(&ds, &Default::default(), &|| {}).unwrap();
    let params: EstimatorParams = serde_json::from_value(report["parameters"].clone()).unwrap();
    let estimator = Estimator::new(&rig, params);
    let p = 12 * 24 + 13;
    let slice: Vec<f32> = rig
        .input_index()
        .iter()
        .flat_map(|&i| stack.pixel(p)[3 * i..3 * i + 3].to_vec())
        .collect();
    let e = estimator.estimate_pixel(&slice);
    assert!(e.residual[0].is_finite() && e.residual[0] > 0.0, "{e:?}");
    assert_eq!(residual[p], e.residual[0] as f32, "pixel {p}");
    // Every estimated pixel by the symmetry or a lobe has one, the others none.
    let (_, source) = symframe_io::read_npy_u8(&out.join("source.npy")).unwrap();
    assert!(source
        .iter()
        .zip(&residual)
        .all(|(&s, r)| s != 0 || r.is_nan()));
    assert!(residual.iter().filter(|r| r.is_finite()).count() > 100);
    // residual.png is residual.npy coloured.
    let png = rgb(&out.join("residual.png"));
    let (px, py) = ((p % 24) as u32, (p / 24) as u32);
    assert_eq!(
        png.get_pixel(px, py).0.to_vec(),
        symframe_job::pictures::residual_rgb8(&[residual[p]])
    );

    // index.html: every picture of the folder, and nothing that is not there.
    let html = fs::read_to_string(out.join("index.html")).unwrap();
    let referenced: BTreeSet<String> = html
        .split("src=\"")
        .skip(1)
        .map(|s| s[..s.find('"').unwrap()].to_string())
        .collect();
    let pictures: BTreeSet<String> = fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png"))
        .collect();
    assert_eq!(referenced, pictures);
    assert!(pictures.contains("lights.png") && pictures.contains("residual_legend.png"));
    // The summary: the counts of the report.
    let estimated = report["pixels"]["estimated"].as_u64().unwrap();
    assert!(
        html.contains(&format!("<th>estimated</th><td>{estimated}</td>")),
        "{html}"
    );
    assert!(html.contains(&format!("<th>dropped</th><td>{dropped}</td>")));
    // And the report lists them as files of the output set.
    let files: Vec<&str> = report["output_set"]["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    for name in pictures.iter().map(String::as_str).chain(["index.html"]) {
        assert!(files.contains(&name), "{name}");
    }
}

/// A baseline uses every light: `lights.png` shows none dropped, and the residual (a symmetry
/// measure) is not measured anywhere.
#[test]
fn a_baseline_draws_every_light_used_and_no_residual() {
    let tmp = tempfile::tempdir().unwrap();
    let (lights, lp) = sphere(&tmp.path().join("data"));
    let out = tmp.path().join("out");
    ok(&estimate(&lp, &out, &["--method", "woodham", "-q"]));
    let pic = rgb(&out.join("lights.png"));
    let used = vec![true; lights.len()];
    let i = isolated(&lights, &used, true);
    let (x, y) = light_position(lights[i]);
    assert_eq!(pic.get_pixel(x as u32, y as u32).0, LIGHT_USED);
    assert!(!pic.pixels().any(|p| p.0 == LIGHT_DROPPED));
    let (_, residual) = read_npy_f32(&out.join("residual.npy")).unwrap();
    assert!(residual.iter().all(|r| r.is_nan()));
}

/// The demo writes the error pictures with their colour bars beside its estimate, and says so:
/// the normal error picture shows, at every evaluated pixel, the colour of that pixel's error,
/// and those errors' mean is the mean the demo prints.
#[test]
fn the_demo_writes_error_pictures_whose_mean_it_prints() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let o = symframe(&["demo", "-o", s(&out), "--size", "24", "--lights", "300"]);
    ok(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let est = out.join("estimate");
    for name in ["normal_error.png", "tangent_error.png", "index.html"] {
        assert!(est.join(name).is_file(), "{name}");
        assert!(stdout.contains(s(&est.join(name))), "{stdout}");
    }
    let printed: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("normal error (pixels within 60 deg of the view): mean "))
        .and_then(|l| l.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no mean error in {stdout}"));

    let (_, normals) = read_npy_f32(&est.join("normals.npy")).unwrap();
    let (_, gt) = read_npy_f32(&out.join("dataset/gt_normals.npy")).unwrap();
    let errors = symframe::Evaluation::normal_error_map(&normals, &gt);
    let eval: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(est.join("eval.json")).unwrap()).unwrap();
    let max = eval["normal_scale_max_deg"].as_f64().unwrap() as f32;
    let pic = rgb(&est.join("normal_error.png"));
    let (x0, y0, zoom) = symframe_job::colorbar::error_map_layout(24, 24);
    let cos60 = 0.5f32;
    let mut evaluated = Vec::new();
    for p in 0..24 * 24 {
        let g = &gt[3 * p..3 * p + 3];
        if g[2].is_nan() || g[2] < cos60 || !errors[p].is_finite() {
            continue;
        }
        evaluated.push(errors[p] as f64);
        let (x, y) = (x0 + (p % 24) * zoom, y0 + (p / 24) * zoom);
        assert_eq!(
            pic.get_pixel(x as u32, y as u32).0.to_vec(),
            symframe_io::gray_map_rgb8(&[errors[p]], 0.0, max),
            "pixel {p}"
        );
    }
    assert!(evaluated.len() > 200, "{}", evaluated.len());
    let mean = evaluated.iter().sum::<f64>() / evaluated.len() as f64;
    assert!(
        (mean - printed).abs() <= 0.006,
        "picture's mean {mean}, printed {printed}"
    );
}
