//! The screened refinement (issue 22, `Search::Screened`, what the pipeline runs) measured
//! against the exhaustive one it replaced (`Search::Exhaustive`) on recorded episodes:
//! heuristic-1 run to the action limit on the first test plans, K = 1 and K = 10, both
//! refinements after every reading from the registration's minimum on. The screened search
//! registers a fraction of the hypotheses; it must answer with the same cell nearly
//! always, be right (coarse success of that cell) as often, and leave the pose as close to
//! the truth.

use activesense_core::episode::{AgentKind, Termination};
use activesense_core::policy::BaselineAgent;
use activesense_core::registration::refine::{refine_with, Search};
use activesense_sim::episode::{run_episode_observed, EpisodeSpec};
use activesense_sim::world::plans::TEST_SEEDS;

#[derive(Default, Debug)]
struct Tally {
    points: u32,
    same_cell: u32,
    right: [u32; 2],
    error: [f64; 2],
    hypotheses: [u64; 2],
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
            for (k, search) in [Search::Exhaustive, Search::Screened]
                .into_iter()
                .enumerate()
            {
                let Ok(r) = refine_with(&input, search) else {
                    continue;
                };
                let pose = r.registration.pose;
                // Capped at 1 m: a wrong mode counts once, not by how far away it is.
                t.error[k] += ((pose.translation() - v.truth.translation()).norm() as f64).min(1.0);
                t.hypotheses[k] += r.hypotheses as u64;
                cells[k] = grid.cell_of_pose(&pose);
                t.right[k] += cells[k]
                    .is_some_and(|c| grid.coarse_success(c, v.truth, pipe.symmetry_order()))
                    as u32;
            }
            t.points += 1;
            t.same_cell += (cells[0] == cells[1]) as u32;
        });
    }
    t
}

fn check(t: &Tally) {
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
}

#[test]
fn screened_refinement_matches_the_exhaustive_one_at_k1() {
    check(&tally(1, 12, 30));
}

#[test]
fn screened_refinement_matches_the_exhaustive_one_at_k10() {
    check(&tally(10, 12, 40));
}
