//! `symframe experiment ... --quick`: each experiment runs, writes its plots and report, and a
//! sanity property of its numbers holds.

use std::path::Path;
use std::process::Command;

fn run(which: &str, out: &Path) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_symframe"))
        .args(["experiment", which, "--quick", "-o"])
        .arg(out)
        .output()
        .expect("run symframe");
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{which} failed: {}\n{stdout}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

fn pngs(dir: &Path, prefix: &str) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.starts_with(prefix) && n.ends_with(".png") && e.metadata().unwrap().len() > 1000
        })
        .count()
}

/// The cells of a markdown row whose first cell is `first`, in the table after `heading`.
fn row_after(s: &str, heading: &str, first: &str) -> Vec<String> {
    let rest = &s[s
        .find(heading)
        .unwrap_or_else(|| panic!("no '{heading}' in\n{s}"))..];
    let line = rest
        .lines()
        .find(|l| l.starts_with(&format!("| {first} |")))
        .unwrap_or_else(|| panic!("no row '{first}' after '{heading}'"));
    line.trim_matches('|')
        .split('|')
        .map(|c| c.trim().to_string())
        .collect()
}

#[test]
fn fig3_quick() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("fig3", dir.path());
    assert!(dir.path().join("fig3.md").is_file());
    assert_eq!(pngs(dir.path(), "fig3_"), 12);
    // Ward, theta_n = 0, theta_d_max = 65: below 1 degree, normal and tangent.
    let row = row_after(&out, "per theta_n", "0");
    let ward: Vec<f64> = row[1]
        .split('/')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    assert!(ward[0] < 1.0 && ward[1] < 1.0, "{row:?}");
}

#[test]
fn fig4_quick() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("fig4", dir.path());
    assert!(dir.path().join("fig4.md").is_file());
    assert_eq!(pngs(dir.path(), "fig4_"), 3);
    // Woodham-robust is near zero on the perfectly diffuse end; symmetry is good there too.
    let row = row_after(&out, "Torrance-Sparrow", "0");
    let num = |c: &str| c.split(' ').next().unwrap().parse::<f64>().unwrap();
    assert!(num(&row[4]) < 0.1, "{row:?}");
    assert!(num(&row[2]) < 1.0, "{row:?}");
}

#[test]
fn fig10_quick() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("fig10", dir.path());
    assert!(dir.path().join("fig10.md").is_file());
    assert_eq!(pngs(dir.path(), "fig10_"), 2);
    // The sphere at the larger light count: a usable estimate over most pixels.
    let row = row_after(&out, "| shape |", "sphere");
    let mean: f64 = row[2].parse().unwrap();
    let coverage: f64 = row[7].trim_end_matches('%').parse().unwrap();
    assert!(mean < 5.0 && coverage > 90.0, "{row:?}");
}

#[test]
fn noise_quick() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("noise", dir.path());
    assert!(dir.path().join("noise.md").is_file());
    assert_eq!(pngs(dir.path(), "noise_"), 2);
    let clean: f64 = row_after(&out, "noise sigma", "0")[1].parse().unwrap();
    let q16: f64 = row_after(&out, "quantisation", "16-bit")[1]
        .parse()
        .unwrap();
    assert!(clean < 5.0 && q16 < 5.0, "{clean} {q16}");
}

#[test]
fn all_quick_writes_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("validation");
    run("all", &out_dir);
    let md = std::fs::read_to_string(dir.path().join("validation.md")).unwrap();
    for s in [
        "Figure 3",
        "Figure 4",
        "Figure 10",
        "Noise",
        "validation/fig3_ward_paper_normal.png",
        "cores",
    ] {
        assert!(md.contains(s), "report lacks '{s}'");
    }
}
