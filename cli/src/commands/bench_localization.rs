//! `activesense bench-localization`: the GHT localizer against the classical grid localizer
//! (cost, memory, recognition), printed as markdown and optionally written as JSON.

use super::options::RotBinsOption;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchLocalizationArgs {
    /// Number of test plans (seeds from 1000000 on).
    #[arg(long, default_value_t = 20)]
    plans: usize,
    /// Agent placements per plan and outlier rate.
    #[arg(long, default_value_t = 3)]
    trials: usize,
    // --rot-bins (default here: 10).
    #[command(flatten)]
    rot_bins: RotBinsOption,
    /// Rotation hypotheses per bin.
    #[arg(long, default_value_t = 4)]
    sub_bins: u8,
    /// Write the report as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

pub fn run(a: BenchLocalizationArgs) -> Result<()> {
    use activesense_lab::bench::localization::{self as bl, BenchOptions};
    let mut opts = BenchOptions {
        plans: a.plans,
        trials_per_plan: a.trials,
        ..BenchOptions::default()
    };
    let rot_bins = a.rot_bins.one(10)?;
    opts.config.rot_bins = rot_bins;
    opts.config.sub_bins = a.sub_bins;
    if rot_bins == 1 {
        opts.smear_sub_bins.clear();
    }
    let report = bl::run(&opts)?;
    print!("{}", bl::markdown(&report));
    if let Some(path) = a.json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
