//! The statistics of an evaluation: means with 95 % intervals ([`MeanCi`], [`wilson`]),
//! medians and quantiles, and the aggregation of one (agent, rotation setting)'s episode rows
//! into its [`GroupResult`]: recognition, pose error, counts, the budget and utility curves
//! ([`UtilityCurve`]) and the reliability of the belief's stated confidence
//! ([`Reliability`]).

use super::record::{curve_cost, EpisodeCurve, EpisodeRow, CURVE_POINTS, MAX_BUDGET};
use activesense_core::episode::AgentKind;
use activesense_core::registration::pose_distance::{PoseErrors, Tolerance};
use serde::{Deserialize, Serialize};

/// A mean with its 95 % confidence interval (normal approximation, 1.96 standard errors).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeanCi {
    /// Sample mean.
    pub mean: f64,
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

impl MeanCi {
    pub(crate) fn of(xs: &[f64]) -> Option<MeanCi> {
        if xs.is_empty() {
            return None;
        }
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = if xs.len() > 1 {
            xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        let half = 1.96 * (var / n).sqrt();
        Some(MeanCi {
            mean,
            lo: mean - half,
            hi: mean + half,
        })
    }
}

/// Wilson score interval for a proportion (95 %), well behaved near 0 and 1.
pub fn wilson(successes: u32, n: u32) -> (f64, f64) {
    wilson_at(successes, n, 1.96)
}

/// The Wilson score interval at `z` standard errors: 1.96 for the two-sided 95 %
/// interval, 1.645 for a one-sided 95 % bound.
pub fn wilson_at(successes: u32, n: u32, z: f64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let n = n as f64;
    let p = successes as f64 / n;
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * ((p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt()) / denom;
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

pub(crate) fn median(xs: &mut [f64]) -> Option<f64> {
    if xs.is_empty() {
        return None;
    }
    xs.sort_by(|a, b| a.total_cmp(b));
    let n = xs.len();
    Some(if n % 2 == 1 {
        xs[n / 2]
    } else {
        0.5 * (xs[n / 2 - 1] + xs[n / 2])
    })
}

/// The `q` quantile of `sorted` (nearest rank; `None` when empty).
pub(crate) fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    Some(sorted[i])
}

/// Aggregated results for one (agent, rot_bins).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupResult {
    /// Agent name.
    pub agent: String,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Episodes (= plans).
    pub plans: u32,
    /// Fraction recognised.
    pub recognition_rate: f64,
    /// Wilson 95 % interval of the recognition rate.
    pub recognition_ci95: [f64; 2],
    /// Mean refined pose error over recognised episodes (m).
    pub pose_error: Option<f64>,
    /// 95 % interval of the mean pose error.
    pub pose_error_ci95: Option<[f64; 2]>,
    /// Median refined pose error over recognised episodes (m).
    pub pose_error_median: Option<f64>,
    /// 95th percentile of the refined pose error over recognised episodes (m): the tail.
    #[serde(default)]
    pub pose_error_p95: Option<f64>,
    /// Mean refined pose error over all registered episodes, recognised or not (m).
    pub pose_error_all: Option<f64>,
    /// Mean coarse (pre-ICP) pose error over all episodes with a belief (m).
    pub coarse_error: Option<f64>,
    /// Mean measurements per episode.
    pub measurements: f64,
    /// 95 % interval of the mean measurements.
    pub measurements_ci95: [f64; 2],
    /// Mean rotations per episode.
    pub rotations: f64,
    /// 95 % interval of the mean rotations.
    pub rotations_ci95: [f64; 2],
    /// Mean action cost per episode.
    pub cost: f64,
    /// Fraction of measurements taken at a bearing the episode had already measured.
    #[serde(default)]
    pub repeated_bearing_fraction: f64,
    /// Episodes that produced no registration (no measurement returned).
    pub unregistered: u32,
    /// Recognition rate if the episode had been cut after `k + 1` measurements, k = 0..
    /// (fraction of episodes recognised with at most that many measurements).
    pub recognition_by_budget: Vec<f64>,
    /// Mean pose error of the episodes recognised within each budget (NaN-free: `None`
    /// where no episode was recognised yet).
    pub pose_error_by_budget: Vec<Option<f64>>,
    /// Utility against accumulated cost (eq. 15).
    #[serde(default)]
    pub curve: UtilityCurve,
    /// Reliability of the belief's stated confidence at the end of the episode.
    #[serde(default)]
    pub reliability: Reliability,
    /// Per-episode rows, in plan order.
    pub episodes: Vec<EpisodeRow>,
    /// Episodes the termination rule ended (the rest ran to the action limit).
    #[serde(default)]
    pub stops: u32,
    /// Of those, the ones whose belief argmax was not a coarse success.
    #[serde(default)]
    pub wrong_stops: u32,
    /// Mean calibrated risk estimate at the confident stops.
    #[serde(default)]
    pub mean_risk_at_stop: Option<f64>,
    /// What the instrument answered by itself, judged by the surveyor's tolerance (the
    /// no-oracle table): `right`, `wrong_of_answered`, `unanswered`, … at the top level of
    /// the group in `results.json`.
    #[serde(flatten)]
    pub answers: Answers,
}

/// The answers of one group judged by a [`Tolerance`]: an episode *answered* when its
/// termination rule ended it (not the action limit); an answer is *right* when its final
/// pose is within the tolerance of the truth modulo symmetry, *wrong* otherwise.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Answers {
    /// The tolerance: position (m).
    pub tolerance_m: f64,
    /// The tolerance: heading (degrees).
    pub tolerance_deg: f64,
    /// Fraction of all episodes answered right.
    pub right: f64,
    /// Wilson 95 % interval of `right`.
    pub right_ci95: [f64; 2],
    /// Wrong answers.
    pub wrong: u32,
    /// Episodes answered.
    pub answered: u32,
    /// Fraction of the answered episodes answered wrong (0 when none answered).
    pub wrong_of_answered: f64,
    /// Wilson 95 % interval of `wrong_of_answered`.
    pub wrong_of_answered_ci95: [f64; 2],
    /// Fraction of all episodes that reached the action limit without an answer.
    pub unanswered: f64,
    /// Mean position error of the right answers (m).
    pub right_position_error: Option<f64>,
    /// Median position error of the right answers (m).
    pub right_position_error_median: Option<f64>,
    /// 95th percentile of the position error of the right answers (m).
    pub right_position_error_p95: Option<f64>,
    /// Mean heading error of the right answers (degrees).
    pub right_heading_error_deg: Option<f64>,
}

impl Answers {
    pub(crate) fn of(rows: &[EpisodeRow], tol: &Tolerance) -> Self {
        let n = rows.len() as u32;
        let answered: Vec<&EpisodeRow> = rows.iter().filter(|r| r.stopped_by_rule).collect();
        let is_right = |r: &EpisodeRow| match (r.position_error, r.heading_error_deg) {
            (Some(p), Some(h)) => tol.admits(&PoseErrors {
                position: p,
                heading: h.to_radians(),
            }),
            _ => false,
        };
        let right: Vec<&EpisodeRow> = answered.iter().copied().filter(|r| is_right(r)).collect();
        let a = answered.len() as u32;
        let k = right.len() as u32;
        let wrong = a - k;
        let mut pos: Vec<f64> = right
            .iter()
            .filter_map(|r| r.position_error.map(f64::from))
            .collect();
        pos.sort_by(f64::total_cmp);
        let head: Vec<f64> = right
            .iter()
            .filter_map(|r| r.heading_error_deg.map(f64::from))
            .collect();
        let (rlo, rhi) = wilson(k, n);
        let (wlo, whi) = wilson(wrong, a);
        Answers {
            tolerance_m: tol.position_m as f64,
            tolerance_deg: (tol.heading_rad as f64).to_degrees(),
            right: k as f64 / n.max(1) as f64,
            right_ci95: [rlo, rhi],
            wrong,
            answered: a,
            wrong_of_answered: wrong as f64 / a.max(1) as f64,
            wrong_of_answered_ci95: [wlo, whi],
            unanswered: (n - a) as f64 / n.max(1) as f64,
            right_position_error: MeanCi::of(&pos).map(|m| m.mean),
            right_position_error_median: median(&mut pos.clone()),
            right_position_error_p95: quantile(&pos, 0.95),
            right_heading_error_deg: MeanCi::of(&head).map(|m| m.mean),
        }
    }
}

/// Bins of the reliability diagram: stated confidence `[i/10, (i+1)/10)` (the last bin
/// includes 1).
pub const RELIABILITY_BINS: usize = 10;

/// Bins with fewer episodes are left out of the diagram (they are in the JSON).
pub const RELIABILITY_MIN_EPISODES: u32 = 5;

/// Stated confidence (the final belief's peak mass) against observed correctness (coarse
/// success): a calibrated belief that says 0.9 is right 9 times in 10.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Reliability {
    /// Episodes per bin.
    pub episodes: Vec<u32>,
    /// Mean stated confidence per bin (`None` for an empty bin).
    pub stated: Vec<Option<f64>>,
    /// Fraction recognised per bin.
    pub observed: Vec<Option<f64>>,
    /// Mean stated confidence over all episodes.
    pub mean_stated: f64,
    /// Expected calibration error: the episode-weighted mean |stated − observed| over bins.
    pub ece: f64,
}

impl Reliability {
    pub(crate) fn of(rows: &[EpisodeRow]) -> Self {
        let mut r = Reliability {
            episodes: vec![0; RELIABILITY_BINS],
            ..Default::default()
        };
        let mut sum = [0.0f64; RELIABILITY_BINS];
        let mut right = [0u32; RELIABILITY_BINS];
        for row in rows {
            let c = row.final_peak_mass.clamp(0.0, 1.0) as f64;
            let b = ((c * RELIABILITY_BINS as f64) as usize).min(RELIABILITY_BINS - 1);
            r.episodes[b] += 1;
            sum[b] += c;
            right[b] += row.recognised as u32;
        }
        let n = rows.len().max(1) as f64;
        for b in 0..RELIABILITY_BINS {
            let k = r.episodes[b];
            let (st, ob) = if k > 0 {
                (Some(sum[b] / k as f64), Some(right[b] as f64 / k as f64))
            } else {
                (None, None)
            };
            if let (Some(st), Some(ob)) = (st, ob) {
                r.ece += k as f64 / n * (st - ob).abs();
            }
            r.stated.push(st);
            r.observed.push(ob);
        }
        r.mean_stated = sum.iter().sum::<f64>() / n;
        r
    }
}

/// Utility against accumulated action cost (eq. 15), averaged over the plans.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct UtilityCurve {
    /// Accumulated cost of each point.
    pub cost: Vec<f64>,
    /// Mean belief entropy (nats).
    pub entropy: Vec<f64>,
    /// Fraction of episodes whose belief argmax is a coarse success at that cost.
    pub recognition: Vec<f64>,
    /// Mean pose error of the pipeline's answer at that cost over the episodes recognised
    /// by then (first `pose_error_plans` plans only; `None` where none is).
    pub pose_error: Vec<Option<f64>>,
    /// Plans the pose-error curve averages over.
    pub pose_error_plans: u32,
}

pub(crate) fn curve_of(curves: &[EpisodeCurve], pose_error_plans: u32) -> UtilityCurve {
    let n = curves.len().max(1) as f64;
    let mut u = UtilityCurve {
        pose_error_plans,
        ..Default::default()
    };
    for i in 0..CURVE_POINTS {
        u.cost.push(curve_cost(i));
        u.entropy
            .push(curves.iter().map(|c| c.entropy[i] as f64).sum::<f64>() / n);
        u.recognition
            .push(curves.iter().filter(|c| c.recognised[i]).count() as f64 / n);
        let errs: Vec<f64> = curves
            .iter()
            .take(pose_error_plans as usize)
            .filter(|c| c.recognised[i])
            .filter_map(|c| c.pose_error[i].map(f64::from))
            .collect();
        u.pose_error.push(MeanCi::of(&errs).map(|m| m.mean));
    }
    u
}

/// Aggregates one (agent, rot_bins) group's rows (in plan order) and curves.
pub(crate) fn aggregate(
    agent: AgentKind,
    rot_bins: u8,
    rows: Vec<EpisodeRow>,
    curves: &[EpisodeCurve],
    curve_plans: u32,
    tolerance: &Tolerance,
) -> GroupResult {
    let n = rows.len() as u32;
    let rec = rows.iter().filter(|r| r.recognised).count() as u32;
    let (lo, hi) = wilson(rec, n);
    let pe: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.pose_error.map(f64::from))
        .collect();
    let pe_rec: Vec<f64> = rows
        .iter()
        .filter(|r| r.recognised)
        .filter_map(|r| r.pose_error.map(f64::from))
        .collect();
    let ce: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.coarse_error.map(f64::from))
        .collect();
    let meas: Vec<f64> = rows.iter().map(|r| r.measurements as f64).collect();
    let rots: Vec<f64> = rows.iter().map(|r| r.rotations as f64).collect();
    let m = MeanCi::of(&meas).unwrap_or(MeanCi {
        mean: 0.0,
        lo: 0.0,
        hi: 0.0,
    });
    let r = MeanCi::of(&rots).unwrap_or(MeanCi {
        mean: 0.0,
        lo: 0.0,
        hi: 0.0,
    });
    let pe_ci = MeanCi::of(&pe_rec);
    let mut budget_rec = Vec::with_capacity(MAX_BUDGET);
    let mut budget_err = Vec::with_capacity(MAX_BUDGET);
    for b in 1..=MAX_BUDGET {
        let within: Vec<&EpisodeRow> = rows
            .iter()
            .filter(|r| r.recognised && r.measurements as usize <= b)
            .collect();
        budget_rec.push(within.len() as f64 / n.max(1) as f64);
        let errs: Vec<f64> = within
            .iter()
            .filter_map(|r| r.pose_error.map(f64::from))
            .collect();
        budget_err.push(MeanCi::of(&errs).map(|c| c.mean));
    }
    GroupResult {
        agent: agent.name().to_string(),
        rot_bins,
        plans: n,
        recognition_rate: rec as f64 / n.max(1) as f64,
        recognition_ci95: [lo, hi],
        pose_error: pe_ci.map(|c| c.mean),
        pose_error_ci95: pe_ci.map(|c| [c.lo, c.hi]),
        pose_error_median: median(&mut pe_rec.clone()),
        pose_error_p95: {
            let mut sorted = pe_rec.clone();
            sorted.sort_by(f64::total_cmp);
            quantile(&sorted, 0.95)
        },
        pose_error_all: MeanCi::of(&pe).map(|c| c.mean),
        coarse_error: MeanCi::of(&ce).map(|c| c.mean),
        measurements: m.mean,
        measurements_ci95: [m.lo, m.hi],
        rotations: r.mean,
        rotations_ci95: [r.lo, r.hi],
        cost: rows.iter().map(|r| r.cost as f64).sum::<f64>() / n.max(1) as f64,
        repeated_bearing_fraction: rows.iter().map(|r| r.repeated_bearings as f64).sum::<f64>()
            / rows
                .iter()
                .map(|r| r.measurements as f64)
                .sum::<f64>()
                .max(1.0),
        unregistered: rows.iter().filter(|r| r.pose_error.is_none()).count() as u32,
        recognition_by_budget: budget_rec,
        pose_error_by_budget: budget_err,
        curve: curve_of(curves, curve_plans.min(n)),
        reliability: Reliability::of(&rows),
        stops: rows.iter().filter(|r| r.stopped_by_rule).count() as u32,
        wrong_stops: rows
            .iter()
            .filter(|r| r.stopped_by_rule && !r.recognised)
            .count() as u32,
        mean_risk_at_stop: MeanCi::of(
            &rows
                .iter()
                .filter_map(|r| r.risk_at_stop.map(f64::from))
                .collect::<Vec<_>>(),
        )
        .map(|m| m.mean),
        answers: Answers::of(&rows, tolerance),
        episodes: rows,
    }
}
