//! `activesense calibrate`: fits the calibrated stop's models ([`activesense_core::stop`]).
//!
//! Episodes of several agents run on calibration plans (generated seeds from
//! `--first-seed`, by default the start of [`CALIBRATION_SEEDS`](activesense_instrument::world::plans::CALIBRATION_SEEDS), which training,
//! test and validation never draw) to the action limit. After every returned range
//! whose belief passes the stop gate, the pipeline's [`StopFeatures`] are recorded with the
//! label "the answer is wrong": the refined pose the stop would answer with is outside the
//! surveyor's tolerance of the truth (5 cm and 0.5° modulo symmetry,
//! [`Tolerance::SURVEYOR`](activesense_core::registration::pose_distance::Tolerance::SURVEYOR), what the no-oracle table judges). A logistic
//! regression per rotation setting (Newton–Raphson / IRLS in f64 with a small ridge) is
//! fitted on the even-indexed plans and checked on the odd-indexed ones: the reliability
//! of its estimate at every step, and what the stop rule "stop at the first step whose
//! estimated risk is below P" would have done there. The models are written as Rust
//! source (`core-nostd/src/stop/calibration.rs`, compiled into the host and the firmware
//! alike) and the report as `calibration.md` / `calibration.json`.

mod analysis;
mod logistic;
mod report;

pub use report::{markdown, rust_source};

pub use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::site::SiteLevel;
pub use analysis::{cross_checked_by_level, level_cell, level_row, read_samples};
use logistic::fit_logistic;

use crate::eval::harness::{episode_bar, EvalOptions};
use crate::eval::stats::wilson_at;
use activesense_core::episode::AgentKind;
use activesense_core::episode::{EpisodeConfig, InstrumentProfile};
use activesense_core::registration::pose_distance::PoseDistance;
use activesense_core::stop::{
    interpolate_table, stop_score, AgentTable, StopFeatures, StopModel, AGENT_TABLES, FEATURES,
    STATED_RISKS,
};
use activesense_instrument::agents::{run_agent_episode_observed, Policies};
use activesense_instrument::episode::Termination;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// What one calibration run fits: the parsed `activesense calibrate` options.
#[derive(Clone, Debug)]
pub struct CalibrateOptions {
    /// Agents whose episodes provide the samples.
    pub agents: Vec<AgentKind>,
    /// Rotation settings to fit (one model each).
    pub rot_bins: Vec<u8>,
    /// Agents whose fitting episodes set the pooled threshold table.
    pub threshold_agents: Vec<AgentKind>,
    /// Agents that also get a threshold table of their own (at most [`AGENT_TABLES`]).
    pub table_agents: Vec<AgentKind>,
    /// Calibration plans per agent and setting (even-indexed fit, odd-indexed check).
    pub plans: u32,
    /// First calibration plan seed.
    pub first_seed: u32,
    /// Episode seed.
    pub episode_seed: u64,
    /// The calibration episodes' configuration (they run to its action limit).
    pub config: EpisodeConfig,
    /// The room the EDM hits in the calibration episodes (`--site`; `mixed` calibrates on
    /// randomised sites).
    pub site: SiteLevel,
    /// Calibration plans per setting for the agents of `table_agents`.
    pub agent_table_plans: u32,
    /// Ridge (L2) penalty on the weights.
    pub ridge: f64,
    /// Where to write the fitted models as Rust source.
    pub rust_out: PathBuf,
    /// Directory of the report.
    pub out: PathBuf,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Also write every decision point as JSON lines here.
    pub samples_out: Option<PathBuf>,
    /// Draw a progress bar.
    pub progress: bool,
}

/// One recorded decision point.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Sample {
    /// Plan index within the calibration set.
    pub plan: u32,
    /// What the stop rule sees.
    pub features: StopFeatures,
    /// The answer (the refined pose) is outside the tolerance of the truth.
    pub wrong: bool,
    /// How far the answer lies from the truth (m; at the nearest symmetric equivalent), for
    /// the analyses in `lab/scripts/`.
    #[serde(default)]
    pub position_error: f32,
    /// The answer's heading error (degrees, at the same equivalent).
    #[serde(default)]
    pub heading_error_deg: f32,
    /// How far the episode's room departed from its plan ([`threshold_table`] keeps the
    /// stated risk on each level).
    #[serde(default)]
    pub level: SiteLevel,
}

/// The samples of one episode, in step order.
pub type EpisodeSamples = Vec<Sample>;

/// An episode's samples with its index in job order (which says the agent).
type Indexed<'a> = (usize, &'a EpisodeSamples);

/// Runs the calibration episodes of one setting, `agents` on the calibration plans
/// `plans`; one sample list per episode, in job order (every plan of the first agent, then
/// the next).
pub fn collect(
    opts: &EvalOptions,
    rot_bins: u8,
    agents: &[AgentKind],
    plans: std::ops::Range<u32>,
    progress: bool,
) -> Vec<EpisodeSamples> {
    let jobs: Vec<(AgentKind, u32)> = agents
        .iter()
        .flat_map(|&a| plans.clone().map(move |i| (a, i)))
        .collect();
    let tolerance = opts.tolerance;
    let bar = episode_bar(jobs.len() as u64, progress);
    let out = jobs
        .par_iter()
        .map(|&(agent, i)| {
            let spec = opts.spec(agent, rot_bins, i, Termination::ActionLimit);
            let mut samples = Vec::new();
            run_agent_episode_observed(&spec, &opts.policies, &mut |v| {
                let Some(step) = v.step else { return };
                if step.range.is_none() {
                    return;
                }
                let pipe = v.runner.pipeline();
                // The label: is the answer (the refined pose) outside the surveyor's
                // tolerance of the truth?
                if let Some(point) = pipe.stop_point() {
                    let distance = PoseDistance::with_order(v.plan, pipe.symmetry_order());
                    let errors = distance.agent_errors(&point.pose, v.truth);
                    samples.push(Sample {
                        plan: i,
                        features: point.features,
                        wrong: !tolerance.admits(&errors),
                        position_error: errors.position,
                        heading_error_deg: errors.heading.to_degrees(),
                        level: v.site_level,
                    });
                }
            })
            .expect("policy loaded for every K");
            bar.inc(1);
            samples
        })
        .collect();
    bar.finish_and_clear();
    out
}

/// The check of a fitted model on held-out episodes.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HeldOut {
    /// Decision points.
    pub samples: usize,
    /// Fraction of them with a wrong answer (the refined pose outside the tolerance).
    pub wrong_rate: f64,
    /// Reliability per bin of the estimated risk `[0, .005, .01, .02, .05, .1, .2, .5, 1]`:
    /// (samples, mean estimated risk, observed wrong rate).
    pub reliability: Vec<(usize, f64, f64)>,
    /// For each stated risk P of [`STATED_RISKS`], on the held-out episodes of the
    /// threshold agents: (P, the model's threshold for it, episodes that stopped at a first
    /// crossing of it, fraction of those that stopped wrongly, mean readings at the stop).
    pub first_crossing: Vec<FirstCrossing>,
    /// Held-out episodes.
    pub episodes: usize,
    /// The same first-crossing check for each agent's own table, on that agent's held-out
    /// episodes.
    #[serde(default)]
    pub agents: Vec<AgentCheck>,
}

/// (stated risk P, the table's threshold for it, episodes that stopped at a first crossing
/// of it, fraction of those that stopped wrongly, mean readings at the stop).
pub type FirstCrossing = (f64, f64, usize, f64, f64);

/// The check of one agent's own threshold table. The table is placed on all of the agent's
/// episodes (its thresholds rest on a few dozen wrong first crossings, so every episode
/// counts); the check is cross-fitted: a table placed on the even-plan half is checked on
/// the odd half and the other way round, pooled.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AgentCheck {
    /// The agent's name.
    pub agent: String,
    /// Episodes the table was placed on (all of them).
    pub fit_episodes: usize,
    /// Episodes of the cross-fitted check (each checked once, by the other half's table).
    pub episodes: usize,
    /// As [`HeldOut::first_crossing`], with the committed table's thresholds and the
    /// cross-fitted halves' stops pooled.
    pub first_crossing: Vec<FirstCrossing>,
}

/// What stopping at the first crossing of `table`'s threshold for each stated risk does in
/// `episodes`.
fn first_crossing_check(
    model: &StopModel,
    table: &[f32; STATED_RISKS.len()],
    episodes: &[&EpisodeSamples],
) -> Vec<FirstCrossing> {
    STATED_RISKS
        .iter()
        .map(|&p| {
            let t = interpolate_table(table, p);
            let c = first_crossings(episodes, t, |s| score(model, s));
            // Through the shortest decimal of the f32, so the report says 0.001, not 0.0010000000474974513.
            let p64 = format!("{p}").parse().unwrap_or(p as f64);
            (p64, t as f64, c.stops, c.wrong_rate(), c.mean_readings())
        })
        .collect()
}

/// [`first_crossing_check`] cross-fitted: a table placed on `a` checked on `b`, and one
/// placed on `b` checked on `a`, pooled; the threshold column is `table`'s.
fn cross_fitted_check(
    model: &StopModel,
    table: &[f32; STATED_RISKS.len()],
    a: &[&EpisodeSamples],
    b: &[&EpisodeSamples],
) -> Vec<FirstCrossing> {
    let ab = first_crossing_check(model, &threshold_table(model, a), b);
    let ba = first_crossing_check(model, &threshold_table(model, b), a);
    ab.iter()
        .zip(&ba)
        .zip(STATED_RISKS)
        .map(|((&(p, _, n1, w1, r1), &(_, _, n2, w2, r2)), risk)| {
            let n = n1 + n2;
            let pool = |x1: f64, x2: f64| {
                if n == 0 {
                    0.0
                } else {
                    (x1 * n1 as f64 + x2 * n2 as f64) / n as f64
                }
            };
            let t = interpolate_table(table, risk) as f64;
            (p, t, n, pool(w1, w2), pool(r1, r2))
        })
        .collect()
}

const RISK_BINS: [f64; 9] = [0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0001];

fn held_out(
    model: &StopModel,
    episodes: &[&EpisodeSamples],
    threshold_episodes: &[&EpisodeSamples],
) -> HeldOut {
    let mut bins = vec![(0usize, 0.0f64, 0usize); RISK_BINS.len() - 1];
    let mut n = 0;
    let mut wrong = 0;
    for s in episodes.iter().flat_map(|e| e.iter()) {
        let r = model.risk(&s.features) as f64;
        let b = RISK_BINS
            .windows(2)
            .position(|w| r >= w[0] && r < w[1])
            .unwrap_or(0);
        bins[b].0 += 1;
        bins[b].1 += r;
        bins[b].2 += s.wrong as usize;
        n += 1;
        wrong += s.wrong as usize;
    }
    let first_crossing = first_crossing_check(model, &model.thresholds, threshold_episodes);
    HeldOut {
        samples: n,
        wrong_rate: wrong as f64 / n.max(1) as f64,
        reliability: bins
            .iter()
            .map(|&(k, sum, w)| (k, sum / k.max(1) as f64, w as f64 / k.max(1) as f64))
            .collect(),
        first_crossing,
        episodes: episodes.len(),
        agents: Vec::new(),
    }
}

/// What stopping at the first decision point whose score is below a threshold does.
pub struct Crossings {
    /// Episodes that stopped.
    pub stops: usize,
    /// Of those, the ones that stopped wrongly.
    pub wrong: usize,
    /// Readings (with repeats) at the stops, summed.
    pub readings: usize,
}

impl Crossings {
    /// Fraction of the stops that were wrong.
    pub fn wrong_rate(&self) -> f64 {
        self.wrong as f64 / self.stops.max(1) as f64
    }
    /// The one-sided 95 % upper bound on the wrong rate ([`UPPER_BOUND_Z`]; 1 without a
    /// stop).
    pub fn wrong_rate_bound(&self) -> f64 {
        wilson_at(self.wrong as u32, self.stops as u32, UPPER_BOUND_Z).1
    }
    /// Mean readings at the stops.
    pub fn mean_readings(&self) -> f64 {
        self.readings as f64 / self.stops.max(1) as f64
    }
}

/// What the threshold table is compared with at `s`: the estimate's [`stop_score`], the
/// stop's leverage veto left out ([`StopFeatures::leverage`]).
///
/// **Why the veto is left out.** The veto only takes answers away from the table: it is a
/// safety net for what the estimate cannot see (a wall off its line carried into the
/// answer), and the table keeps what the estimate can (flips, a rival). Placed on the
/// stop's score with the veto (vetoed points never crossing, [`decision_score`]), the
/// learnt K = 10 table loosened threefold once the veto had taken the riskiest points
/// away, and 180° flips came through on sites: 4 gross answers in 1000 validation setups
/// instead of 1 (`docs/lab/stop.md`, "The wall leverage as a veto").
pub fn score(model: &StopModel, s: &Sample) -> f32 {
    stop_score(model.risk(&s.features), s.features.readings)
}

/// The first crossings of `threshold` by `score` in `episodes` (readings counted with
/// repeats).
pub fn first_crossings(
    episodes: &[&EpisodeSamples],
    threshold: f32,
    score: impl Fn(&Sample) -> f32,
) -> Crossings {
    let mut c = Crossings {
        stops: 0,
        wrong: 0,
        readings: 0,
    };
    for s in episodes
        .iter()
        .filter_map(|e| e.iter().find(|s| score(s) < threshold))
    {
        c.stops += 1;
        c.wrong += s.wrong as usize;
        c.readings += (s.features.readings + s.features.repeats) as usize;
    }
    c
}

/// Thresholds on the estimate for candidate searches: 400 steps, log-spaced over
/// `[1e-5, 0.9]`.
fn candidate_thresholds() -> impl Iterator<Item = f32> {
    (0..400).map(|i| (1e-5f64 * (0.9f64 / 1e-5).powf(i as f64 / 399.0)) as f32)
}

/// z of the bound a threshold's wrong rate must keep: the one-sided 95 % Wilson bound.
/// A threshold placed where the fitting episodes' wrong rate just reaches P is wrong more
/// often than P about half the time on new plans; with the bound, about one time in
/// twenty (`docs/EVALUATION.md`, "A stated risk kept with 95 % confidence").
pub const UPPER_BOUND_Z: f64 = 1.645;

/// The share of a site level's episodes its threshold for a stated risk must answer for
/// the level to set that row ([`threshold_table`]): a risk kept on one level only by
/// refusing most setups there is not kept at the price of every other level's answers.
pub const MIN_ANSWERED_SHARE: f64 = 0.5;

/// The threshold table of `model` ([`StopModel::thresholds`]) from the fitting episodes:
/// for each stated risk P, the largest candidate threshold such that it and every smaller
/// one answered wrongly at first crossing in at most a fraction P of the episodes that
/// stopped, and whose own wrong rate's one-sided 95 % upper bound
/// ([`Crossings::wrong_rate_bound`]) is at most P. A stated risk no threshold meets gets
/// the smallest candidate.
///
/// **On each site level.** Where the episodes mix site levels (`calibrate --site mixed`),
/// each level's episodes get a table of their own and the smallest threshold of the
/// levels is kept, so that the stated risk holds in a furnished room, not only on the
/// average of the levels: the instrument cannot tell which room it stands in. A level on
/// which no threshold keeps a stated risk does not set it (building sites at 1 %, where
/// walls 3–6 cm off their lines move answers past the 5 cm tolerance unseen: every
/// threshold of theirs failed, and the instrument would never answer anywhere);
/// `docs/EVALUATION.md` says where the stated risk is not kept. Nor does a level whose
/// threshold answers fewer than [`MIN_ANSWERED_SHARE`] of its episodes (sites at K = 10
/// kept 1 % answering one setup in ten, and left a fifth of the plan setups unanswered).
/// Fitted on the pooled episodes, the EDM-only stop stated 1 % and answered wrongly in 1.6 %
/// of the answers in furnished rooms (`docs/EVALUATION.md`, "Rooms that are not their
/// plans").
pub fn threshold_table(
    model: &StopModel,
    episodes: &[&EpisodeSamples],
) -> [f32; STATED_RISKS.len()] {
    threshold_table_with(model, episodes, MIN_ANSWERED_SHARE)
}

/// [`threshold_table`] with another least answered share for a level to set a row
/// (`examples/threshold_by_level.rs` compares them; 0: every level that keeps a stated
/// risk sets it, however few setups it answers).
pub fn threshold_table_with(
    model: &StopModel,
    episodes: &[&EpisodeSamples],
    min_answered_share: f64,
) -> [f32; STATED_RISKS.len()] {
    threshold_table_scored(episodes, |s| score(model, s), min_answered_share)
}

/// [`threshold_table_with`] on any score of a decision point (`examples/leverage_veto.rs`
/// places tables with other vetoes by it).
pub fn threshold_table_scored(
    episodes: &[&EpisodeSamples],
    score: impl Fn(&Sample) -> f32 + Copy,
    min_answered_share: f64,
) -> [f32; STATED_RISKS.len()] {
    let levels = [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site];
    let of_level = |l: SiteLevel| -> Vec<&EpisodeSamples> {
        episodes
            .iter()
            .copied()
            .filter(|e| e.first().is_some_and(|s| s.level == l))
            .collect()
    };
    let present: Vec<Vec<&EpisodeSamples>> = levels
        .iter()
        .map(|&l| of_level(l))
        .filter(|e| !e.is_empty())
        .collect();
    if present.len() <= 1 {
        return threshold_table_by(episodes, score);
    }
    let mut table: [Option<f32>; STATED_RISKS.len()] = [None; STATED_RISKS.len()];
    for level in &present {
        let answers_enough = |t: &f32| {
            let stops = first_crossings(level, *t, score).stops;
            stops as f64 >= min_answered_share * level.len() as f64
        };
        let t = kept_thresholds(level, score).map(|t| t.filter(answers_enough));
        for (a, b) in table.iter_mut().zip(t) {
            *a = match (*a, b) {
                (Some(x), Some(y)) => Some(x.min(y)),
                (x, y) => x.or(y),
            };
        }
    }
    let smallest = candidate_thresholds().next().unwrap_or(1e-5);
    monotone(table.map(|t| t.unwrap_or(smallest)))
}

/// `table` with no stated risk's threshold above a larger risk's: a user who asks for less
/// risk never gets a looser stop, and [`StopModel::calibrated_risk`] (which bisects the
/// table) reads one number per score. Each row is placed on its own, and a level that
/// cannot keep one risk does not set that row ([`MIN_ANSWERED_SHARE`]), so without this
/// the committed EDM-only learnt K = 10 table answered at 0.0078 for 1 % and 0.0072 for
/// 3 %.
fn monotone(mut table: [f32; STATED_RISKS.len()]) -> [f32; STATED_RISKS.len()] {
    for i in (0..table.len().saturating_sub(1)).rev() {
        table[i] = table[i].min(table[i + 1]);
    }
    table
}

/// [`threshold_table`] for any score of a decision point (`examples/stop_score_exponent.rs`
/// compares scores by it).
pub fn threshold_table_by(
    episodes: &[&EpisodeSamples],
    score: impl Fn(&Sample) -> f32,
) -> [f32; STATED_RISKS.len()] {
    let smallest = candidate_thresholds().next().unwrap_or(1e-5);
    monotone(kept_thresholds(episodes, score).map(|t| t.unwrap_or(smallest)))
}

/// [`threshold_table_by`] with `None` where no candidate keeps the stated risk.
fn kept_thresholds(
    episodes: &[&EpisodeSamples],
    score: impl Fn(&Sample) -> f32,
) -> [Option<f32>; STATED_RISKS.len()] {
    // The running maximum of the wrong rate over ever larger thresholds, and each
    // threshold's own upper bound.
    let mut envelope = 0.0f64;
    let rates: Vec<(f32, f64, f64)> = candidate_thresholds()
        .map(|t| {
            let c = first_crossings(episodes, t, &score);
            envelope = envelope.max(c.wrong_rate());
            (t, envelope, c.wrong_rate_bound())
        })
        .collect();
    STATED_RISKS.map(|p| {
        rates
            .iter()
            .take_while(|&&(_, w, _)| w <= p as f64)
            .filter(|&&(_, _, bound)| bound <= p as f64)
            .last()
            .map(|&(t, _, _)| t)
    })
}

/// The episodes of `set` (index, samples) whose index passes `keep`.
fn episodes_where<'a>(
    set: &[Indexed<'a>],
    keep: impl Fn(usize) -> bool,
) -> Vec<&'a EpisodeSamples> {
    set.iter()
        .filter(|(i, _)| keep(*i))
        .map(|&(_, e)| e)
        .collect()
}

/// One fitted setting.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Fitted {
    /// The model.
    pub model: StopModel,
    /// Decision points it was fitted on.
    pub fit_samples: usize,
    /// The held-out check.
    pub held_out: HeldOut,
}

/// Appends the decision points of `episodes` (episode `i` played by `agent_of(i)`) to the
/// JSON-lines file `path`, one `{"rot_bins", "agent", "sample"}` object a line.
fn append_samples(
    path: &std::path::Path,
    rot_bins: u8,
    episodes: &[EpisodeSamples],
    agent_of: impl Fn(usize) -> AgentKind,
) -> anyhow::Result<()> {
    use std::io::Write;
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    let mut f = std::io::BufWriter::new(file);
    for (i, e) in episodes.iter().enumerate() {
        let agent = agent_of(i).name();
        for s in e {
            let line = serde_json::json!({"rot_bins": rot_bins, "agent": agent, "sample": s});
            writeln!(f, "{line}")?;
        }
    }
    Ok(())
}

/// Runs one calibration (`command`: the command line, recorded in the generated source).
pub fn calibrate(a: &CalibrateOptions, command: &str) -> anyhow::Result<()> {
    let (agents, rot_bins, threshold_agents, table_agents) =
        (&a.agents, &a.rot_bins, &a.threshold_agents, &a.table_agents);
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .ok();
    }
    let policies = if agents
        .iter()
        .any(|k| matches!(k, AgentKind::Learnt | AgentKind::LearntInt8))
    {
        Policies::load_for(a.config.instrument, &[], rot_bins)?
    } else {
        Policies::default()
    };
    let opts = EvalOptions {
        agents: agents.clone(),
        rot_bins: rot_bins.clone(),
        plans: a.plans,
        first_seed: a.first_seed,
        episode_seed: a.episode_seed,
        config: a.config,
        sensor: SensorModel {
            site: a.site,
            ..Default::default()
        },
        termination: Termination::ActionLimit,
        policy_files: Vec::new(),
        policies,
        progress: a.progress,
        curve_plans: 0,
        tolerance: Default::default(),
        user_plans: Vec::new(),
        refused_plans: Vec::new(),
    };
    let t0 = std::time::Instant::now();
    let mut fitted = Vec::new();
    for &k in rot_bins {
        eprintln!(
            "K = {k}: running {} episodes",
            agents.len() as u32 * a.plans
        );
        let episodes = collect(&opts, k, agents, 0..a.plans, opts.progress);
        if let Some(path) = &a.samples_out {
            append_samples(path, k, &episodes, |i| agents[i / a.plans as usize])?;
        }
        // Episodes come in job order: every plan of the first agent, then the next.
        let agent_of = |i: usize| agents[i / a.plans as usize];
        let (fit, check): (Vec<Indexed>, Vec<Indexed>) = episodes
            .iter()
            .enumerate()
            .filter(|(_, e)| !e.is_empty())
            .partition(|(_, e)| e[0].plan % 2 == 0);
        let of_threshold_agents = |i: usize| threshold_agents.contains(&agent_of(i));
        let threshold_fit = episodes_where(&fit, of_threshold_agents);
        let threshold_check = episodes_where(&check, of_threshold_agents);
        let fit: Vec<&EpisodeSamples> = fit.into_iter().map(|(_, e)| e).collect();
        let check: Vec<&EpisodeSamples> = check.into_iter().map(|(_, e)| e).collect();
        let xs: Vec<[f64; FEATURES]> = fit
            .iter()
            .flat_map(|e| e.iter())
            .map(|s| s.features.to_vector().map(|v| v as f64))
            .collect();
        let ys: Vec<bool> = fit.iter().flat_map(|e| e.iter()).map(|s| s.wrong).collect();
        if xs.is_empty() {
            anyhow::bail!("K = {k}: no decision point passed the stop gate; nothing to fit");
        }
        let (w, b) = fit_logistic(&xs, &ys, a.ridge);
        let mut model = StopModel {
            rot_bins: k,
            weights: w.map(|v| v as f32),
            bias: b as f32,
            thresholds: STATED_RISKS,
            agent_tables: [None; AGENT_TABLES],
        };
        model.thresholds = threshold_table(&model, &threshold_fit);
        let mut checks = Vec::new();
        for (slot, &agent) in table_agents.iter().enumerate() {
            if a.agent_table_plans > a.plans {
                eprintln!(
                    "K = {k}: running {} more episodes of {} for its own table",
                    a.agent_table_plans - a.plans,
                    agent.name()
                );
            }
            let extra = collect(
                &opts,
                k,
                &[agent],
                a.plans..a.agent_table_plans,
                opts.progress,
            );
            if let Some(path) = &a.samples_out {
                append_samples(path, k, &extra, |_| agent)?;
            }
            let first = agents.iter().position(|&x| x == agent).unwrap_or(0) * a.plans as usize;
            let (fit, check): (Vec<&EpisodeSamples>, Vec<&EpisodeSamples>) = episodes
                [first..first + a.plans as usize]
                .iter()
                .chain(&extra)
                .filter(|e| !e.is_empty())
                .partition(|e| e[0].plan % 2 == 0);
            let all: Vec<&EpisodeSamples> = fit.iter().chain(&check).copied().collect();
            let thresholds = threshold_table(&model, &all);
            model.agent_tables[slot] = Some(AgentTable { agent, thresholds });
            checks.push(AgentCheck {
                agent: agent.name().to_string(),
                fit_episodes: all.len(),
                episodes: all.len(),
                first_crossing: cross_fitted_check(&model, &thresholds, &fit, &check),
            });
        }
        let mut held_out = held_out(&model, &check, &threshold_check);
        held_out.agents = checks;
        fitted.push(Fitted {
            model,
            fit_samples: xs.len(),
            held_out,
        });
    }
    std::fs::create_dir_all(&a.out)?;
    std::fs::write(
        &a.rust_out,
        rust_source(&fitted, command, a.config.instrument),
    )?;
    std::fs::write(a.out.join("calibration.md"), markdown(&fitted, command))?;
    std::fs::write(
        a.out.join("calibration.json"),
        serde_json::to_string_pretty(&fitted)?,
    )?;
    eprintln!(
        "wrote {}, {}/calibration.{{md,json}} in {:.0} s",
        a.rust_out.display(),
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model whose estimate is the peak mass itself: σ(logit p) = p.
    fn peak_mass_model() -> StopModel {
        let mut weights = [0.0; FEATURES];
        weights[0] = 1.0;
        StopModel {
            rot_bins: 1,
            weights,
            bias: 0.0,
            thresholds: STATED_RISKS,
            agent_tables: [None; AGENT_TABLES],
        }
    }

    /// A decision point after 8 readings (the stop score equals the estimate `risk`).
    fn point(risk: f32, wrong: bool) -> Sample {
        Sample {
            plan: 0,
            features: StopFeatures {
                peak_mass: risk,
                entropy: 0.0,
                readings: 8,
                repeats: 0,
                explained: 3,
                unknowns: 2,
                observability: 0.0,
                offset_cells: 0.0,
                offset_bins: 0.0,
                edge_margin: 0.0,
                agrees: true,
                rival_margin: 0.0,
                precision: None,
                leverage: None,
            },
            wrong,
            position_error: 0.0,
            heading_error_deg: 0.0,
            level: SiteLevel::Plan,
        }
    }

    /// The table is placed on the estimate alone: decision points the stop's leverage veto
    /// holds at count as if they answered, so the veto only takes answers away from it.
    #[test]
    fn the_table_is_placed_on_the_estimate_and_the_veto_only_takes_answers_away() {
        use activesense_core::stop::{decision_score, LeverageVeto};
        let model = peak_mass_model();
        let past = LeverageVeto {
            position: 0.5,
            heading: 1.0,
        };
        let episodes = |veto: Option<LeverageVeto>| -> Vec<EpisodeSamples> {
            (0..4000)
                .map(|i| {
                    let mut first = point(0.05, i < 320);
                    first.features.leverage = veto;
                    vec![first, point(0.6, false)]
                })
                .collect()
        };
        let one = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap();
        let vetoed = episodes(Some(past));
        let plain = episodes(None);
        let table = |e: &[EpisodeSamples]| {
            let refs: Vec<&EpisodeSamples> = e.iter().collect();
            threshold_table(&model, &refs)
        };
        assert!(vetoed[0][0].features.vetoed());
        assert_eq!(table(&vetoed), table(&plain));
        assert!(table(&vetoed)[one] <= 0.05);
        // What the stop does at those points: never answer.
        let s = &vetoed[0][0];
        assert_eq!(
            decision_score(&s.features, model.risk(&s.features)),
            f32::INFINITY
        );
    }

    /// No stated risk's threshold is above a larger risk's.
    #[test]
    fn tables_are_made_monotone() {
        assert_eq!(
            monotone([0.1, 0.05, 0.3, 0.2, 0.9]),
            [0.05, 0.05, 0.2, 0.2, 0.9]
        );
    }

    /// Mixed site levels: 4000 plan-level episodes never wrong, and 4000 site-level ones
    /// wrong in 15 % of the stops at 0.4 and 8 % at 0.04. Pooled, 7.5 % passes a stated
    /// 10 % at 0.4; on each level the site's 15 % holds it below 0.4.
    #[test]
    fn threshold_table_keeps_the_stated_risk_on_each_site_level() {
        let model = peak_mass_model();
        let at = |level, risk, wrong| Sample {
            level,
            ..point(risk, wrong)
        };
        let mut episodes: Vec<EpisodeSamples> = (0..4000)
            .map(|_| {
                vec![
                    at(SiteLevel::Plan, 0.4, false),
                    at(SiteLevel::Plan, 0.001, false),
                ]
            })
            .collect();
        episodes.extend((0..4000).map(|i| {
            vec![
                at(SiteLevel::Site, 0.4, i < 600),
                at(SiteLevel::Site, 0.04, i < 320),
                at(SiteLevel::Site, 0.001, false),
            ]
        }));
        // A third level wrong in 5 % of the stops at every score keeps no 1 %: it does not
        // set that threshold (else nothing would ever answer), and keeps 10 % anywhere.
        episodes.extend((0..4000).map(|i| {
            vec![
                at(SiteLevel::Furnished, 0.4, i < 200),
                at(SiteLevel::Furnished, 0.04, i < 200),
                at(SiteLevel::Furnished, 0.001, i < 200),
            ]
        }));
        let refs: Vec<&EpisodeSamples> = episodes.iter().collect();
        let t = threshold_table(&model, &refs);
        let pooled = threshold_table_by(&refs[..8000], |s| score(&model, s));
        let ten = STATED_RISKS.iter().position(|&p| p == 0.1).unwrap();
        let one = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap();
        assert!(pooled[ten] > 0.4, "{pooled:?}");
        assert!(t[ten] > 0.04 && t[ten] <= 0.4, "{t:?}");
        assert!(t[one] > 0.001 && t[one] <= 0.04, "{t:?}");
        // One level alone is the pooled table.
        let plan_only: Vec<&EpisodeSamples> = refs[..4000].to_vec();
        assert_eq!(
            threshold_table(&model, &plan_only),
            threshold_table_by(&plan_only, |s| score(&model, s))
        );
    }

    /// A level that keeps 1 % only by answering one episode in ten does not set the 1 %
    /// row ([`MIN_ANSWERED_SHARE`]): plans then set it.
    #[test]
    fn a_level_that_keeps_a_risk_only_by_refusing_most_setups_does_not_set_it() {
        let model = peak_mass_model();
        let at = |level, risk, wrong| Sample {
            level,
            ..point(risk, wrong)
        };
        let mut episodes: Vec<EpisodeSamples> = (0..4000)
            .map(|_| vec![at(SiteLevel::Plan, 0.4, false)])
            .collect();
        episodes.extend((0..4000).map(|i| {
            let mut e = vec![
                at(SiteLevel::Site, 0.4, i < 600),
                at(SiteLevel::Site, 0.04, i < 320),
            ];
            if i % 10 == 0 {
                e.insert(0, at(SiteLevel::Site, 0.001, false));
            }
            e
        }));
        let refs: Vec<&EpisodeSamples> = episodes.iter().collect();
        let one = STATED_RISKS.iter().position(|&p| p == 0.01).unwrap();
        let t = threshold_table(&model, &refs);
        // Not the site's own 1 % (at most 0.04): plans would set it at 0.9, and the
        // site's 10 % row (below 0.4) caps it, the table being monotone.
        let ten = STATED_RISKS.iter().position(|&p| p == 0.1).unwrap();
        assert!(t[one] > 0.04 && t[one] == t[ten], "{t:?}");
        // The site level alone keeps 1 % at 0.001, answering a tenth of its episodes.
        let site = threshold_table_by(&refs[4000..], |s| score(&model, s));
        assert!(site[one] > 0.001 && site[one] <= 0.04, "{site:?}");
    }

    /// The threshold table: 4000 episodes whose first crossings are wrong in 0 %, 8 % and
    /// 50 % of the stops below 0.05, 0.5 and above give each stated risk the largest
    /// threshold that keeps it, upper bound included (8 % of 4000: at most 8.7 %).
    #[test]
    fn threshold_table_keeps_each_stated_risk_at_first_crossing() {
        let model = peak_mass_model();
        let episodes: Vec<EpisodeSamples> = (0..4000)
            .map(|i| {
                vec![
                    point(0.6, i < 2000),
                    point(0.05, i < 320),
                    point(0.001, false),
                ]
            })
            .collect();
        let refs: Vec<&EpisodeSamples> = episodes.iter().collect();
        assert!((model.risk(&episodes[0][1].features) - 0.05).abs() < 1e-6);
        let t = threshold_table(&model, &refs);
        for (p, t) in STATED_RISKS.iter().zip(&t) {
            if *p < 0.1 {
                // Every stop below 0.05 is right; one above it lets the 8 % in.
                assert!((0.04..=0.05).contains(t), "P = {p}: {t}");
            } else {
                assert!((0.5..=0.6).contains(t), "P = {p}: {t}");
            }
        }
        // The held-out report states what the table does there.
        let h = held_out(
            &StopModel {
                thresholds: t,
                ..model
            },
            &refs,
            &refs,
        );
        let at_10 = h.first_crossing.iter().find(|r| r.0 == 0.1).unwrap();
        assert_eq!((at_10.2, at_10.3), (4000, 0.08));
        // Cross-fitted, each half checks the other half's table. The second half is never
        // wrong, so its table stops at the first reading, and the first half, wrong there
        // every time, answers wrongly in all 2000: half of the 4000 pooled stops. The
        // threshold column is the committed table's own.
        let (first, second) = refs.split_at(2000);
        let c = cross_fitted_check(&model, &t, first, second);
        let at_10 = c.iter().find(|r| r.0 == 0.1).unwrap();
        assert_eq!(
            (at_10.1, at_10.2),
            (f64::from(interpolate_table(&t, 0.1)), 4000)
        );
        assert!((at_10.3 - 0.5).abs() < 1e-9, "{at_10:?}");
    }

    /// Too few stops to vouch for a stated risk: 100 episodes, every answer right, keep
    /// 3 % and 10 % (upper bound 2.6 %) but not 1 %, which gets the smallest candidate
    /// (never stop), though not one of the 100 answers was wrong.
    #[test]
    fn threshold_table_needs_enough_stops_for_the_bound() {
        let model = peak_mass_model();
        let episodes: Vec<EpisodeSamples> = (0..100)
            .map(|_| vec![point(0.6, false), point(0.001, false)])
            .collect();
        let refs: Vec<&EpisodeSamples> = episodes.iter().collect();
        let t = threshold_table(&model, &refs);
        let smallest = candidate_thresholds().next().unwrap();
        assert_eq!(&t[..3], &[smallest; 3]);
        assert!(t[3] > 0.6 && t[4] > 0.6, "{t:?}");
        let c = first_crossings(&refs, 0.9, |s| score(&model, s));
        assert_eq!((c.stops, c.wrong), (100, 0));
        assert!((c.wrong_rate_bound() - 0.0264).abs() < 1e-3);
    }

    /// The generated source is the committed file byte for byte: regenerating the
    /// compiled models reproduces `core-nostd/src/stop/calibration.rs`, laid out as rustfmt
    /// lays it out (so `cargo fmt --check` leaves a fresh `calibrate` output alone).
    #[test]
    fn the_generated_sources_are_the_committed_files() {
        use activesense_core::stop::{calibration, calibration_edm};
        for (file, models, instrument) in [
            (
                "calibration.rs",
                calibration::MODELS,
                InstrumentProfile::EdmScan,
            ),
            (
                "calibration_edm.rs",
                calibration_edm::MODELS,
                InstrumentProfile::Edm,
            ),
        ] {
            let path = format!(
                "{}/../core-nostd/src/stop/{file}",
                env!("CARGO_MANIFEST_DIR")
            );
            let committed = std::fs::read_to_string(path).unwrap();
            let command = committed
                .split("Generated by `")
                .nth(1)
                .and_then(|r| r.split('`').next())
                .unwrap();
            let samples = committed
                .lines()
                .filter_map(|l| {
                    l.trim()
                        .strip_prefix("// ")?
                        .strip_suffix(" decision points.")
                })
                .map(|n| n.parse::<usize>().unwrap());
            let fitted: Vec<Fitted> = models
                .iter()
                .zip(samples)
                .map(|(model, fit_samples)| Fitted {
                    model: *model,
                    fit_samples,
                    held_out: HeldOut {
                        samples: 0,
                        wrong_rate: 0.0,
                        reliability: Vec::new(),
                        first_crossing: Vec::new(),
                        episodes: 0,
                        agents: Vec::new(),
                    },
                })
                .collect();
            assert_eq!(fitted.len(), models.len(), "{file}");
            assert_eq!(
                rust_source(&fitted, command, instrument),
                committed,
                "{file}"
            );
        }
    }
}
