//! The `sim` and `serial` commands of the `activesense` CLI: run episodes against a
//! remote instrument controller (firmware in QEMU, on a serial port or TCP, or the core
//! session in a thread) while the host plays the instrument's sensors with the simulated
//! world.
//!
//! The device localizes (GHT), decides when to stop and registers (sparse ICP); it reports
//! counts, cost, the trace fingerprint, and its coarse and refined AgentPoses. `--verify`
//! additionally replays each episode in-process ([`activesense_core::device::instrument::run_local`])
//! and fails unless actions, observations and report are bit-identical.

use super::options::{parse_agent, EpisodeOptions};
use activesense_core::episode::AgentKind;
use activesense_core::protocol::{EpisodeParams, EpisodeReport, UpdateStats};
use activesense_core::FloorPlan;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::link::device::{sim_episode, SimInstrument};
use activesense_instrument::link::runner::{end_session, open_link, print_link_counters, run_one};
use activesense_instrument::link::serial::{self, EpisodeRun, LinkSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::SimWorld;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::time::Instant;

/// Episode options shared by `sim` and `serial run`.
#[derive(Args, Clone, Debug)]
pub struct RemoteEpisodeArgs {
    /// Number of episodes (plan seeds first-seed, first-seed+1, ...).
    #[arg(long, default_value_t = 10)]
    pub episodes: u32,
    /// Agent: blind-0..2, heuristic-0..3, or learnt (= learnt-int8: the int8 policy the
    /// instrument carries, or one uploaded with `activesense policy upload`).
    #[arg(long, value_parser = parse_agent, default_value = "heuristic-1")]
    pub agent: AgentKind,
    /// How the episodes are played (the rotation setting, limit and stop are sent to the
    /// device).
    #[command(flatten)]
    pub options: EpisodeOptions,
    /// Reply time-out in milliseconds. Default: what the device announces as its slowest
    /// reply (its `Hello`), plus half again; a request without a reply in time is re-sent.
    #[arg(long)]
    pub timeout_ms: Option<u64>,
    /// Replay every episode in-process and require bit-identical results.
    #[arg(long)]
    pub verify: bool,
    /// Power the instrument off at the end (protocol `Shutdown`; the firmware exits).
    /// Without it the session ends and the instrument keeps serving: a policy uploaded to
    /// its RAM stays. (A `loopback` or `qemu` device this command started ends with it.)
    #[arg(long)]
    pub shutdown: bool,
    /// An approximate heading, DEG±TOL (degrees counter-clockwise from the plan's +x axis):
    /// breaks the tie between the poses a symmetric room leaves (see `episode --help`).
    #[arg(long, value_parser = activesense_instrument::answer::parse_heading_hint, allow_hyphen_values = true)]
    pub heading_hint: Option<activesense_instrument::answer::HeadingHint>,
}

/// `activesense sim`.
#[derive(Args, Debug)]
pub struct SimArgs {
    // clap's help text: the brackets are optional parts, not rustdoc links.
    #[allow(rustdoc::broken_intra_doc_links)]
    /// loopback | qemu[:ELF] | tcp:HOST:PORT | serial:PATH[@BAUD]
    #[arg(long, default_value = "loopback")]
    pub link: LinkSpec,
    /// First plan seed (default: the first test plan).
    #[arg(long, default_value_t = TEST_SEEDS.start)]
    pub first_seed: u32,
    /// Extra argument for qemu-system-arm (`qemu` links only; repeatable), e.g.
    /// `--qemu-arg=-icount --qemu-arg=shift=0`.
    #[arg(long = "qemu-arg", allow_hyphen_values = true)]
    pub qemu_args: Vec<String>,
    /// Write the emulator's raw stderr (the firmware's defmt log frames) to this file
    /// (`qemu` links; decoded by `cargo xtask qemu-log`).
    #[arg(long)]
    pub defmt_out: Option<PathBuf>,
    /// Run in the room of this plan file (JSON, GeoJSON or DXF; `docs/PLANS.md`) instead of
    /// generated plans: `--episodes` episodes, episode seeds episode-seed, episode-seed+1, ...
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Run `--episodes` episodes in every room of these plan files or directories.
    #[arg(long, num_args = 1..)]
    pub plans_from: Vec<PathBuf>,
    #[command(flatten)]
    pub read: activesense_instrument::world::planfile::PlanReadArgs,
    #[command(flatten)]
    pub episode: RemoteEpisodeArgs,
}

/// `activesense serial ...`.
#[derive(Args, Debug)]
pub struct SerialArgs {
    #[command(subcommand)]
    pub command: SerialCommand,
}

/// Serial subcommands.
#[derive(Subcommand, Debug)]
pub enum SerialCommand {
    /// List the serial ports of this machine.
    List,
    /// Load a plan file into the instrument controller and run episodes in that room.
    Run(SerialRunArgs),
    /// Power the instrument off (protocol `Shutdown`; the firmware exits). Every other
    /// command leaves it serving.
    Shutdown(SerialShutdownArgs),
}

/// `activesense serial shutdown`.
#[derive(Args, Debug)]
pub struct SerialShutdownArgs {
    /// Serial device (e.g. /dev/ttyUSB0).
    #[arg(long)]
    pub port: String,
    /// Baud rate.
    #[arg(long, default_value_t = serial::DEFAULT_BAUD)]
    pub baud: u32,
    /// Reply time-out in milliseconds (default: as announced by the device).
    #[arg(long)]
    pub timeout_ms: Option<u64>,
}

/// `activesense serial run`.
#[derive(Args, Debug)]
pub struct SerialRunArgs {
    /// Serial device (e.g. /dev/ttyUSB0).
    #[arg(long)]
    pub port: String,
    /// Baud rate.
    #[arg(long, default_value_t = serial::DEFAULT_BAUD)]
    pub baud: u32,
    /// Floor-plan file: our JSON {"vertices": [[x, y], ...]}, GeoJSON or DXF
    /// (`docs/PLANS.md`; metres unless --units, any orientation; it is re-centred on its
    /// perimeter centroid, the model frame).
    #[arg(long)]
    pub plan: PathBuf,
    #[command(flatten)]
    pub read: activesense_instrument::world::planfile::PlanReadArgs,
    #[command(flatten)]
    pub episode: RemoteEpisodeArgs,
}

/// The episode on plan `plan_seed` that `agent` plays on a device with rotation setting
/// `rot_bins`.
pub(super) fn spec_for(
    plan_seed: u32,
    agent: AgentKind,
    rot_bins: u8,
    o: &EpisodeOptions,
) -> Result<EpisodeSpec> {
    if agent.is_greedy() {
        bail!(
            "{} is a host-side benchmark (paper §4.3): OIGM needs the ground truth and EEM ray-casts {} belief hypotheses per bearing, so the instrument does not run them; use `activesense episode` or `activesense eval --agents {}`",
            agent.name(),
            activesense_instrument::baselines::greedy::EEM_PARTICLES,
            agent.name()
        );
    }
    // The instrument runs the learnt policy in its int8 form: that is what `learnt` means
    // on a device (the float network exists only on the host).
    let agent = match agent {
        AgentKind::Learnt => AgentKind::LearntInt8,
        other => other,
    };
    let mut spec = EpisodeSpec::new(plan_seed, agent);
    spec.episode_seed = o.episode_seed;
    spec.rot_bins = rot_bins;
    spec.config = o.config();
    spec.termination = o.termination;
    spec.sensor = o.sensor(spec.sensor);
    Ok(spec)
}

#[derive(Default)]
struct Totals {
    /// Pose errors of the episodes with an estimate (m).
    pose_errors: Vec<f32>,
    episodes: u32,
    actions: u64,
    measurements: u64,
    no_returns: u64,
    cost: f64,
}

fn mean_cycles(s: &UpdateStats) -> u64 {
    s.total_cycles / s.updates.max(1) as u64
}

/// Symmetry-aware pose error of the device's answer (refined, else coarse) against the
/// simulated truth, and which estimate it was.
fn pose_error(
    plan: &FloorPlan,
    truth: &activesense_core::Pose2,
    r: &EpisodeReport,
) -> Option<(f32, &'static str)> {
    use activesense_core::registration::pose_distance::PoseDistance;
    use activesense_core::world::symmetry::SymmetryTolerance;
    let d = PoseDistance::new(plan, &SymmetryTolerance::default());
    match (r.refined, r.coarse) {
        (Some(p), _) => Some((d.agent_distance(&p, truth), "refined")),
        (None, Some(p)) => Some((d.agent_distance(&p, truth), "coarse")),
        _ => None,
    }
}

fn print_run(
    label: &str,
    run: &EpisodeRun,
    plan: &FloorPlan,
    params: &EpisodeParams,
    t: &mut Totals,
) {
    let r = &run.report;
    let err = params
        .ground_truth
        .as_ref()
        .and_then(|truth| pose_error(plan, truth, r));
    if let Some((e, _)) = err {
        t.pose_errors.push(e);
    }
    let pose = |p: Option<activesense_core::Pose2>| {
        p.map(|p| format!("({:.3}, {:.3}, {:.1}°)", p.x, p.y, p.theta.to_degrees()))
            .unwrap_or_else(|| "none".into())
    };
    println!(
        "{label}: {:?} after {} actions ({} measurements, {} no-return, {} rotations), cost {:.3}, \
         coarse {}, refined {}{}, pose error {}, stop risk {}{}, trace {:08x}, cycles/update mean {} max {} (vote mean {}, rotation mean {}), finish {}",
        r.end,
        r.actions,
        r.measurements,
        r.no_returns,
        r.rotations,
        r.cost,
        pose(r.coarse),
        pose(r.refined),
        match r.recognised {
            Some(true) => " (recognised)",
            Some(false) => " (not recognised)",
            None => "",
        },
        match err {
            Some((e, which)) => format!("{e:.4} m ({which})"),
            None => "none".to_string(),
        },
        r.stop_risk
            .map_or_else(|| "n/a".to_string(), |p| format!("{:.2} %", 100.0 * p)),
        if r.answer_readings < r.measurements.saturating_sub(r.no_returns) {
            format!(
                " (answer from reading {} of {}: the lowest-risk moment)",
                r.answer_readings,
                r.measurements.saturating_sub(r.no_returns)
            )
        } else {
            String::new()
        },
        r.trace_hash,
        mean_cycles(&r.cycles.updates()),
        r.cycles.updates().max_cycles,
        mean_cycles(&r.cycles.vote),
        mean_cycles(&r.cycles.rotation),
        r.cycles.finish
    );
    t.episodes += 1;
    t.actions += r.actions as u64;
    t.measurements += r.measurements as u64;
    t.no_returns += r.no_returns as u64;
    t.cost += r.cost as f64;
}

/// The episode's answer ([`activesense_instrument::answer::Answer`]) in the plan's coordinates, indented
/// under its report line.
fn print_answer(
    label: &str,
    run: &EpisodeRun,
    plan: &FloorPlan,
    frame: &activesense_instrument::world::planfile::PlanFrame,
    params: &EpisodeParams,
    a: &RemoteEpisodeArgs,
) {
    let answer = activesense_instrument::answer::Answer::of_report(
        label.to_string(),
        plan,
        frame,
        params,
        &run.report,
        &run.steps,
        SensorModel::default().sigma,
        a.heading_hint,
    );
    for line in answer.to_text().lines() {
        println!("  {line}");
    }
}

fn print_totals(t: &Totals, secs: f64) {
    let n = t.episodes.max(1) as f64;
    println!(
        "{} episodes in {:.2} s: mean {:.2} actions, {:.2} measurements, {:.2} no-returns, cost {:.3}",
        t.episodes,
        secs,
        t.actions as f64 / n,
        t.measurements as f64 / n,
        t.no_returns as f64 / n,
        t.cost / n
    );
    if !t.pose_errors.is_empty() {
        let mut e = t.pose_errors.clone();
        e.sort_by(f32::total_cmp);
        println!(
            "pose error against the simulated truth: mean {:.4} m, median {:.4} m over {} episodes with an estimate",
            e.iter().map(|x| *x as f64).sum::<f64>() / e.len() as f64,
            e[e.len() / 2],
            e.len()
        );
    }
}

/// `activesense sim`.
pub fn cmd_sim(a: SimArgs) -> Result<()> {
    let mut link = open_link(&a.link, &a.qemu_args, a.episode.timeout_ms)?;
    let info = link.client.hello().context("handshake")?;
    println!(
        "device: {} (protocol v{}, capabilities {:#x}, max {} vertices, max {} actions)",
        info.firmware, info.protocol, info.capabilities, info.max_vertices, info.max_actions
    );
    let start = Instant::now();
    let mut t = Totals::default();
    let rooms = activesense_instrument::world::planfile::rooms_for_command(
        a.plan.as_deref(),
        &a.plans_from,
        &a.read,
    )?;
    // Generated plans: one episode per plan seed. The user's rooms: `--episodes` episodes in
    // each, episode seeds episode-seed, episode-seed + 1, ...
    let k = a.episode.options.one_rot_bins(1)?;
    let ep = &a.episode;
    let specs: Vec<(String, EpisodeSpec)> = match &rooms {
        None => (0..a.episode.episodes)
            .map(|i| {
                let seed = a.first_seed.wrapping_add(i);
                Ok((
                    format!("plan {seed}"),
                    spec_for(seed, ep.agent, k, &ep.options)?,
                ))
            })
            .collect::<Result<_>>()?,
        Some((rooms, _)) => {
            let mut v = Vec::new();
            for room in rooms {
                for i in 0..a.episode.episodes {
                    let mut spec = spec_for(room.seed(), ep.agent, k, &ep.options)?;
                    spec.episode_seed = ep.options.episode_seed.wrapping_add(i as u64);
                    spec.user_plan = Some(room.clone());
                    v.push((format!("{} episode {i}", room.name), spec));
                }
            }
            v
        }
    };
    let mut restarts = 0;
    for (label, spec) in &specs {
        let run = run_one(
            &mut link,
            &|| sim_episode(spec),
            a.episode.verify,
            &mut restarts,
        )
        .with_context(|| format!("episode on {label}"))?;
        let (plan, params, _) = sim_episode(spec);
        print_run(label, &run, &plan, &params, &mut t);
        let frame = spec.user_plan.as_ref().map(|p| p.frame.clone());
        print_answer(
            label,
            &run,
            &plan,
            &frame.unwrap_or_default(),
            &params,
            &a.episode,
        );
    }
    let status = link.client.status().context("status")?;
    if status.stack.size > 0 {
        println!(
            "device stack: deepest {} of {} bytes since boot ({} never touched)",
            status.stack.high_water,
            status.stack.size,
            status.stack.size.saturating_sub(status.stack.high_water)
        );
    }
    println!(
        "link: {} frames ok, {} bad, {} sequence errors, {} retransmissions{}",
        status.link.frames_ok,
        status.link.frames_bad,
        status.link.sequence_errors,
        status.link.retransmissions,
        if a.episode.verify {
            "; every episode verified bit-identical to the in-process run"
        } else {
            ""
        }
    );
    print_link_counters(&link, restarts);
    print_totals(&t, start.elapsed().as_secs_f64());
    let (out, raw) = end_session(link, a.episode.shutdown)?;
    if let Some(path) = &a.defmt_out {
        std::fs::write(path, &raw).with_context(|| format!("writing {}", path.display()))?;
    }
    for line in out.lines().filter(|l| !l.trim().is_empty()) {
        println!("device console: {line}");
    }
    Ok(())
}

/// Reads a plan file (our JSON, GeoJSON or DXF, metres; [`activesense_instrument::world::planfile`]) into a
/// model-frame plan.
pub fn read_plan_file(path: &std::path::Path) -> Result<FloorPlan> {
    Ok(
        activesense_instrument::world::planfile::load_plan(path, &Default::default())?
            .plan
            .plan,
    )
}

/// `activesense serial ...`.
pub fn cmd_serial(a: SerialArgs) -> Result<()> {
    match a.command {
        SerialCommand::List => {
            let ports = serialport::available_ports().context("listing serial ports")?;
            if ports.is_empty() {
                println!("no serial ports found");
            }
            for p in ports {
                println!("{}\t{:?}", p.port_name, p.port_type);
            }
            Ok(())
        }
        SerialCommand::Run(r) => {
            let loaded =
                activesense_instrument::world::planfile::load_plan(&r.plan, &r.read.options())?;
            for w in &loaded.warnings {
                eprintln!("warning: {}: {w}", loaded.plan.name);
            }
            let plan = loaded.plan.plan.clone();
            let spec = LinkSpec::Serial {
                path: r.port.clone(),
                baud: r.baud,
            };
            let mut link = open_link(&spec, &[], r.episode.timeout_ms)?;
            let info = link
                .client
                .hello()
                .with_context(|| format!("handshake on {}", r.port))?;
            println!("device: {} (protocol v{})", info.firmware, info.protocol);
            let mut t = Totals::default();
            let start = Instant::now();
            let mut restarts = 0;
            for i in 0..r.episode.episodes {
                let spec = spec_for(
                    0,
                    r.episode.agent,
                    r.episode.options.one_rot_bins(1)?,
                    &r.episode.options,
                )?;
                let world_seed = spec.world_seed() ^ i as u64;
                let mk = || {
                    let mut world =
                        SimWorld::new(plan.clone(), spec.sensor, spec.config, world_seed);
                    let initial_scan = world.scan();
                    let truth = world.truth();
                    let mut params = spec.params(truth, initial_scan);
                    params.seed ^= i as u64;
                    (plan.clone(), params, SimInstrument::new(world))
                };
                let run = run_one(&mut link, &mk, r.episode.verify, &mut restarts)
                    .with_context(|| format!("episode {i} on {}", r.port))?;
                let (p, params, _) = mk();
                print_run(&format!("episode {i}"), &run, &p, &params, &mut t);
                print_answer(
                    &format!("episode {i}"),
                    &run,
                    &p,
                    &loaded.plan.frame,
                    &params,
                    &r.episode,
                );
            }
            if r.episode.verify {
                println!(
                    "every episode verified bit-identical to the in-process run ({} episodes)",
                    t.episodes
                );
            }
            print_link_counters(&link, restarts);
            print_totals(&t, start.elapsed().as_secs_f64());
            // The instrument keeps serving unless --shutdown.
            end_session(link, r.episode.shutdown)?;
            Ok(())
        }
        SerialCommand::Shutdown(s) => {
            let spec = LinkSpec::Serial {
                path: s.port.clone(),
                baud: s.baud,
            };
            let mut link = open_link(&spec, &[], s.timeout_ms)?;
            let info = link
                .client
                .hello()
                .with_context(|| format!("handshake on {}", s.port))?;
            link.shutdown().context("shutting the device down")?;
            println!("{} on {}: shut down", info.firmware, s.port);
            Ok(())
        }
    }
}
