//! `activesense answer-coverage`: how honest the answer's printed precision is, and how
//! often answers are ambiguous ([`activesense_lab::coverage`]), on generated plans or the
//! user's rooms; prints one markdown row per rotation setting.

use super::options::{parse_agent, EpisodeOptions};
use activesense_core::episode::AgentKind;
use activesense_instrument::world::planfile::{self, PlanReadArgs};
use activesense_instrument::world::plans::{TEST_SEEDS, TRAIN_SEEDS};
use activesense_lab::coverage::{coverage, CoverageReport, CoverageRun};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct AnswerCoverageArgs {
    /// Generated plans to run (one episode each).
    #[arg(long, default_value_t = 200)]
    plans: u32,
    /// Take the plans from the training seeds instead of the test seeds (what the
    /// precision's noise factor was chosen on).
    #[arg(long)]
    train: bool,
    /// Run in these rooms instead (files or directories, as `eval --plans-from`).
    #[arg(long, num_args = 1..)]
    plans_from: Vec<PathBuf>,
    #[command(flatten)]
    read: PlanReadArgs,
    /// Episodes per room with --plans-from.
    #[arg(long, default_value_t = 20)]
    episodes: u32,
    /// The agent.
    #[arg(long, value_parser = parse_agent, default_value = "heuristic-1")]
    agent: AgentKind,
    /// How the episodes are played (default: K = 1 and 10).
    #[command(flatten)]
    episode: EpisodeOptions,
    /// Give every episode a heading hint of its true heading plus OFFSET, ± TOL degrees
    /// ("OFFSET,TOL", e.g. "5,20"), to measure the tie-break.
    #[arg(long, value_parser = parse_offset_tol, allow_hyphen_values = true)]
    hint_offset_tol: Option<(f64, f64)>,
}

/// Parses `OFFSET,TOL` (degrees).
fn parse_offset_tol(s: &str) -> Result<(f64, f64), String> {
    let bad = || format!("'{s}' is not OFFSET,TOL (two numbers of degrees, e.g. 10,30)");
    let (o, t) = s.split_once(',').ok_or_else(bad)?;
    let o: f64 = o.trim().parse().map_err(|_| bad())?;
    let t: f64 = t.trim().parse().map_err(|_| bad())?;
    if o.is_finite() && t.is_finite() && t >= 0.0 {
        Ok((o, t))
    } else {
        Err(bad())
    }
}

/// Runs and prints the table.
pub fn run(a: AnswerCoverageArgs) -> Result<()> {
    let rooms = planfile::rooms_for_command(None, &a.plans_from, &a.read)?
        .map(|(r, _)| r)
        .unwrap_or_default();
    let first = if a.train {
        TRAIN_SEEDS.start
    } else {
        TEST_SEEDS.start
    };
    println!(
        "answer coverage: agent {}, termination {}, {}",
        a.agent.name(),
        a.episode.termination.name(),
        if rooms.is_empty() {
            format!(
                "{} {} plans from seed {first}",
                a.plans,
                if a.train { "training" } else { "test" }
            )
        } else {
            format!("{} room(s), {} episodes each", rooms.len(), a.episodes)
        }
    );
    println!("{}", CoverageReport::header());
    for k in a.episode.rot_bins_or(&[1, 10])? {
        let r = coverage(&CoverageRun {
            seeds: first..first.saturating_add(a.plans),
            rooms: rooms.clone(),
            episodes: a.episodes,
            rot_bins: k,
            agent: a.agent,
            termination: a.episode.termination,
            config: a.episode.config(),
            site: a.episode.site,
            episode_seed: a.episode.episode_seed,
            hint: a.hint_offset_tol,
        });
        println!("{}", r.row());
    }
    Ok(())
}
