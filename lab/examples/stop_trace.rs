//! What a no-ground-truth stop could reach (docs/EVALUATION.md, "Calibrated stop").
//!
//! Runs heuristic-1 on the first N test plans to the action limit and records, after every
//! reading, whether the belief argmax is a coarse success, whether the confident stop's
//! answer (the refined pose) is within the surveyor's tolerance (5 cm, 0.5°), and the
//! calibrated stop's risk estimate. From those traces it replays the confident rule for
//! several stop risks P, with the episode answering at the action limit either with its last
//! reading or with its lowest-risk moment (what `Pipeline::finish` does), next to the
//! fraction of episodes whose argmax (what the oracle rule stops on) or answer was right at
//! *some* reading. The last column scores the same answered moments by the belief argmax
//! instead, the criterion of the oracle-terminated runs.
//!
//! ```sh
//! cargo run --release -p activesense-lab --example stop_trace -- 300 10   # plans, rotation bins
//! ```

use activesense_core::episode::AgentKind;
use activesense_core::episode::Termination;
use activesense_core::policy::BaselineAgent;
use activesense_core::registration::pose_distance::{PoseDistance, Tolerance};
use activesense_core::stop::{stop_score, StopModel};
use activesense_core::Pose2;
use activesense_instrument::episode::{run_episode_observed, EpisodeSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use rayon::prelude::*;

/// After one reading: readings so far, answer right, argmax right, risk estimate, and
/// whether the refined pose left the argmax's cell (`None` below the stop gate).
struct Point {
    readings: usize,
    /// Distinct bearings the refinement fitted (what the stop score scales by).
    bearings: u16,
    right: bool,
    argmax_right: bool,
    risk: Option<f32>,
    overruled: Option<bool>,
}

impl Point {
    /// The stop's test: the estimate's score ([`stop_score`]) is below the threshold `p`.
    fn stops_below(&self, p: f32) -> bool {
        self.risk.is_some_and(|r| stop_score(r, self.bearings) < p)
    }
}

fn trace(plan: u32, rot_bins: u8) -> (Vec<Point>, usize) {
    let mut spec = EpisodeSpec::new(TEST_SEEDS.start + plan, AgentKind::Heuristic1);
    spec.rot_bins = rot_bins;
    spec.termination = Termination::ActionLimit;
    let mut agent = BaselineAgent::new(spec.agent, spec.agent_seed());
    let mut points = Vec::new();
    let mut min_readings = 0;
    run_episode_observed(&spec, &mut agent, &mut |v| {
        let pipe = v.runner.pipeline();
        let n = pipe.observations().len();
        min_readings = pipe.min_measurements();
        if !pipe.has_belief() || points.last().is_some_and(|p: &Point| p.readings == n) {
            return;
        }
        let order = pipe.symmetry_order();
        let argmax_right = pipe.localizer().coarse_success(v.truth, order);
        // Right: the refined pose within the surveyor's tolerance (what the stop's label is).
        let distance = PoseDistance::with_order(v.plan, order);
        let right_pose = |p: &Pose2| Tolerance::SURVEYOR.admits(&distance.agent_errors(p, v.truth));
        // Past the stop gate one refinement gives the features and the answer; below it the
        // answer still is the refined pose, else (nothing registers) the argmax's cell.
        let point = match pipe.stop_point() {
            Some(sp) => {
                let f = sp.features;
                Point {
                    readings: n,
                    bearings: f.readings,
                    right: right_pose(&sp.pose),
                    argmax_right,
                    risk: Some(StopModel::for_rot_bins(rot_bins).risk(&f)),
                    overruled: Some(!f.agrees),
                }
            }
            None => Point {
                readings: n,
                bearings: 0,
                right: match pipe.refine(v.plan) {
                    Ok(r) => right_pose(&r.registration.pose),
                    Err(_) => argmax_right,
                },
                argmax_right,
                risk: None,
                overruled: None,
            },
        };
        points.push(point);
    });
    (points, min_readings)
}

/// What the pipeline answers for one trace under the threshold `p` on the estimate (the
/// model's for a stated risk): the stop, else the lowest-risk moment when the end is
/// riskier or has no estimate, else the end.
fn answer<'a>(eligible: &[&'a Point], p: f32) -> Option<&'a Point> {
    if let Some(stop) = eligible.iter().find(|q| q.stops_below(p)) {
        return Some(stop);
    }
    let end = *eligible.last()?;
    let best = eligible
        .iter()
        .filter(|q| q.risk.is_some())
        .fold(None::<&Point>, |b, q| match b {
            Some(b) if b.risk <= q.risk => Some(b),
            _ => Some(q),
        });
    Some(match best {
        Some(b) if end.risk.is_none_or(|r| b.risk.is_some_and(|br| br < r)) => b,
        _ => end,
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let plans: u32 = args.get(1).map_or(300, |s| s.parse().expect("plans"));
    let rot_bins: u8 = args
        .get(2)
        .map_or(10, |s| s.parse().expect("rotation bins"));
    eprintln!("tracing heuristic-1 on {plans} test plans, K = {rot_bins}, to the action limit");
    let traces: Vec<(Vec<Point>, usize)> = (0..plans)
        .into_par_iter()
        .map(|i| trace(i, rot_bins))
        .collect();
    let n = traces.len().max(1) as f32;
    let ever = |right: fn(&Point) -> bool| {
        traces
            .iter()
            .filter(|(t, m)| t.iter().any(|p| right(p) && p.readings >= *m))
            .count() as f32
            / n
    };
    println!(
        "argmax right at some reading (what the oracle can catch): {:.3}",
        ever(|p| p.argmax_right)
    );
    println!(
        "answer (refined pose within 5 cm and 0.5°) right at some reading: {:.3}",
        ever(|p| p.right)
    );
    // Where the refinement leaves the argmax's cell, which of the two is right?
    let overruled: Vec<&Point> = traces
        .iter()
        .flat_map(|(t, m)| t.iter().filter(move |q| q.readings >= *m))
        .filter(|q| q.overruled == Some(true))
        .collect();
    println!(
        "readings past the stop gate where the refined pose left the argmax's cell: {}; the refined pose right in {}, the argmax's cell in {}",
        overruled.len(),
        overruled.iter().filter(|q| q.right).count(),
        overruled.iter().filter(|q| q.argmax_right).count()
    );
    // The gap at P = 0.01: right at some reading, wrong in the answer; were those right
    // readings ones with a risk estimate at all?
    let (mut gap, mut unestimated) = (0, 0);
    for (t, m) in &traces {
        let eligible: Vec<&Point> = t.iter().filter(|q| q.readings >= *m).collect();
        if !eligible.iter().any(|q| q.right)
            || answer(
                &eligible,
                StopModel::for_rot_bins(rot_bins).threshold_for(AgentKind::Heuristic1, 0.01),
            )
            .is_none_or(|a| a.right)
        {
            continue;
        }
        gap += 1;
        unestimated += usize::from(eligible.iter().all(|q| !q.right || q.risk.is_none()));
    }
    println!(
        "P = 0.01: {gap} episodes with the answer right at some reading but answered wrongly; in {unestimated} of them it was right only at readings without a risk estimate (below the gate)"
    );
    println!("| P | stopped | wrong stops | right, last reading | right, lowest-risk moment | same moments scored by the argmax's cell |");
    println!("|---|---|---|---|---|---|");
    for stated in [0.005f32, 0.01, 0.02, 0.03, 0.05, 0.1] {
        let p = StopModel::for_rot_bins(rot_bins).threshold_for(AgentKind::Heuristic1, stated);
        let (mut stops, mut wrong, mut last, mut lowest, mut argmax) = (0, 0, 0, 0, 0);
        for (t, m) in &traces {
            let eligible: Vec<&Point> = t.iter().filter(|q| q.readings >= *m).collect();
            if let Some(stop) = eligible.iter().find(|q| q.stops_below(p)) {
                stops += 1;
                wrong += usize::from(!stop.right);
            }
            let stopped = answer(&eligible, p).filter(|a| a.stops_below(p));
            last += usize::from(stopped.or(t.last()).is_some_and(|q| q.right));
            let answered = answer(&eligible, p).or(t.last());
            lowest += usize::from(answered.is_some_and(|q| q.right));
            argmax += usize::from(answered.is_some_and(|q| q.argmax_right));
        }
        println!(
            "| {stated} | {stops} | {wrong} | {:.3} | {:.3} | {:.3} |",
            last as f32 / n,
            lowest as f32 / n,
            argmax as f32 / n
        );
    }
}
