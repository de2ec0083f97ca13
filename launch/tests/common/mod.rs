//! Helpers shared by the `sabr` command-line tests: run the binary and hand it paths.

// Each test crate includes this module and uses only part of it.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// Runs the `sabr` binary with `args` and waits for it: whether it exited with success, its
/// standard output and its standard error (both UTF-8).
pub fn run(args: &[&str]) -> (bool, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_sabr"))
        .args(args)
        .output()
        .unwrap();
    (
        output.status.success(),
        String::from_utf8(output.stdout).unwrap(),
        String::from_utf8(output.stderr).unwrap(),
    )
}

/// `path` as a command-line argument (the tests' temporary paths are UTF-8).
pub fn arg(path: &Path) -> &str {
    path.to_str().unwrap()
}
