//! `activesense train`: train the learnt sampling policy (advantage actor-critic, paper §3.1)
//! and write the policy file, its learning curve and logs.

use super::command_line;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct TrainArgs {
    /// Rotation bins of the localizer: 1 = heading known, 10 = heading unknown.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=10))]
    rot_bins: u8,
    /// Number of updates (each: --envs environments × --segment steps, one gradient step).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    updates: u64,
    /// Stop after this many minutes of wall time even if --updates is not reached (the
    /// result then depends on the machine's speed; --updates alone is reproducible).
    #[arg(long)]
    minutes: Option<f64>,
    /// Master seed (network, rooms, noise, action draws).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Parallel environments.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..=1024))]
    envs: u64,
    /// Steps per environment per update (n-step segment).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..=512))]
    segment: u64,
    /// Warm-start updates imitating the teacher (0 = pure A2C from scratch).
    #[arg(long, default_value_t = 200)]
    imitation_updates: u64,
    /// Adam learning rate.
    #[arg(long, default_value_t = 3e-4)]
    lr: f32,
    /// Entropy bonus coefficient.
    #[arg(long, default_value_t = 0.01)]
    ent_coef: f32,
    /// Start from this policy file instead of a fresh network (fine-tuning, resuming from
    /// DIR/checkpoint.policy).
    #[arg(long)]
    init: Option<PathBuf>,
    /// Worker threads (default: all cores). The weights do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Output directory: policy.policy, checkpoint.policy, log.csv, log.json, curve.svg.
    #[arg(long)]
    out: PathBuf,
    /// Print a log line per --log-every updates instead of a progress bar.
    #[arg(long)]
    no_progress: bool,
    /// Updates between log lines.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    log_every: u64,
    /// Inputs the network is shown: `full`, or the §4.4 ablations `no-scans` (topological
    /// scans zeroed) and `no-belief` (belief map zeroed: scans and history only).
    #[arg(long, default_value = "full", value_parser = parse_inputs)]
    inputs: crate::learn::agent::InputMask,
    /// Scale of the clipped quadratic registration-error reward (0 = the §4.4 ablation
    /// without the final-registration-error term).
    #[arg(long, default_value_t = 1.0)]
    registration_reward: f32,
}

fn parse_inputs(s: &str) -> Result<crate::learn::agent::InputMask, String> {
    crate::learn::agent::InputMask::from_name(s)
        .ok_or_else(|| format!("unknown input set '{s}' (expected full, no-scans or no-belief)"))
}

pub fn run(a: TrainArgs) -> Result<()> {
    use crate::learn::{agent::shape_for, file, train};
    use std::io::IsTerminal;
    if a.rot_bins != 1 && a.rot_bins != 10 {
        bail!(
            "--rot-bins must be 1 or 10 (the paper's two settings), got {}",
            a.rot_bins
        );
    }
    super::set_threads(a.threads)?;
    let mut hp = train::HyperParams::defaults(a.rot_bins);
    hp.seed = a.seed;
    hp.updates = a.updates;
    hp.num_envs = a.envs as usize;
    hp.segment_len = a.segment as usize;
    hp.imitation_updates = a.imitation_updates;
    hp.learning_rate = a.lr;
    hp.ent_coef = a.ent_coef;
    hp.log_every = a.log_every;
    hp.inputs = a.inputs;
    hp.registration_reward = a.registration_reward;
    let init = match &a.init {
        Some(p) => Some(file::load_expecting(p, a.rot_bins, shape_for(a.rot_bins).side)?.0),
        None => None,
    };
    let command = command_line();
    let shape = shape_for(a.rot_bins);
    eprintln!(
        "training K = {}: network {} ({} parameters, {} multiply-accumulates per decision), {} threads",
        a.rot_bins,
        crate::learn::net::ARCH_NAME,
        shape.param_count(),
        shape.macs(),
        rayon::current_num_threads()
    );
    eprintln!("hyper-parameters:\n{}", hp.table());
    let opts = train::RunOptions {
        out: Some(a.out.clone()),
        minutes: a.minutes,
        progress: !a.no_progress && std::io::stderr().is_terminal(),
        command,
        init,
    };
    let outcome = train::train(&hp, &opts)?;
    if let Some(last) = outcome.log.last() {
        println!(
            "trained {} updates ({} environment steps, {} episodes) in {:.1} min: last window return {:+.3}, recognition {:.3}, {:.2} measurements, {:.2} rotations, cost {:.3}",
            outcome.updates,
            last.env_steps,
            last.episodes,
            outcome.wall_s / 60.0,
            last.mean_return,
            last.recognition,
            last.measurements,
            last.rotations,
            last.cost
        );
    }
    for f in [
        "policy.policy",
        "checkpoint.policy",
        "log.csv",
        "log.json",
        "curve.svg",
    ] {
        let p = a.out.join(f);
        if p.exists() {
            println!("wrote {}", p.display());
        }
    }
    Ok(())
}
