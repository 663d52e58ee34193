//! Whether the stated risk holds on each site level, and what holding it would cost: the
//! measurement behind [`activesense_lab::calibrate::MIN_ANSWERED_SHARE`].
//!
//! Reads the decision points `activesense calibrate --samples-out FILE` wrote (each line
//! names its agent and K; the agent-table episodes are there too) and, for each agent and K
//! and each least answered share a site level needs to set a row of the table (the
//! committed 0.5, and 0: every level that keeps the stated risk sets it), places the 1 %
//! threshold on one half of the plans by the calibration's own rule
//! (`calibrate::threshold_table_with`, the committed stop model's scores) and checks it on
//! the other half, both ways round, per site level: answered share and wrong answers.
//!
//! ```sh
//! cargo run --release -p activesense -- calibrate --instrument edm --site mixed \
//!     --samples-out /tmp/samples-edm.jsonl --rust-out /tmp/calibration_edm.rs --out /tmp/calibration-edm
//! cargo run --release -p activesense-lab --example threshold_by_level -- /tmp/samples-edm.jsonl edm
//! ```
//!
//! The scores come from the stop model built into this binary: run it on the samples of the
//! calibration that wrote the committed tables (or rebuild with the new tables first).

use activesense_core::episode::InstrumentProfile;
use activesense_core::stop::{StopModel, STATED_RISKS};
use activesense_lab::calibrate::{self, threshold_table_with, Sample};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: threshold_by_level SAMPLES.jsonl [edm|edm+scan]"))?;
    let instrument = match args.next().as_deref() {
        None | Some("edm") => InstrumentProfile::Edm,
        Some("edm+scan") => InstrumentProfile::EdmScan,
        Some(other) => anyhow::bail!("unknown instrument profile {other:?}"),
    };
    let episodes = calibrate::read_samples(path.as_ref())?;
    let one_percent = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap_or(2);
    println!("| K | agent | least answered share | threshold (even / odd) | plan: answered / wrong | furnished: answered / wrong | site: answered / wrong |");
    println!("|---|---|---|---|---|---|---|");
    for ((k, agent), list) in &episodes {
        if list.len() < 1000 {
            continue;
        }
        let model = StopModel::built_in(instrument, *k);
        let score = |s: &Sample| calibrate::score(model, s);
        for share in [0.5, 0.0] {
            let (thresholds, checked) = calibrate::cross_checked_by_level(
                list,
                |half| threshold_table_with(model, half, share)[one_percent],
                score,
            );
            println!(
                "{}",
                calibrate::level_row(
                    &format!("{k} | {agent} | {share}"),
                    thresholds,
                    checked,
                    false
                )
            );
        }
    }
    Ok(())
}
