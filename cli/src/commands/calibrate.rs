//! `activesense calibrate`: the options of the stop's calibration, parsed and checked; the
//! fit itself is `activesense_lab::calibrate`.

use super::options::{parse_agent, EpisodeOptions};
use activesense_core::episode::{InstrumentProfile, Termination};
use activesense_core::stop::AGENT_TABLES;
use activesense_instrument::world::plans;
use activesense_lab::calibrate::{calibrate, CalibrateOptions};
use clap::Args;
use std::path::PathBuf;

/// `activesense calibrate` arguments.
#[derive(Args, Debug)]
#[command(mut_arg("termination", |a| a.default_value("action-limit")))]
pub struct CalibrateArgs {
    /// Agents whose episodes provide the samples (comma-separated; the learnt agent uses the
    /// committed policies).
    #[arg(long, default_value = "heuristic-1,learnt,blind-0,heuristic-0,oigm")]
    pub agents: String,
    /// Calibration plans per agent and setting (even-indexed ones fit, odd-indexed ones check).
    #[arg(long, default_value_t = 1000)]
    pub plans: u32,
    /// First calibration plan seed (default: the calibration range, which the training,
    /// test and validation sets never draw from).
    #[arg(long, default_value_t = plans::CALIBRATION_SEEDS.start)]
    pub first_seed: u32,
    /// How the calibration episodes are played: one model per rotation setting (default:
    /// 1,10), run to the action limit.
    #[command(flatten)]
    pub episode: EpisodeOptions,
    /// Agents whose fitting episodes set the threshold table (the stated risk → threshold
    /// map, `StopModel::thresholds`; default: every agent of --agents). Each must be among
    /// --agents. Pooled by default: the table must not depend on a policy trained against
    /// the stop it belongs to (`docs/LEARNING.md`), and one agent's 500 fitting episodes
    /// leave its rare wrong stops too few to place a threshold by.
    #[arg(long)]
    pub threshold_agents: Option<String>,
    /// Agents that also get a threshold table of their own (`StopModel::agent_tables`, at
    /// most 2; the agents an instrument runs; "none" for none). Each must be among
    /// --agents; the learnt policy's table serves learnt-int8 too.
    #[arg(long, default_value = "learnt,heuristic-1")]
    pub agent_tables: String,
    /// Calibration plans per setting for the agents of --agent-tables (at least --plans;
    /// the first --plans are the pooled fit's episodes, the rest run for the table alone).
    /// One agent's 500 fitting episodes hold about five wrong stops at 1 %, too few to
    /// place its threshold by, and 4000 held about four at 0.1 % (`docs/EVALUATION.md`,
    /// "Twelve thousand episodes per table").
    #[arg(long, default_value_t = 12000)]
    pub agent_table_plans: u32,
    /// Ridge (L2) penalty on the weights.
    #[arg(long, default_value_t = 1e-3)]
    pub ridge: f64,
    /// Where to write the fitted models as Rust source (the file the core compiles; default:
    /// core-nostd/src/stop/calibration.rs, for --instrument edm calibration_edm.rs).
    #[arg(long)]
    pub rust_out: Option<PathBuf>,
    /// Directory of the report (calibration.md, calibration.json; default:
    /// results/calibration, for --instrument edm results/calibration/edm).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Also write every decision point (features, label, agent, K) as JSON lines to this file,
    /// the agent-table episodes too (`lab/examples/threshold_by_level.rs` reads them).
    #[arg(long)]
    pub samples_out: Option<PathBuf>,
    /// Do not draw a progress bar.
    #[arg(long)]
    pub no_progress: bool,
}

/// Runs `activesense calibrate`.
pub fn cmd_calibrate(a: CalibrateArgs) -> anyhow::Result<()> {
    let agents = a
        .agents
        .split(',')
        .map(|s| parse_agent(s.trim()).map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<Vec<_>>>()?;
    a.episode
        .require_termination("calibrate", &[Termination::ActionLimit])?;
    let rot_bins = a.episode.rot_bins_or(&[1, 10])?;
    let threshold_agents = a
        .threshold_agents
        .as_deref()
        .unwrap_or(&a.agents)
        .split(',')
        .map(|s| parse_agent(s.trim()).map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<Vec<_>>>()?;
    if let Some(k) = threshold_agents.iter().find(|k| !agents.contains(k)) {
        anyhow::bail!("--threshold-agents: {k:?} is not among --agents");
    }
    let table_agents = match a.agent_tables.trim() {
        "" | "none" => Vec::new(),
        list => list
            .split(',')
            .map(|s| parse_agent(s.trim()).map_err(anyhow::Error::msg))
            .collect::<anyhow::Result<Vec<_>>>()?,
    };
    if let Some(k) = table_agents.iter().find(|k| !agents.contains(k)) {
        anyhow::bail!("--agent-tables: {k:?} is not among --agents");
    }
    if table_agents.len() > AGENT_TABLES {
        anyhow::bail!("--agent-tables: at most {AGENT_TABLES} agents have a table of their own");
    }
    if a.plans < 2 {
        anyhow::bail!("--plans must be at least 2 (half fit, half check)");
    }
    if a.agent_table_plans < a.plans {
        anyhow::bail!(
            "--agent-table-plans ({}) must be at least --plans ({})",
            a.agent_table_plans,
            a.plans
        );
    }
    let instrument = a.episode.instrument.instrument;
    // The command recorded in the generated source, less `--samples-out FILE`: it writes
    // the decision points beside the fit and changes nothing in it, so a calibration run
    // for its samples writes the same source as `cargo xtask reproduce`.
    let mut args = std::env::args().skip(1);
    let mut recorded = vec!["activesense".to_string()];
    while let Some(arg) = args.next() {
        if arg == "--samples-out" {
            args.next();
        } else if !arg.starts_with("--samples-out=") {
            recorded.push(arg);
        }
    }
    let command = recorded.join(" ");
    let opts = CalibrateOptions {
        agents,
        rot_bins,
        threshold_agents,
        table_agents,
        plans: a.plans,
        first_seed: a.first_seed,
        episode_seed: a.episode.episode_seed,
        config: a.episode.config(),
        site: a.episode.site,
        agent_table_plans: a.agent_table_plans,
        ridge: a.ridge,
        rust_out: a.rust_out.unwrap_or_else(|| match instrument {
            InstrumentProfile::EdmScan => "core-nostd/src/stop/calibration.rs".into(),
            InstrumentProfile::Edm => "core-nostd/src/stop/calibration_edm.rs".into(),
        }),
        out: a.out.unwrap_or_else(|| match instrument {
            InstrumentProfile::EdmScan => "results/calibration".into(),
            InstrumentProfile::Edm => "results/calibration/edm".into(),
        }),
        threads: a.threads,
        samples_out: a.samples_out,
        progress: !a.no_progress,
    };
    calibrate(&opts, &command)
}
