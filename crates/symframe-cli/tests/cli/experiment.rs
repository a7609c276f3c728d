//! `symframe experiment all --quick`: every experiment runs end to end and the report, plots
//! and JSON figures are written (each experiment's figures are checked by its unit tests).

use crate::common::{s, symframe};

#[test]
fn all_quick_writes_the_report_plots_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("validation");
    let o = symframe(&["experiment", "all", "--quick", "-o", s(&out_dir)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
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
    for name in ["fig3", "fig4", "fig10", "noise", "relight"] {
        let json = std::fs::read_to_string(out_dir.join(format!("{name}.json"))).unwrap();
        let figures: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert!(!figures.is_null(), "{name}");
    }
}
