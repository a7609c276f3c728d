//! Figure 10: normal and error maps of a sphere and a bumpy surface at 1512, 743, 380 and 172
//! lights (fewer lights, faceted normal field).

use anyhow::Result;
use glam::DVec3;
use symframe::brdf::{Brdf, Ward};
use symframe::render::{BumpParams, Scene, TangentField};
use symframe::{uniform_cone_lights, Rig, RigOptions};

use super::plot::{self, md_table};
use super::{Ctx, Section};

/// Per light count: (lights, mean normal error, facet measure).
type Facets = Vec<(usize, f64, f64)>;

/// Top of the error maps' colour scale, degrees.
const ERROR_MAX: f64 = 10.0;

/// Mean over 4-neighbour pixel pairs (both estimated, both in the mask) of
/// `|angle(n_p, n_q) - angle(gt_p, gt_q)|`, degrees: how much rougher (faceted) the estimated
/// field is than the true one.
fn facet_excess(normals: &[f32], gt: &[f32], mask: &[bool], w: usize, h: usize) -> f64 {
    let v =
        |a: &[f32], p: usize| DVec3::new(a[p * 3] as f64, a[p * 3 + 1] as f64, a[p * 3 + 2] as f64);
    let ok = |p: usize| mask[p] && normals[p * 3].is_finite();
    let (mut s, mut n) = (0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            for q in [(x + 1 < w).then(|| p + 1), (y + 1 < h).then(|| p + w)]
                .into_iter()
                .flatten()
            {
                if ok(p) && ok(q) {
                    let e = super::angle_deg(v(normals, p), v(normals, q));
                    let g = super::angle_deg(v(gt, p), v(gt, q));
                    s += (e - g).abs();
                    n += 1;
                }
            }
        }
    }
    if n > 0 {
        s / n as f64
    } else {
        f64::NAN
    }
}

/// One shape at one light count.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// Shape (`sphere`, `bumps`).
    pub shape: String,
    /// Lights.
    pub lights: usize,
    /// Normal error against ground truth over pixels within 60 degrees of the view.
    pub evaluation: symframe::Evaluation,
    /// The facet measure, degrees.
    pub facet: f64,
}

/// Runs the experiment: the plots into `ctx.out`, the section and every row back.
pub fn run(ctx: &Ctx) -> Result<Section<Vec<Row>>> {
    let (size, counts): (usize, Vec<usize>) = if ctx.quick {
        (20, vec![380, 172])
    } else {
        (64, vec![1512, 743, 380, 172])
    };
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let shapes = [
        (
            "sphere",
            Scene::sphere(size, TangentField::Circular),
            65.0,
            "a sphere filling the frame (circular tangent field), lights uniform over the \
             theta_d_max = 65 cone, estimated with theta_d_max = 65",
        ),
        (
            "bumps",
            Scene::bumps(size, &BumpParams::default(), TangentField::Axial(DVec3::X)),
            45.0,
            "12 seeded Gaussian bumps on flat ground with cast shadows (tangents along image \
             x), lights uniform over the theta_d_max = 45 cone (all within 90° of the view, so \
             none below the ground's horizon), estimated with theta_d_max = 45",
        ),
    ];
    let mut md = String::from("## Figure 10: fewer lights\n\n");
    md += &format!(
        "Set-up: noise-free {size} x {size} renders of the paper's Ward material ({}), \
         estimated with the paper's cosine form at {:?} lights. Shapes:\n\n",
        brdf.name(),
        counts
    );
    for (name, _, _, desc) in &shapes {
        md += &format!("- `{name}`: {desc}.\n");
    }
    md += "\nErrors over pixels whose true normal is within 60° of the view (the maps show every pixel; the bright rim of the sphere lies beyond that range). `facet` is the \
           mean over neighbouring pixel pairs of |angle between the estimated normals - angle \
           between the true normals| (degrees): it grows when the field breaks into facets.\n\n";
    let header: Vec<String> = [
        "shape",
        "lights",
        "normal mean",
        "median",
        "p90",
        "tangent mean",
        "tangent median",
        "coverage",
        "facet",
    ]
    .map(String::from)
    .to_vec();
    let mut table = Vec::new();
    let mut facets: Vec<(String, Facets)> = Vec::new();
    let mut figures = Vec::new();
    for (name, scene, cone, _) in &shapes {
        let gt_n = scene.gt_normals();
        let gt_t = scene.gt_tangents();
        let mut tiles = Vec::new();
        let mut fs = Vec::new();
        for &n in &counts {
            let lights = uniform_cone_lights(n, *cone);
            let rig = Rig::new(
                &lights,
                RigOptions {
                    theta_d_max_deg: *cone,
                },
            )?;
            let stack = scene.render_stack(&brdf as &dyn Brdf, &lights);
            let (maps, e) = super::estimate_and_evaluate(scene, &stack, &rig, &gt_n, &gt_t)?;
            let facet = facet_excess(&maps.normals, &gt_n, &scene.mask, size, size);
            fs.push((n, e.normal_error.mean, facet));
            table.push(vec![
                name.to_string(),
                n.to_string(),
                format!("{:.2}", e.normal_error.mean),
                format!("{:.2}", e.normal_error.median),
                format!("{:.2}", e.normal_error.p90),
                format!("{:.2}", e.tangent_error.mean),
                format!("{:.2}", e.tangent_error.median),
                format!("{:.1}%", 100.0 * e.coverage),
                format!("{facet:.2}"),
            ]);
            figures.push(Row {
                shape: name.to_string(),
                lights: n,
                evaluation: e,
                facet,
            });
            let err = symframe::Evaluation::normal_error_map(&maps.normals, &gt_n);
            tiles.push(plot::normal_tile(&maps.normals, &scene.mask));
            tiles.push(plot::error_tile(&err, &scene.mask, ERROR_MAX));
        }
        let pic = plot::grid(
            &format!("{name}: estimated normals and normal error"),
            &counts.iter().map(|n| format!("{n} lights")).collect::<Vec<_>>(),
            &["normal map".to_string(), "normal error".to_string()],
            &tiles,
            size,
            size,
            (192 / size).max(1),
            &format!(
                "error: viridis 0 to {ERROR_MAX:.0}° (yellow ≥ {ERROR_MAX:.0}°), magenta: no estimate"
            ),
        )?;
        md += &ctx.save(&pic, &format!("fig10_{name}.png"), &format!("{name} grid"))?;
        facets.push((name.to_string(), fs));
    }
    let t = md_table(&header, &table);
    println!("{t}");
    md += &format!(
        "\n{t}\n### Reading\n\nPaper's claim: fewer lights (1512, 743, 380, 172) give a \
                    faceted normal field (poor local minima).\n\n"
    );
    for (name, fs) in &facets {
        let (first, last) = (fs[0], fs[fs.len() - 1]);
        let monotone = fs.windows(2).all(|w| w[1].2 >= w[0].2 - 0.05);
        md += &format!(
            "- {name}: from {} to {} lights the mean normal error goes {:.2}° -> {:.2}° and \
             the facet measure {:.2}° -> {:.2}°{}.\n",
            first.0,
            last.0,
            first.1,
            last.1,
            first.2,
            last.2,
            if last.2 > first.2 * 1.5 && monotone {
                ": the field gets steadily more faceted, as the paper reports"
            } else if last.2 > first.2 {
                ": rougher with fewer lights, but not steadily"
            } else {
                ": NOT more faceted with fewer lights here"
            }
        );
    }
    Ok(Section {
        markdown: md,
        figures,
    })
}
