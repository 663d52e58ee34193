//! Every committed chart, drawn again from the JSON it was drawn from: an evaluation's
//! `results.json` gives `budget.svg`, `utility-k{K}.svg` and `reliability-k{K}.svg`;
//! `frontier.json` gives `frontier.svg`; `extra.json` gives `extra.svg`; a training run's
//! `log.json` with its policy file's hyper-parameters gives `curve.svg`. So a change to how
//! a chart is drawn regenerates every picture in seconds, and `cargo xtask reproduce
//! --check` compares them byte for byte without running an episode.

use super::experiments::{extra_svg, ExtraReport};
use super::frontier::{self, Frontier};
use super::harness::EvalReport;
use super::report::{budget_svg, reliability_svg, utility_svg};
use crate::learn::hyper::HyperParams;
use crate::learn::log::{curve_svg, LogRow};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The charts one directory's JSON files draw: (file name, SVG text). Empty when the
/// directory holds none of the files above.
pub fn charts_of(dir: &Path) -> Result<Vec<(String, String)>> {
    let read = |name: &str| -> Result<Option<String>> {
        let p = dir.join(name);
        if p.exists() {
            Ok(Some(
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?,
            ))
        } else {
            Ok(None)
        }
    };
    let parse_err = |name: &str| format!("parsing {}", dir.join(name).display());
    let mut out = Vec::new();
    if let Some(text) = read("results.json")? {
        let report: EvalReport =
            serde_json::from_str(&text).with_context(|| parse_err("results.json"))?;
        out.push(("budget.svg".to_string(), budget_svg(&report)));
        for &k in &report.options.rot_bins {
            out.push((format!("utility-k{k}.svg"), utility_svg(&report, k)));
            out.push((format!("reliability-k{k}.svg"), reliability_svg(&report, k)));
        }
    }
    if let Some(text) = read("frontier.json")? {
        let f: Frontier =
            serde_json::from_str(&text).with_context(|| parse_err("frontier.json"))?;
        out.push(("frontier.svg".to_string(), frontier::svg(&f)));
    }
    if let Some(text) = read("extra.json")? {
        let r: ExtraReport =
            serde_json::from_str(&text).with_context(|| parse_err("extra.json"))?;
        out.push(("extra.svg".to_string(), extra_svg(&r)));
    }
    if let Some(text) = read("log.json")? {
        let log: Vec<LogRow> =
            serde_json::from_str(&text).with_context(|| parse_err("log.json"))?;
        let policy = dir.join("policy.policy");
        let (_, meta) = activesense_instrument::learn::file::load(&policy)?;
        let hp: HyperParams = serde_json::from_value(meta["hyper_params"].clone())
            .with_context(|| format!("the hyper-parameters in {}", policy.display()))?;
        out.push(("curve.svg".to_string(), curve_svg(&log, &hp)));
    }
    Ok(out)
}

/// Every directory under `root` (itself included) that holds a chart's JSON, in path order.
pub fn chart_dirs(root: &Path) -> Result<Vec<PathBuf>> {
    let mut dirs = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        let mut has = false;
        for e in std::fs::read_dir(&d).with_context(|| format!("reading {}", d.display()))? {
            let p = e?.path();
            if p.is_dir() {
                stack.push(p);
            } else if let Some(n) = p.file_name().and_then(|n| n.to_str()) {
                has |= matches!(
                    n,
                    "results.json" | "frontier.json" | "extra.json" | "log.json"
                );
            }
        }
        if has {
            dirs.push(d);
        }
    }
    dirs.sort();
    Ok(dirs)
}
