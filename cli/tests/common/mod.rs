//! Helpers the CLI integration tests share: run the `activesense` binary, a fresh scratch
//! directory per test and process, paths as arguments.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `activesense` binary built for this test run.
pub fn activesense(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_activesense"))
        .args(args)
        .output()
        .expect("run activesense")
}

/// An empty directory `activesense-{name}-{pid}` under the temp dir.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("activesense-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}
