//! The evaluation harness proper: what to evaluate ([`EvalOptions`]), every (agent, rotation
//! setting, plan) episode in parallel and deterministic for its seeds ([`run`]), and the
//! result it returns ([`EvalReport`], with wall times apart in [`Timing`]).

use super::record::{CurveRecorder, EpisodeCurve, EpisodeRow};
use super::stats::{aggregate, GroupResult};
use activesense_core::episode::AgentKind;
use activesense_core::episode::EpisodeConfig;
use activesense_core::registration::pose_distance::Tolerance;
use activesense_instrument::agents::{run_agent_episode_observed, Policies};
use activesense_instrument::episode::{EpisodeSpec, Termination};
use activesense_instrument::world::sensor::SensorModel;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

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
    pub user_plans: Vec<activesense_instrument::world::planfile::NamedPlan>,
    /// When an answer is right (`--tolerance`; default 5 cm and 0.5°).
    #[serde(default)]
    pub tolerance: Tolerance,
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
pub(crate) type Group = (AgentKind, u8);

/// The (agent, rot_bins) groups in report order, and one job (group, plan index) per
/// episode, plan-major: every stretch of the job list mixes the groups as the whole does,
/// so the progress bar's rate (and ETA) is the run's from the start. (Group-major, the
/// cheap K = 1 episodes came first and the ETA started at a third of the real time.)
/// Within a group the jobs stay in plan order, which the reports rely on.
pub(crate) fn groups_and_jobs(opts: &EvalOptions) -> (Vec<Group>, Vec<(usize, u32)>) {
    let groups: Vec<Group> = opts
        .agents
        .iter()
        .flat_map(|&a| opts.rot_bins.iter().map(move |&k| (a, k)))
        .collect();
    let n = groups.len();
    let jobs = (0..opts.plans)
        .flat_map(|i| (0..n).map(move |g| (g, i)))
        .collect();
    (groups, jobs)
}

/// The remaining time of a run at `pos` of `len` episodes after `elapsed`: the whole run's
/// mean rate so far (not a recent-rate estimate, which follows whichever episodes
/// finished last), and nothing until a warm-up of 2 s and 2 % of the episodes (at least
/// one per worker thread) has passed.
pub fn run_eta(pos: u64, len: u64, elapsed: Duration, threads: u64) -> Option<Duration> {
    let warm = (len / 50).max(threads).max(1);
    if pos < warm || elapsed < Duration::from_secs(2) || pos > len {
        return None;
    }
    Some(elapsed.mul_f64((len - pos) as f64 / pos as f64))
}

/// The progress bar of a run of `len` episodes (hidden when `show` is false); its ETA is
/// [`run_eta`].
pub fn episode_bar(len: u64, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let threads = rayon::current_num_threads() as u64;
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} episodes ({per_sec}, eta {run_eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .with_key(
            "run_eta",
            move |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = match run_eta(s.pos(), s.len().unwrap_or(0), s.elapsed(), threads) {
                    Some(d) => write!(w, "{}", indicatif::HumanDuration(d)),
                    None => write!(w, "estimating"),
                };
            },
        )
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
        .map(|((&(a, k), rows), c)| aggregate(a, k, rows, c, opts.curve_plans, &opts.tolerance))
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
