//! What the episode's last refinement buys with each budget (docs/EVALUATION.md,
//! "The refinement's budget").
//!
//! Runs each baseline agent to its oracle stop on the first N test plans and, at the end of
//! every episode, refines the final readings under several [`Budget`]s: the exhaustive
//! search the refinement once was, the screened one that runs after every
//! reading, and variants that spend more on the leave-outs and the heading sweep. For each
//! it prints the mean pose error of recognised episodes (the main job's column), its p95,
//! how many exceed 0.3 m, and the hypotheses registered per refinement (what a budget
//! costs is counted on the device by `cargo xtask mcu-bench`, for the budget the pipeline
//! uses; the output has no timings, so it regenerates byte for byte).
//!
//! ```sh
//! cargo run --release -p activesense-lab --example refine_budget -- 1000   # plans
//! ```

use activesense_core::episode::{AgentKind, Termination};
use activesense_core::policy::BaselineAgent;
use activesense_core::registration::pose_distance::PoseDistance;
use activesense_core::registration::refine::refine_within;
use activesense_core::registration::refine::Budget;
use activesense_instrument::episode::{run_episode_observed, EpisodeSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use rayon::prelude::*;

/// The budgets compared, by name.
fn budgets(heading_known: bool) -> Vec<(&'static str, Budget)> {
    let s = Budget::SCREENED;
    let mut v = vec![
        ("exhaustive", Budget::EXHAUSTIVE),
        ("screened (every reading)", s),
        (
            "end of episode (pipeline)",
            Budget::end_of_episode(heading_known),
        ),
        (
            "screened, every leave-out",
            Budget {
                leave_outs: u8::MAX,
                ..s
            },
        ),
    ];
    if !heading_known {
        v.extend([
            (
                "screened, sweep to convergence",
                Budget {
                    sweep_iterations: u16::MAX,
                    ..s
                },
            ),
            ("screened, 2 sweep starts on", Budget { sweep_keep: 2, ..s }),
            (
                "3 leave-outs, 2 starts on",
                Budget {
                    leave_outs: 3,
                    sweep_keep: 2,
                    ..s
                },
            ),
            (
                "every leave-out, 2 starts on",
                Budget {
                    leave_outs: u8::MAX,
                    sweep_keep: 2,
                    ..s
                },
            ),
            (
                "3 leave-outs, 1 start on",
                Budget {
                    leave_outs: 3,
                    sweep_keep: 1,
                    ..s
                },
            ),
            (
                "3 leave-outs, 3 starts on",
                Budget {
                    leave_outs: 3,
                    sweep_keep: 3,
                    ..s
                },
            ),
        ]);
    }
    v
}

/// One episode's end under every budget: (recognised, pose error, hypotheses).
fn episode_end(spec: &EpisodeSpec, budgets: &[(&str, Budget)]) -> Vec<(bool, f32, u16)> {
    let steps = {
        let mut agent = BaselineAgent::new(spec.agent, spec.agent_seed());
        run_episode_observed(spec, &mut agent, &mut |_| {})
            .steps
            .len()
    };
    let mut agent = BaselineAgent::new(spec.agent, spec.agent_seed());
    let mut out = Vec::new();
    let mut views = 0;
    run_episode_observed(spec, &mut agent, &mut |v| {
        views += 1;
        let pipe = v.runner.pipeline();
        // The last view is the episode's end.
        if views != steps + 1 || !pipe.has_belief() || pipe.observations().len() < 2 {
            return;
        }
        let order = pipe.symmetry_order();
        let recognised = pipe.localizer().coarse_success(v.truth, order);
        let distance = PoseDistance::with_order(v.plan, order);
        let input = pipe.refine_input(v.plan);
        for (_, b) in budgets {
            let (err, hypotheses) = refine_within(&input, b).map_or((f32::NAN, 0), |r| {
                (
                    distance.agent_distance(&r.registration.pose, v.truth),
                    r.hypotheses,
                )
            });
            out.push((recognised, err, hypotheses));
        }
    });
    out
}

fn main() {
    let plans: u32 = std::env::args()
        .nth(1)
        .map_or(1000, |a| a.parse().expect("plans: a number"));
    println!("# The end-of-episode refinement under several budgets\n");
    println!(
        "`cargo run --release -p activesense-lab --example refine_budget -- {plans}`: each agent to its oracle stop on test plans {}..{}, episode seed 0; every budget refines the same final readings. Pose error: mean over recognised episodes (the main job's column). Hypotheses: registrations per refinement (the device's instruction counts for the pipeline's budget are `cargo xtask mcu-bench`'s).\n",
        TEST_SEEDS.start,
        TEST_SEEDS.start + plans
    );
    for (agent, k) in [
        (AgentKind::Heuristic1, 10u8),
        (AgentKind::Blind1, 10),
        (AgentKind::Blind0, 10),
        (AgentKind::Heuristic0, 10),
        (AgentKind::Heuristic1, 1),
        (AgentKind::Blind0, 1),
    ] {
        let bs = budgets(k == 1);
        let rows: Vec<Vec<(bool, f32, u16)>> = (0..plans)
            .into_par_iter()
            .map(|p| {
                let mut spec = EpisodeSpec::new(TEST_SEEDS.start + p, agent);
                spec.rot_bins = k;
                spec.termination = Termination::Oracle;
                episode_end(&spec, &bs)
            })
            .filter(|r| !r.is_empty())
            .collect();
        println!("## {} K = {k}\n", agent.name());
        println!(
            "| budget | recognised | pose error (m) | p95 (m) | > 0.3 m | hypotheses mean | max |"
        );
        println!("|---|---|---|---|---|---|---|");
        for (j, (name, _)) in bs.iter().enumerate() {
            let mut errs: Vec<f32> = rows
                .iter()
                .filter(|r| r[j].0 && r[j].1.is_finite())
                .map(|r| r[j].1)
                .collect();
            errs.sort_by(f32::total_cmp);
            let n = errs.len().max(1);
            let mean = errs.iter().map(|&e| e as f64).sum::<f64>() / n as f64;
            let p95 = errs.get(errs.len() * 95 / 100).copied().unwrap_or(0.0);
            let big = errs.iter().filter(|&&e| e > 0.3).count();
            let h: Vec<u16> = rows.iter().map(|r| r[j].2).collect();
            println!(
                "| {name} | {} | {mean:.4} | {p95:.4} | {big} | {:.2} | {} |",
                errs.len(),
                h.iter().map(|&x| x as f64).sum::<f64>() / h.len().max(1) as f64,
                h.iter().max().copied().unwrap_or(0)
            );
        }
        println!();
    }
}
