//! What the stop's wall-leverage veto (`activesense_core::stop::LeverageVeto`, EDM only,
//! heading unknown) would buy at each bound with the tables placed on what it lets through
//! (vetoed decision points never crossing): the variant `docs/lab/stop.md` measured and did
//! not keep ("The wall leverage as a veto after the estimate"; the committed tables are
//! placed on the estimate alone, `calibrate::score`).
//!
//! Reads the decision points `activesense calibrate --samples-out FILE` wrote (their
//! features carry the leverages), and for each agent at K = 10 and each pair of bounds
//! (position, heading; `inf`: no bound) places the 1 % threshold on one half of the plans
//! by the calibration's rule (`calibrate::threshold_table_scored`, the committed stop
//! model's estimate, decision points past the bounds skipped) and checks it on the other
//! half, both ways round, per site level: right answers, answered share and wrong answers.
//!
//! ```sh
//! cargo run --release -p activesense -- calibrate --instrument edm --site mixed \
//!     --samples-out /tmp/samples-edm.jsonl --rust-out /tmp/calibration_edm.rs --out /tmp/calibration-edm
//! cargo run --release -p activesense-lab --example leverage_veto -- /tmp/samples-edm.jsonl
//! ```

use activesense_core::episode::InstrumentProfile;
use activesense_core::stop::{stop_score, StopModel, STATED_RISKS};
use activesense_lab::calibrate::{self, threshold_table_scored, Sample, MIN_ANSWERED_SHARE};

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: leverage_veto SAMPLES.jsonl"))?;
    let episodes = calibrate::read_samples(path.as_ref())?;
    let one_percent = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap_or(2);
    let inf = f32::INFINITY;
    let bounds = [
        (inf, inf),
        (0.9, inf),
        (inf, 0.15),
        (inf, 0.25),
        (1.2, 0.25),
        (1.0, 0.2),
        (0.9, 0.15),
        (0.8, 0.15),
        (0.9, 0.1),
    ];
    println!("| agent | position / heading bound | 1 % threshold (even / odd) | plan: right / answered / wrong | furnished | site |");
    println!("|---|---|---|---|---|---|");
    for ((k, agent), list) in &episodes {
        if *k != 10 || list.len() < 1000 {
            continue;
        }
        let model = StopModel::built_in(InstrumentProfile::Edm, *k);
        for &(position, heading) in &bounds {
            let score = |s: &Sample| {
                let vetoed = s
                    .features
                    .leverage
                    .is_some_and(|l| !(l.position <= position && l.heading <= heading));
                if vetoed {
                    f32::INFINITY
                } else {
                    stop_score(model.risk(&s.features), s.features.readings)
                }
            };
            let (thresholds, checked) = calibrate::cross_checked_by_level(
                list,
                |half| threshold_table_scored(half, score, MIN_ANSWERED_SHARE)[one_percent],
                score,
            );
            println!(
                "{}",
                calibrate::level_row(
                    &format!("{agent} | {position} / {heading}"),
                    thresholds,
                    checked,
                    true
                )
            );
        }
    }
    Ok(())
}
