//! Why a confident episode goes unanswered: for each site level, the learnt policy on the
//! first N test plans (EDM only, calibrated stop at 1 %), and for every episode that reached
//! the action limit the rule that held the answer back at each of its readings past the
//! minimum, the first that applies in the stop's order (`Pipeline::features_with`, then the
//! veto and the threshold): the belief's gate, no registration, the room not matching its
//! plan (heading unknown), a direction resting on one wall, the wall leverage before the
//! estimate (heading known), another rule without features (the turned image), the
//! leverage veto (heading unknown), the score above the threshold. It also says whether the
//! answer was right (5 cm, 0.5°) at that reading, so that a rule can be priced: what it held
//! back right and what wrong.
//!
//! The answer checked here is a fresh refinement of the readings (`Pipeline::stop_point`),
//! not the kept one the stop carries with its rivals, so the classes are close to the
//! stop's, not equal to them.
//!
//! ```sh
//! cargo run --release -p activesense-lab --example unanswered -- 300 1   # plans, rotation bins
//! ```

use activesense_core::episode::{AgentKind, InstrumentProfile, Termination};
use activesense_core::registration::pose_distance::{PoseDistance, Tolerance};
use activesense_core::registration::precision::{rests_on_one_wall, WallLeverage};
use activesense_core::stop::{self, stop_score, StopModel};
use activesense_instrument::agents::{run_agent_episode_observed, Policies};
use activesense_instrument::episode::{EndReason, EpisodeSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use activesense_instrument::world::site::SiteLevel;
use rayon::prelude::*;
use std::collections::BTreeMap;

const REASONS: [&str; 8] = [
    "gate",
    "no registration",
    "room mismatch",
    "rests on one wall",
    "leverage (K = 1)",
    "other (turned image)",
    "veto (K = 10)",
    "score",
];

/// The rule holding the answer back at the current reading (index into [`REASONS`]), and
/// whether the refined answer was right there.
fn held_back(v: &activesense_instrument::episode::EpisodeView<'_>, k: u8) -> (usize, bool) {
    let pipe = v.runner.pipeline();
    let order = pipe.symmetry_order();
    let distance = PoseDistance::with_order(v.plan, order);
    let right = |p: &activesense_core::Pose2| {
        Tolerance::SURVEYOR.admits(&distance.agent_errors(p, v.truth))
    };
    let known = k == 1;
    if pipe.localizer().peak_mass(order) < stop::GATE_PEAK_MASS {
        let r = pipe
            .refine(v.plan)
            .is_ok_and(|r| right(&r.registration.pose));
        return (0, r);
    }
    let Ok(refined) = pipe.refine(v.plan) else {
        return (1, false);
    };
    let pose = refined.registration.pose;
    let ok = right(&pose);
    let obs = pipe.observations();
    if !known && stop::room_mismatch(refined.fit.bearings, refined.fit.explained_bearings) {
        return (2, ok);
    }
    if rests_on_one_wall(v.plan, obs, &pose, known, stop::PRECISION_GATE) {
        return (3, ok);
    }
    if known
        && WallLeverage::of(v.plan, obs, &pose, stop::PRECISION_GATE).worst(true)
            > stop::MAX_WALL_LEVERAGE
    {
        return (4, ok);
    }
    let Some(f) = pipe.stop_features() else {
        return (5, ok);
    };
    if f.vetoed() {
        return (6, ok);
    }
    let model = StopModel::built_in(InstrumentProfile::Edm, k);
    let threshold = model.threshold_for(AgentKind::Learnt, 0.01);
    if stop_score(model.risk(&f), f.readings) >= threshold {
        return (7, ok);
    }
    // Past every rule: the fresh refinement would stop where the kept one did not.
    (5, ok)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let plans: u32 = args.get(1).map_or(300, |s| s.parse().expect("plans"));
    let k: u8 = args.get(2).map_or(1, |s| s.parse().expect("rotation bins"));
    let policies = Policies::load_for(InstrumentProfile::Edm, &[], &[k])?;
    for level in [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site] {
        // Per unanswered episode: (reason, right) at each reading past the minimum.
        let runs: Vec<Option<Vec<(usize, bool)>>> = (0..plans)
            .into_par_iter()
            .map(|i| {
                let mut spec = EpisodeSpec::new(TEST_SEEDS.start + i, AgentKind::Learnt);
                spec.rot_bins = k;
                spec.config.instrument = InstrumentProfile::Edm;
                spec.termination = Termination::Confident;
                spec.sensor.site = level;
                let mut points = Vec::new();
                let mut last = 0;
                let (t, _) = run_agent_episode_observed(&spec, &policies, &mut |v| {
                    let pipe = v.runner.pipeline();
                    let n = pipe.observations().len();
                    if n == last || !pipe.has_belief() || n < pipe.min_measurements() {
                        return;
                    }
                    last = n;
                    points.push(held_back(&v, k));
                })
                .expect("episode");
                (t.end == EndReason::ActionLimit).then_some(points)
            })
            .collect();
        let unanswered: Vec<&Vec<(usize, bool)>> = runs.iter().flatten().collect();
        println!(
            "\n{level:?}, K = {k}: {} of {plans} unanswered",
            unanswered.len()
        );
        let mut at_end: BTreeMap<usize, (usize, usize)> = BTreeMap::new();
        let mut over: BTreeMap<usize, (usize, usize)> = BTreeMap::new();
        let mut ever_right = 0;
        for points in &unanswered {
            if let Some(&(r, ok)) = points.last() {
                let e = at_end.entry(r).or_default();
                e.0 += 1;
                e.1 += usize::from(ok);
            }
            for &(r, ok) in points.iter() {
                let e = over.entry(r).or_default();
                e.0 += 1;
                e.1 += usize::from(ok);
            }
            ever_right += usize::from(points.iter().any(|p| p.1));
        }
        println!("right at some reading: {ever_right}");
        println!("| held back by | at the last reading (right there) | over all readings (right there) |");
        println!("|---|---|---|");
        for (i, name) in REASONS.iter().enumerate() {
            let (a, ar) = at_end.get(&i).copied().unwrap_or_default();
            let (o, or) = over.get(&i).copied().unwrap_or_default();
            println!("| {name} | {a} ({ar}) | {o} ({or}) |");
        }
    }
    Ok(())
}
