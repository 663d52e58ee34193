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
use activesense_core::stop::{stop_score, StopModel, STATED_RISKS};
use activesense_instrument::world::site::SiteLevel;
use activesense_lab::calibrate::{first_crossings, threshold_table_with, EpisodeSamples, Sample};
use std::collections::BTreeMap;
use std::io::BufRead;

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
    // (K, agent) -> episodes, in file order (an episode's samples are consecutive).
    let mut episodes: BTreeMap<(u8, String), Vec<EpisodeSamples>> = BTreeMap::new();
    let mut last: Option<(u8, String, u32)> = None;
    for line in std::io::BufReader::new(std::fs::File::open(&path)?).lines() {
        let v: serde_json::Value = serde_json::from_str(&line?)?;
        let k = v["rot_bins"].as_u64().unwrap_or(0) as u8;
        let agent = v["agent"]
            .as_str()
            .ok_or_else(|| {
                anyhow::anyhow!("a line without \"agent\": samples of an older calibrate")
            })?
            .to_string();
        let s: Sample = serde_json::from_value(v["sample"].clone())?;
        let key = (k, agent.clone());
        let same_episode = last.as_ref() == Some(&(k, agent, s.plan));
        let list = episodes.entry(key.clone()).or_default();
        match list.last_mut() {
            Some(e) if same_episode => e.push(s),
            _ => list.push(vec![s]),
        }
        last = Some((key.0, key.1, s.plan));
    }
    let one_percent = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap_or(2);
    let levels = [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site];
    println!("| K | agent | least answered share | threshold (even / odd) | plan: answered / wrong | furnished: answered / wrong | site: answered / wrong |");
    println!("|---|---|---|---|---|---|---|");
    for ((k, agent), list) in &episodes {
        if list.len() < 1000 {
            continue;
        }
        let model = StopModel::built_in(instrument, *k);
        let score = |s: &Sample| stop_score(model.risk(&s.features), s.features.readings);
        for share in [0.5, 0.0] {
            let mut thresholds = Vec::new();
            // Per level: (episodes checked, stops, wrong).
            let mut checked = [(0usize, 0usize, 0usize); 3];
            for fit_parity in [0, 1] {
                let half = |parity: u32| -> Vec<&EpisodeSamples> {
                    list.iter().filter(|e| e[0].plan % 2 == parity).collect()
                };
                let (fitting, checking) = (half(fit_parity), half(1 - fit_parity));
                let t = threshold_table_with(model, &fitting, share)[one_percent];
                thresholds.push(format!("{t:.5}"));
                for (slot, level) in levels.iter().enumerate() {
                    let of_level: Vec<&EpisodeSamples> = checking
                        .iter()
                        .copied()
                        .filter(|e| e[0].level == *level)
                        .collect();
                    let c = first_crossings(&of_level, t, score);
                    checked[slot].0 += of_level.len();
                    checked[slot].1 += c.stops;
                    checked[slot].2 += c.wrong;
                }
            }
            let cell = |(n, stops, wrong): (usize, usize, usize)| {
                format!(
                    "{:.3} / {wrong} of {stops} ({:.2} %)",
                    stops as f64 / n.max(1) as f64,
                    100.0 * wrong as f64 / stops.max(1) as f64
                )
            };
            println!(
                "| {k} | {agent} | {share} | {} | {} | {} | {} |",
                thresholds.join(" / "),
                cell(checked[0]),
                cell(checked[1]),
                cell(checked[2])
            );
        }
    }
    Ok(())
}
