//! How the calibrated stop's threshold should grow with the readings (issue 21): the
//! measurement behind [`activesense_core::stop::stop_score`]'s exponent.
//!
//! Reads the decision points `activesense calibrate --samples-out FILE` wrote (default
//! agents and plans: heuristic-1, learnt, blind-0, heuristic-0, OIGM on 1000 plans each, in
//! that job order) and, for the learnt policy and heuristic-1 at every K, compares stop
//! scores `estimate × (8 / distinct bearings)^a` for exponents a = 0, 0.5, 1, 1.5: the 1 % threshold
//! is fitted on one half of the plans (the calibration's rule: the largest threshold whose
//! first crossings, and every smaller one's, were wrong at most 1 % of the time) and
//! checked on the other, both ways round. Exponent 0 is the estimate itself.
//!
//! ```sh
//! cargo run --release -p activesense-sim -- calibrate --samples-out /tmp/samples.jsonl \
//!     --rust-out /tmp/calibration.rs --out /tmp/calibration
//! cargo run --release -p activesense-sim --example stop_score_exponent -- /tmp/samples.jsonl
//! ```

use activesense_core::stop::StopModel;
use activesense_sim::calibrate::Sample;
use std::collections::BTreeMap;
use std::io::BufRead;

/// The calibration's default agents, in job order.
const AGENTS: [&str; 5] = ["heuristic-1", "learnt", "blind-0", "heuristic-0", "oigm"];

/// One episode's decision points: (estimate, distinct bearings, wrong).
type Episode = Vec<(f32, u16, bool)>;

/// What stopping at the first score below `t` does: (stopped, wrong, bearings at the stops).
fn first_crossings(episodes: &[&Episode], exponent: f32, t: f32) -> (usize, usize, usize) {
    let mut c = (0, 0, 0);
    for e in episodes {
        let score =
            |&&(risk, n, _): &&(f32, u16, bool)| risk * (8.0 / f32::from(n.max(1))).powf(exponent);
        if let Some(&(_, n, wrong)) = e.iter().find(|p| score(p) < t) {
            c.0 += 1;
            c.1 += usize::from(wrong);
            c.2 += usize::from(n);
        }
    }
    c
}

/// The largest of 400 log-spaced thresholds whose first crossings (and every smaller
/// one's) were wrong at most `p` of the time.
fn fit(episodes: &[&Episode], exponent: f32, p: f64) -> f32 {
    let mut envelope = 0.0f64;
    let mut best = 1e-5f32;
    for i in 0..400 {
        let t = (1e-5f64 * (0.9f64 / 1e-5).powf(i as f64 / 399.0)) as f32;
        let (stops, wrong, _) = first_crossings(episodes, exponent, t);
        envelope = envelope.max(wrong as f64 / stops.max(1) as f64);
        if envelope > p {
            break;
        }
        best = t;
    }
    best
}

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: stop_score_exponent SAMPLES.jsonl"))?;
    // (K, agent) -> (plan, episode), in file order.
    let mut episodes: BTreeMap<(u8, usize), Vec<(u32, Episode)>> = BTreeMap::new();
    let mut last: Option<(u8, usize, u32)> = None;
    for line in std::io::BufReader::new(std::fs::File::open(&path)?).lines() {
        let v: serde_json::Value = serde_json::from_str(&line?)?;
        let k = v["rot_bins"].as_u64().unwrap_or(0) as u8;
        let s: Sample = serde_json::from_value(v["sample"].clone())?;
        // Job order: an agent's plans ascend; a plan index below the last one starts the
        // next agent (or, with a new K, the first).
        let agent = match last {
            Some((lk, a, lp)) if lk == k && s.plan < lp => a + 1,
            Some((lk, a, _)) if lk == k => a,
            _ => 0,
        };
        let risk = StopModel::for_rot_bins(k).risk(&s.features);
        let point = (risk, s.features.readings, s.wrong);
        let list = episodes.entry((k, agent)).or_default();
        match list.last_mut() {
            Some((plan, e)) if *plan == s.plan && last.is_some_and(|l| l.2 == s.plan) => {
                e.push(point)
            }
            _ => list.push((s.plan, vec![point])),
        }
        last = Some((k, agent, s.plan));
    }
    println!("| K | agent | exponent | fitted on | threshold | checked: stopped | wrong | bearings at the stop |");
    println!("|---|---|---|---|---|---|---|---|");
    for (&(k, agent), list) in &episodes {
        let name = AGENTS.get(agent).copied().unwrap_or("?");
        if name != "learnt" && name != "heuristic-1" {
            continue;
        }
        for exponent in [0.0f32, 0.5, 1.0, 1.5] {
            for fit_parity in [0, 1] {
                let half = |parity: u32| -> Vec<&Episode> {
                    list.iter()
                        .filter(|(plan, _)| plan % 2 == parity)
                        .map(|(_, e)| e)
                        .collect()
                };
                let (fitting, checking) = (half(fit_parity), half(1 - fit_parity));
                let t = fit(&fitting, exponent, 0.01);
                let (stops, wrong, readings) = first_crossings(&checking, exponent, t);
                println!(
                    "| {k} | {name} | {exponent} | {} plans | {t:.4} | {stops} of {} | {:.2} % | {:.2} |",
                    if fit_parity == 0 { "even" } else { "odd" },
                    checking.len(),
                    100.0 * wrong as f64 / stops.max(1) as f64,
                    readings as f64 / stops.max(1) as f64
                );
            }
        }
    }
    Ok(())
}
