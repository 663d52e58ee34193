//! `activesense train`: train the learnt sampling policy (advantage actor-critic, paper §3.1)
//! and write the policy file, its learning curve and logs.

use super::command_line;
use super::options::{EpisodeOption, EpisodeOptions};
use activesense_core::episode::{InstrumentProfile, Termination};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct TrainArgs {
    // Every hyper-parameter flag (--updates, --seed, --envs, ...): their defaults and help
    // are written once, in HyperParams.
    #[command(flatten)]
    hp: activesense_lab::learn::train::HyperParams,
    /// The training episodes: --rot-bins (required), --termination (oracle, the paper's, or
    /// confident: the calibrated stop an instrument uses; the answer is then rewarded +1
    /// when right within the surveyor's tolerance and −--wrong-penalty when wrong) and
    /// --max-actions.
    #[command(flatten)]
    episode: EpisodeOptions,
    /// Stop after this many minutes of wall time even if --updates is not reached (the
    /// result then depends on the machine's speed; --updates alone is reproducible).
    #[arg(long)]
    minutes: Option<f64>,
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
}

pub fn run(a: TrainArgs) -> Result<()> {
    use activesense_instrument::learn::{agent::shape_for, file};
    use activesense_lab::learn::train;
    use std::io::IsTerminal;
    if a.episode.rot_bins.rot_bins.is_empty() {
        bail!("give the rotation setting to train for: --rot-bins 1 or 10");
    }
    a.episode
        .require_termination("train", &[Termination::Oracle, Termination::Confident])?;
    a.episode.refuse(
        "train",
        &[
            EpisodeOption::EpisodeSeed,
            EpisodeOption::StepsPerTurn,
            EpisodeOption::StopRisk,
            EpisodeOption::MinObservability,
        ],
        "a training run draws its episodes from --seed and plays them on the evaluation's encoder grid with the default stop",
    )?;
    // An EDM-only instrument has no camera: its policy never sees a scan.
    if a.episode.instrument.instrument == InstrumentProfile::Edm
        && a.hp.inputs != activesense_instrument::learn::agent::InputMask::NoScans
    {
        bail!("--instrument edm has no camera: train its policy with --inputs no-scans");
    }
    super::set_threads(a.threads)?;
    let mut hp = a.hp;
    hp.rot_bins = a.episode.one_rot_bins(1)?;
    hp.termination = a.episode.termination;
    hp.instrument = a.episode.instrument.instrument;
    hp.site = a.episode.site;
    hp.max_actions = a.episode.max_actions;
    let init = match &a.init {
        Some(p) => Some(file::load_expecting(p, hp.rot_bins, shape_for(hp.rot_bins).side)?.0),
        None => None,
    };
    let command = command_line();
    let shape = shape_for(hp.rot_bins);
    eprintln!(
        "training K = {}: network {} ({} parameters, {} multiply-accumulates per decision), {} threads",
        hp.rot_bins,
        activesense_instrument::learn::net::ARCH_NAME,
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
