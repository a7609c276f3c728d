//! Hostile jobs: commands pointed at folders they did not write, forged shard manifests,
//! circles that do not fit the image, exports that fail half-way or would replace their own
//! inputs, and `--quiet` on every subcommand.

use crate::common::{stderr, symframe};

/// `--quiet` leaves nothing on stdout or stderr of any subcommand run on good inputs (only
/// errors and warnings are printed with it, and these inputs give none).
#[test]
fn quiet_silences_every_subcommand() {
    let tmp = tempfile::tempdir().unwrap();
    let t = |p: &str| tmp.path().join(p).to_str().unwrap().to_string();
    let data = t("data");
    let lp = format!("{data}/lights.lp");
    let cap = t("cap");
    // Each subcommand, after the ones whose outputs it reads.
    let runs: Vec<Vec<String>> = [
        vec!["synth", "-o", &data, "--size", "24", "--rig", "cone:60"],
        vec!["estimate", &lp, "-o", &t("est")],
        vec![
            "estimate",
            &lp,
            "-o",
            &t("s1"),
            "--tiles",
            "1/2",
            "--tile-size",
            "8",
        ],
        vec![
            "estimate",
            &lp,
            "-o",
            &t("s2"),
            "--tiles",
            "2/2",
            "--tile-size",
            "8",
        ],
        vec!["merge", &t("s1"), &t("s2"), "-o", &t("merged")],
        vec!["fit", &lp, "--frames", &t("est"), "-o", &t("fit")],
        vec![
            "relight",
            &t("fit"),
            "--light",
            "0.3,0.2,1",
            "-o",
            &t("relit"),
        ],
        vec!["view", &t("fit")],
        vec!["eval", &data, &t("est")],
        vec!["integrate", &t("est"), "-o", &t("shape")],
        vec!["export", "gltf", &t("fit"), "-o", &t("asset/a.glb")],
        vec![
            "synth",
            "-o",
            &cap,
            "--size",
            "48",
            "--rig",
            "cone:30",
            "--chrome-sphere",
        ],
        vec![
            "calibrate",
            &format!("{cap}/images"),
            "-o",
            &format!("{cap}/cal.lp"),
        ],
        vec!["demo", "-o", &t("demo"), "--size", "16", "--lights", "16"],
    ]
    .iter()
    .map(|v| v.iter().map(|a| a.to_string()).collect())
    .collect();
    let mut seen = std::collections::BTreeSet::new();
    for args in &runs {
        let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
        a.push("--quiet");
        let o = symframe(&a);
        assert!(o.status.success(), "{a:?}: {}", stderr(&o));
        assert_eq!(
            (
                String::from_utf8_lossy(&o.stdout).as_ref(),
                stderr(&o).as_str()
            ),
            ("", ""),
            "{a:?} --quiet printed something"
        );
        seen.insert(a[0]);
    }
    for cmd in [
        "estimate",
        "merge",
        "fit",
        "relight",
        "view",
        "synth",
        "eval",
        "calibrate",
        "integrate",
        "export",
        "demo",
    ] {
        assert!(seen.contains(cmd), "{cmd} not run");
    }
}
