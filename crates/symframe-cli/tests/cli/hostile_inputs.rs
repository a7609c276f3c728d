//! End-to-end regression tests of hostile inputs: files beside the light file that were read
//! (or ignored) without a word, EXR layers and masks read the wrong way, images whose size
//! defeated `--decode-memory`, and paths that are not regular files read without bound.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{assert_one_line_error, estimate, ok, s, symframe, Truth};
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
