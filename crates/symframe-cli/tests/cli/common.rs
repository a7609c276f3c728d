//! Helpers shared by the CLI integration tests: running the binary, checking its failures, and
//! writing a small rendered sphere dataset.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use symframe::brdf::Brdf;
use symframe::render::{Scene, TangentField};
use symframe::uniform_cone_lights;
use symframe_io::{write_lp_dataset, ImageFormat};

/// The `symframe` binary under test: this build's, or the one `SYMFRAME_TEST_BIN` names (to
/// show that a regression test fails on a build from before its fix).
pub fn bin() -> PathBuf {
    std::env::var_os("SYMFRAME_TEST_BIN")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_symframe")))
}

/// Runs the `symframe` binary with `args`.
pub fn symframe(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .expect("run symframe")
}

/// Runs `symframe estimate INPUT -o OUT` with `extra` flags.
pub fn estimate(input: &Path, out: &Path, extra: &[&str]) -> Output {
    symframe(&[&["estimate", s(input), "-o", s(out)], extra].concat())
}

/// Runs `symframe estimate INPUT -o OUT --tile-size 8` with `extra` flags (small tiles, so
/// a 32-40 pixel image has 16-25 of them).
pub fn estimate_tiled(input: &Path, out: &Path, extra: &[&str]) -> Output {
    estimate(input, out, &[&["--tile-size", "8"], extra].concat())
}

/// Asserts the run succeeded, showing its standard error otherwise.
pub fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// The `report.json` of an output folder.
pub fn report(out: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

/// The `warnings` of an output folder's report, one string each.
pub fn report_warnings(out: &Path) -> Vec<String> {
    report(out)["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

/// A `size` x `size` anisotropic Ward sphere under `lights` lights as float EXR (decoding is
/// exact), without ground truth; returns the `.lp` path.
pub fn ward_sphere(dir: &Path, size: usize, lights: usize) -> PathBuf {
    let brdf = symframe::brdf::Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let truth = Truth {
        normals: false,
        tangents: false,
    };
    sphere_dataset(dir, size, lights, &brdf, ImageFormat::Exr, 1.0, truth).1
}

/// The run's standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether `line` is a plain progress line (`decoding 3/60 images`, `tiles 4/16`), as printed
/// when stderr is not a terminal.
pub fn is_progress_line(line: &str) -> bool {
    let mut w = line.split_whitespace();
    matches!(
        w.next(),
        Some("decoding" | "tiles" | "estimating" | "fitting" | "merging")
    ) && w.next().is_some_and(|c| {
        c.split_once('/')
            .is_some_and(|(a, b)| a.parse::<u64>().is_ok() && b.parse::<u64>().is_ok())
    })
}

/// The run failed with a one-line error (no panic) that names `needle` (progress and
/// `warning:` lines before it aside).
pub fn assert_one_line_error(o: &Output, needle: &str) {
    let all = stderr(o);
    let err: String = all
        .lines()
        .filter(|l| !is_progress_line(l) && !l.starts_with("warning: "))
        .collect::<Vec<_>>()
        .join("\n");
    assert!(!o.status.success(), "expected failure, stderr: {all}");
    assert!(err.contains(needle), "error should name {needle:?}: {all}");
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {all}");
    assert!(!err.contains("panicked"), "{err}");
}

/// [`assert_one_line_error`], and neither the output folder `out` nor a staging folder beside
/// it was left behind.
pub fn assert_fails_naming(o: &Output, needle: &str, out: &Path) {
    assert_one_line_error(o, needle);
    assert!(!out.exists(), "no output folder may be left behind");
    for e in fs::read_dir(out.parent().unwrap()).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(
            !name.contains(".partial"),
            "staging folder left behind: {name}"
        );
    }
}

/// Which ground-truth maps a dataset is written with.
#[derive(Clone, Copy)]
pub struct Truth {
    pub normals: bool,
    pub tangents: bool,
}

/// A `size x size` sphere (circular tangent field) of `brdf` rendered under `n_lights` lights
/// uniform over the 65-degree cone, scaled by `exposure`, written as an `.lp` dataset with its
/// mask (and the ground truth asked for) into `dir`; returns the scene and the `.lp` path.
pub fn sphere_dataset(
    dir: &Path,
    size: usize,
    n_lights: usize,
    brdf: &dyn Brdf,
    format: ImageFormat,
    exposure: f32,
    truth: Truth,
) -> (Scene, PathBuf) {
    let scene = Scene::sphere(size, TangentField::Circular);
    let lights = uniform_cone_lights(n_lights, 65.0);
    let images: Vec<Vec<f32>> = lights
        .iter()
        .map(|&l| {
            let mut image = scene.render(brdf, l);
            if exposure != 1.0 {
                image.iter_mut().for_each(|v| *v *= exposure);
            }
            image
        })
        .collect();
    let lp = write_lp_dataset(
        dir,
        &lights,
        &images,
        size,
        size,
        format,
        truth.normals.then(|| scene.gt_normals()).as_deref(),
        truth.tangents.then(|| scene.gt_tangents()).as_deref(),
        Some(&scene.mask),
    )
    .unwrap();
    (scene, lp)
}

/// A failure after the images were decoded: [`assert_one_line_error`], and the output folder
/// `out` holds at most the tile cache (kept so the rerun decodes nothing), no outputs and no
/// staging folder.
pub fn assert_fails_keeping_cache(o: &Output, needle: &str, out: &Path) {
    assert_one_line_error(o, needle);
    if out.exists() {
        for e in fs::read_dir(out).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            assert_eq!(
                name, ".symframe-cache",
                "only the cache may be left in {out:?}"
            );
        }
    }
}

/// `symframe synth` of a 32-pixel object with a chrome sphere (and, with `matte`, a matte
/// sphere) beside it under 8 lights, into `data`.
pub fn chrome_sphere_capture(data: &Path, matte: bool) {
    let mut args = vec!["synth", "-o", s(data), "--size", "32", "--rig", "cone:8"];
    args.push("--chrome-sphere");
    if matte {
        args.push("--matte-sphere");
    }
    args.push("--quiet");
    ok(&symframe(&args));
}

/// Runs the `symframe` binary with `args`, stdout and stderr piped.
fn spawn_piped(args: &[&str]) -> std::process::Child {
    use std::process::Stdio;
    Command::new(bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run symframe")
}

/// Runs the `symframe` binary with `args`, killing it (and failing the test) if it has not
/// ended within `secs` seconds.
pub fn run_with_timeout(args: &[&str], secs: u64) -> Output {
    let mut child = spawn_piped(args);
    let t0 = std::time::Instant::now();
    while child.try_wait().expect("wait for symframe").is_none() {
        if t0.elapsed().as_secs() >= secs {
            child.kill().ok();
            child.wait().ok();
            panic!("symframe {args:?} still running after {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().expect("symframe's output")
}

/// Runs the `symframe` binary with `args`; returns its output and its peak resident set size
/// in KiB (`ru_maxrss` of this one child, from `wait4`, so jobs that other tests run at the
/// same time do not count).
#[cfg(target_os = "linux")]
// The child is waited for by `wait4` (for its resource usage), not by `Child::wait`.
#[allow(clippy::zombie_processes)]
pub fn run_measuring_rss(args: &[&str]) -> (Output, u64) {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    let mut child = spawn_piped(args);
    let (mut out, mut err) = (Vec::new(), Vec::new());
    let mut so = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        so.read_to_end(&mut out).ok();
        out
    });
    child.stderr.take().unwrap().read_to_end(&mut err).ok();
    let out = reader.join().unwrap();
    let mut status = 0;
    // SAFETY: an all-zero `rusage` is a valid value of the plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for our own child (not waited for elsewhere: `child` is not used again),
    // writing into the two locals.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as libc::pid_t, "wait4 failed");
    let output = Output {
        status: std::process::ExitStatus::from_raw(status),
        stdout: out,
        stderr: err,
    };
    (output, usage.ru_maxrss as u64)
}

/// This test process's own peak resident set size in KiB (`VmHWM`). A child started by
/// [`run_measuring_rss`] reports at least it: `exec` carries the peak of the memory it
/// replaces (here, the test process's, shared by `vfork`) into the child's `ru_maxrss`.
#[cfg(target_os = "linux")]
pub fn own_peak_kib() -> u64 {
    let s = fs::read_to_string("/proc/self/status").unwrap();
    let line = s.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Runs the `symframe` binary with `args` and its address space limited to `max_bytes`
/// (`RLIMIT_AS`), so a run that reads without bound fails fast instead of taking the
/// machine's memory.
#[cfg(target_os = "linux")]
pub fn run_with_address_space_cap(args: &[&str], max_bytes: u64) -> Output {
    use std::os::unix::process::CommandExt;
    let mut cmd = Command::new(bin());
    cmd.args(args);
    // SAFETY: the closure runs in the forked child before exec and only calls setrlimit,
    // which is async-signal-safe.
    unsafe {
        cmd.pre_exec(move || {
            let lim = libc::rlimit {
                rlim_cur: max_bytes as libc::rlim_t,
                rlim_max: max_bytes as libc::rlim_t,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.output().expect("run symframe")
}
