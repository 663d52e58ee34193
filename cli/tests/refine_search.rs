//! The screened refinement (`Search::Screened`) and the one the pipeline keeps
//! after every reading past the stop gate (`Budget::per_reading`: at K = 10 carried from
//! the previous reading, `refine_after`) measured against the exhaustive one they replaced
//! (`Search::Exhaustive`) on recorded episodes: heuristic-1 run to the action limit on the
//! first test plans, K = 1 and K = 10, every refinement after every reading from the
//! registration's minimum on. They register a fraction of the hypotheses; each must answer
//! with the same cell nearly always, be right (coarse success of that cell) as often, and
//! leave the pose as close to the truth.

use activesense_core::episode::{AgentKind, Termination};
use activesense_core::policy::BaselineAgent;
use activesense_core::registration::refine::{refine_with, Search};
use activesense_instrument::episode::{run_episode_observed, EpisodeSpec};
use activesense_instrument::world::plans::TEST_SEEDS;

#[derive(Default, Debug)]
struct Tally {
    points: u32,
    same_cell: u32,
    same_cell_kept: u32,
    right: [u32; 3],
    error: [f64; 3],
    /// The exhaustive search's errors at the points the pipeline kept a refinement.
    error_exhaustive_at_kept: f64,
    right_exhaustive_at_kept: u32,
    hypotheses: [u64; 2],
    kept_points: u32,
}

fn tally(rot_bins: u8, plans: u32, max_actions: u16) -> Tally {
    let mut t = Tally::default();
    for p in 0..plans {
        let mut spec = EpisodeSpec::new(TEST_SEEDS.start + p, AgentKind::Heuristic1);
        spec.rot_bins = rot_bins;
        spec.termination = Termination::ActionLimit;
        spec.config.max_actions = max_actions;
        let mut agent = BaselineAgent::new(spec.agent, spec.agent_seed());
        let mut last = 0;
        run_episode_observed(&spec, &mut agent, &mut |v| {
            let pipe = v.runner.pipeline();
            let n = pipe.observations().len();
            if n == last || n < pipe.min_measurements() || !pipe.has_belief() {
                return;
            }
            last = n;
            let input = pipe.refine_input(v.plan);
            let grid = pipe.localizer().grid();
            let mut cells = [None; 2];
            let mut exhaustive = (0.0, false);
            for (k, search) in [Search::Exhaustive, Search::Screened]
                .into_iter()
                .enumerate()
            {
                let Ok(r) = refine_with(&input, search) else {
                    continue;
                };
                let pose = r.registration.pose;
                // Capped at 1 m: a wrong mode counts once, not by how far away it is.
                let err = ((pose.translation() - v.truth.translation()).norm() as f64).min(1.0);
                t.error[k] += err;
                t.hypotheses[k] += r.hypotheses as u64;
                cells[k] = grid.cell_of_pose(&pose);
                let right = cells[k]
                    .is_some_and(|c| grid.coarse_success(c, v.truth, pipe.symmetry_order()));
                t.right[k] += right as u32;
                if k == 0 {
                    exhaustive = (err, right);
                }
            }
            t.points += 1;
            t.same_cell += (cells[0] == cells[1]) as u32;
            // The pipeline's own (kept) refinement of the same readings, past the stop gate.
            if pipe.stop_features().is_some() {
                if let Ok(r) = pipe.refine(v.plan) {
                    let pose = r.registration.pose;
                    t.error[2] +=
                        ((pose.translation() - v.truth.translation()).norm() as f64).min(1.0);
                    let cell = grid.cell_of_pose(&pose);
                    t.right[2] += cell
                        .is_some_and(|c| grid.coarse_success(c, v.truth, pipe.symmetry_order()))
                        as u32;
                    t.kept_points += 1;
                    t.same_cell_kept += (cell == cells[0]) as u32;
                    t.error_exhaustive_at_kept += exhaustive.0;
                    t.right_exhaustive_at_kept += exhaustive.1 as u32;
                }
            }
        });
    }
    t
}

fn check(t: &Tally) {
    println!("{t:?}");
    let n = t.points as f64;
    assert!(t.points > 40, "{t:?}");
    assert!(t.same_cell as f64 >= 0.9 * n, "same answer cell: {t:?}");
    assert!(
        t.right[1] as f64 >= t.right[0] as f64 - 0.01 * n,
        "right cells: {t:?}"
    );
    assert!(
        t.error[1] / n <= t.error[0] / n * 1.1 + 0.005,
        "mean capped pose error: {t:?}"
    );
    assert!(
        (t.hypotheses[1] as f64) <= 0.5 * t.hypotheses[0] as f64,
        "registrations: {t:?}"
    );
    // The pipeline's kept refinement against the exhaustive one at the same points. Measured
    // (40 plans): K = 1, 29 points... see the test names' tallies with `--nocapture`; at
    // K = 10 the carried re-fit answered the same cell at all 29 points, right as often,
    // with the capped error summed 5.96 m against the exhaustive 5.19 m (+15 %, mid-episode
    // poses; the confident table's answers stay within their intervals, docs/EVALUATION.md).
    let k = t.kept_points as f64;
    assert!(t.kept_points > 20, "{t:?}");
    assert!(
        t.same_cell_kept as f64 >= 0.9 * k,
        "kept: same answer cell: {t:?}"
    );
    assert!(
        t.right[2] as f64 >= t.right_exhaustive_at_kept as f64 - 0.02 * k,
        "kept: right cells: {t:?}"
    );
    assert!(
        t.error[2] <= t.error_exhaustive_at_kept * 1.2 + 0.005 * k,
        "kept: mean capped pose error: {t:?}"
    );
}

#[test]
fn screened_refinement_matches_the_exhaustive_one_at_k1() {
    check(&tally(1, 40, 30));
}

#[test]
fn screened_refinement_matches_the_exhaustive_one_at_k10() {
    check(&tally(10, 40, 40));
}
