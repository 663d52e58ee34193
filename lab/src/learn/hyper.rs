//! The trainer's hyper-parameters, defined once (CleanRL's one-dataclass habit): every
//! field of [`HyperParams`] carries its default here, as a clap attribute. The fields a user
//! may set are `activesense train` flags (the command flattens this struct, so the flag, its
//! help text and its default are these lines); the rest are `skip` fields, fixed at the
//! value written next to them. [`HyperParams::defaults`] parses an empty command line, so
//! the code and the CLI cannot disagree. A run prints the set ([`HyperParams::table`]) and
//! stores it in the policy file's metadata (`hyper_params`).

use activesense_core::episode::{AgentKind, InstrumentProfile, Termination};
use activesense_instrument::learn::agent::InputMask;
use activesense_instrument::world::site::SiteLevel;
use clap::{Args, FromArgMatches};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Every hyper-parameter of a training run. The flags are `activesense train`'s
/// (doc comment = help text); the others are fixed.
#[derive(Args, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HyperParams {
    /// Rotation bins of the localizer: 1 = heading known, 10 = heading unknown (set from
    /// the command's episode options, `--rot-bins`).
    #[arg(skip = 1u8)]
    pub rot_bins: u8,
    /// Number of updates (each: --envs environments × --segment steps, one gradient step).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub updates: u64,
    /// Master seed (network, rooms, noise, action draws).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Parallel environments.
    #[arg(long = "envs", value_name = "ENVS", default_value_t = 16,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1024))]
    pub num_envs: usize,
    /// Steps per environment per update (n-step segment).
    #[arg(long = "segment", value_name = "SEGMENT", default_value_t = 16,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=512))]
    pub segment_len: usize,
    /// Warm-start updates imitating the teacher (0 = pure A2C from scratch).
    #[arg(long, default_value_t = 200)]
    pub imitation_updates: u64,
    /// Updates after the imitation that train only the critic (the policy's gradient is
    /// zero; actions are still drawn from it): a fine-tune (`--init`) under another
    /// `--termination` starts with a critic that predicts the old episode's returns.
    #[arg(long, default_value_t = 0)]
    #[serde(default)]
    pub critic_warmup_updates: u64,
    /// Adam learning rate.
    #[arg(long = "lr", value_name = "LR", default_value_t = 3e-4)]
    pub learning_rate: f32,
    /// Anneal the A2C phase's learning rate linearly from --lr at its first update to
    /// --lr / (A2C updates) at the last (CleanRL's `anneal_lr`): the late updates refine
    /// instead of wandering.
    #[arg(long, default_value_t = false)]
    #[serde(default)]
    pub anneal_lr: bool,
    /// Gradient steps per A2C segment. 1 (the default) is A2C; more turns the update into
    /// PPO's: every step after the first re-weights each sample's policy gradient by
    /// π_new(a|s) / π_old(a|s) and drops it where that ratio left [1 − --clip-coef,
    /// 1 + --clip-coef] in the advantage's favour (CleanRL's `update_epochs`, whole segment
    /// per step). The imitation and critic warm-up phases always take one.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    #[serde(default = "one")]
    pub update_epochs: u64,
    /// PPO's clip on the probability ratio (used only with --update-epochs > 1: the first
    /// step's ratio is exactly 1).
    #[arg(long, default_value_t = 0.2)]
    #[serde(default = "default_clip_coef")]
    pub clip_coef: f32,
    /// Entropy bonus coefficient.
    #[arg(long, default_value_t = 0.01)]
    pub ent_coef: f32,
    /// Updates between log lines.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub log_every: u64,
    /// Inputs the network is shown: `full`, or the §4.4 ablations `no-scans` (topological
    /// scans zeroed) and `no-belief` (belief map zeroed: scans and history only).
    #[arg(long, default_value = "full", value_parser = parse_inputs)]
    #[serde(default)]
    pub inputs: InputMask,
    /// Scale of the clipped quadratic registration-error reward (0 = the §4.4 ablation
    /// without the final-registration-error term).
    #[arg(long, default_value_t = 1.0)]
    pub registration_reward: f32,
    /// Reward: −this × min((e − e_tol) / e_tol, 1) for a final registration error e beyond
    /// e_tol (0: the paper's clipped term alone). The clipped term says nothing about gross
    /// registrations, and they decide the mean pose error (`docs/LEARNING.md`, "A penalty
    /// for gross registrations").
    #[arg(long, default_value_t = 0.0, value_parser = parse_non_negative)]
    #[serde(default, skip_serializing_if = "is_zero")]
    pub registration_penalty: f32,
    /// What ends a training episode: `oracle` (the paper's: the first coarse success) or
    /// `confident` (the calibrated stop an instrument uses; the answer is then rewarded
    /// +1 when right within the surveyor's tolerance and −`--wrong-penalty` when wrong).
    /// Set from the command's episode options (`--termination`).
    #[arg(skip = Termination::Oracle)]
    #[serde(default = "oracle")]
    pub termination: Termination,
    /// The instrument the training episodes are played on: its stop's tables end a
    /// `confident` episode. Set from the command's episode options (`--instrument`).
    #[arg(skip = InstrumentProfile::EdmScan)]
    #[serde(default, skip_serializing_if = "InstrumentProfile::is_edm_scan")]
    pub instrument: InstrumentProfile,
    /// The room the EDM hits in the training episodes (`--site`; `mixed` randomises it per
    /// episode). Set from the command's episode options.
    #[arg(skip = SiteLevel::Plan)]
    #[serde(default, skip_serializing_if = "SiteLevel::is_plan")]
    pub site: SiteLevel,
    /// Reward: −this for a wrong answer under `--termination confident` (W of the
    /// right/wrong reward; the oracle stop never answers wrongly).
    #[arg(long, default_value_t = default_wrong_penalty())]
    #[serde(default = "default_wrong_penalty")]
    pub wrong_penalty: f32,

    // Fixed: not on the command line.
    /// Discount γ (eq. 1).
    #[arg(skip = 0.99)]
    pub gamma: f32,
    /// GAE λ (eq. 4).
    #[arg(skip = 0.95)]
    pub gae_lambda: f32,
    /// Adam learning rate while imitating the teacher (`learning_rate` is the A2C phase's).
    #[arg(skip = 1e-3)]
    pub imitation_learning_rate: f32,
    /// Value loss coefficient.
    #[arg(skip = 0.5)]
    pub vf_coef: f32,
    /// Global gradient-norm clip.
    #[arg(skip = 0.5)]
    pub max_grad_norm: f32,
    /// Normalise advantages within each update.
    #[arg(skip = true)]
    pub norm_adv: bool,
    /// Action limit of a training episode.
    #[arg(skip = 100u16)]
    pub max_actions: u16,
    /// Reward: +this on coarse success.
    #[arg(skip = 1.0)]
    pub success_reward: f32,
    /// Reward: −this at the action limit.
    #[arg(skip = 1.0)]
    pub limit_penalty: f32,
    /// Reward: error e_tol (m) at which the registration term reaches 0.
    #[arg(skip = 0.10)]
    pub registration_tolerance: f32,
    /// Exploration bonus β per step (0 disables it).
    #[arg(skip = 0.002)]
    pub exploration_bonus: f32,
    /// Visits n₀ at which the bonus for a step index has halved.
    #[arg(skip = 1000.0)]
    pub exploration_half_visits: f32,
    /// The teacher (a Table-3 baseline).
    #[arg(skip = AgentKind::Heuristic1)]
    pub teacher: AgentKind,
    /// Updates between checkpoints.
    #[arg(skip = 100u64)]
    pub checkpoint_every: u64,
}

fn one() -> u64 {
    1
}

/// Leaves a switch that is off out of the policy file's metadata, so that the files of
/// commands without it stay as they were.
fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

fn default_clip_coef() -> f32 {
    0.2
}

fn oracle() -> Termination {
    Termination::Oracle
}

/// The `--wrong-penalty` default, also used for policy files written before the flag.
fn default_wrong_penalty() -> f32 {
    2.0
}

/// A reward weight: a finite number, not negative (a negative penalty would reward gross
/// registrations).
fn parse_non_negative(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(_) => Err(format!("'{s}' is not a finite number ≥ 0")),
        Err(e) => Err(format!("'{s}': {e}")),
    }
}

fn parse_inputs(s: &str) -> Result<InputMask, String> {
    InputMask::from_name(s)
        .ok_or_else(|| format!("unknown input set '{s}' (expected full, no-scans or no-belief)"))
}

impl HyperParams {
    /// The defaults the committed policies were trained with, K set by the caller: what
    /// `activesense train --rot-bins K` runs with (the K = 10 command adds `--lr 1e-4
    /// --update-epochs 4`).
    pub fn defaults(rot_bins: u8) -> Self {
        let cmd = Self::augment_args(clap::Command::new("hyper-params").no_binary_name(true));
        let m = cmd
            .try_get_matches_from(std::iter::empty::<&str>())
            .expect("the defaults parse");
        HyperParams {
            rot_bins,
            ..Self::from_arg_matches(&m).expect("the defaults parse")
        }
    }

    /// The Adam learning rate of A2C update `update` (1-based, counted with the imitation
    /// updates): `learning_rate`, or with `anneal_lr` its linear decay over the A2C updates.
    pub fn a2c_learning_rate(&self, update: u64) -> f32 {
        if !self.anneal_lr {
            return self.learning_rate;
        }
        let first = self.imitation_updates + 1;
        let total = self.updates.saturating_sub(first) + 1;
        let done = update.saturating_sub(first).min(total - 1);
        self.learning_rate * (total - done) as f32 / total as f32
    }

    /// One `name = value` line per hyper-parameter.
    pub fn table(&self) -> String {
        let v = serde_json::to_value(self).unwrap_or_default();
        let mut s = String::new();
        if let Some(map) = v.as_object() {
            for (k, v) in map {
                let _ = writeln!(s, "  {k:<24} = {v}");
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The values the committed policies were trained with, written out: a change to a
    /// default above must be a change to this test too.
    #[test]
    fn defaults_are_the_committed_policies() {
        let hp = HyperParams::defaults(10);
        let expected = HyperParams {
            rot_bins: 10,
            updates: 1000,
            seed: 1,
            num_envs: 16,
            segment_len: 16,
            imitation_updates: 200,
            critic_warmup_updates: 0,
            learning_rate: 3e-4,
            anneal_lr: false,
            update_epochs: 1,
            clip_coef: 0.2,
            ent_coef: 0.01,
            log_every: 10,
            inputs: InputMask::Full,
            registration_reward: 1.0,
            registration_penalty: 0.0,
            termination: Termination::Oracle,
            instrument: InstrumentProfile::EdmScan,
            site: SiteLevel::Plan,
            wrong_penalty: 2.0,
            gamma: 0.99,
            gae_lambda: 0.95,
            imitation_learning_rate: 1e-3,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            norm_adv: true,
            max_actions: 100,
            success_reward: 1.0,
            limit_penalty: 1.0,
            registration_tolerance: 0.10,
            exploration_bonus: 0.002,
            exploration_half_visits: 1000.0,
            teacher: AgentKind::Heuristic1,
            checkpoint_every: 100,
        };
        assert_eq!(hp, expected);
    }

    #[test]
    fn flags_override_and_fixed_fields_stay() {
        let cmd = HyperParams::augment_args(clap::Command::new("t").no_binary_name(true));
        let m = cmd
            .try_get_matches_from(["--envs", "4", "--lr", "1e-4"])
            .unwrap();
        let hp = HyperParams::from_arg_matches(&m).unwrap();
        assert_eq!(hp.num_envs, 4);
        assert_eq!(hp.learning_rate, 1e-4);
        assert_eq!(hp.gamma, 0.99);
        let cmd = HyperParams::augment_args(clap::Command::new("t").no_binary_name(true));
        assert!(cmd.try_get_matches_from(["--envs", "0"]).is_err());
        for bad in ["-0.5", "NaN", "inf", "half"] {
            let cmd = HyperParams::augment_args(clap::Command::new("t").no_binary_name(true));
            let flag = format!("--registration-penalty={bad}");
            let e = cmd.try_get_matches_from([flag.as_str()]).unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    /// The anneal starts at --lr on the first A2C update, ends at --lr / (A2C updates) on
    /// the last, and leaves the imitation phase and an un-annealed run alone.
    #[test]
    fn the_annealed_learning_rate_falls_linearly_over_the_a2c_updates() {
        let mut hp = HyperParams::defaults(1);
        hp.updates = 1200;
        hp.learning_rate = 1e-3;
        assert_eq!(hp.a2c_learning_rate(201), 1e-3);
        assert_eq!(hp.a2c_learning_rate(1200), 1e-3);
        hp.anneal_lr = true;
        assert_eq!(hp.a2c_learning_rate(201), 1e-3);
        assert!((hp.a2c_learning_rate(701) - 0.5e-3).abs() < 1e-9);
        assert!((hp.a2c_learning_rate(1200) - 1e-6).abs() < 1e-12);
    }
}
