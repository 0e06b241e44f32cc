//! Running the built `ravel` binary, and scratch folders, for the
//! integration tests that go through the command line (each test crate
//! includes this file with `#[path = "common/binary.rs"] mod binary;`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// `ravel ARGS` in the repository's root: exit code (−1 when ended by a
/// signal), standard output and standard error.
pub fn ravel(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A fresh, empty folder `PREFIX-NAME-PID` in the system's temporary folder
/// (the process id keeps concurrent runs of the tests apart).
pub fn scratch(prefix: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("{prefix}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("a scratch folder");
    d
}

/// The repository's root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}
