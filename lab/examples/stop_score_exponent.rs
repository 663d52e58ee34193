//! How the calibrated stop's threshold should grow with the readings: the
//! measurement behind [`activesense_core::stop::stop_score`]'s exponent.
//!
//! Reads the decision points `activesense calibrate --samples-out FILE` wrote (default
//! agents and plans: heuristic-1, learnt, blind-0, heuristic-0, OIGM on 1000 plans each, in
//! that job order) and, for the learnt policy and heuristic-1 at every K, compares stop
//! scores `estimate × (8 / distinct bearings)^a` for exponents a = 0, 0.5, 1, 1.5: the 1 % threshold
//! is fitted on one half of the plans by the calibration's own rule
//! (`calibrate::threshold_table_by`) and checked on the other, both ways round. Exponent 0 is the estimate itself.
//!
//! ```sh
//! cargo run --release -p activesense -- calibrate --samples-out /tmp/samples.jsonl \
//!     --rust-out /tmp/calibration.rs --out /tmp/calibration
//! cargo run --release -p activesense-lab --example stop_score_exponent -- /tmp/samples.jsonl
//! ```

use activesense_core::stop::{StopModel, STATED_RISKS};
use activesense_lab::calibrate::{first_crossings, threshold_table_by, EpisodeSamples, Sample};
use std::collections::BTreeMap;
use std::io::BufRead;

/// The calibration's default agents, in job order.
const AGENTS: [&str; 5] = ["heuristic-1", "learnt", "blind-0", "heuristic-0", "oigm"];

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: stop_score_exponent SAMPLES.jsonl"))?;
    // (K, agent) -> episodes, in file order.
    let mut episodes: BTreeMap<(u8, usize), Vec<EpisodeSamples>> = BTreeMap::new();
    let mut last: Option<(u8, usize, u32)> = None;
    for line in std::io::BufReader::new(std::fs::File::open(&path)?).lines() {
        let v: serde_json::Value = serde_json::from_str(&line?)?;
        let k = v["rot_bins"].as_u64().unwrap_or(0) as u8;
        let s: Sample = serde_json::from_value(v["sample"].clone())?;
        // Job order: an agent's plans ascend; a plan index below the last one starts the
        // next agent (or, with a new K, the first).
        // Newer samples name their agent (and include the agent-table episodes); older ones
        // are in job order.
        let agent = match (v["agent"].as_str(), last) {
            (Some(name), _) => AGENTS
                .iter()
                .position(|&a| a == name)
                .unwrap_or(AGENTS.len()),
            (None, Some((lk, a, lp))) if lk == k && s.plan < lp => a + 1,
            (None, Some((lk, a, _))) if lk == k => a,
            _ => 0,
        };
        let list = episodes.entry((k, agent)).or_default();
        match list.last_mut() {
            Some(e) if e[0].plan == s.plan && last.is_some_and(|l| l.2 == s.plan) => e.push(s),
            _ => list.push(vec![s]),
        }
        last = Some((k, agent, s.plan));
    }
    let one_percent = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap_or(2);
    println!("| K | agent | exponent | fitted on | threshold | checked: stopped | wrong | readings at the stop |");
    println!("|---|---|---|---|---|---|---|---|");
    for (&(k, agent), list) in &episodes {
        let name = AGENTS.get(agent).copied().unwrap_or("?");
        if name != "learnt" && name != "heuristic-1" {
            continue;
        }
        for exponent in [0.0f32, 0.5, 1.0, 1.5] {
            for fit_parity in [0, 1] {
                let half = |parity: u32| -> Vec<&EpisodeSamples> {
                    list.iter().filter(|e| e[0].plan % 2 == parity).collect()
                };
                let (fitting, checking) = (half(fit_parity), half(1 - fit_parity));
                let model = StopModel::for_rot_bins(k);
                let score = |s: &Sample| {
                    let bearings = f32::from(s.features.readings.max(1));
                    model.risk(&s.features) * (8.0 / bearings).powf(exponent)
                };
                let t = threshold_table_by(&fitting, score)[one_percent];
                let c = first_crossings(&checking, t, score);
                println!(
                    "| {k} | {name} | {exponent} | {} plans | {t:.4} | {} of {} | {:.2} % | {:.2} |",
                    if fit_parity == 0 { "even" } else { "odd" },
                    c.stops,
                    checking.len(),
                    100.0 * c.wrong_rate(),
                    c.mean_readings()
                );
            }
        }
    }
    Ok(())
}
