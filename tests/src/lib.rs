//! Helpers for hexacomp's multi-process tests.
//!
//! A test crate cannot see other packages' binaries through `CARGO_BIN_EXE_*`, so
//! [`binary`] builds the workspace's binaries once, with the profile the tests were built with,
//! and returns the path of one of them.

#![warn(missing_docs)]

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The directory holding the workspace binaries of the current profile (`target/debug` when
/// the tests run unoptimised, `target/release` with `--release`), built on first use.
fn binary_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // The test executable lives in target/<profile>/deps/.
        let exe = std::env::current_exe().expect("test executable path");
        let dir = exe
            .parent()
            .and_then(|deps| deps.parent())
            .expect("test executable inside target/<profile>/deps")
            .to_path_buf();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut build = Command::new(cargo);
        build.args(["build", "--workspace", "--bins", "--quiet"]);
        if dir.file_name().is_some_and(|n| n == "release") {
            build.arg("--release");
        }
        let status = build
            .status()
            .expect("running cargo build for the binaries");
        assert!(status.success(), "building the workspace binaries failed");
        dir
    })
}

/// The path of workspace binary `name` (e.g. `hexacomp-trainer`), built if needed.
pub fn binary(name: &str) -> PathBuf {
    let path = binary_dir().join(name);
    assert!(path.exists(), "{} was not built", path.display());
    path
}

/// Runs workspace binary `name` with `args` to completion and returns its output.
pub fn run(name: &str, args: &[&str]) -> Output {
    Command::new(binary(name))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {name}: {e}"))
}
