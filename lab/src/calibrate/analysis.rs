//! What the threshold analyses in `examples/` share: the decision points a calibration
//! wrote (`activesense calibrate --samples-out FILE`), read back by agent and K, and a
//! threshold placed on one half of the plans and checked per site level on the other.

use super::{first_crossings, EpisodeSamples, Sample};
use activesense_instrument::world::site::SiteLevel;

/// The decision points `activesense calibrate --samples-out FILE` wrote, by (K, agent
/// name), as episodes in file order (an episode's samples are consecutive): what the
/// threshold analyses in `examples/` read.
pub fn read_samples(
    path: &std::path::Path,
) -> anyhow::Result<std::collections::BTreeMap<(u8, String), Vec<EpisodeSamples>>> {
    use std::io::BufRead;
    let mut episodes: std::collections::BTreeMap<(u8, String), Vec<EpisodeSamples>> =
        Default::default();
    let mut last: Option<(u8, String, u32)> = None;
    for line in std::io::BufReader::new(std::fs::File::open(path)?).lines() {
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
    Ok(episodes)
}

/// What a threshold placed on one half of `episodes` does on the other, both ways round
/// (even- and odd-indexed plans): `place` puts the threshold on a half, `score` is what it
/// is compared with. The two thresholds, and per site level (plan, furnished, site) the
/// episodes checked, the stops and the wrong ones among them: the threshold analyses in
/// `examples/` report these.
pub fn cross_checked_by_level(
    episodes: &[EpisodeSamples],
    place: impl Fn(&[&EpisodeSamples]) -> f32,
    score: impl Fn(&Sample) -> f32 + Copy,
) -> ([f32; 2], [(usize, usize, usize); 3]) {
    let levels = [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site];
    let mut thresholds = [0.0; 2];
    let mut checked = [(0usize, 0usize, 0usize); 3];
    for fit_parity in [0, 1] {
        let half = |parity: u32| -> Vec<&EpisodeSamples> {
            episodes
                .iter()
                .filter(|e| e.first().is_some_and(|s| s.plan % 2 == parity))
                .collect()
        };
        let (fitting, checking) = (half(fit_parity), half(1 - fit_parity));
        let t = place(&fitting);
        thresholds[fit_parity as usize] = t;
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
    (thresholds, checked)
}

/// One site level's cell of a threshold analysis's table, from [`cross_checked_by_level`]'s
/// (episodes, stops, wrong stops): the right share first when `with_right`, then the
/// answered share and the wrong answers of the answered.
pub fn level_cell((n, stops, wrong): (usize, usize, usize), with_right: bool) -> String {
    let share = |k: usize| k as f64 / n.max(1) as f64;
    let right = if with_right {
        format!("{:.3} / ", share(stops - wrong))
    } else {
        String::new()
    };
    format!(
        "{right}{:.3} / {wrong} of {stops} ({:.2} %)",
        share(stops),
        100.0 * wrong as f64 / stops.max(1) as f64
    )
}

/// One table row of a threshold analysis: the row's leading cells, the two cross-fitted
/// thresholds and the three site levels' cells ([`level_cell`]).
pub fn level_row(
    lead: &str,
    thresholds: [f32; 2],
    checked: [(usize, usize, usize); 3],
    with_right: bool,
) -> String {
    format!(
        "| {lead} | {:.5} / {:.5} | {} | {} | {} |",
        thresholds[0],
        thresholds[1],
        level_cell(checked[0], with_right),
        level_cell(checked[1], with_right),
        level_cell(checked[2], with_right)
    )
}
