//! Advantage actor-critic with GAE (paper §3.1, eqs. 1–4; §4.2), in one file, CleanRL style:
//! every hyper-parameter is a field of [`HyperParams`] (printed at the start of a run and
//! stored in the policy file), and [`train`] reads top to bottom: collect a segment of
//! `num_envs × segment_len` steps from parallel simulated rooms, compute GAE advantages,
//! take one gradient step (or, with `--update-epochs N`, N steps under PPO's clipped ratio:
//! [`clipped_ratio_weight`]), log, checkpoint.
//!
//! **Environment.** Each of the `num_envs` environments is a simulated room from the
//! *training* seeds (`plans::TRAIN_SEEDS`, never the test range) with an
//! [`EpisodeRunner`]: the same core loop the evaluation and the instrument run, so the
//! features the network trains on are exactly those it will see. Episodes end on coarse
//! success (oracle termination, §4.2's first experiment; the default), or with
//! `--termination confident` when the calibrated stop answers (right or wrong by
//! `Tolerance::SURVEYOR`), or at the action limit.
//!
//! **Reward** (§4.2; `docs/LEARNING.md` has the formula):
//! `r_t = −c(a_t) + b(t)` for every action, plus at the end of the episode
//! `+1` on coarse success or `−1` at the action limit, and
//! `R_reg · (1 − min(1, (e / e_tol)²))` for the refined registration error `e` (the clipped
//! quadratic). `c` is 0.05 per measurement and 0.005 per rotation; `b(t) = β · n₀ / (n₀ + N(t))`
//! is the exploration bonus, decaying with the number `N(t)` of steps with index `t`
//! visited so far in training (the inverse visitation frequency of the episode length).
//!
//! **Warm start.** The first `imitation_updates` updates clone a teacher (heuristic-1 by
//! default): the teacher acts, the actor is trained by cross-entropy on its actions and the
//! critic on the returns of the paper's reward. Then the policy acts and A2C takes over,
//! after `critic_warmup_updates` updates (default 0) in which only the critic learns: a
//! fine-tune under another termination starts with a critic fitted to the old returns.
//!
//! **Determinism.** Each environment draws from its own PCG stream derived from the seed;
//! environments step in parallel but only touch their own state; the visitation counts
//! are updated between segments in environment order; and the network's gradient is
//! reduced in a fixed chunk order. The same seed gives the same weights byte for byte,
//! whatever the number of threads.

pub use super::hyper::HyperParams;
use super::log::{csv_line, progress_bar, row_line, CSV_HEADER};
pub use super::log::{curve_svg, write_text, LogRow};
use activesense_core::episode::EpisodeConfig;
use activesense_core::episode::{Action, AgentKind};
use activesense_core::pipeline::runner::EpisodeRunner;
use activesense_core::pipeline::Stop;
use activesense_core::policy::BaselineAgent;
use activesense_core::policy::{Policy, BELIEF_PLANE, SIDE_FEATURES};
use activesense_core::registration::pose_distance::Tolerance;
use activesense_core::{FloorPlan, Pose2};
use activesense_instrument::episode::{score, start_episode, EpisodeSpec};
use activesense_instrument::learn::agent::{action_index, masked_features, shape_for, ACTIONS};
use activesense_instrument::learn::file;
use activesense_instrument::learn::net::{self, Adam, BatchCache, NetShape, PolicyNet};
use activesense_instrument::world::plans;
use activesense_instrument::world::SimWorld;
use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use std::path::PathBuf;
use std::time::Instant;

/// The paper's reward for one step (before the end-of-episode terms).
pub fn step_reward(action: Action, bonus: f32) -> f32 {
    let costs = EpisodeConfig::default().costs;
    -costs.of(action) + bonus
}

/// How a training episode ended, for the end-of-episode reward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ending {
    /// Oracle stop: coarse success. Calibrated stop: an answer within the surveyor's
    /// tolerance ([`Tolerance::SURVEYOR`]).
    Right,
    /// Calibrated stop only: the instrument answered, and the answer is outside the tolerance.
    Wrong,
    /// The action limit.
    Limit,
}

/// The end-of-episode reward: right (+`success_reward`), wrong (−`wrong_penalty`) or the
/// action limit (−`limit_penalty`), plus the clipped quadratic registration term and, with
/// `registration_penalty`, a penalty that ramps up from the clip to twice it.
pub fn final_reward(hp: &HyperParams, ending: Ending, pose_error: Option<f32>) -> f32 {
    let outcome = match ending {
        Ending::Right => hp.success_reward,
        Ending::Wrong => -hp.wrong_penalty,
        Ending::Limit => -hp.limit_penalty,
    };
    let reg = pose_error
        .map(|e| {
            let x = e / hp.registration_tolerance;
            let clipped = hp.registration_reward * (1.0 - (x * x).min(1.0));
            if hp.registration_penalty > 0.0 {
                clipped - hp.registration_penalty * (x - 1.0).clamp(0.0, 1.0)
            } else {
                clipped
            }
        })
        .unwrap_or(0.0);
    outcome + reg
}

/// Exploration bonus for a step with index `t`, given the visit counts.
fn bonus(hp: &HyperParams, visits: &[u64], t: usize) -> f32 {
    if hp.exploration_bonus <= 0.0 {
        return 0.0;
    }
    let n = visits.get(t).copied().unwrap_or(0) as f32;
    hp.exploration_bonus * hp.exploration_half_visits / (hp.exploration_half_visits + n)
}

/// One finished training episode.
#[derive(Clone, Copy, Debug, Default)]
struct Finished {
    ret: f32,
    success: bool,
    measurements: u16,
    rotations: u16,
    cost: f32,
    pose_error: Option<f32>,
}

/// One simulated room with its episode loop.
struct Env {
    rng: Pcg64,
    runner: Box<EpisodeRunner>,
    plan: FloorPlan,
    world: SimWorld,
    truth: Pose2,
    teacher: BaselineAgent,
    ret: f32,
}

impl Env {
    fn new(hp: &HyperParams, index: usize) -> Self {
        let mut rng = Pcg64::seed_from_u64(activesense_core::world::math::splitmix64(
            hp.seed ^ (index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        ));
        let spec = Self::draw(hp, &mut rng);
        Self::with_spec(hp, &spec, rng)
    }

    /// An environment starting with the episode `spec`.
    fn with_spec(hp: &HyperParams, spec: &EpisodeSpec, rng: Pcg64) -> Self {
        let mut runner = Box::new(EpisodeRunner::new_empty());
        let (plan, world, _) = start_episode(spec, &mut runner);
        Env {
            truth: world.truth(),
            teacher: BaselineAgent::new(hp.teacher, spec.agent_seed()),
            rng,
            runner,
            plan,
            world,
            ret: 0.0,
        }
    }

    /// A fresh episode on a random training plan.
    fn draw(hp: &HyperParams, rng: &mut Pcg64) -> EpisodeSpec {
        let plan_seed = rng.gen_range(plans::TRAIN_SEEDS);
        let mut spec = EpisodeSpec::new(plan_seed, AgentKind::Learnt);
        spec.episode_seed = rng.gen();
        spec.rot_bins = hp.rot_bins;
        spec.config.max_actions = hp.max_actions;
        spec.config.instrument = hp.instrument;
        spec.sensor.site = hp.site;
        spec.termination = hp.termination;
        spec
    }

    fn reset(&mut self, hp: &HyperParams) {
        let spec = Self::draw(hp, &mut self.rng);
        let (plan, world, _) = start_episode(&spec, &mut self.runner);
        self.plan = plan;
        self.truth = world.truth();
        self.world = world;
        self.teacher = BaselineAgent::new(hp.teacher, spec.agent_seed());
        self.ret = 0.0;
    }

    /// Samples an action from `logits` with this environment's stream.
    fn sample(&mut self, logits: &[f32; 3]) -> usize {
        let p = net::softmax(logits);
        let u: f32 = self.rng.gen();
        let mut acc = 0.0;
        for (i, pi) in p.iter().enumerate() {
            acc += pi;
            if u < acc {
                return i;
            }
        }
        2
    }

    /// Plays `action`; returns (reward, done, finished-episode summary).
    fn step(&mut self, hp: &HyperParams, action: Action, bonus: f32) -> (f32, Option<Finished>) {
        let (obs, _) = self.world.act(action);
        self.runner
            .observe(action, &obs)
            .expect("simulated observation is valid");
        let mut r = step_reward(action, bonus);
        if !self.runner.is_over() {
            self.ret += r;
            return (r, None);
        }
        let result = self.runner.finish(&self.plan);
        let outcome = score(&self.plan, &self.truth, &result);
        let ending = match self.runner.stop() {
            Some(Stop::CoarseSuccess) => Ending::Right,
            Some(Stop::Confident)
                if outcome
                    .errors
                    .is_some_and(|e| Tolerance::SURVEYOR.admits(&e)) =>
            {
                Ending::Right
            }
            Some(Stop::Confident) => Ending::Wrong,
            _ => Ending::Limit,
        };
        let success = ending == Ending::Right;
        r += final_reward(hp, ending, outcome.pose_error);
        self.ret += r;
        let s = self.runner.state();
        let done = Finished {
            ret: self.ret,
            success,
            measurements: s.measurements,
            rotations: s.rotations,
            cost: s.cost,
            pose_error: outcome.pose_error.filter(|_| success),
        };
        self.reset(hp);
        (r, Some(done))
    }
}

/// What a finished run produced.
pub struct TrainOutcome {
    /// The trained network.
    pub net: PolicyNet,
    /// The learning curve.
    pub log: Vec<LogRow>,
    /// Wall time (s).
    pub wall_s: f64,
    /// Updates done.
    pub updates: u64,
}

/// Options outside the learning problem itself.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Output directory (policy, logs, curve, checkpoints).
    pub out: Option<PathBuf>,
    /// Stop after this many minutes of wall time, whatever `updates` says.
    pub minutes: Option<f64>,
    /// Show a progress bar.
    pub progress: bool,
    /// The command line, recorded in the policy file.
    pub command: String,
    /// Start from this network instead of a fresh one.
    pub init: Option<PolicyNet>,
}

/// Trains a policy. See the module doc for the algorithm.
pub fn train(hp: &HyperParams, opts: &RunOptions) -> Result<TrainOutcome> {
    let t0 = Instant::now();
    let shape: NetShape = shape_for(hp.rot_bins);
    let mut net = match &opts.init {
        Some(n) => n.clone(),
        None => PolicyNet::new(shape, hp.seed),
    };
    anyhow::ensure!(net.shape == shape, "initial network has another shape");
    let mut adam = Adam::new(shape.param_count(), hp.learning_rate);
    let mut envs: Vec<Env> = (0..hp.num_envs).map(|i| Env::new(hp, i)).collect();
    let (e, t_len) = (hp.num_envs, hp.segment_len);
    let (bl, sl) = (hp.rot_bins as usize * BELIEF_PLANE, SIDE_FEATURES);
    let n = e * t_len;
    // Rollout storage, [t][env] order.
    let mut beliefs = vec![0.0f32; n * bl];
    let mut sides = vec![0.0f32; n * sl];
    let mut actions = vec![0usize; n];
    let mut rewards = vec![0.0f32; n];
    let mut dones = vec![false; n];
    let mut values = vec![0.0f32; n];
    let mut visits: Vec<u64> = vec![0; hp.max_actions as usize + 1];
    let mut cache = BatchCache::new();
    let mut grad = vec![0.0f32; shape.param_count()];
    let mut log: Vec<LogRow> = Vec::new();
    let mut window: Vec<Finished> = Vec::new();
    let (mut env_steps, mut episodes) = (0u64, 0u64);
    if let Some(dir) = &opts.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    }
    let bar = progress_bar(opts.progress, hp.updates);
    let mut csv = String::from(CSV_HEADER);
    let mut done_updates = 0;
    for update in 1..=hp.updates {
        if let Some(m) = opts.minutes {
            if t0.elapsed().as_secs_f64() > m * 60.0 {
                break;
            }
        }
        let imitation = update <= hp.imitation_updates;
        let critic_only = !imitation && update <= hp.imitation_updates + hp.critic_warmup_updates;
        adam.lr = if imitation {
            hp.imitation_learning_rate
        } else {
            hp.a2c_learning_rate(update)
        };
        // 1. Collect a segment from every environment.
        for t in 0..t_len {
            let rows = t * e..(t + 1) * e;
            beliefs[rows.start * bl..rows.end * bl]
                .par_chunks_mut(bl)
                .zip(sides[rows.start * sl..rows.end * sl].par_chunks_mut(sl))
                .zip(envs.par_iter())
                .for_each(|((b, s), env)| masked_features(&env.runner.input(), hp.inputs, b, s));
            let (logits, v) = net.forward_batch(
                &beliefs[rows.start * bl..rows.end * bl],
                &sides[rows.start * sl..rows.end * sl],
                e,
                &mut cache,
            );
            values[rows.clone()].copy_from_slice(&v);
            for (i, env) in envs.iter_mut().enumerate() {
                actions[rows.start + i] = if imitation {
                    let input = env.runner.input();
                    action_index(env.teacher.act(&input))
                } else {
                    env.sample(&logits[i])
                };
            }
            let bonuses: Vec<f32> = envs
                .iter()
                .map(|env| bonus(hp, &visits, env.runner.state().actions as usize))
                .collect();
            let results: Vec<(f32, Option<Finished>)> = envs
                .par_iter_mut()
                .enumerate()
                .map(|(i, env)| env.step(hp, ACTIONS[actions[rows.start + i]], bonuses[i]))
                .collect();
            for (i, (r, fin)) in results.into_iter().enumerate() {
                rewards[rows.start + i] = r;
                dones[rows.start + i] = fin.is_some();
                if let Some(f) = fin {
                    window.push(f);
                    episodes += 1;
                }
            }
            for env in &envs {
                // The step index each environment is about to take (visit counts).
                let k = (env.runner.state().actions as usize).min(visits.len() - 1);
                visits[k] += 1;
            }
            env_steps += e as u64;
        }
        // 2. Bootstrap values of the states after the segment, then GAE (eq. 4).
        let mut next_b = vec![0.0f32; e * bl];
        let mut next_s = vec![0.0f32; e * sl];
        next_b
            .par_chunks_mut(bl)
            .zip(next_s.par_chunks_mut(sl))
            .zip(envs.par_iter())
            .for_each(|((b, s), env)| masked_features(&env.runner.input(), hp.inputs, b, s));
        let (_, next_v) = net.forward_batch(&next_b, &next_s, e, &mut cache);
        let (advantages, returns) = gae(
            &rewards,
            &values,
            &dones,
            &next_v,
            e,
            t_len,
            hp.gamma,
            hp.gae_lambda,
        );
        // 3. Gradient steps on the whole segment: one (A2C), or --update-epochs (PPO's
        //    clipped ratio); the log reports the first step's entropy and value loss.
        let mut adv = advantages.clone();
        if hp.norm_adv && !imitation {
            normalise(&mut adv);
        }
        let epochs = if imitation || critic_only {
            1
        } else {
            hp.update_epochs
        };
        let mut old_logp = vec![0.0f32; n];
        let (mut entropy_sum, mut vloss_sum) = (0.0f64, 0.0f64);
        let mut grad_norm = 0.0f32;
        for epoch in 0..epochs {
            let (logits, v) = net.forward_batch(&beliefs, &sides, n, &mut cache);
            let mut dlogits = vec![0.0f32; n * 3];
            let mut dvalues = vec![0.0f32; n];
            let inv_n = 1.0 / n as f32;
            for i in 0..n {
                let p = net::softmax(&logits[i]);
                let logp = net::log_softmax(&logits[i]);
                let h: f32 = -(0..3).map(|j| p[j] * logp[j]).sum::<f32>();
                let a = actions[i];
                if epoch == 0 {
                    entropy_sum += h as f64;
                    old_logp[i] = logp[a];
                }
                // Policy term: imitation = cross-entropy to the teacher's action (weight 1);
                // A2C = −A·log π(a|s) (eq. 2). Both have gradient w·(π − onehot(a)). PPO's
                // −min(r·A, clip(r)·A), r = π(a|s)/π_old(a|s), has w = r·A where the ratio is
                // inside the clip or on the advantage's losing side, and 0 where it is clipped
                // (r = 1 exactly on the first step: that step is A2C's).
                let w = if imitation {
                    1.0
                } else {
                    clipped_ratio_weight(adv[i], logp[a] - old_logp[i], hp.clip_coef)
                };
                for j in 0..3 {
                    let onehot = if j == a { 1.0 } else { 0.0 };
                    // Entropy bonus: d(−c·H)/dz_j = c·π_j·(log π_j + H).
                    let dent = hp.ent_coef * p[j] * (logp[j] + h);
                    // The critic's warm-up moves the value head (and the shared trunk) only.
                    dlogits[i * 3 + j] = if critic_only {
                        0.0
                    } else {
                        (w * (p[j] - onehot) + dent) * inv_n
                    };
                }
                let dv = v[i] - returns[i];
                if epoch == 0 {
                    vloss_sum += 0.5 * (dv as f64) * (dv as f64);
                }
                dvalues[i] = hp.vf_coef * dv * inv_n;
            }
            grad.iter_mut().for_each(|g| *g = 0.0);
            net.backward_batch(&mut cache, &dlogits, &dvalues, &mut grad);
            grad_norm = net::clip_global_norm(&mut grad, hp.max_grad_norm);
            adam.step(&mut net.params, &grad);
        }
        done_updates = update;
        bar.inc(1);
        // 4. Log and checkpoint.
        if update % hp.log_every == 0 || update == hp.updates {
            let wall = t0.elapsed().as_secs_f64();
            let row = summarise(
                &window,
                update,
                env_steps,
                episodes,
                wall,
                if imitation {
                    "imitation"
                } else if critic_only {
                    "critic"
                } else {
                    "a2c"
                },
                entropy_sum / n as f64,
                vloss_sum / n as f64,
                grad_norm as f64,
            );
            bar.set_message(format!(
                "{} eps ({:.0} eps/s, {:.0} steps/s), return {:+.3}, recognition {:.3}, cost {:.3}, entropy {:.3}",
                row.episodes,
                row.episodes as f64 / wall.max(1e-9),
                row.steps_per_s,
                row.mean_return,
                row.recognition,
                row.cost,
                row.policy_entropy
            ));
            if !opts.progress {
                eprintln!("{}", row_line(&row));
            }
            csv.push_str(&csv_line(&row));
            log.push(row);
            window.clear();
            if let Some(dir) = &opts.out {
                std::fs::write(dir.join("log.csv"), &csv)
                    .with_context(|| format!("cannot write {}", dir.display()))?;
            }
        }
        if let Some(dir) = &opts.out {
            if update % hp.checkpoint_every == 0 {
                let meta = metadata(hp, opts, update, env_steps, t0.elapsed().as_secs_f64());
                file::save(dir.join("checkpoint.policy"), &net, &meta)?;
            }
        }
    }
    bar.finish_and_clear();
    let wall_s = t0.elapsed().as_secs_f64();
    if let Some(dir) = &opts.out {
        let meta = metadata(hp, opts, done_updates, env_steps, wall_s);
        file::save(dir.join("policy.policy"), &net, &meta)?;
        std::fs::write(
            dir.join("log.json"),
            serde_json::to_string_pretty(&log).context("serialising the log")?,
        )?;
        std::fs::write(dir.join("curve.svg"), curve_svg(&log, hp))?;
    }
    Ok(TrainOutcome {
        net,
        log,
        wall_s,
        updates: done_updates,
    })
}

/// The weight `w` of one sample's policy gradient `w·(π − onehot(a))` under PPO's clipped
/// surrogate `−min(r·A, clip(r, 1 − c, 1 + c)·A)`, `r = exp(log_ratio)`: `r·A`, or 0 where
/// the clip holds the surrogate constant (the ratio already moved past the clip in the
/// advantage's favour). At `log_ratio = 0` it is `A`, A2C's weight, bit for bit.
pub fn clipped_ratio_weight(advantage: f32, log_ratio: f32, clip: f32) -> f32 {
    let r = log_ratio.exp();
    let clipped = (advantage > 0.0 && r > 1.0 + clip) || (advantage < 0.0 && r < 1.0 - clip);
    if clipped {
        0.0
    } else {
        r * advantage
    }
}

/// The policy file's metadata: everything needed to reproduce and judge the run.
fn metadata(
    hp: &HyperParams,
    opts: &RunOptions,
    updates: u64,
    env_steps: u64,
    wall_s: f64,
) -> serde_json::Value {
    serde_json::json!({
        "command": opts.command,
        "hyper_params": hp,
        "updates_done": updates,
        "env_steps": env_steps,
        "wall_s": wall_s,
        "threads": rayon::current_num_threads(),
        "architecture": net::ARCH_NAME,
    })
}

/// Generalised advantage estimation (eq. 4) over a `[t][env]` segment; `dones[i]` marks
/// a step that ended its episode (no bootstrap across it).
#[allow(clippy::too_many_arguments)]
pub fn gae(
    rewards: &[f32],
    values: &[f32],
    dones: &[bool],
    next_values: &[f32],
    envs: usize,
    t_len: usize,
    gamma: f32,
    lambda: f32,
) -> (Vec<f32>, Vec<f32>) {
    let mut adv = vec![0.0f32; rewards.len()];
    for e in 0..envs {
        let mut last = 0.0f32;
        for t in (0..t_len).rev() {
            let i = t * envs + e;
            let next_v = if t + 1 < t_len {
                values[(t + 1) * envs + e]
            } else {
                next_values[e]
            };
            let live = if dones[i] { 0.0 } else { 1.0 };
            let delta = rewards[i] + gamma * next_v * live - values[i];
            last = delta + gamma * lambda * live * last;
            adv[i] = last;
        }
    }
    let returns = adv.iter().zip(values).map(|(a, v)| a + v).collect();
    (adv, returns)
}

fn normalise(x: &mut [f32]) {
    let n = x.len().max(1) as f32;
    let mean = x.iter().sum::<f32>() / n;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n;
    let sd = var.sqrt() + 1e-8;
    x.iter_mut().for_each(|v| *v = (*v - mean) / sd);
}

#[allow(clippy::too_many_arguments)]
fn summarise(
    w: &[Finished],
    update: u64,
    env_steps: u64,
    episodes: u64,
    wall_s: f64,
    phase: &str,
    policy_entropy: f64,
    value_loss: f64,
    grad_norm: f64,
) -> LogRow {
    let k = w.len().max(1) as f64;
    let mean = |f: &dyn Fn(&Finished) -> f64| w.iter().map(f).sum::<f64>() / k;
    let errs: Vec<f64> = w
        .iter()
        .filter_map(|f| f.pose_error.map(f64::from))
        .collect();
    LogRow {
        update,
        env_steps,
        episodes,
        wall_s,
        phase: phase.to_string(),
        mean_return: mean(&|f| f.ret as f64),
        recognition: mean(&|f| f.success as u8 as f64),
        measurements: mean(&|f| f.measurements as f64),
        rotations: mean(&|f| f.rotations as f64),
        cost: mean(&|f| f.cost as f64),
        pose_error: (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64),
        policy_entropy,
        value_loss,
        grad_norm,
        steps_per_s: env_steps as f64 / wall_s.max(1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use activesense_core::policy::PolicyInput;
    use activesense_instrument::episode::run_episode_with;
    use activesense_instrument::learn::agent::features;

    fn tiny(rot_bins: u8, updates: u64, imitation: u64) -> HyperParams {
        HyperParams {
            num_envs: 8,
            segment_len: 8,
            updates,
            imitation_updates: imitation,
            log_every: updates.max(1),
            checkpoint_every: u64::MAX,
            ..HyperParams::defaults(rot_bins)
        }
    }

    /// Records the network inputs a policy is shown, while a teacher acts.
    struct Recorder {
        teacher: BaselineAgent,
        seen: Vec<(Vec<f32>, Vec<f32>)>,
    }

    impl Policy for Recorder {
        fn act(&mut self, input: &PolicyInput<'_>) -> Action {
            let mut b = vec![0.0; input.belief_len()];
            let mut s = vec![0.0; SIDE_FEATURES];
            features(input, &mut b, &mut s);
            self.seen.push((b, s));
            self.teacher.act(input)
        }
    }

    #[test]
    fn trainer_sees_the_features_the_episode_runner_builds() {
        // The same episode played by the evaluation's runner and by a training environment:
        // the inputs handed to the network are bit-identical at every step.
        for rot_bins in [1, 10] {
            let hp = tiny(rot_bins, 1, 1);
            let mut rng = Pcg64::seed_from_u64(5);
            let spec = Env::draw(&hp, &mut rng);
            let mut rec = Recorder {
                teacher: BaselineAgent::new(AgentKind::Heuristic1, spec.agent_seed()),
                seen: Vec::new(),
            };
            let t = run_episode_with(&spec, &mut rec);
            let mut env = Env::with_spec(&hp, &spec, rng);
            let (bl, sl) = (rot_bins as usize * BELIEF_PLANE, SIDE_FEATURES);
            for (k, (b, s)) in rec.seen.iter().enumerate() {
                let (mut b2, mut s2) = (vec![0.0; bl], vec![0.0; sl]);
                features(&env.runner.input(), &mut b2, &mut s2);
                assert!(b
                    .iter()
                    .map(|v| v.to_bits())
                    .eq(b2.iter().map(|v| v.to_bits())));
                assert!(s
                    .iter()
                    .map(|v| v.to_bits())
                    .eq(s2.iter().map(|v| v.to_bits())));
                let a = env.teacher.act(&env.runner.input());
                assert_eq!(a, t.steps[k].action, "step {k}");
                let (_, fin) = env.step(&hp, a, 0.0);
                assert_eq!(
                    fin.is_some(),
                    k + 1 == rec.seen.len(),
                    "episode ends together"
                );
            }
            assert!(rec.seen.len() > 3);
        }
    }

    #[test]
    fn same_seed_same_weights_whatever_the_threads() {
        let hp = tiny(10, 3, 1);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| train(&hp, &RunOptions::default()).unwrap().net.params)
        };
        let a = run(1);
        let b = run(2);
        assert!(a
            .iter()
            .map(|v| v.to_bits())
            .eq(b.iter().map(|v| v.to_bits())));
        let other = train(
            &HyperParams {
                seed: 2,
                ..hp.clone()
            },
            &RunOptions::default(),
        )
        .unwrap()
        .net
        .params;
        assert_ne!(a, other);
    }

    /// Mean return of `net` (greedy) over a few fixed training-range episodes.
    fn greedy_return(hp: &HyperParams, net: &PolicyNet) -> f32 {
        let mut total = 0.0;
        let n = 12;
        for i in 0..n {
            let mut env = Env::new(hp, 1000 + i);
            let mut agent = activesense_instrument::learn::agent::LearntAgent::new(
                std::sync::Arc::new(net.clone()),
            );
            loop {
                let a = env.runner.decide(&mut agent).expect("running");
                if let (_, Some(f)) = env.step(hp, a, 0.0) {
                    total += f.ret;
                    break;
                }
            }
        }
        total / n as f32
    }

    /// Trains `hp` (K = 1, 220 updates, 200 of them imitating heuristic-1) from its fixed seed
    /// and checks that it beats the untrained network's return on fixed episodes, which end
    /// by `hp.termination` as the training episodes do.
    fn short_run_raises_the_return(termination: activesense_core::episode::Termination) {
        let hp = HyperParams {
            num_envs: 16,
            segment_len: 16,
            termination,
            ..tiny(1, 220, 200)
        };
        let untrained = PolicyNet::new(shape_for(1), hp.seed);
        let before = greedy_return(&hp, &untrained);
        let out = train(&hp, &RunOptions::default()).unwrap();
        let after = greedy_return(&hp, &out.net);
        assert!(
            after > before + 0.5,
            "{} return before {before:.3}, after {after:.3}",
            termination.name()
        );
        assert_eq!(out.updates, 220);
        assert!(!out.log.is_empty());
    }

    #[test]
    fn the_critic_warm_up_leaves_the_actor_head_alone() {
        // Three updates that train only the critic: the actor's own layer keeps its
        // weights bit for bit, while the critic's moves; the log names the phase.
        let hp = HyperParams {
            critic_warmup_updates: 3,
            ..tiny(1, 3, 0)
        };
        let start = PolicyNet::new(shape_for(1), hp.seed);
        let out = train(
            &hp,
            &RunOptions {
                init: Some(start.clone()),
                ..RunOptions::default()
            },
        )
        .unwrap();
        let layer = |name: &str| {
            let l = start
                .shape
                .layers()
                .into_iter()
                .find(|l| l.name == name)
                .unwrap();
            l.offset..l.offset + l.len()
        };
        assert_eq!(out.net.params[layer("actor")], start.params[layer("actor")]);
        assert_ne!(
            out.net.params[layer("critic")],
            start.params[layer("critic")]
        );
        assert!(out.log.iter().all(|r| r.phase == "critic"));
    }

    #[test]
    fn update_epochs_reach_only_the_a2c_phase() {
        // Imitation alone: the same weights whatever --update-epochs says; with A2C updates
        // the extra clipped steps move them.
        let run = |updates, epochs| {
            let hp = HyperParams {
                update_epochs: epochs,
                ..tiny(1, updates, 2)
            };
            train(&hp, &RunOptions::default()).unwrap().net.params
        };
        assert_eq!(run(2, 1), run(2, 4));
        assert_ne!(run(4, 1), run(4, 4));
    }

    #[test]
    fn smoke_training_raises_the_return() {
        // The CI's short training run, with the paper's oracle stop.
        short_run_raises_the_return(activesense_core::episode::Termination::Oracle);
    }

    #[test]
    fn confident_training_raises_the_no_oracle_return() {
        // The no-oracle episode: the calibrated stop ends it, right answers earn +1 and
        // wrong ones −W.
        short_run_raises_the_return(activesense_core::episode::Termination::Confident);
    }

    #[test]
    fn the_clipped_ratio_weight_is_ppo_s_surrogate_gradient() {
        // First step: A2C's weight, exactly.
        assert_eq!(clipped_ratio_weight(0.7, 0.0, 0.2), 0.7);
        assert_eq!(clipped_ratio_weight(-1.3, 0.0, 0.2), -1.3);
        // Inside the clip: r·A (r = 1.1).
        let w = clipped_ratio_weight(2.0, 1.1f32.ln(), 0.2);
        assert!((w - 2.2).abs() < 1e-6, "{w}");
        // Past 1 + c with A > 0, and below 1 − c with A < 0: no gradient.
        assert_eq!(clipped_ratio_weight(2.0, 1.3f32.ln(), 0.2), 0.0);
        assert_eq!(clipped_ratio_weight(-2.0, 0.7f32.ln(), 0.2), 0.0);
        // Past the clip on the losing side the gradient stays (min picks the unclipped term).
        let w = clipped_ratio_weight(-2.0, 1.3f32.ln(), 0.2);
        assert!((w + 2.6).abs() < 1e-6, "{w}");
        let w = clipped_ratio_weight(2.0, 0.7f32.ln(), 0.2);
        assert!((w - 1.4).abs() < 1e-6, "{w}");
    }

    #[test]
    fn gae_matches_a_hand_computed_case() {
        // One environment, three steps, the second ends its episode.
        let (adv, ret) = gae(
            &[1.0, 2.0, 3.0],
            &[0.5, 0.25, 1.0],
            &[false, true, false],
            &[2.0],
            1,
            3,
            0.9,
            0.5,
        );
        let d2 = 3.0 + 0.9 * 2.0 - 1.0;
        let d1 = 2.0 - 0.25;
        let d0 = 1.0 + 0.9 * 0.25 - 0.5;
        let want = [d0 + 0.45 * d1, d1, d2];
        for i in 0..3 {
            assert!((adv[i] - want[i]).abs() < 1e-6, "{adv:?} vs {want:?}");
        }
        assert!((ret[0] - (want[0] + 0.5)).abs() < 1e-6);
    }

    #[test]
    fn reward_terms_follow_the_paper() {
        let hp = HyperParams::defaults(1);
        assert!((step_reward(Action::Measure, 0.0) + 0.05).abs() < 1e-7);
        assert!((step_reward(Action::RotateLeft, 0.0) + 0.005).abs() < 1e-7);
        assert_eq!(final_reward(&hp, Ending::Right, Some(0.0)), 2.0);
        assert_eq!(final_reward(&hp, Ending::Right, Some(0.5)), 1.0);
        assert!((final_reward(&hp, Ending::Right, Some(0.05)) - 1.75).abs() < 1e-6);
        assert_eq!(final_reward(&hp, Ending::Limit, None), -1.0);
        assert_eq!(final_reward(&hp, Ending::Wrong, Some(0.5)), -2.0);
        // The gross-registration penalty: nothing within the clip, half of it at 1.5 × the
        // clip, all of it from twice the clip on.
        let penalised = HyperParams {
            registration_penalty: 0.5,
            ..hp.clone()
        };
        assert!((final_reward(&penalised, Ending::Right, Some(0.05)) - 1.75).abs() < 1e-6);
        assert!((final_reward(&penalised, Ending::Right, Some(0.15)) - 0.75).abs() < 1e-6);
        assert!((final_reward(&penalised, Ending::Right, Some(0.5)) - 0.5).abs() < 1e-6);
        let visits = [0u64, 1000, 3000];
        assert!((bonus(&hp, &visits, 0) - hp.exploration_bonus).abs() < 1e-9);
        assert!((bonus(&hp, &visits, 1) - hp.exploration_bonus / 2.0).abs() < 1e-9);
        assert!(bonus(&hp, &visits, 2) < bonus(&hp, &visits, 1));
    }
}
