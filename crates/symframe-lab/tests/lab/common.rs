//! Helpers shared by the lab's integration tests: running the binary and checking that a run
//! succeeded.

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `symframe-lab` binary of this build with `args`.
pub fn lab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_symframe-lab"))
        .args(args)
        .output()
        .expect("run symframe-lab")
}

/// Asserts the run succeeded, showing its standard error otherwise.
pub fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}
