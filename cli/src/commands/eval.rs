//! `activesense eval`: evaluate agents on the test plans or the user's plans (the paper's
//! Table 4) and write results.json, results.md, timing.json and the charts; or, with
//! `--extra-measurements`, the pose error past the minimal set.

use super::command_line;
use super::options::{parse_agent, parse_stop_risk, parse_tolerance, EpisodeOptions, SensorArgs};
use activesense_core::episode::{AgentKind, InstrumentProfile};
use activesense_instrument::agents::Policies;
use activesense_instrument::world::planfile::{self, PlanReadArgs};
use activesense_instrument::world::plans;
use activesense_instrument::world::site::SiteLevel;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct EvalArgs {
    /// Comma-separated agent names (blind-0..2, heuristic-0..3, learnt, learnt-int8, and the
    /// greedy benchmarks oigm, oigm-cost, eem), or
    /// "all" for the learnt policy (float and int8) and the seven Table-3 baselines.
    #[arg(long, default_value = "all", value_parser = parse_agents)]
    agents: AgentList,
    /// Learnt policy file(s), each used for the K its header names (repeat for K = 1 and
    /// 10); default: the committed policies/k{K}/policy.policy.
    #[arg(long)]
    policy: Vec<PathBuf>,
    /// int8 policy blob(s) for learnt-int8, each used for the K its header names;
    /// default: the blobs built into the firmware (policies/k{K}/policy.q8).
    #[arg(long)]
    int8: Vec<PathBuf>,
    /// Number of test plans (generated; see --plan / --plans-from for your own).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(1..))]
    plans: u32,
    /// Evaluate in the room of this plan file instead of the test plans (JSON, GeoJSON or
    /// DXF; docs/PLANS.md).
    #[arg(long)]
    plan: Option<PathBuf>,
    /// Evaluate in every room of these plan files and directories (.json, .geojson, .dxf;
    /// refused files are listed and skipped).
    #[arg(long, num_args = 1..)]
    plans_from: Vec<PathBuf>,
    #[command(flatten)]
    read: PlanReadArgs,
    /// First plan seed (the test set is 1000000..1001000).
    #[arg(long, default_value_t = plans::TEST_SEEDS.start)]
    first_seed: u32,
    #[command(flatten)]
    episode: EpisodeOptions,
    #[command(flatten)]
    sensor: SensorArgs,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Do not draw a progress bar.
    #[arg(long)]
    no_progress: bool,
    /// The pose-error-vs-cost curve (utility-k{K}.svg) registers after every measurement of
    /// the first N plans (the entropy and recognition curves use all plans).
    #[arg(long, default_value_t = 200)]
    curve_plans: u32,
    /// Instead of Table 4: follow every episode past the point where the oracle rule would
    /// stop it for N more ranges, registering after each (writes extra.json, extra.md and
    /// extra.svg; episodes run to --max-actions, so give room, e.g. --max-actions 300).
    #[arg(long)]
    extra_measurements: Option<usize>,
    /// When an answer is right: position error in metres and heading error in degrees,
    /// modulo the room's symmetry (results.json `right`, `wrong_of_answered`; the
    /// no-oracle table).
    #[arg(long, default_value = "0.05,0.5", value_parser = parse_tolerance)]
    tolerance: activesense_core::registration::pose_distance::Tolerance,
    /// Also evaluate the same agents stopping by themselves (`--termination confident`)
    /// and write that run into OUT/no-oracle/: the table an instrument without an oracle
    /// lives by (README, "Without an oracle"); for the paper's sensor also the EDM-only
    /// instrument's (its policies and stop tables) into OUT/no-oracle-edm/, and that
    /// instrument's agents (learnt, learnt-int8, heuristic-1) in furnished rooms and on
    /// building sites (--site) into OUT/no-oracle-edm-furnished/ and OUT/no-oracle-edm-site/.
    #[arg(long)]
    with_no_oracle: bool,
    /// With --termination confident: run the evaluation once per stop risk (comma-separated,
    /// e.g. 0.001,0.003,0.01,0.03,0.1) and write the risk–cost frontier (frontier.md,
    /// frontier.json, frontier.svg) instead of Table 4.
    #[arg(long, value_delimiter = ',', value_parser = parse_stop_risk)]
    stop_risks: Vec<f32>,
}

#[derive(Clone)]
struct AgentList(Vec<AgentKind>);

fn parse_agents(s: &str) -> Result<AgentList, String> {
    if s == "all" {
        let mut all = AgentKind::ALL.to_vec();
        all.insert(0, AgentKind::LearntInt8);
        all.insert(0, AgentKind::Learnt);
        return Ok(AgentList(all));
    }
    let mut v = Vec::new();
    for name in s.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        let a = parse_agent(name)?;
        if !v.contains(&a) {
            v.push(a);
        }
    }
    if v.is_empty() {
        return Err("no agent given".into());
    }
    Ok(AgentList(v))
}

pub fn run(a: EvalArgs) -> Result<()> {
    use activesense_lab::eval::{experiments, harness, report};
    use std::io::IsTerminal;
    let rot_bins = a.episode.rot_bins_or(&[1, 10])?;
    // Fail now, not after the whole run, when the results cannot be written.
    super::ensure_writable_dir(&a.out)?;
    super::set_threads(a.threads)?;
    let rooms = planfile::rooms_for_command(a.plan.as_deref(), &a.plans_from, &a.read)?;
    let (user_plans, refused) = rooms.unwrap_or_default();
    let opts = harness::EvalOptions {
        agents: a.agents.0.clone(),
        rot_bins,
        plans: if user_plans.is_empty() {
            a.plans
        } else {
            user_plans.len() as u32
        },
        user_plans,
        refused_plans: refused.iter().map(|e| e.to_string()).collect(),
        first_seed: a.first_seed,
        episode_seed: a.episode.episode_seed,
        config: a.episode.config(),
        sensor: a.episode.sensor(a.sensor.model()?),
        termination: a.episode.termination,
        policy_files: Vec::new(),
        policies: Policies::default(),
        progress: !a.no_progress && std::io::stderr().is_terminal(),
        curve_plans: a.curve_plans,
        tolerance: a.tolerance,
    };
    let mut opts = opts;
    if opts.agents.contains(&AgentKind::Learnt) {
        opts.policies = Policies::load_for(opts.config.instrument, &a.policy, &opts.rot_bins)?;
    } else if !a.policy.is_empty() {
        bail!("--policy given but the learnt agent is not among --agents");
    }
    if opts.agents.contains(&AgentKind::LearntInt8) {
        opts.policies
            .load_int8_for(opts.config.instrument, &a.int8, &opts.rot_bins)?;
    } else if !a.int8.is_empty() {
        bail!("--int8 given but the learnt-int8 agent is not among --agents");
    }
    opts.policy_files = opts
        .policies
        .iter()
        .map(|p| p.describe())
        .chain(opts.policies.int8().map(|p| p.describe()))
        .collect();
    let command = command_line();
    if !a.stop_risks.is_empty() {
        if opts.termination != activesense_instrument::episode::Termination::Confident {
            bail!("--stop-risks sweeps the calibrated stop: give --termination confident");
        }
        let t0 = std::time::Instant::now();
        let f = activesense_lab::eval::frontier::run(&opts, &a.stop_risks);
        let md = activesense_lab::eval::frontier::markdown(&f, &command);
        return write_analysis(
            &a.out,
            [
                ("frontier.json", serde_json::to_string_pretty(&f)? + "\n"),
                ("frontier.md", md.clone()),
                ("frontier.svg", activesense_lab::eval::frontier::svg(&f)),
            ],
            &md,
            t0,
        );
    }
    if let Some(extra) = a.extra_measurements {
        eprintln!(
            "following {} agent(s) x {} rotation setting(s) x {} plans for {extra} ranges past the minimal set",
            opts.agents.len(),
            opts.rot_bins.len(),
            opts.plans
        );
        let t0 = std::time::Instant::now();
        let report = experiments::extra_measurements(&opts, extra);
        let md = experiments::extra_markdown(&report, &command);
        return write_analysis(
            &a.out,
            [
                ("extra.json", serde_json::to_string_pretty(&report)? + "\n"),
                ("extra.md", md.clone()),
                ("extra.svg", experiments::extra_svg(&report)),
            ],
            &md,
            t0,
        );
    }
    eprintln!(
        "evaluating {} agent(s) x {} rotation setting(s) x {} plans = {} episodes",
        opts.agents.len(),
        opts.rot_bins.len(),
        opts.plans,
        opts.agents.len() * opts.rot_bins.len() * opts.plans as usize
    );
    let (report, timing) = harness::run(&opts);
    let files = report::write_outputs(&report, &timing, &a.out, &command)?;
    print_summary(&report, &timing, &files);
    if a.with_no_oracle
        && opts.termination != activesense_instrument::episode::Termination::Confident
    {
        let mut no_oracle = opts.clone();
        no_oracle.termination = activesense_instrument::episode::Termination::Confident;
        // The pose-error curve registers after every measurement: it is the oracle run's.
        no_oracle.curve_plans = 0;
        let dir = a.out.join("no-oracle");
        eprintln!(
            "without an oracle: the same {} episodes, each stopping by itself (calibrated stop, --stop-risk {})",
            opts.agents.len() * opts.rot_bins.len() * opts.plans as usize,
            opts.config.stop_risk
        );
        let (report, timing) = harness::run(&no_oracle);
        let files = report::write_outputs(&report, &timing, &dir, &command)?;
        print_summary(&report, &timing, &files);
        // The instrument surveyors own has no camera: the same table for it, with its own
        // policies and stop tables.
        if no_oracle.config.instrument == InstrumentProfile::EdmScan {
            let mut edm = no_oracle;
            edm.config.instrument = InstrumentProfile::Edm;
            edm.policies = Policies::default();
            if edm.agents.contains(&AgentKind::Learnt) {
                edm.policies = Policies::load_for(InstrumentProfile::Edm, &[], &edm.rot_bins)?;
            }
            if edm.agents.contains(&AgentKind::LearntInt8) {
                edm.policies
                    .load_int8_for(InstrumentProfile::Edm, &[], &edm.rot_bins)?;
            }
            edm.policy_files = edm
                .policies
                .iter()
                .map(|p| p.describe())
                .chain(edm.policies.int8().map(|p| p.describe()))
                .collect();
            let dir = a.out.join("no-oracle-edm");
            eprintln!(
                "the EDM-only instrument (no scan), without an oracle: the same {} episodes",
                edm.agents.len() * edm.rot_bins.len() * edm.plans as usize
            );
            let (report, timing) = harness::run(&edm);
            let files = report::write_outputs(&report, &timing, &dir, &command)?;
            print_summary(&report, &timing, &files);
            // No room is its plan: the same episodes in furnished rooms and on building
            // sites (`--site`), for the agents an instrument runs.
            if edm.sensor.site.is_plan() {
                for level in [SiteLevel::Furnished, SiteLevel::Site] {
                    let mut on_site = edm.clone();
                    on_site.sensor.site = level;
                    on_site.agents.retain(|k| INSTRUMENT_AGENTS.contains(k));
                    if on_site.agents.is_empty() {
                        continue;
                    }
                    let dir = a.out.join(format!("no-oracle-edm-{}", level.name()));
                    eprintln!(
                        "the EDM-only instrument in {} rooms (--site {}): {} episodes",
                        level.name(),
                        level.name(),
                        on_site.agents.len() * on_site.rot_bins.len() * on_site.plans as usize
                    );
                    let (report, timing) = harness::run(&on_site);
                    let files = report::write_outputs(&report, &timing, &dir, &command)?;
                    print_summary(&report, &timing, &files);
                }
            }
        }
    }
    Ok(())
}

/// The agents an instrument runs (`station`, `serial run`): the site-level tables are theirs.
const INSTRUMENT_AGENTS: [AgentKind; 3] = [
    AgentKind::Learnt,
    AgentKind::LearntInt8,
    AgentKind::Heuristic1,
];

/// Writes an analysis run's files (`frontier.*`, `extra.*`) into `out`, then prints its
/// markdown and the wall time since `t0`.
fn write_analysis(
    out: &std::path::Path,
    files: [(&str, String); 3],
    md: &str,
    t0: std::time::Instant,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    for (name, body) in files {
        let p = out.join(name);
        std::fs::write(&p, body).with_context(|| format!("cannot write {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    print!("{md}");
    println!("{:.1} s wall time", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The terminal summary of one evaluation: a line per group, the wall time, the files.
fn print_summary(
    report: &activesense_lab::eval::harness::EvalReport,
    timing: &activesense_lab::eval::harness::Timing,
    files: &[PathBuf],
) {
    println!(
        "agent         bins  recognition  pose error (m)  right  wrong/answered  measurements  rotations   cost"
    );
    for r in &report.results {
        println!(
            "{:<12}  {:>4}  {:>11.3}  {:>14}  {:>5.3}  {:>14.4}  {:>12.2}  {:>9.2}  {:.3}",
            r.agent,
            r.rot_bins,
            r.recognition_rate,
            r.pose_error
                .map(|e| format!("{e:.4}"))
                .unwrap_or_else(|| "-".into()),
            r.answers.right,
            r.answers.wrong_of_answered,
            r.measurements,
            r.rotations,
            r.cost
        );
    }
    println!("{:.1} s wall time", timing.total_s);
    for f in files {
        println!("wrote {}", f.display());
    }
}
