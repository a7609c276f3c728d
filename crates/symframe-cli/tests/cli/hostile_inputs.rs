//! End-to-end regression tests of hostile inputs: files beside the light file that were read
//! (or ignored) without a word, EXR layers and masks read the wrong way, images whose size
//! defeated `--decode-memory`, and paths that are not regular files read without bound.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{assert_one_line_error, estimate, ok, report, s, stderr, symframe, Truth};
use symframe::brdf::lambertian::Lambertian;
use symframe_io::ImageFormat;

/// A small Lambertian sphere as float EXR; returns the `.lp` path.
fn lambert(dir: &Path, size: usize, lights: usize) -> PathBuf {
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    let brdf = Lambertian::new([0.6; 3]);
    crate::common::sphere_dataset(dir, size, lights, &brdf, ImageFormat::Exr, 1.0, truth).1
}

/// The `warnings` of an output folder's report, one string each.
fn report_warnings(out: &Path) -> Vec<String> {
    report(out)["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

/// `light_intensities.txt` was silently ignored once a second `.lp` sat beside the first (a
/// Lambertian test went from 0.000 to 1.34 degrees with nothing in report.json).
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
        report_warnings(&out).iter().any(|w| w.contains(want)),
        "{:?}",
        report_warnings(&out)
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
    assert!(report_warnings(&out).iter().any(|w| w.contains(want)));
    // Rows of no light file beside it: an error.
    fs::write(data.join("light_intensities.txt"), "1 1 1\n".repeat(7)).unwrap();
    let o = estimate(&lp, &tmp.path().join("c"), &["--method", "woodham"]);
    assert_one_line_error(&o, "light_intensities.txt: 7 light intensities but");
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

/// A light `1e200 0 1e200` was "zero or not finite"; an `.lp` with CR-only line ends was one
/// line (its error quoted the whole file).
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
