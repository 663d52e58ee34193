//! The evaluation harness (paper §4.2, Table 4): every agent on the fixed test plans, for
//! every rotation setting, in parallel, deterministic for its seeds.
//!
//! Outputs, in `--out DIR`:
//! - `results.json` — one object per (agent, rot_bins), plus the full configuration. It is a
//!   pure function of the options: two runs give byte-identical files (wall times are kept
//!   out of it, in `timing.json`).
//! - `results.md` — the Table-4 layout with 95 % confidence intervals, the coarse (pre-ICP)
//!   error and wall time, next to the paper's numbers.
//! - `budget.svg` — recognition rate and pose error against the measurement budget.
//!
//! Definitions (also in `docs/EVALUATION.md`):
//! - *recognition rate*: fraction of episodes whose belief argmax reached coarse success
//!   (within one translation cell and one rotation bin of the truth or a symmetric
//!   equivalent) by the end of the episode;
//! - *pose error*: symmetry-aware pose distance (Brégier et al.) between the refined
//!   registration and the truth, in metres, averaged over the **recognised** episodes. The
//!   paper does not say; its numbers only fit this reading (heuristic-1 with 10 bins: 0.94
//!   recognition and 0.092 m mean error, whereas an unrecognised episode registers metres
//!   away). The mean over all registered episodes (`pose_error_all`) and the median over
//!   recognised ones are reported beside it;
//! - *measurements / rotations*: mean counts per episode, including failed episodes that
//!   ran to the action limit.

use crate::episode::{score, EpisodeSpec, EpisodeView, Termination, Trajectory};
use crate::learn::agent::{run_agent_episode_observed, Policies};
use crate::world::sensor::SensorModel;
use activesense_core::agents::AgentKind;
use activesense_core::episode::EpisodeConfig;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// What to evaluate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvalOptions {
    /// Agents, in output order.
    pub agents: Vec<AgentKind>,
    /// Rotation settings (1 and/or 10).
    pub rot_bins: Vec<u8>,
    /// Number of plans.
    pub plans: u32,
    /// First plan seed (test set starts at 1000000).
    pub first_seed: u32,
    /// Episode seed shared by every episode (placement and noise depend on the plan seed too).
    pub episode_seed: u64,
    /// Episode configuration (action limit, rotation step, costs).
    pub config: EpisodeConfig,
    /// Sensor parameters.
    pub sensor: SensorModel,
    /// Termination rule.
    pub termination: Termination,
    /// Files of the learnt policies (when the learnt agent is evaluated).
    #[serde(default)]
    pub policy_files: Vec<String>,
    /// The learnt policies themselves.
    #[serde(skip)]
    pub policies: Policies,
    /// Show a progress bar.
    #[serde(skip)]
    pub progress: bool,
    /// The pose-error-vs-cost curve registers after every measurement of the first this
    /// many plans (the entropy and recognition curves use every plan).
    #[serde(default)]
    pub curve_plans: u32,
    /// The user's rooms (`--plans-from`, `docs/PLANS.md`): when not empty they replace the
    /// generated plans, and `plans` is their number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub user_plans: Vec<crate::world::planfile::NamedPlan>,
    /// Plan files `--plans-from` refused, with why (listed in `results.md`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refused_plans: Vec<String>,
}

impl EvalOptions {
    /// The episode of `agent` with `rot_bins` on the `i`-th plan, stopped by `termination`.
    pub fn spec(
        &self,
        agent: AgentKind,
        rot_bins: u8,
        i: u32,
        termination: Termination,
    ) -> EpisodeSpec {
        let user_plan = self.user_plans.get(i as usize).cloned();
        EpisodeSpec {
            plan_seed: match &user_plan {
                Some(p) => p.seed(),
                None => self.first_seed.wrapping_add(i),
            },
            episode_seed: self.episode_seed,
            agent,
            rot_bins,
            config: self.config,
            sensor: self.sensor,
            termination,
            user_plan,
        }
    }
}

/// Summary of one episode kept for aggregation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EpisodeRow {
    /// Plan seed.
    pub plan_seed: u32,
    /// The user's room name (`--plans-from` evaluations only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<String>,
    /// Coarse success at the end.
    pub recognised: bool,
    /// Measurement actions.
    pub measurements: u16,
    /// Rotation actions.
    pub rotations: u16,
    /// Accumulated cost.
    pub cost: f32,
    /// Pose error after refinement (m).
    pub pose_error: Option<f32>,
    /// Pose error of the coarse estimate (m).
    pub coarse_error: Option<f32>,
    /// Room symmetry order.
    pub symmetry_order: u8,
    /// Measurements taken at an encoder bearing already measured in the episode.
    #[serde(default)]
    pub repeated_bearings: u16,
    /// The belief's stated confidence at the end: PMF mass within the coarse tolerance of
    /// the argmax and its symmetric equivalents (0 without a vote).
    #[serde(default)]
    pub final_peak_mass: f32,
    /// The termination rule ended the episode (not the action limit).
    #[serde(default)]
    pub stopped_by_rule: bool,
    /// With `--termination confident`: the calibrated estimate of P(wrong) the episode
    /// stopped on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub risk_at_stop: Option<f32>,
}

impl EpisodeRow {
    fn of(t: &Trajectory) -> Self {
        EpisodeRow {
            plan_seed: t.spec.plan_seed,
            plan: t.spec.user_plan.as_ref().map(|p| p.name.clone()),
            recognised: t.outcome.recognised,
            measurements: t.summary.measurements,
            rotations: t.summary.rotations,
            cost: t.summary.cost,
            pose_error: t.outcome.pose_error,
            coarse_error: t.outcome.coarse_error,
            symmetry_order: t.outcome.symmetry_order,
            final_peak_mass: 0.0,
            stopped_by_rule: t.end != crate::episode::EndReason::ActionLimit,
            risk_at_stop: (t.end == crate::episode::EndReason::Confident)
                .then_some(t.outcome.stop_risk)
                .flatten(),
            repeated_bearings: {
                let mut seen = std::collections::BTreeSet::new();
                t.steps
                    .iter()
                    .filter(|st| st.action == activesense_core::agents::Action::Measure)
                    .filter(|st| !seen.insert(st.bearing_index))
                    .count() as u16
            },
        }
    }
}

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
    fn of(xs: &[f64]) -> Option<MeanCi> {
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
    if n == 0 {
        return (0.0, 1.0);
    }
    let z = 1.96f64;
    let n = n as f64;
    let p = successes as f64 / n;
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * ((p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt()) / denom;
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

fn median(xs: &mut [f64]) -> Option<f64> {
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
    /// Episodes whose final pose is within [`REGISTERED_TOLERANCE`] of the truth (symmetry-
    /// aware), recognised or not: what the surveyor gets.
    #[serde(default)]
    pub registered: f64,
}

/// Largest measurement budget plotted.
pub const MAX_BUDGET: usize = 30;

/// Points of the utility-vs-cost curves: accumulated cost `0, Δ, …, CURVE_MAX_COST`.
pub const CURVE_POINTS: usize = 81;
/// Largest accumulated action cost on the curves (80 rotations and 8 measurements).
pub const CURVE_MAX_COST: f64 = 0.8;
/// β values of the Perf(π) = U + β·C table (eq. 15).
pub const PERF_BETAS: [f64; 4] = [-0.25, -0.5, -1.0, -2.0];

/// Cost of curve point `i`.
pub fn curve_cost(i: usize) -> f64 {
    CURVE_MAX_COST * i as f64 / (CURVE_POINTS - 1) as f64
}

/// One episode's state sampled on the curve's cost grid (the state after the last action
/// whose accumulated cost is within the grid value; after the episode ended, its final
/// state).
#[derive(Clone, Debug, Default)]
struct EpisodeCurve {
    entropy: Vec<f32>,
    recognised: Vec<bool>,
    pose_error: Vec<Option<f32>>,
}

/// Records an episode's state after every action for [`EpisodeCurve`]; registers after
/// every returned range when `register` is set.
struct CurveRecorder {
    register: bool,
    /// (cost, entropy, recognised, pose error so far).
    samples: Vec<(f32, f32, bool, Option<f32>)>,
    /// The belief's peak mass (its stated confidence) after the last vote.
    peak_mass: f32,
}

impl CurveRecorder {
    fn observe(&mut self, v: EpisodeView<'_>) {
        let pipe = v.runner.pipeline();
        let loc = pipe.localizer();
        let last = self.samples.last().and_then(|s| s.3);
        let (cost, recognised) = match v.step {
            None => (0.0, false),
            Some(st) => (st.cost, st.coarse_success),
        };
        let measured = v.step.is_some_and(|st| st.range.is_some());
        if measured {
            // The belief changes only when a range is voted.
            self.peak_mass = loc.peak_mass(pipe.symmetry_order());
        }
        let pose_error = if self.register && measured {
            score(v.plan, v.truth, &v.runner.finish(v.plan)).pose_error
        } else {
            last
        };
        self.samples
            .push((cost, loc.entropy(), recognised, pose_error));
    }

    fn curve(&self) -> EpisodeCurve {
        let mut c = EpisodeCurve::default();
        let mut k = 0;
        for i in 0..CURVE_POINTS {
            let x = curve_cost(i) as f32 + 1e-6;
            while k + 1 < self.samples.len() && self.samples[k + 1].0 <= x {
                k += 1;
            }
            let s = self
                .samples
                .get(k)
                .copied()
                .unwrap_or((0.0, 0.0, false, None));
            c.entropy.push(s.1);
            c.recognised.push(s.2);
            c.pose_error.push(s.3);
        }
        c
    }
}

/// Pose error (m) up to which an episode counts as registered in the confident-stop table.
pub const REGISTERED_TOLERANCE: f32 = 0.05;

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
    fn of(rows: &[EpisodeRow]) -> Self {
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

/// The reliability diagram of one rotation setting, one line per agent.
pub fn reliability_svg(report: &EvalReport, k: u8) -> String {
    use crate::plot::{line_panels, LinePanel, Series};
    let mut series = vec![Series {
        name: "calibrated (stated = observed)".into(),
        points: vec![(0.0, Some(0.0)), (1.0, Some(1.0))],
    }];
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        series.push(Series {
            name: r.agent.clone(),
            points: r
                .reliability
                .stated
                .iter()
                .zip(&r.reliability.observed)
                .zip(&r.reliability.episodes)
                .filter(|(_, &n)| n >= RELIABILITY_MIN_EPISODES)
                .filter_map(|((s, o), _)| s.map(|s| (s, *o)))
                .collect(),
        });
    }
    let tag = if k == 1 {
        "1 rotation bin"
    } else {
        "10 rotation bins"
    };
    line_panels(
        &format!(
            "Final belief's confidence vs correctness, {tag}, termination {:?}",
            report.options.termination
        ),
        &[LinePanel {
            title: format!("bins with ≥ {RELIABILITY_MIN_EPISODES} episodes"),
            xlabel: "stated confidence: final belief's peak mass (bin mean)".into(),
            ylabel: "fraction of episodes recognised".into(),
            x: (0.0, 1.0),
            y: (0.0, 1.0),
            series,
        }],
        1,
    )
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

fn curve_of(curves: &[EpisodeCurve], pose_error_plans: u32) -> UtilityCurve {
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

fn aggregate(
    agent: AgentKind,
    rot_bins: u8,
    rows: Vec<EpisodeRow>,
    curves: &[EpisodeCurve],
    curve_plans: u32,
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
        registered: rows
            .iter()
            .filter(|r| r.pose_error.is_some_and(|e| e <= REGISTERED_TOLERANCE))
            .count() as f64
            / n.max(1) as f64,
        episodes: rows,
    }
}

/// The whole evaluation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvalReport {
    /// Options it ran with.
    pub options: EvalOptions,
    /// One entry per (agent, rot_bins), agents outer, rotation settings inner.
    pub results: Vec<GroupResult>,
}

/// Wall-clock times (kept apart from the deterministic report).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Timing {
    /// Whole harness (s).
    pub total_s: f64,
    /// Summed episode time per (agent, rot_bins) in report order (s, CPU time across threads).
    pub group_episode_s: Vec<f64>,
    /// Mean time per decision of the agent per (agent, rot_bins) (ms; the policy alone).
    #[serde(default)]
    pub group_decision_ms: Vec<f64>,
    /// Worker threads.
    pub threads: usize,
}

/// An (agent, rot_bins) group of an evaluation.
type Group = (AgentKind, u8);

/// The (agent, rot_bins) groups in report order, and one job (group, plan index) per
/// episode.
fn groups_and_jobs(opts: &EvalOptions) -> (Vec<Group>, Vec<(usize, u32)>) {
    let groups: Vec<Group> = opts
        .agents
        .iter()
        .flat_map(|&a| opts.rot_bins.iter().map(move |&k| (a, k)))
        .collect();
    let jobs = (0..groups.len())
        .flat_map(|g| (0..opts.plans).map(move |i| (g, i)))
        .collect();
    (groups, jobs)
}

/// The progress bar of a run of `len` episodes (hidden when `show` is false).
pub fn episode_bar(len: u64, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} episodes ({per_sec}, eta {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    b
}

/// One evaluated episode: group, row, wall time, curve, (decisions, seconds deciding).
type JobOutput = (usize, EpisodeRow, f64, EpisodeCurve, (u32, f64));

/// Runs the evaluation.
pub fn run(opts: &EvalOptions) -> (EvalReport, Timing) {
    let t0 = Instant::now();
    let (groups, jobs) = groups_and_jobs(opts);
    let bar = episode_bar(jobs.len() as u64, opts.progress);
    let rows: Vec<JobOutput> = jobs
        .par_iter()
        .map(|&(g, i)| {
            let (agent, rot_bins) = groups[g];
            let spec = opts.spec(agent, rot_bins, i, opts.termination);
            let t = Instant::now();
            let mut rec = CurveRecorder {
                register: i < opts.curve_plans,
                samples: Vec::new(),
                peak_mass: 0.0,
            };
            // The policies were loaded for every evaluated setting before the run.
            let (traj, decided) =
                run_agent_episode_observed(&spec, &opts.policies, &mut |v| rec.observe(v))
                    .expect("policy loaded for every K");
            let mut row = EpisodeRow::of(&traj);
            row.final_peak_mass = rec.peak_mass;
            bar.inc(1);
            (
                g,
                row,
                t.elapsed().as_secs_f64(),
                rec.curve(),
                (decided.decisions, decided.seconds),
            )
        })
        .collect();
    bar.finish_and_clear();
    let mut per_group: Vec<Vec<EpisodeRow>> = vec![Vec::new(); groups.len()];
    let mut curves: Vec<Vec<EpisodeCurve>> = vec![Vec::new(); groups.len()];
    let mut secs = vec![0.0; groups.len()];
    let mut decisions = vec![(0u64, 0.0f64); groups.len()];
    // `collect` on an indexed parallel iterator keeps job order, so rows arrive in plan order.
    for (g, row, s, c, (n, ds)) in rows {
        per_group[g].push(row);
        curves[g].push(c);
        secs[g] += s;
        decisions[g].0 += n as u64;
        decisions[g].1 += ds;
    }
    let results = groups
        .iter()
        .zip(per_group)
        .zip(&curves)
        .map(|((&(a, k), rows), c)| aggregate(a, k, rows, c, opts.curve_plans))
        .collect();
    (
        EvalReport {
            options: opts.clone(),
            results,
        },
        Timing {
            total_s: t0.elapsed().as_secs_f64(),
            group_episode_s: secs,
            group_decision_ms: decisions
                .iter()
                .map(|&(n, s)| 1e3 * s / n.max(1) as f64)
                .collect(),
            threads: rayon::current_num_threads(),
        },
    )
}

/// The paper's Table 4, quoted (the paper's published numbers, not ours):
/// (agent, recognition 1 bin, recognition 10 bins, pose error 1, pose error 10,
/// measurements 1, measurements 10, rotations 1, rotations 10).
pub const PAPER_TABLE_4: [(&str, [f64; 8]); 8] = [
    (
        "our approach (learnt)",
        [0.997, 0.966, 0.0541, 0.0627, 4.084, 8.524, 9.777, 26.552],
    ),
    (
        "blind-0",
        [0.987, 0.862, 0.0595, 0.1740, 5.354, 13.355, 16.214, 39.891],
    ),
    (
        "blind-1",
        [0.977, 0.794, 0.0706, 0.2549, 11.179, 27.894, 11.146, 27.941],
    ),
    (
        "blind-2",
        [0.698, 0.243, 0.2150, 0.8040, 15.468, 28.837, 30.079, 56.506],
    ),
    (
        "heuristic-0",
        [0.989, 0.891, 0.0651, 0.1525, 9.323, 24.026, 8.544, 23.429],
    ),
    (
        "heuristic-1",
        [0.994, 0.940, 0.0507, 0.0921, 3.199, 7.248, 11.539, 32.390],
    ),
    (
        "heuristic-2",
        [0.951, 0.640, 0.0644, 0.3861, 2.439, 4.577, 25.506, 65.097],
    ),
    (
        "heuristic-3",
        [0.639, 0.115, 0.2117, 0.9036, 1.713, 1.961, 54.447, 93.563],
    ),
];

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map(|v| format!("{v:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// "N plans from seed S", or the user's rooms by name.
fn plan_source(o: &EvalOptions) -> String {
    if o.user_plans.is_empty() {
        return format!("{} plans from seed {}", o.plans, o.first_seed);
    }
    let names: Vec<&str> = o.user_plans.iter().map(|p| p.name.as_str()).collect();
    format!("{} user plans ({})", names.len(), names.join(", "))
}

/// Renders `results.md`.
pub fn markdown(report: &EvalReport, timing: &Timing, command: &str) -> String {
    let o = &report.options;
    let mut s = String::new();
    let _ = writeln!(s, "# Evaluation results\n");
    let _ = writeln!(s, "Produced by `{command}`.\n");
    let _ = writeln!(
        s,
        "{}, episode seed {}, action limit {}, rotation step 360°/{}, termination `{:?}`; \
         EDM σ = {} m, outliers {:.0} %, max range {} m, max incidence {:.0}°. \
         Wall time {:.1} s on {} threads.\n",
        plan_source(o),
        o.episode_seed,
        o.config.max_actions,
        o.config.steps_per_turn,
        o.termination,
        o.sensor.sigma,
        o.sensor.outlier_prob * 100.0,
        o.sensor.max_range,
        o.sensor.max_incidence.to_degrees(),
        timing.total_s,
        timing.threads
    );
    if !o.refused_plans.is_empty() {
        let _ = writeln!(s, "Plan files refused (not evaluated):\n");
        for r in &o.refused_plans {
            let _ = writeln!(s, "- {r}");
        }
        let _ = writeln!(s);
    }
    for &k in &o.rot_bins {
        let _ = writeln!(
            s,
            "## {} rotation bin{}\n",
            k,
            if k == 1 { " (heading known)" } else { "s" }
        );
        let _ = writeln!(
            s,
            "| agent | recognition rate [95% CI] | pose error (m) [95% CI] | median pose error (m) | p95 pose error (m) | pose error, all episodes (m) | coarse error (m) | measurements [95% CI] | rotations [95% CI] | cost | repeated bearings | episode time (s) | time per decision (ms) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for (g, r) in report
            .results
            .iter()
            .enumerate()
            .filter(|(_, r)| r.rot_bins == k)
        {
            let _ = writeln!(
                s,
                "| {} | {:.3} [{:.3}, {:.3}] | {} [{}, {}] | {} | {} | {} | {} | {:.2} [{:.2}, {:.2}] | {:.2} [{:.2}, {:.2}] | {:.3} | {:.2} | {:.1} | {:.3} |",
                r.agent,
                r.recognition_rate,
                r.recognition_ci95[0],
                r.recognition_ci95[1],
                opt(r.pose_error, 4),
                opt(r.pose_error_ci95.map(|c| c[0]), 4),
                opt(r.pose_error_ci95.map(|c| c[1]), 4),
                opt(r.pose_error_median, 4),
                opt(r.pose_error_p95, 4),
                opt(r.pose_error_all, 4),
                opt(r.coarse_error, 3),
                r.measurements,
                r.measurements_ci95[0],
                r.measurements_ci95[1],
                r.rotations,
                r.rotations_ci95[0],
                r.rotations_ci95[1],
                r.cost,
                r.repeated_bearing_fraction,
                timing.group_episode_s.get(g).copied().unwrap_or(0.0),
                timing.group_decision_ms.get(g).copied().unwrap_or(0.0)
            );
        }
        let _ = writeln!(s);
        perf_table(&mut s, report, k);
        reliability_table(&mut s, report, k);
        if o.termination == Termination::Confident {
            stop_table(&mut s, report, k);
        }
    }
    let _ = writeln!(s, "## Side by side with the paper's Table 4\n");
    let _ = writeln!(
        s,
        "Format as in the paper: 1 rotation bin, (10 rotation bins) in parentheses. \"paper\" rows are the paper's \
         published numbers, quoted; \"ours\" rows come from this run.\n"
    );
    let _ = writeln!(
        s,
        "| agent | | recognition rate | pose error (m) | measurements | rotations | cost |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    let find = |agent: &str, k: u8| {
        report
            .results
            .iter()
            .find(|r| r.agent == agent && r.rot_bins == k)
    };
    let costs = opts_costs(report);
    for (name, p) in PAPER_TABLE_4.iter() {
        let _ = writeln!(
            s,
            "| {name} | paper | {:.3} ({:.3}) | {:.4} ({:.4}) | {:.3} ({:.3}) | {:.3} ({:.3}) | {:.3} ({:.3}) |",
            p[0],
            p[1],
            p[2],
            p[3],
            p[4],
            p[5],
            p[6],
            p[7],
            costs.0 * p[4] + costs.1 * p[6],
            costs.0 * p[5] + costs.1 * p[7]
        );
        let ours: &[(&str, &str)] = if name.starts_with("our approach") {
            &[("learnt", "**ours**"), ("learnt-int8", "**ours, int8**")]
        } else {
            &[(name, "**ours**")]
        };
        for (agent, label) in ours {
            let (a, b) = (find(agent, 1), find(agent, 10));
            if a.is_none() && b.is_none() {
                continue;
            }
            let f =
                |r: Option<&GroupResult>, get: &dyn Fn(&GroupResult) -> Option<f64>, d: usize| {
                    r.and_then(get)
                        .map(|v| format!("{v:.d$}"))
                        .unwrap_or_else(|| "–".into())
                };
            let _ = writeln!(
                s,
                "| | {label} | {} ({}) | {} ({}) | {} ({}) | {} ({}) | {} ({}) |",
                f(a, &|r| Some(r.recognition_rate), 3),
                f(b, &|r| Some(r.recognition_rate), 3),
                f(a, &|r| r.pose_error, 4),
                f(b, &|r| r.pose_error, 4),
                f(a, &|r| Some(r.measurements), 3),
                f(b, &|r| Some(r.measurements), 3),
                f(a, &|r| Some(r.rotations), 3),
                f(b, &|r| Some(r.rotations), 3),
                f(a, &|r| Some(r.cost), 3),
                f(b, &|r| Some(r.cost), 3),
            );
        }
    }
    s
}

/// The Perf(π) = U + β·C table (eq. 15) of one rotation setting: U the recognition rate,
/// C the mean action cost per episode, β < 0 the price of a unit of cost.
fn perf_table(s: &mut String, report: &EvalReport, k: u8) {
    let _ = writeln!(
        s,
        "Perf(π) = U + β·C (eq. 15) with U = recognition rate and C = mean action cost per episode, for a few β \
         (how much recognition one unit of cost is worth); utility-vs-cost curves in `utility-k{k}.svg`.\n"
    );
    let mut head = String::from("| agent | U | C |");
    let mut rule = String::from("|---|---|---|");
    for b in PERF_BETAS {
        let _ = write!(head, " β = {b} |");
        rule.push_str("---|");
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let mut line = format!(
            "| {} | {:.3} | {:.3} |",
            r.agent, r.recognition_rate, r.cost
        );
        for b in PERF_BETAS {
            let _ = write!(line, " {:.3} |", r.recognition_rate + b * r.cost);
        }
        let _ = writeln!(s, "{line}");
    }
    let _ = writeln!(s);
}

/// The calibrated stop's record per agent (`--termination confident`).
fn stop_table(s: &mut String, report: &EvalReport, k: u8) {
    let _ = writeln!(
        s,
        "Calibrated stop (`--stop-risk {}`): how many episodes the rule stopped, how many of those stops were wrong \
         (the answer, the cell the refined pose lies in, not a coarse success), the mean estimated risk at the stops \
         (what the rule claimed), and the episodes whose final pose is within {} cm of the truth, recognised or not. \
         Recognition here scores that answer; oracle-terminated runs score the belief argmax.\n",
        report.options.config.stop_risk,
        100.0 * REGISTERED_TOLERANCE
    );
    let _ = writeln!(
        s,
        "| agent | stopped by the rule | wrong stops (of stops) | mean estimated risk at stop | recognition | pose within {} cm |\n|---|---|---|---|---|---|",
        100.0 * REGISTERED_TOLERANCE
    );
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let _ = writeln!(
            s,
            "| {} | {:.3} | {} ({:.4}) | {} | {:.3} | {:.3} |",
            r.agent,
            r.stops as f64 / r.plans.max(1) as f64,
            r.wrong_stops,
            r.wrong_stops as f64 / r.stops.max(1) as f64,
            opt(r.mean_risk_at_stop, 4),
            r.recognition_rate,
            r.registered
        );
    }
    let _ = writeln!(s);
}

/// Stated confidence against observed recognition per agent (`reliability-k{K}.svg` has
/// the diagram).
fn reliability_table(s: &mut String, report: &EvalReport, k: u8) {
    let _ = writeln!(
        s,
        "Reliability of the final belief's stated confidence (peak mass around the argmax) against recognition; \
         diagram in `reliability-k{k}.svg`. ECE = expected calibration error over {RELIABILITY_BINS} bins.\n"
    );
    let _ = writeln!(
        s,
        "| agent | mean stated confidence | observed recognition | ECE |\n|---|---|---|---|"
    );
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let _ = writeln!(
            s,
            "| {} | {:.3} | {:.3} | {:.3} |",
            r.agent, r.reliability.mean_stated, r.recognition_rate, r.reliability.ece
        );
    }
    let _ = writeln!(s);
}

/// The utility-vs-cost curves of one rotation setting: mean belief entropy, recognition and
/// pose error against accumulated action cost, one line per agent.
pub fn utility_svg(report: &EvalReport, k: u8) -> String {
    use crate::plot::{line_panels, LinePanel, Series};
    let groups: Vec<&GroupResult> = report.results.iter().filter(|r| r.rot_bins == k).collect();
    let series = |get: &dyn Fn(&UtilityCurve, usize) -> Option<f64>| -> Vec<Series> {
        groups
            .iter()
            .map(|r| Series {
                name: r.agent.clone(),
                points: (0..r.curve.cost.len())
                    .map(|i| (r.curve.cost[i], get(&r.curve, i)))
                    .collect(),
            })
            .collect()
    };
    let hmax = groups
        .iter()
        .flat_map(|r| r.curve.entropy.iter().copied())
        .fold(0.0f64, f64::max)
        .ceil();
    let emax = {
        let mut all: Vec<f64> = groups
            .iter()
            .flat_map(|r| r.curve.pose_error.iter().flatten().copied())
            .collect();
        all.sort_by(f64::total_cmp);
        let p90 = all.get(all.len() * 9 / 10).copied().unwrap_or(0.1);
        [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0]
            .into_iter()
            .find(|v| *v >= p90)
            .unwrap_or(10.0)
    };
    let plans = groups.first().map(|r| r.plans).unwrap_or(0);
    let reg_plans = groups
        .first()
        .map(|r| r.curve.pose_error_plans)
        .unwrap_or(0);
    let xlabel = "accumulated action cost (measurement 0.05, rotation 0.005)".to_string();
    let panels = vec![
        LinePanel {
            title: "mean belief entropy".into(),
            xlabel: xlabel.clone(),
            ylabel: "entropy (nats)".into(),
            x: (0.0, CURVE_MAX_COST),
            y: (0.0, hmax.max(1.0)),
            series: series(&|c, i| Some(c.entropy[i])),
        },
        LinePanel {
            title: "recognition (coarse success so far)".into(),
            xlabel: xlabel.clone(),
            ylabel: "fraction of episodes".into(),
            x: (0.0, CURVE_MAX_COST),
            y: (0.0, 1.0),
            series: series(&|c, i| Some(c.recognition[i])),
        },
        LinePanel {
            title: format!("pose error of recognised ({reg_plans} plans)"),
            xlabel,
            ylabel: "mean pose error (m)".into(),
            x: (0.0, CURVE_MAX_COST),
            y: (0.0, emax),
            series: series(&|c, i| c.pose_error[i]),
        },
    ];
    let tag = if k == 1 {
        "1 rotation bin (heading known)".to_string()
    } else {
        format!("{k} rotation bins")
    };
    line_panels(
        &format!("Utility against cost, {tag}, {plans} plans"),
        &panels,
        3,
    )
}

/// (measurement, rotation) costs of the run, for the paper's cost column.
fn opts_costs(report: &EvalReport) -> (f64, f64) {
    let c = report.options.config.costs;
    (c.measure as f64, c.rotate as f64)
}

/// Writes results.json, results.md, timing.json and budget.svg into `out`.
pub fn write_outputs(
    report: &EvalReport,
    timing: &Timing,
    out: &std::path::Path,
    command: &str,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut files = vec![
        (
            "results.json".to_string(),
            serde_json::to_string_pretty(report)? + "\n",
        ),
        ("results.md".to_string(), markdown(report, timing, command)),
        (
            "timing.json".to_string(),
            serde_json::to_string_pretty(timing)? + "\n",
        ),
        ("budget.svg".to_string(), crate::plot::budget_svg(report)),
    ];
    for &k in &report.options.rot_bins {
        files.push((format!("utility-k{k}.svg"), utility_svg(report, k)));
        files.push((format!("reliability-k{k}.svg"), reliability_svg(report, k)));
    }
    let mut written = Vec::new();
    for (name, body) in files {
        let p = out.join(name);
        std::fs::write(&p, body).with_context(|| format!("cannot write {}", p.display()))?;
        written.push(p);
    }
    Ok(written)
}

/// Pose error after each measurement beyond the minimal set (paper §4.3's to-do: "how the
/// final registration error changes with each new measurement action performed after a
/// minimal set"). The minimal set of an episode is the ranges it had when the oracle rule
/// would have stopped it (coarse success with the pipeline's minimum number of ranges);
/// the episode then goes on with the same agent, and the pipeline registers after every
/// further range.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExtraReport {
    /// Options it ran with (termination is overridden to the action limit).
    pub options: EvalOptions,
    /// Extra measurements followed.
    pub extra: usize,
    /// One entry per (agent, rot_bins).
    pub results: Vec<ExtraGroup>,
}

/// One agent and rotation setting of [`ExtraReport`].
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExtraGroup {
    /// Agent name.
    pub agent: String,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Episodes that reached the minimal set (oracle stop) within the action limit.
    pub stopped: u32,
    /// Mean size of the minimal set (ranges).
    pub minimal_set: f64,
    /// Per extra measurement `j = 0..=extra`: episodes that got that far.
    pub episodes: Vec<u32>,
    /// Mean pose error after `j` extra ranges (m).
    pub mean: Vec<Option<f64>>,
    /// Median pose error (m).
    pub median: Vec<Option<f64>>,
    /// 90th percentile (m).
    pub p90: Vec<Option<f64>>,
    /// Fraction of those episodes whose belief argmax is still a coarse success.
    #[serde(default)]
    pub still_recognised: Vec<f64>,
    /// Mean pose error over the episodes still recognised (m).
    #[serde(default)]
    pub mean_still_recognised: Vec<Option<f64>>,
}

/// Follows one episode for [`extra_measurements`].
struct ExtraRecorder {
    extra: usize,
    minimal: Option<usize>,
    /// (pose error, argmax still a coarse success) after each registration.
    errors: Vec<(f32, bool)>,
}

impl ExtraRecorder {
    fn observe(&mut self, v: EpisodeView<'_>) {
        let Some(step) = v.step else { return };
        let pipe = v.runner.pipeline();
        let ranges = pipe.observations().len();
        let register = match self.minimal {
            None if step.coarse_success && ranges >= pipe.min_measurements() => {
                self.minimal = Some(ranges);
                true
            }
            Some(_) => step.range.is_some() && self.errors.len() <= self.extra,
            None => false,
        };
        if register {
            // A registered episode has a pose; without one there is nothing to follow.
            if let Some(e) = score(v.plan, v.truth, &v.runner.finish(v.plan)).pose_error {
                self.errors.push((e, step.coarse_success));
            }
        }
    }
}

fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    Some(sorted[i])
}

/// One followed episode: group, minimal-set size, (error, still recognised) per registration.
type ExtraRow = (usize, Option<usize>, Vec<(f32, bool)>);

/// Runs the extra-measurement analysis (termination forced to the action limit).
pub fn extra_measurements(opts: &EvalOptions, extra: usize) -> ExtraReport {
    let (groups, jobs) = groups_and_jobs(opts);
    let bar = episode_bar(jobs.len() as u64, opts.progress);
    let rows: Vec<ExtraRow> = jobs
        .par_iter()
        .map(|&(g, i)| {
            let (agent, rot_bins) = groups[g];
            let spec = opts.spec(agent, rot_bins, i, Termination::ActionLimit);
            let mut rec = ExtraRecorder {
                extra,
                minimal: None,
                errors: Vec::new(),
            };
            run_agent_episode_observed(&spec, &opts.policies, &mut |v| rec.observe(v))
                .expect("policy loaded for every K");
            bar.inc(1);
            (g, rec.minimal, rec.errors)
        })
        .collect();
    bar.finish_and_clear();
    let results = groups
        .iter()
        .enumerate()
        .map(|(g, &(a, k))| {
            let mine: Vec<&ExtraRow> = rows.iter().filter(|r| r.0 == g).collect();
            let stopped: Vec<usize> = mine.iter().filter_map(|r| r.1).collect();
            let mut out = ExtraGroup {
                agent: a.name().to_string(),
                rot_bins: k,
                stopped: stopped.len() as u32,
                minimal_set: stopped.iter().sum::<usize>() as f64 / stopped.len().max(1) as f64,
                episodes: Vec::new(),
                mean: Vec::new(),
                median: Vec::new(),
                p90: Vec::new(),
                still_recognised: Vec::new(),
                mean_still_recognised: Vec::new(),
            };
            for j in 0..=extra {
                let at_j: Vec<(f32, bool)> =
                    mine.iter().filter_map(|r| r.2.get(j).copied()).collect();
                let kept: Vec<f64> = at_j.iter().filter(|x| x.1).map(|x| x.0 as f64).collect();
                out.still_recognised
                    .push(kept.len() as f64 / at_j.len().max(1) as f64);
                out.mean_still_recognised
                    .push(MeanCi::of(&kept).map(|m| m.mean));
                let mut e: Vec<f64> = at_j.iter().map(|x| x.0 as f64).collect();
                e.sort_by(f64::total_cmp);
                out.episodes.push(e.len() as u32);
                out.mean.push(MeanCi::of(&e).map(|m| m.mean));
                out.median.push(quantile(&e, 0.5));
                out.p90.push(quantile(&e, 0.9));
            }
            out
        })
        .collect();
    ExtraReport {
        options: opts.clone(),
        extra,
        results,
    }
}

/// `extra.md`: one table per rotation setting.
pub fn extra_markdown(r: &ExtraReport, command: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Pose error after each measurement beyond the minimal set\n"
    );
    let _ = writeln!(s, "Produced by `{command}`.\n");
    let _ = writeln!(
        s,
        "{}, action limit {}. The minimal set is the ranges an episode had when the oracle rule \
         would have stopped it; the agent then carries on and the pipeline registers after every further range. \
         Cells: mean / median / p90 pose error (m) over the episodes that got that far (their number in the last \
         column group).\n",
        plan_source(&r.options),
        r.options.config.max_actions
    );
    for &k in &r.options.rot_bins {
        let _ = writeln!(s, "## K = {k}\n");
        let groups: Vec<&ExtraGroup> = r.results.iter().filter(|g| g.rot_bins == k).collect();
        let mut head = String::from("| extra ranges |");
        let mut rule = String::from("|---|");
        for g in &groups {
            let _ = write!(head, " {} (minimal set {:.2}) |", g.agent, g.minimal_set);
            rule.push_str("---|");
        }
        let table = |s: &mut String, cell: &dyn Fn(&ExtraGroup, usize) -> String| {
            let _ = writeln!(s, "{head}\n{rule}");
            for j in 0..=r.extra {
                let mut line = format!("| +{j} |");
                for g in &groups {
                    let _ = write!(line, " {} |", cell(g, j));
                }
                let _ = writeln!(s, "{line}");
            }
            let _ = writeln!(s);
        };
        table(&mut s, &|g, j| {
            format!(
                "{} / {} / {} (n = {})",
                opt(g.mean[j], 4),
                opt(g.median[j], 4),
                opt(g.p90[j], 4),
                g.episodes[j]
            )
        });
        let _ = writeln!(
            s,
            "Still recognised (the belief argmax is still a coarse success) / mean pose error over those (m):\n"
        );
        table(&mut s, &|g, j| {
            format!(
                "{:.3} / {}",
                g.still_recognised.get(j).copied().unwrap_or(0.0),
                opt(g.mean_still_recognised.get(j).copied().flatten(), 4)
            )
        });
    }
    s
}

/// `extra.svg`: mean and median pose error against extra ranges, per rotation setting.
pub fn extra_svg(r: &ExtraReport) -> String {
    use crate::plot::{line_panels, LinePanel, Series};
    let mut panels = Vec::new();
    for &k in &r.options.rot_bins {
        let groups: Vec<&ExtraGroup> = r.results.iter().filter(|g| g.rot_bins == k).collect();
        for (what, get) in [
            (
                "mean",
                &(|g: &ExtraGroup, j: usize| g.mean[j])
                    as &dyn Fn(&ExtraGroup, usize) -> Option<f64>,
            ),
            ("median", &|g: &ExtraGroup, j: usize| g.median[j]),
        ] {
            let ymax = groups
                .iter()
                .flat_map(|g| (0..=r.extra).filter_map(|j| get(g, j)))
                .fold(0.0f64, f64::max);
            panels.push(LinePanel {
                title: format!("{what} pose error, K = {k}"),
                xlabel: "ranges beyond the minimal set".into(),
                ylabel: format!("{what} pose error (m)"),
                x: (0.0, r.extra as f64),
                y: (0.0, ymax * 1.05),
                series: groups
                    .iter()
                    .map(|g| Series {
                        name: g.agent.clone(),
                        points: (0..=r.extra).map(|j| (j as f64, get(g, j))).collect(),
                    })
                    .collect(),
            });
        }
    }
    line_panels(
        &format!(
            "Pose error after each measurement beyond the minimal set ({} plans)",
            r.options.plans
        ),
        &panels,
        2,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(plans: u32) -> EvalOptions {
        EvalOptions {
            agents: vec![AgentKind::Heuristic1, AgentKind::Blind2],
            rot_bins: vec![1, 10],
            plans,
            first_seed: crate::world::plans::TEST_SEEDS.start,
            episode_seed: 0,
            config: EpisodeConfig::default(),
            sensor: SensorModel::default(),
            termination: Termination::Oracle,
            policy_files: Vec::new(),
            policies: Policies::default(),
            progress: false,
            curve_plans: 3,
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
}
