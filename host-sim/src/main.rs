//! `activesense` — the command-line front end of the simulator, evaluation harness and
//! instrument driver. Run `activesense --help` for the list of commands.

use activesense_core::agents::AgentKind;
use activesense_core::episode::{EpisodeConfig, DEFAULT_STEPS_PER_TURN, EVAL_MAX_ACTIONS};
use activesense_sim::episode::{
    parse_agent, parse_observability, parse_stop_risk, parse_termination, scan_string, EpisodeSpec,
};
use activesense_sim::learn::agent::{run_agent_episode, Policies};
use activesense_sim::planfile::{self, PlanReadArgs};
use activesense_sim::plans::{self, Family};
use activesense_sim::sensor::SensorModel;
use activesense_sim::svg::{self, Scene};
use activesense_sim::world::placement;
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Register a known floor-plan against a room with as few EDM measurements as possible.
///
/// activesense is the reference implementation of "Learning Effective Sparse Sampling
/// Strategies using Deep Active Sensing". This tool generates floor-plans, runs simulated
/// sampling episodes, evaluates agents and drives a real or emulated instrument.
#[derive(Parser)]
#[command(name = "activesense", version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate one floor-plan from its seed and draw it (outline, visual centre, agent disc, agent).
    Plan(PlanArgs),
    /// Run one simulated episode with a baseline or the learnt agent and print its step log.
    Episode(EpisodeArgs),
    /// Train the learnt sampling policy (advantage actor-critic with GAE, paper §3.1) on
    /// generated training plans; writes the policy file, its learning curve and logs.
    Train(TrainArgs),
    /// Run episodes on the instrument controller (QEMU, serial, TCP or loopback) while the host plays its sensors.
    Sim(activesense_sim::remote::SimArgs),
    /// Talk to an instrument controller on a serial port.
    Serial(activesense_sim::remote::SerialArgs),
    /// Count the firmware's instructions per update and per registration under QEMU
    /// (-icount shift=0); prints a markdown table (see `cargo xtask mcu-bench`).
    McuBench(activesense_sim::remote::McuBenchArgs),
    /// Summarise a seed range of generated plans (shapes, vertex counts, extents) as a table.
    Dataset(DatasetArgs),
    /// Evaluate agents on the test plans (the paper's Table 4): writes results.json,
    /// results.md, timing.json, budget.svg and the utility-vs-cost curves utility-k{K}.svg
    /// into --out (or, with --extra-measurements, the pose error past the minimal set).
    Eval(EvalArgs),
    /// Measure sparse-registration accuracy from coarse poses on the test plans.
    BenchRegistration(BenchRegistrationArgs),
    /// Benchmark the GHT localizer against the classical grid localizer (cost, memory, recognition).
    BenchLocalization(BenchLocalizationArgs),
    /// The int8 policy for the instrument: quantise a float policy into a blob
    /// (docs/policy-blob.md), measure how often it acts as the float one, upload it to an
    /// instrument, or ask an instrument which policy it runs.
    #[command(subcommand)]
    Policy(PolicyCommand),
    /// The inspection tool (paper §3.5): a self-contained web page to step through a
    /// learnt-agent trajectory (episode --agent learnt --json FILE) with a guided
    /// back-propagation overlay, or (--aggregate) the Fig.-4 analysis over many episodes.
    Inspect(activesense_sim::inspect::InspectArgs),
    /// Fit the calibrated stop (--termination confident, --stop-risk): run episodes on
    /// calibration plans, fit P(wrong registration) from the belief and the readings, and
    /// write the models the core compiles (core-nostd/src/stop_calibration.rs) with a
    /// held-out check (results/calibration/).
    Calibrate(activesense_sim::calibrate::CalibrateArgs),
}

#[derive(Subcommand)]
enum PolicyCommand {
    /// Post-training int8 quantisation of a float policy file, calibrated on greedy episodes
    /// on training plans; writes the blob the firmware runs.
    Quantize(QuantizeArgs),
    /// Float vs int8 on the test plans: argmax agreement per state and whole-episode
    /// outcomes of each; prints a table, writes JSON.
    Agreement(AgreementArgs),
    /// Upload an int8 policy into the instrument's RAM slot, replacing the one serving its
    /// K without reflashing (a corrupt or mismatched blob is refused; the old one serves on).
    Upload(activesense_sim::remote::PolicyUploadArgs),
    /// Show which policy serves K = 1 and K = 10 on the instrument (built-in or uploaded).
    Info(activesense_sim::remote::PolicyInfoArgs),
}

#[derive(Args)]
struct QuantizeArgs {
    /// Float policy file (activesense train output).
    #[arg(long)]
    policy: PathBuf,
    /// Where to write the int8 blob.
    #[arg(long)]
    out: PathBuf,
    /// Greedy episodes on training plans whose states calibrate the activation ranges.
    #[arg(long, default_value_t = activesense_sim::learn::quantize::DEFAULT_CALIBRATION_EPISODES)]
    calibration_episodes: usize,
    /// Seed of the calibration plans and placements.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(Args)]
struct AgreementArgs {
    /// Comma-separated rotation settings.
    #[arg(long, default_value = "1,10", value_delimiter = ',', value_parser = clap::value_parser!(u8).range(1..=10))]
    rot_bins: Vec<u8>,
    /// Test plans per setting (seeds from 1000000 on).
    #[arg(long, default_value_t = 200)]
    plans: usize,
    /// Float policy file(s), each for the K its header names; default: the committed
    /// policies/k{K}/policy.policy.
    #[arg(long)]
    policy: Vec<PathBuf>,
    /// int8 blob(s) to check, each for the K it names; default: quantised on the fly.
    #[arg(long)]
    int8: Vec<PathBuf>,
    /// Calibration episodes when quantising on the fly.
    #[arg(long, default_value_t = activesense_sim::learn::quantize::DEFAULT_CALIBRATION_EPISODES)]
    calibration_episodes: usize,
    /// Calibration seed when quantising on the fly.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write the report as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Args)]
struct BenchLocalizationArgs {
    /// Number of test plans (seeds from 1000000 on).
    #[arg(long, default_value_t = 20)]
    plans: usize,
    /// Agent placements per plan and outlier rate.
    #[arg(long, default_value_t = 3)]
    trials: usize,
    /// Rotation bins (1 = orientation known, 10 = paper default).
    #[arg(long, default_value_t = 10)]
    rot_bins: u8,
    /// Rotation hypotheses per bin.
    #[arg(long, default_value_t = 4)]
    sub_bins: u8,
    /// Write the report as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Args)]
struct BenchRegistrationArgs {
    /// Number of test plans.
    #[arg(long, default_value_t = 1000)]
    plans: usize,
    /// Measurements per trial.
    #[arg(long, default_value_t = 6)]
    measurements: usize,
    /// Grid cells across the larger room side (coarse position error within one cell).
    #[arg(long, default_value_t = 30.0)]
    cells: f32,
    /// Seed of the measurement and coarse-pose stream.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    sensor: SensorArgs,
    /// Write the full report (statistics and every trial) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Args)]
struct EvalArgs {
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
    /// Comma-separated rotation settings: 1 (heading known) and/or 10.
    #[arg(long, default_value = "1,10", value_delimiter = ',', value_parser = clap::value_parser!(u8).range(1..=10))]
    rot_bins: Vec<u8>,
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
    /// Episode seed (placement and noise also depend on the plan seed).
    #[arg(long, default_value_t = 0)]
    episode_seed: u64,
    /// Action limit per episode.
    #[arg(long, default_value_t = EVAL_MAX_ACTIONS, value_parser = clap::value_parser!(u16).range(1..))]
    max_actions: u16,
    /// When an episode stops: coarse success against the ground truth (the paper), or the
    /// calibrated stop (no ground truth; it answers with the refined pose, and recognition
    /// scores the cell that pose lies in), or only the action limit.
    #[arg(long, value_parser = parse_termination, default_value = "oracle")]
    termination: activesense_sim::episode::Termination,
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
    /// Stop only once the readings determine the pose: the smallest eigenvalue of their
    /// normalised information matrix at the belief argmax must reach this (0 = off; the
    /// instrument applies the same threshold; docs/EVALUATION.md, "Observability").
    #[arg(long, default_value_t = 0.0, value_parser = parse_observability)]
    min_observability: f32,
    /// With --termination confident: stop only once the estimated probability that the
    /// registration is wrong is below P (calibrated on training plans; docs/EVALUATION.md,
    /// 'Calibrated stop'). The instrument applies the same rule.
    #[arg(long, default_value_t = activesense_core::pipeline::DEFAULT_STOP_RISK, value_parser = parse_stop_risk)]
    stop_risk: f32,
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

#[derive(Args)]
struct DatasetArgs {
    /// Which published seed range to summarise.
    #[arg(long, value_enum, default_value = "test")]
    split: Split,
    /// Summarise only the first N plans of the split.
    #[arg(long)]
    plans: Option<u32>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Split {
    /// Seeds 1000000..1001000.
    Test,
    /// Seeds 0..1000000.
    Train,
}

#[derive(Args)]
struct PlanArgs {
    /// Plan seed (u32). Test plans are 1000000..1001000, training plans 0..1000000.
    #[arg(long)]
    seed: u32,
    /// Restrict the generator to one family.
    #[arg(long, value_enum)]
    family: Option<Family>,
    /// Write an SVG picture here.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Write the plan (vertices, shape, placement) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Episode seed used to place the drawn agent.
    #[arg(long, default_value_t = 0)]
    episode_seed: u64,
}

/// Sensor options shared by every simulating command.
#[derive(Args, Clone)]
struct SensorArgs {
    /// EDM range noise, standard deviation in metres.
    #[arg(long, default_value_t = 0.01)]
    sigma: f32,
    /// Probability that a measurement is an outlier (uniform random range).
    #[arg(long, default_value_t = 0.05)]
    outliers: f32,
    /// No EDM return beyond this range (m).
    #[arg(long, default_value_t = 50.0)]
    max_range: f32,
    /// No EDM return beyond this incidence angle from the wall normal (degrees).
    #[arg(long, default_value_t = 75.0)]
    max_incidence_deg: f32,
    /// Topological scan false-negative rate per pixel.
    #[arg(long, default_value_t = 0.0)]
    scan_fn: f32,
    /// Topological scan false-positive rate per pixel.
    #[arg(long, default_value_t = 0.0)]
    scan_fp: f32,
}

impl SensorArgs {
    fn model(&self) -> Result<SensorModel> {
        let m = SensorModel {
            sigma: self.sigma,
            outlier_prob: self.outliers,
            max_range: self.max_range,
            max_incidence: self.max_incidence_deg.to_radians(),
            scan_false_negative: self.scan_fn,
            scan_false_positive: self.scan_fp,
        };
        m.validate().map_err(anyhow::Error::msg)?;
        Ok(m)
    }
}

#[derive(Args)]
struct EpisodeArgs {
    /// Plan seed (u32).
    #[arg(long, required_unless_present = "plan", conflicts_with = "plan")]
    seed: Option<u32>,
    /// Play the episode in the room of this plan file instead of a generated plan (JSON,
    /// GeoJSON or DXF; docs/PLANS.md).
    #[arg(long)]
    plan: Option<PathBuf>,
    #[command(flatten)]
    read: PlanReadArgs,
    /// Stop only once the readings determine the pose: the smallest eigenvalue of their
    /// normalised information matrix at the belief argmax must reach this (0 = off; the
    /// instrument applies the same threshold; docs/EVALUATION.md, "Observability").
    #[arg(long, default_value_t = 0.0, value_parser = parse_observability)]
    min_observability: f32,
    /// With --termination confident: stop only once the estimated probability that the
    /// registration is wrong is below P (calibrated on training plans; docs/EVALUATION.md,
    /// 'Calibrated stop'). The instrument applies the same rule.
    #[arg(long, default_value_t = activesense_core::pipeline::DEFAULT_STOP_RISK, value_parser = parse_stop_risk)]
    stop_risk: f32,
    /// Agent: blind-0, blind-1, blind-2, heuristic-0, heuristic-1, heuristic-2, heuristic-3,
    /// learnt, learnt-int8, or the greedy benchmarks oigm, oigm-cost, eem (docs/BENCHMARKS.md).
    #[arg(long, value_parser = parse_agent, default_value = "heuristic-1")]
    agent: AgentKind,
    /// Policy file for the learnt agent (default: the committed policies/k{K}/policy.policy).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// int8 blob for learnt-int8 (default: the one built into the firmware for this K).
    #[arg(long)]
    int8: Option<PathBuf>,
    /// Rotation bins of the localizer: 1 = heading known, 10 = heading unknown.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=10))]
    rot_bins: u8,
    /// Action limit (100 for evaluation, 500 for training).
    #[arg(long, default_value_t = EVAL_MAX_ACTIONS, value_parser = clap::value_parser!(u16).range(1..))]
    max_actions: u16,
    /// Rotation steps per full turn (rotation step = 360° / this).
    #[arg(long, default_value_t = DEFAULT_STEPS_PER_TURN, value_parser = clap::value_parser!(u16).range(2..=3600))]
    steps_per_turn: u16,
    /// Episode seed (placement, noise and agent randomness).
    #[arg(long, default_value_t = 0)]
    episode_seed: u64,
    #[command(flatten)]
    sensor: SensorArgs,
    /// When to stop: on coarse success against the ground truth (paper), by the calibrated
    /// stop (no ground truth; answers with the refined pose), or only at the action limit.
    #[arg(long, value_parser = parse_termination, default_value = "oracle")]
    termination: activesense_sim::episode::Termination,
    /// Write the full trajectory as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write an SVG of the room, agent and measurement beams here.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Print only the summary, not every step.
    #[arg(long)]
    quiet: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Plan(a) => cmd_plan(a),
        Command::Episode(a) => cmd_episode(a),
        Command::Train(a) => cmd_train(a),
        Command::Dataset(a) => cmd_dataset(a),
        Command::Eval(a) => cmd_eval(a),
        Command::Calibrate(a) => activesense_sim::calibrate::cmd_calibrate(a),
        Command::BenchRegistration(a) => cmd_bench_registration(a),
        Command::BenchLocalization(a) => cmd_bench_localization(a),
        Command::Sim(a) => activesense_sim::remote::cmd_sim(a),
        Command::Serial(a) => activesense_sim::remote::cmd_serial(a),
        Command::McuBench(a) => activesense_sim::remote::cmd_mcu_bench(a),
        Command::Policy(PolicyCommand::Quantize(a)) => cmd_policy_quantize(a),
        Command::Policy(PolicyCommand::Agreement(a)) => cmd_policy_agreement(a),
        Command::Policy(PolicyCommand::Upload(a)) => activesense_sim::remote::cmd_policy_upload(a),
        Command::Policy(PolicyCommand::Info(a)) => activesense_sim::remote::cmd_policy_info(a),
        Command::Inspect(a) => activesense_sim::inspect::cmd_inspect(a, &command_line()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn cmd_bench_registration(a: BenchRegistrationArgs) -> Result<()> {
    use activesense_sim::bench_registration as bench;
    let opts = bench::BenchOptions {
        plans: a.plans,
        measurements: a.measurements,
        cells: a.cells,
        sensor: a.sensor.model()?,
        seed: a.seed,
        ..Default::default()
    };
    let report = bench::run(&opts)?;
    print!("{}", bench::summary(&report));
    if let Some(path) = &a.json {
        write_file(path, &serde_json::to_string_pretty(&report)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn cmd_policy_quantize(a: QuantizeArgs) -> Result<()> {
    use activesense_sim::learn::{file, quantize};
    let (net, meta) = file::load(&a.policy).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mask = activesense_sim::learn::agent::InputMask::of_metadata(&meta);
    if mask != activesense_sim::learn::agent::InputMask::Full {
        bail!(
            "{} is an ablation trained on '{}' inputs; the instrument's int8 policy shows the network every input, so only full-input policies can be quantised",
            a.policy.display(),
            mask.name()
        );
    }
    let (blob, r) = quantize::quantize_calibrated(&net, a.calibration_episodes, a.seed);
    std::fs::write(&a.out, &blob).with_context(|| format!("cannot write {}", a.out.display()))?;
    println!(
        "calibrated on {} states of {} training episodes (seed {}); wrote {} ({} bytes, K = {})",
        r.states,
        a.calibration_episodes,
        a.seed,
        a.out.display(),
        blob.len(),
        net.shape.rot_bins
    );
    Ok(())
}

/// Reads an int8 blob, naming the file in every error.
fn read_blob(path: &Path) -> Result<(u8, Vec<u8>)> {
    use activesense_core::quantized::QuantizedPolicy;
    let bytes = std::fs::read(path).with_context(|| format!("cannot read '{}'", path.display()))?;
    let k = QuantizedPolicy::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("'{}' is not a usable int8 policy blob: {e}", path.display()))?
        .rot_bins();
    Ok((k, bytes))
}

fn cmd_policy_agreement(a: AgreementArgs) -> Result<()> {
    use activesense_sim::learn::quantize;
    let mut rot_bins = a.rot_bins.clone();
    rot_bins.dedup();
    let policies = Policies::load(&a.policy, &rot_bins)?;
    let mut blobs = Vec::new();
    for path in &a.int8 {
        blobs.push((read_blob(path)?, path.clone()));
    }
    let mut reports = Vec::new();
    println!("| K | plans | states | action agreement | identical episodes | success float / int8 | mean actions float / int8 | max logit error | blob |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for &k in &rot_bins {
        let p = policies
            .for_rot_bins(k)
            .ok_or_else(|| anyhow::anyhow!("no float policy for K = {k}"))?;
        let blob = match blobs.iter().find(|((bk, _), _)| *bk == k) {
            Some(((_, b), _)) => b.clone(),
            None => quantize::quantize_calibrated(&p.net, a.calibration_episodes, a.seed).0,
        };
        let r = quantize::agreement(&p.net, &blob, a.plans).map_err(|e| {
            anyhow::anyhow!("int8 blob for K = {k} does not fit {}: {e}", p.describe())
        })?;
        println!(
            "| {} | {} | {} | {:.4} | {} / {} | {:.3} / {:.3} | {:.1} / {:.1} | {:.4} | {} B, crc {:08x} |",
            r.rot_bins,
            r.plans,
            r.states,
            r.action_agreement,
            r.identical_episodes,
            r.plans,
            r.float.success_rate,
            r.int8.success_rate,
            r.float.mean_actions,
            r.int8.mean_actions,
            r.max_logit_error,
            r.blob_bytes,
            r.blob_crc
        );
        reports.push(serde_json::json!({ "policy": p.describe(), "agreement": r }));
    }
    if let Some(path) = &a.json {
        write_file(path, &serde_json::to_string_pretty(&reports)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn write_file(path: &Path, contents: &str) -> Result<()> {
    std::fs::write(path, contents).with_context(|| format!("cannot write {}", path.display()))
}

fn cmd_plan(a: PlanArgs) -> Result<()> {
    let g = plans::generate_detailed(a.seed, a.family);
    let p = placement(&g.plan);
    let (lo, hi) = g.plan.bounds();
    println!(
        "plan {}: {:?} ({:?}), {} vertices, {:.2} m x {:.2} m, perimeter {:.2} m, area {:.2} m²",
        g.seed,
        g.shape,
        g.family,
        g.plan.len(),
        hi.x - lo.x,
        hi.y - lo.y,
        g.plan.perimeter(),
        g.plan.signed_area()
    );
    println!(
        "visual centre ({:.3}, {:.3}), placement radius {:.3} m",
        p.visual_centre[0], p.visual_centre[1], p.radius
    );
    let world = activesense_sim::world::SimWorld::new(
        g.plan.clone(),
        SensorModel::default(),
        EpisodeConfig::default(),
        EpisodeSpec {
            episode_seed: a.episode_seed,
            ..EpisodeSpec::new(a.seed, AgentKind::Heuristic1)
        }
        .world_seed(),
    );
    let truth = world.truth();
    println!(
        "agent ({:.3}, {:.3}), heading {:.1}°",
        truth.x,
        truth.y,
        truth.theta.to_degrees()
    );
    if let Some(path) = &a.json {
        let doc = serde_json::json!({ "generated": g, "placement": p, "agent": truth });
        write_file(path, &serde_json::to_string_pretty(&doc)?)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &a.svg {
        let scene = Scene {
            title: format!("plan {} — {:?}, {} vertices", g.seed, g.shape, g.plan.len()),
            placement: Some(p),
            agent: Some(truth),
            ..Default::default()
        };
        write_file(path, &svg::render(&g.plan, &scene))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn cmd_episode(a: EpisodeArgs) -> Result<()> {
    if a.rot_bins != 1 && a.rot_bins != 10 {
        bail!(
            "--rot-bins must be 1 or 10 (the paper's two settings), got {}",
            a.rot_bins
        );
    }
    let user_plan = match &a.plan {
        Some(p) => {
            let rooms = planfile::rooms_for_command(Some(p), &[], &a.read)?;
            rooms.and_then(|(mut r, _)| r.pop())
        }
        None => None,
    };
    let spec = EpisodeSpec {
        plan_seed: match &user_plan {
            Some(p) => p.seed(),
            None => a.seed.unwrap_or_default(),
        },
        user_plan,
        episode_seed: a.episode_seed,
        agent: a.agent,
        rot_bins: a.rot_bins,
        config: EpisodeConfig {
            steps_per_turn: a.steps_per_turn,
            max_actions: a.max_actions,
            min_observability: a.min_observability,
            stop_risk: a.stop_risk,
            ..Default::default()
        },
        sensor: a.sensor.model()?,
        termination: a.termination,
    };
    let mut policies = Policies::default();
    match spec.agent {
        AgentKind::Learnt => policies = Policies::load(a.policy.as_slice(), &[spec.rot_bins])?,
        AgentKind::LearntInt8 => policies.load_int8(a.int8.as_slice(), &[spec.rot_bins])?,
        _ => {}
    }
    // The learnt float policy's episodes carry the inspection data (`activesense inspect`).
    let t = match policies.for_rot_bins(spec.rot_bins) {
        Some(p) if spec.agent == AgentKind::Learnt => {
            activesense_sim::inspect::record_episode(&spec, p)
        }
        _ => run_agent_episode(&spec, &policies)?,
    };
    for p in policies.iter() {
        println!("policy: {}", p.path.display());
    }
    for p in policies.int8() {
        println!("policy: {}", p.describe());
    }
    println!(
        "episode: {} agent {} rot-bins {} max-actions {} episode-seed {}",
        spec.plan_label(),
        spec.agent.name(),
        spec.rot_bins,
        spec.config.max_actions,
        spec.episode_seed
    );
    println!(
        "truth: agent ({:.3}, {:.3}) heading {:.1}° (hidden from the agent)",
        t.truth.x,
        t.truth.y,
        t.truth.theta.to_degrees()
    );
    if !a.quiet {
        println!("step  action        bearing  range       scan (left..right)    cost   entropy");
        println!(
            "   -  start         {:7.1}°  {:<10}  {}",
            0.0,
            "",
            scan_string(t.initial_scan)
        );
        for s in &t.steps {
            let range = match (s.range, s.action) {
                (Some(r), _) => format!("{r:8.3} m"),
                (None, activesense_core::agents::Action::Measure) => "no return".into(),
                _ => String::new(),
            };
            println!(
                "{:4}  {:<12}  {:7.1}°  {:<10}  {}  {:.3}  {:.2}",
                s.step,
                s.action.name(),
                s.bearing.to_degrees(),
                range,
                scan_string(s.scan),
                s.cost,
                s.entropy
            );
        }
    }
    println!(
        "end: {:?} after {} actions ({} measurements, {} rotations), cost {:.3}",
        t.end, t.summary.actions, t.summary.measurements, t.summary.rotations, t.summary.cost
    );
    let o = &t.outcome;
    let fmt_pose = |p: &activesense_core::Pose2| {
        format!(
            "({:.3}, {:.3}) heading {:.1}°",
            p.x,
            p.y,
            p.theta.to_degrees()
        )
    };
    // Under the calibrated stop the answer is the refined pose, scored by its cell.
    let answer_is_refined = t.spec.termination == activesense_sim::episode::Termination::Confident
        && o.refined.is_some();
    println!(
        "recognised: {} (room symmetry C{}{})",
        if o.recognised { "yes" } else { "no" },
        o.symmetry_order,
        if answer_is_refined {
            "; scored on the cell the refined pose lies in"
        } else {
            ""
        }
    );
    if let (Some(c), Some(e)) = (o.coarse, o.coarse_error) {
        let what = if answer_is_refined {
            "coarse estimate (the refined pose's cell):"
        } else {
            "coarse estimate:"
        };
        println!("{what}  {}  error {:.3} m", fmt_pose(&c), e);
    }
    match (&o.refined, o.pose_error) {
        (Some(r), Some(e)) => println!(
            "refined estimate: {}  error {:.4} m (registration rms {:.4} m, {} inliers)",
            fmt_pose(&r.pose),
            e,
            r.error,
            r.inliers
        ),
        _ => println!(
            "refined estimate: none ({})",
            o.registration_note.as_deref().unwrap_or("not registered")
        ),
    }
    match o.stop_risk {
        Some(r) => println!(
            "estimated risk of a wrong registration: {:.2} % (the confident stop stops below {:.2} %)",
            100.0 * r,
            100.0 * t.spec.config.stop_risk
        ),
        None => println!(
            "estimated risk of a wrong registration: not available (belief peak mass below {}, fewer readings than unknowns, or no registration)",
            activesense_core::stop::GATE_PEAK_MASS
        ),
    }
    let readings = t.steps.iter().filter(|s| s.range.is_some()).count();
    if (o.answer_readings as usize) < readings {
        println!(
            "answer from the lowest-risk moment, after reading {} of {}: the action limit came before a confident stop",
            o.answer_readings, readings
        );
    }
    if let Some(path) = &a.json {
        // The inspection arrays (K × 900 floats per step) are written compactly.
        let text = if t.inspection.is_some() {
            serde_json::to_string(&t)?
        } else {
            serde_json::to_string_pretty(&t)?
        };
        write_file(path, &text)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &a.svg {
        let scene = Scene {
            title: format!(
                "{} — {} episode, {} measurements",
                spec.plan_label(),
                spec.agent.name(),
                t.summary.measurements
            ),
            placement: Some(t.placement),
            agent: Some(t.truth),
            trajectory: Some(&t),
            estimate: o.refined.map(|r| r.pose),
        };
        write_file(path, &svg::render(&t.plan, &scene))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn cmd_dataset(a: DatasetArgs) -> Result<()> {
    let range = match a.split {
        Split::Test => plans::TEST_SEEDS,
        Split::Train => plans::TRAIN_SEEDS,
    };
    let n = a
        .plans
        .unwrap_or(range.end - range.start)
        .min(range.end - range.start);
    let mut by_shape: std::collections::BTreeMap<String, (u32, usize, usize, f32, f32)> =
        Default::default();
    for seed in range.start..range.start + n {
        let g = plans::generate_detailed(seed, None);
        let (lo, hi) = g.plan.bounds();
        let side = (hi - lo).x.max((hi - lo).y);
        let e = by_shape
            .entry(format!("{:?} ({:?})", g.shape, g.family))
            .or_insert((0, usize::MAX, 0, f32::INFINITY, 0.0));
        e.0 += 1;
        e.1 = e.1.min(g.plan.len());
        e.2 = e.2.max(g.plan.len());
        e.3 = e.3.min(side);
        e.4 = e.4.max(side);
    }
    println!("{n} plans from seed {}", range.start);
    println!("| shape (family) | plans | share | vertices | longest side (m) |");
    println!("|---|---:|---:|---|---|");
    for (k, (c, vmin, vmax, smin, smax)) in by_shape {
        println!(
            "| {k} | {c} | {:.1}% | {vmin}–{vmax} | {smin:.1}–{smax:.1} |",
            100.0 * c as f32 / n as f32
        );
    }
    Ok(())
}

fn cmd_eval(a: EvalArgs) -> Result<()> {
    use activesense_sim::eval;
    use std::io::IsTerminal;
    if let Some(bad) = a.rot_bins.iter().find(|k| **k != 1 && **k != 10) {
        bail!("--rot-bins takes 1 and/or 10 (the paper's two settings), got {bad}");
    }
    let mut rot_bins = a.rot_bins.clone();
    rot_bins.dedup();
    if let Some(n) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("cannot set the thread count")?;
    }
    let rooms = planfile::rooms_for_command(a.plan.as_deref(), &a.plans_from, &a.read)?;
    let (user_plans, refused) = rooms.unwrap_or_default();
    let opts = eval::EvalOptions {
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
        episode_seed: a.episode_seed,
        config: EpisodeConfig {
            max_actions: a.max_actions,
            min_observability: a.min_observability,
            stop_risk: a.stop_risk,
            ..Default::default()
        },
        sensor: a.sensor.model()?,
        termination: a.termination,
        policy_files: Vec::new(),
        policies: Policies::default(),
        progress: !a.no_progress && std::io::stderr().is_terminal(),
        curve_plans: a.curve_plans,
    };
    let mut opts = opts;
    if opts.agents.contains(&AgentKind::Learnt) {
        opts.policies = Policies::load(&a.policy, &opts.rot_bins)?;
    } else if !a.policy.is_empty() {
        bail!("--policy given but the learnt agent is not among --agents");
    }
    if opts.agents.contains(&AgentKind::LearntInt8) {
        opts.policies.load_int8(&a.int8, &opts.rot_bins)?;
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
    if let Some(extra) = a.extra_measurements {
        eprintln!(
            "following {} agent(s) x {} rotation setting(s) x {} plans for {extra} ranges past the minimal set",
            opts.agents.len(),
            opts.rot_bins.len(),
            opts.plans
        );
        let t0 = std::time::Instant::now();
        let report = eval::extra_measurements(&opts, extra);
        std::fs::create_dir_all(&a.out)
            .with_context(|| format!("cannot create {}", a.out.display()))?;
        let md = eval::extra_markdown(&report, &command);
        for (name, body) in [
            ("extra.json", serde_json::to_string_pretty(&report)? + "\n"),
            ("extra.md", md.clone()),
            ("extra.svg", eval::extra_svg(&report)),
        ] {
            let p = a.out.join(name);
            std::fs::write(&p, body).with_context(|| format!("cannot write {}", p.display()))?;
            println!("wrote {}", p.display());
        }
        print!("{md}");
        println!("{:.1} s wall time", t0.elapsed().as_secs_f64());
        return Ok(());
    }
    eprintln!(
        "evaluating {} agent(s) x {} rotation setting(s) x {} plans = {} episodes",
        opts.agents.len(),
        opts.rot_bins.len(),
        opts.plans,
        opts.agents.len() * opts.rot_bins.len() * opts.plans as usize
    );
    let (report, timing) = eval::run(&opts);
    let files = eval::write_outputs(&report, &timing, &a.out, &command)?;
    println!("agent         bins  recognition  pose error (m)  measurements  rotations   cost");
    for r in &report.results {
        println!(
            "{:<12}  {:>4}  {:>11.3}  {:>14}  {:>12.2}  {:>9.2}  {:.3}",
            r.agent,
            r.rot_bins,
            r.recognition_rate,
            r.pose_error
                .map(|e| format!("{e:.4}"))
                .unwrap_or_else(|| "-".into()),
            r.measurements,
            r.rotations,
            r.cost
        );
    }
    println!("{:.1} s wall time", timing.total_s);
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

fn cmd_bench_localization(a: BenchLocalizationArgs) -> Result<()> {
    use activesense_sim::bench_localization::{self as bl, BenchOptions};
    let mut opts = BenchOptions {
        plans: a.plans,
        trials_per_plan: a.trials,
        ..BenchOptions::default()
    };
    opts.config.rot_bins = a.rot_bins;
    opts.config.sub_bins = a.sub_bins;
    if a.rot_bins == 1 {
        opts.smear_sub_bins.clear();
    }
    let report = bl::run(&opts)?;
    print!("{}", bl::markdown(&report));
    if let Some(path) = a.json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[derive(Args)]
struct TrainArgs {
    // Every hyper-parameter flag (--rot-bins, --updates, --seed, --envs, ...): their
    // defaults and help are written once, in HyperParams.
    #[command(flatten)]
    hp: activesense_sim::learn::train::HyperParams,
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

fn cmd_train(a: TrainArgs) -> Result<()> {
    use activesense_sim::learn::{agent::shape_for, file, train};
    use std::io::IsTerminal;
    if a.hp.rot_bins != 1 && a.hp.rot_bins != 10 {
        bail!(
            "--rot-bins must be 1 or 10 (the paper's two settings), got {}",
            a.hp.rot_bins
        );
    }
    if let Some(n) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("cannot set the thread count")?;
    }
    let hp = a.hp;
    let init = match &a.init {
        Some(p) => Some(file::load_expecting(p, hp.rot_bins, shape_for(hp.rot_bins).side)?.0),
        None => None,
    };
    let command = command_line();
    let shape = shape_for(hp.rot_bins);
    eprintln!(
        "training K = {}: network {} ({} parameters, {} multiply-accumulates per decision), {} threads",
        hp.rot_bins,
        activesense_sim::learn::net::ARCH_NAME,
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

/// The command line as typed, with the program's directory dropped (`activesense eval …`),
/// for the outputs that record how they were made.
fn command_line() -> String {
    std::env::args()
        .enumerate()
        .map(|(i, w)| {
            if i == 0 {
                w.rsplit('/').next().unwrap_or(&w).to_string()
            } else {
                w
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}
