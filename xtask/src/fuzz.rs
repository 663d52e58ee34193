//! `cargo xtask fuzz [SECS]`: bounded cargo-fuzz runs of `fuzz/fuzz_targets/session.rs`
//! (frame decoder + device session state machine) and `fuzz/fuzz_targets/policy_blob.rs`
//! (int8 policy blob parser + one decision), SECS each, default 60 s.
//!
//! cargo-fuzz needs nightly-only rustc flags (`-Zsanitizer=address`, sancov passes); on the
//! stable toolchain this project pins, `RUSTC_BOOTSTRAP=1` unlocks them. Requires
//! `cargo install cargo-fuzz`.

use anyhow::{bail, Context, Result};
use std::process::Command;

/// Runs the fuzz target for the given number of seconds (first argument, default 60).
pub fn run(args: &[String]) -> Result<()> {
    let secs: u64 = match args.first() {
        Some(s) => s
            .parse()
            .with_context(|| format!("'{s}' is not a number of seconds"))?,
        None => 60,
    };
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .context("workspace root")?
        .to_path_buf();
    let has_fuzz = Command::new("cargo")
        .args(["fuzz", "--version"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !has_fuzz {
        bail!("cargo-fuzz is not installed (cargo install cargo-fuzz)");
    }
    for (target, max_len) in [("session", "4096"), ("policy_blob", "20000")] {
        let status = Command::new("cargo")
            .current_dir(&root)
            .env("RUSTC_BOOTSTRAP", "1")
            .args([
                "fuzz",
                "run",
                target,
                "--",
                &format!("-max_total_time={secs}"),
                &format!("-max_len={max_len}"),
            ])
            .status()
            .context("running cargo fuzz")?;
        if !status.success() {
            bail!("fuzzing {target} failed ({status}); crashes are in fuzz/artifacts/{target}/");
        }
        println!("fuzz {target}: {secs} s without a crash");
    }
    Ok(())
}
