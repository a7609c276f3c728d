//! `symframe-lab experiment all --quick`: every experiment runs end to end and the report, plots
//! and JSON figures are written (each experiment's figures are checked by its unit tests).

use crate::common::{lab, ok, s};

#[test]
fn all_quick_writes_the_report_plots_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("validation");
    ok(&lab(&["experiment", "all", "--quick", "-o", s(&out_dir)]));
    let md = std::fs::read_to_string(dir.path().join("validation.md")).unwrap();
    for s in [
        "Figure 3",
        "Figure 4",
        "Figure 10",
        "Noise",
        "Real-capture conditions",
        "validation/fig3_ward_paper_normal.png",
        "cores",
    ] {
        assert!(md.contains(s), "report lacks '{s}'");
    }
    for name in [
        "fig3",
        "fig4",
        "fig10",
        "noise",
        "relight",
        "materials",
        "capture",
    ] {
        let json = std::fs::read_to_string(out_dir.join(format!("{name}.json"))).unwrap();
        let figures: serde_json::Value = serde_json::from_str(&json).unwrap();
        let non_empty = figures
            .as_array()
            .map_or(figures.is_object(), |a| !a.is_empty());
        assert!(non_empty, "{name}: {figures}");
    }
    // The capture sweep's rows carry the estimator's and the baselines' figures.
    let json = std::fs::read_to_string(out_dir.join("capture.json")).unwrap();
    let rows: serde_json::Value = serde_json::from_str(&json).unwrap();
    for r in rows.as_array().unwrap() {
        assert_eq!(r["cells"].as_array().unwrap().len(), 3, "{r}");
        assert!(r["cells"][0]["normal_mean"].as_f64().is_some(), "{r}");
    }
}
