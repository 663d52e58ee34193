//! `activesense bench-registration`: sparse-registration accuracy from coarse poses on the
//! test plans, printed as a summary and optionally written as JSON.

use super::options::SensorArgs;
use super::write_file;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchRegistrationArgs {
    /// Number of test plans.
    #[arg(long, default_value_t = 1000)]
    plans: usize,
    /// Measurements per trial.
    #[arg(long, default_value_t = 6)]
    measurements: usize,
    /// Grid cells across the larger room side (coarse position error within one cell).
    #[arg(long, default_value_t = 30.0)]
    cells: f32,
    /// Seed of the measurement and coarse-pose stream.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    sensor: SensorArgs,
    /// Write the full report (statistics and every trial) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

pub fn run(a: BenchRegistrationArgs) -> Result<()> {
    use activesense_lab::bench::registration as bench;
    let opts = bench::BenchOptions {
        plans: a.plans,
        measurements: a.measurements,
        cells: a.cells,
        sensor: a.sensor.model()?,
        seed: a.seed,
        ..Default::default()
    };
    let report = bench::run(&opts)?;
    print!("{}", bench::summary(&report));
    if let Some(path) = &a.json {
        write_file(path, &serde_json::to_string_pretty(&report)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
