//! `activesense inspect`: one trajectory's page, or (`--aggregate`) the Fig.-4 analysis over
//! many episodes (the tool itself is `activesense_lab::inspect`).

use super::options::{EpisodeOption, EpisodeOptions};
use activesense_instrument::learn::agent::LearntPolicy;
use activesense_lab::inspect::{aggregate, write_page};
use anyhow::{bail, Result};

/// `activesense inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Trajectory JSON written by `activesense episode --agent learnt --json FILE` (not with
    /// --aggregate).
    pub trajectory: Option<std::path::PathBuf>,
    /// The HTML page to write; with --aggregate, the output directory.
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Instead of one page: the Fig.-4 analysis over many test-plan episodes (mean
    /// normalised guided-back-propagation maps of measure and rotate decisions).
    #[arg(long)]
    pub aggregate: bool,
    /// Agent of the aggregate episodes (only the learnt float policy has maps).
    #[arg(long, value_parser = super::options::parse_agent, default_value = "learnt")]
    pub agent: activesense_core::episode::AgentKind,
    /// Test plans of the aggregate (seeds from 1000000 on).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub plans: u32,
    /// The aggregate's episodes: --rot-bins (default 1) and --episode-seed.
    #[command(flatten)]
    pub episode: EpisodeOptions,
    /// Float policy file for the aggregate (default: the committed policies/k{K}/policy.policy).
    #[arg(long)]
    pub policy: Option<std::path::PathBuf>,
    /// Do not draw a progress bar.
    #[arg(long)]
    pub no_progress: bool,
}

/// Runs `activesense inspect` (`command`: the command line, recorded in the aggregate).
pub fn cmd_inspect(a: InspectArgs, command: &str) -> Result<()> {
    use std::io::IsTerminal;
    if !a.aggregate {
        let Some(path) = &a.trajectory else {
            bail!("give a trajectory JSON (activesense episode --agent learnt --json FILE), or --aggregate");
        };
        write_page(path, &a.out)?;
        println!("wrote {}", a.out.display());
        return Ok(());
    }
    if let Some(p) = &a.trajectory {
        bail!(
            "--aggregate runs its own episodes; do not give a trajectory ('{}')",
            p.display()
        );
    }
    if a.agent != activesense_core::episode::AgentKind::Learnt {
        bail!(
            "--aggregate needs --agent learnt (only the float policy has guided back-propagation maps), got {}",
            a.agent.name()
        );
    }
    let rot_bins = a.episode.one_rot_bins(1)?;
    if a.episode.instrument.instrument != activesense_core::episode::InstrumentProfile::EdmScan {
        bail!("the Fig.-4 aggregate is the paper's analysis: --instrument edm+scan");
    }
    a.episode.refuse(
        "inspect --aggregate",
        &[
            EpisodeOption::MaxActions,
            EpisodeOption::StepsPerTurn,
            EpisodeOption::StopRisk,
            EpisodeOption::MinObservability,
            EpisodeOption::Termination,
        ],
        "the Fig.-4 aggregate plays the paper's evaluation episodes",
    )?;
    let path = a
        .policy
        .clone()
        .unwrap_or_else(|| activesense_instrument::learn::agent::default_policy_path(rot_bins));
    let policy = LearntPolicy::load(&path, rot_bins)?;
    let opts = aggregate::AggregateOptions {
        plans: a.plans,
        episode_seed: a.episode.episode_seed,
        rot_bins,
        progress: !a.no_progress && std::io::stderr().is_terminal(),
        ..Default::default()
    };
    aggregate::cmd(&opts, &policy, &a.out, command)
}
