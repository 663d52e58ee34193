//! Tests of the evaluation harness: deterministic output, consistent aggregates, the
//! Wilson interval.

use super::harness::{run, EvalOptions};
use super::stats::wilson;
use activesense_core::episode::AgentKind;
use activesense_core::episode::EpisodeConfig;
use activesense_instrument::agents::Policies;
use activesense_instrument::episode::Termination;
use activesense_instrument::world::sensor::SensorModel;

fn small(plans: u32) -> EvalOptions {
    EvalOptions {
        agents: vec![AgentKind::Heuristic1, AgentKind::Blind2],
        rot_bins: vec![1, 10],
        plans,
        first_seed: activesense_instrument::world::plans::TEST_SEEDS.start,
        episode_seed: 0,
        config: EpisodeConfig::default(),
        sensor: SensorModel::default(),
        termination: Termination::Oracle,
        policy_files: Vec::new(),
        policies: Policies::default(),
        progress: false,
        curve_plans: 3,
        tolerance: Default::default(),
        user_plans: Vec::new(),
        refused_plans: Vec::new(),
    }
}

#[test]
fn deterministic_json() {
    let a = serde_json::to_string(&run(&small(6)).0).unwrap();
    let b = serde_json::to_string(&run(&small(6)).0).unwrap();
    assert_eq!(a, b);
}

#[test]
fn aggregates_are_consistent() {
    let (rep, _) = run(&small(8));
    assert_eq!(rep.results.len(), 4);
    for r in &rep.results {
        assert_eq!(r.plans, 8);
        assert_eq!(r.episodes.len(), 8);
        let rec = r.episodes.iter().filter(|e| e.recognised).count() as f64 / 8.0;
        assert!((r.recognition_rate - rec).abs() < 1e-12);
        assert!(
            r.recognition_ci95[0] <= r.recognition_rate
                && r.recognition_rate <= r.recognition_ci95[1]
        );
        let rel = &r.reliability;
        assert_eq!(rel.episodes.iter().sum::<u32>(), 8);
        assert!((0.0..=1.0).contains(&rel.ece) && (0.0..=1.0).contains(&rel.mean_stated));
        let last = *r.recognition_by_budget.last().unwrap();
        assert!(last <= r.recognition_rate + 1e-12);
        assert!(r.recognition_by_budget.windows(2).all(|w| w[0] <= w[1]));
    }
}

#[test]
fn wilson_interval() {
    let (lo, hi) = wilson(50, 100);
    assert!((lo - 0.4038).abs() < 1e-3 && (hi - 0.5962).abs() < 1e-3);
    let (lo, hi) = wilson(100, 100);
    assert!(lo > 0.96 && hi > 0.9999 && hi <= 1.0);
}

/// Jobs run plan-major (every stretch of the list mixes the groups like the whole run, so
/// the progress rate is the run's), each group still in plan order.
#[test]
fn jobs_interleave_groups_in_plan_order() {
    let (groups, jobs) = super::harness::groups_and_jobs(&small(3));
    assert_eq!(groups.len(), 4);
    assert_eq!(&jobs[..5], &[(0, 0), (1, 0), (2, 0), (3, 0), (0, 1)]);
    for g in 0..groups.len() {
        let plans: Vec<u32> = jobs.iter().filter(|j| j.0 == g).map(|j| j.1).collect();
        assert_eq!(plans, vec![0, 1, 2]);
    }
}

/// The ETA is the run's mean rate after a warm-up, never a guess from the first episodes.
#[test]
fn eta_waits_for_warm_up_then_uses_the_mean_rate() {
    use super::harness::run_eta;
    use std::time::Duration;
    let s = Duration::from_secs;
    assert_eq!(run_eta(1, 1000, s(10), 2), None); // under 2 % done
    assert_eq!(run_eta(100, 1000, s(1), 2), None); // under 2 s
    assert_eq!(run_eta(1, 4, s(10), 2), None); // fewer than one per thread
    assert_eq!(run_eta(250, 1000, s(60), 2), Some(s(180)));
    assert_eq!(run_eta(1000, 1000, s(60), 2), Some(s(0)));
}

#[test]
fn answers_add_up_and_follow_the_tolerance() {
    let mut o = small(10);
    o.termination = Termination::Confident;
    let (rep, _) = run(&o);
    for g in &rep.results {
        let a = &g.answers;
        let n = g.plans as f64;
        let answered = g.episodes.iter().filter(|r| r.stopped_by_rule).count() as u32;
        assert_eq!(a.answered, answered);
        // right + wrong + unanswered = every episode.
        let right = (a.right * n).round() as u32;
        assert_eq!(
            right + a.wrong + ((a.unanswered * n).round() as u32),
            g.plans
        );
        // Every right answer is within 5 cm and 0.5°; a looser tolerance never has fewer.
        let within = |r: &super::record::EpisodeRow, m: f32, d: f32| {
            r.stopped_by_rule
                && r.position_error.is_some_and(|p| p <= m)
                && r.heading_error_deg.is_some_and(|h| h <= d)
        };
        assert_eq!(
            right as usize,
            g.episodes.iter().filter(|r| within(r, 0.05, 0.5)).count()
        );
        let loose = super::stats::Answers::of(
            &g.episodes,
            &activesense_core::registration::pose_distance::Tolerance {
                position_m: 1.0,
                heading_rad: 0.5,
            },
        );
        assert!(loose.right >= a.right && loose.wrong <= a.wrong);
        assert!(a.wrong_of_answered_ci95[0] <= a.wrong_of_answered);
        assert!(a.wrong_of_answered <= a.wrong_of_answered_ci95[1]);
    }
}
