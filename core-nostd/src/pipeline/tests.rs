//! Unit tests of the pipeline: refused parameters, noise-free episodes that stop and
//! register, and the calibrated stop's answer and threshold.

use super::*;
use crate::episode::{Action, Observation};
use crate::fixtures::l_room_8x6;
use crate::limits::DEFAULT_STOP_RISK;
use crate::policy::{Policy, PolicyInput};
use crate::stop::StopModel;
use crate::world::geometry::unit;

#[test]
fn refuses_incomplete_params() {
    let mut p = Pipeline::new_empty();
    let base = EpisodeParams {
        agent: AgentKind::Heuristic1,
        seed: 1,
        rot_bins: 1,
        known_heading: None,
        ground_truth: None,
        initial_scan: 0,
        termination: Termination::ActionLimit,
        config: EpisodeConfig {
            min_observability: 0.0,
            stop_risk: DEFAULT_STOP_RISK,
            ..EpisodeConfig::DEFAULT
        },
    };
    assert_eq!(
        p.start(&l_room_8x6(), &base),
        Err(PipelineError::KnownHeadingRequired)
    );
    let oracle = EpisodeParams {
        rot_bins: 10,
        termination: Termination::Oracle,
        ..base
    };
    assert_eq!(
        p.start(&l_room_8x6(), &oracle),
        Err(PipelineError::GroundTruthRequired)
    );
    assert!(!p.measure(0.0, 1.0), "not started: nothing booked");
}

#[test]
fn noise_free_episode_stops_and_registers() {
    let plan = l_room_8x6();
    let truth = Pose2::new(-1.3, -0.6, 0.4);
    let mut p = Pipeline::new_empty();
    p.start(
        &plan,
        &EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 3,
            rot_bins: 10,
            known_heading: None,
            ground_truth: Some(truth),
            initial_scan: 0,
            termination: Termination::Oracle,
            config: EpisodeConfig {
                min_observability: 0.0,
                stop_risk: DEFAULT_STOP_RISK,
                ..EpisodeConfig::DEFAULT
            },
        },
    )
    .unwrap();
    let mut stopped = None;
    for k in 0..12 {
        let bearing = k as f32 * 0.55;
        let hit = plan
            .ray_cast(truth.translation(), unit(truth.theta + bearing))
            .unwrap();
        assert!(p.measure(bearing, hit.range));
        if let Some(s) = p.should_stop() {
            stopped = Some((k, s));
            break;
        }
    }
    let (_, why) = stopped.expect("coarse success within 12 measurements");
    assert_eq!(why, Stop::CoarseSuccess);
    let r = p.finish(&plan);
    assert_eq!(r.recognised, Some(true));
    let best = r.best().unwrap();
    assert!(
        (best.translation() - truth.translation()).norm() < 0.05,
        "{best:?} vs {truth:?}"
    );
    let o = r.observability.expect("reported with a belief");
    assert!(o.min_eigenvalue > 0.0 && o.constraints as usize == p.observations().len());
    // The observability threshold holds the stop back: the same readings stop the
    // episode under a threshold they meet and not under one above what they reach.
    p.params.config.min_observability = 0.5 * o.min_eigenvalue;
    assert_eq!(p.should_stop(), Some(Stop::CoarseSuccess));
    p.params.config.min_observability = 2.0 * o.min_eigenvalue;
    assert_eq!(p.should_stop(), None);
}

/// Confident termination at K = 10 with the truth known (for scoring) and stop risk `p`.
fn confident_params(truth: Pose2, p: f32) -> EpisodeParams {
    EpisodeParams {
        agent: AgentKind::Heuristic1,
        seed: 5,
        rot_bins: 10,
        known_heading: None,
        ground_truth: Some(truth),
        initial_scan: 0,
        termination: Termination::Confident,
        config: EpisodeConfig {
            min_observability: 0.0,
            stop_risk: p,
            ..EpisodeConfig::DEFAULT
        },
    }
}

/// A confident episode that never gets sure enough to stop answers with its lowest-risk
/// moment when the end is riskier; an action-limit episode answers with its end.
#[test]
fn an_unsure_confident_episode_answers_with_its_lowest_risk_moment() {
    let plan = l_room_8x6();
    let truth = Pose2::new(0.9, -0.4, 2.0);
    let mut params = confident_params(truth, 1e-9);
    let readings = |k: usize| {
        let bearing = k as f32 * 0.77;
        let hit = plan
            .ray_cast(truth.translation(), unit(truth.theta + bearing))
            .unwrap();
        // Every third range from the fifth on is an outlier: the risk goes up and down.
        let range = if k >= 4 && k % 3 == 1 {
            0.55 * hit.range
        } else {
            hit.range
        };
        (bearing, range)
    };
    let mut p = Pipeline::new_empty();
    p.start(&plan, &params).unwrap();
    let mut lowest: Option<(f32, usize)> = None;
    let n = 14;
    for k in 0..n {
        let (bearing, range) = readings(k);
        assert!(p.measure(bearing, range));
        assert_eq!(p.should_stop(), None, "a 1e-9 risk never stops");
        if let Some(r) = p.stop_risk_estimate() {
            if lowest.is_none_or(|(l, _)| r < l) {
                lowest = Some((r, k + 1));
            }
        }
    }
    let (low, at) = lowest.expect("the gate opened");
    let end = p.stop_risk_estimate();
    assert!(
        end.is_none_or(|e| low < e) && at < n,
        "the readings make an earlier moment the safest: {low} at {at}, end {end:?}"
    );
    let r = p.finish(&plan);
    assert_eq!((r.stop_risk, r.answer_readings), (Some(low), at as u16));

    // The same readings to the action limit answer with the end.
    params.termination = Termination::ActionLimit;
    p.start(&plan, &params).unwrap();
    for k in 0..n {
        let (bearing, range) = readings(k);
        assert!(p.measure(bearing, range));
        assert_eq!(p.should_stop(), None);
    }
    assert_eq!(p.finish(&plan).answer_readings, n as u16);
}

/// The calibrated stop on noise-free readings: it stops by itself, on a pose every reading
/// explains and that is right (the refinement may have left the argmax's cell: with the
/// residuals' variance factor the stop answers noise-free readings after four), and the
/// risk setting moves the stop.
#[test]
fn confident_stop_follows_the_stop_risk() {
    let plan = l_room_8x6();
    let truth = Pose2::new(0.9, -0.4, 2.0);
    let params = confident_params(truth, DEFAULT_STOP_RISK);
    let mut p = Pipeline::new_empty();
    p.start(&plan, &params).unwrap();
    let mut stopped = false;
    let mut taken: heapless::Vec<(f32, f32), 48> = heapless::Vec::new();
    for k in 0..40 {
        let bearing = k as f32 * 0.77;
        let hit = plan
            .ray_cast(truth.translation(), unit(truth.theta + bearing))
            .unwrap();
        assert!(p.measure(bearing, hit.range));
        taken.push((bearing, hit.range)).unwrap();
        if p.should_stop() == Some(Stop::Confident) {
            stopped = true;
            break;
        }
    }
    assert!(
        stopped,
        "noise-free readings reach a 1 % risk within 40 ranges"
    );
    let f = p.stop_features().expect("stopped on features");
    assert!(f.explained as usize == p.observations().len(), "{f:?}");
    let risk = p.stop_risk_estimate().expect("features agree");
    let model = StopModel::for_rot_bins(params.rot_bins);
    // What the threshold is compared with: the estimate scaled by the distinct bearings.
    let score = crate::stop::stop_score(risk, f.readings);
    assert!(score < model.threshold_for(params.agent, DEFAULT_STOP_RISK));
    let r = p.finish(&plan);
    assert_eq!(r.recognised, Some(true));
    assert_eq!(
        r.stop_risk,
        Some(risk),
        "finish reports the estimate it stopped on"
    );
    let best = r.best().unwrap();
    assert!(
        (best.translation() - truth.translation()).norm() < 0.02,
        "{best:?}"
    );
    // The same readings do not stop at a stated risk whose threshold is below the
    // score, and stop again at one whose threshold is just above it.
    let stated_with_threshold = |t: f32| {
        // threshold_for() is non-decreasing in the stated risk: bisect in ln p.
        let (mut lo, mut hi) = (1e-9f32, 1.0f32);
        for _ in 0..60 {
            let mid = libm::sqrtf(lo * hi);
            if model.threshold_for(params.agent, mid) < t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (lo, hi)
    };
    let (below, above) = stated_with_threshold(score);
    assert!(
        model.threshold_for(params.agent, below) < score
            && model.threshold_for(params.agent, above) >= score
    );
    p.params.config.stop_risk = below;
    assert_eq!(p.should_stop(), None);
    p.params.config.stop_risk = stated_with_threshold(score * 1.01).1;
    assert_eq!(p.should_stop(), Some(Stop::Confident));

    // The kept refinement follows the readings: after one more range the pipeline's
    // refinement equals that of a fresh pipeline fed the same ranges.
    let kept = p.refine(&plan).unwrap();
    let hit = plan
        .ray_cast(truth.translation(), unit(truth.theta + 0.4))
        .unwrap();
    assert!(p.measure(0.4, hit.range));
    taken.push((0.4, hit.range)).unwrap();
    let mut fresh = Pipeline::new_empty();
    fresh.start(&plan, &params).unwrap();
    for &(b, r) in taken.iter() {
        assert!(fresh.measure(b, r));
    }
    let after = p.refine(&plan).unwrap();
    assert_eq!(after, fresh.refine(&plan).unwrap());
    assert_ne!(after.fit.log_likelihood, kept.fit.log_likelihood);
}

/// A policy that reads a fan of three neighbouring bearings and then turns back and forth
/// at its edge: with the heading known every answer from its readings rests on the wall
/// the fan hits, and only the runner's aim ([`Pipeline::aim`]) can get the confident
/// stop the second wall it asks for.
struct Fan;

impl Policy for Fan {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        let step = EpisodeConfig::DEFAULT.rot_step();
        let k = crate::world::math::round(input.bearing / step) as i32;
        match k {
            0..=2 if input.measurements as i32 <= k => Action::Measure,
            0..=2 => Action::RotateLeft,
            _ => Action::RotateRight,
        }
    }
}

#[test]
fn the_runner_aims_at_the_wall_the_stop_lacks() {
    use crate::pipeline::runner::EpisodeRunner;
    use crate::registration::precision::rests_on_one_wall;
    let plan = l_room_8x6();
    let truth = Pose2::new(-1.3, -0.6, 0.4);
    let params = EpisodeParams {
        rot_bins: 1,
        known_heading: Some(truth.theta),
        ..confident_params(truth, DEFAULT_STOP_RISK)
    };
    let mut runner = EpisodeRunner::new_empty();
    runner.start(&plan, &params).unwrap();
    let mut fan = Fan;
    while let Some(action) = runner.decide(&mut fan) {
        let range = (action == Action::Measure)
            .then(|| {
                let b = runner.state().bearing();
                plan.ray_cast(truth.translation(), unit(truth.theta + b))
            })
            .flatten()
            .map(|h| h.range);
        runner
            .observe(action, &Observation { range, scan: 0 })
            .unwrap();
    }
    let obs = runner.pipeline().observations();
    let fan_only = Observations::from_slice(
        &obs.readings()
            .take(3)
            .map(|(b, r)| Measurement::new(b, r))
            .collect::<heapless::Vec<_, 3>>(),
    )
    .unwrap();
    assert!(rests_on_one_wall(
        &plan,
        &fan_only,
        &truth,
        true,
        crate::stop::PRECISION_GATE
    ));
    assert_eq!(
        runner.stop(),
        Some(Stop::Confident),
        "aimed readings let it stop"
    );
    assert!(obs.len() > 3 && obs.len() <= 8, "{} readings", obs.len());
    assert!(!rests_on_one_wall(
        &plan,
        obs,
        &truth,
        true,
        crate::stop::PRECISION_GATE
    ));
}
