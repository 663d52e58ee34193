//! The bodies of the `activesense` commands, one module per command; `src/main.rs` holds
//! only the clap tree and dispatches here. The options several commands share are declared
//! once in [`options`]; the small helpers they all use (writing a file, the command line as
//! typed) live in this module.

pub mod answer_coverage;
pub mod bench_localization;
pub mod bench_registration;
pub mod calibrate;
pub mod dataset;
pub mod episode;
pub mod eval;
pub mod inspect;
pub mod mcu_bench;
pub mod options;
pub mod plan;
pub mod policy;
pub mod remote;
pub mod station;
pub mod train;

use anyhow::{Context, Result};
use std::path::Path;

pub(crate) fn write_file(path: &Path, contents: &str) -> Result<()> {
    std::fs::write(path, contents).with_context(|| format!("cannot write {}", path.display()))
}

/// The command line as typed, with the program's directory dropped (`activesense eval …`),
/// for the outputs that record how they were made.
pub fn command_line() -> String {
    std::env::args()
        .enumerate()
        .map(|(i, w)| {
            if i == 0 {
                w.rsplit('/').next().unwrap_or(&w).to_string()
            } else {
                w
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Sizes rayon's global pool to `threads` (at least 1) when given; default: all cores.
pub(crate) fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("cannot set the thread count")?;
    }
    Ok(())
}

/// Creates `dir` if needed and checks that a file can be written in it (a probe file,
/// removed again), so a long command refuses an unwritable `--out` before it runs.
pub fn ensure_writable_dir(dir: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "cannot create the output directory {} (check the path and its permissions)",
            dir.display()
        )
    })?;
    let probe = dir.join(format!(".activesense-write-check-{}", std::process::id()));
    std::fs::write(&probe, b"").with_context(|| {
        format!(
            "cannot write into the output directory {} (check its permissions)",
            dir.display()
        )
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}
