//! `activesense episode`: run one simulated episode with a baseline or the learnt agent and
//! print its step log and outcome; optionally write the trajectory as JSON and an SVG.

use super::options::{parse_agent, EpisodeOptions, SensorArgs};
use super::write_file;
use activesense_core::episode::AgentKind;
use activesense_instrument::agents::{run_agent_episode, Policies};
use activesense_instrument::answer::{parse_heading_hint, Answer, HeadingHint};
use activesense_instrument::episode::{scan_string, EpisodeSpec, Trajectory};
use activesense_instrument::plot::svg::{self, Scene};
use activesense_instrument::world::planfile::{self, PlanReadArgs};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct EpisodeArgs {
    /// Plan seed (u32).
    #[arg(long, required_unless_present = "plan", conflicts_with = "plan")]
    seed: Option<u32>,
    /// Play the episode in the room of this plan file instead of a generated plan (JSON,
    /// GeoJSON or DXF; docs/PLANS.md).
    #[arg(long)]
    plan: Option<PathBuf>,
    #[command(flatten)]
    read: PlanReadArgs,
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
    #[command(flatten)]
    episode: EpisodeOptions,
    #[command(flatten)]
    sensor: SensorArgs,
    /// Write the full trajectory as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write an SVG of the room, agent and measurement beams here.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Write the answer alone as JSON here (the station in the plan's coordinates, its
    /// precision, candidates, ambiguity; `--json` embeds the same object as "answer").
    #[arg(long)]
    answer_json: Option<PathBuf>,
    /// An approximate heading, DEG±TOL (e.g. 160±20; degrees counter-clockwise from the
    /// plan's +x axis, as the answer prints it): breaks the tie between the poses a
    /// symmetric room leaves when the heading is unknown (from the instrument's compass or
    /// the site plan).
    #[arg(long, value_parser = parse_heading_hint, allow_hyphen_values = true)]
    heading_hint: Option<HeadingHint>,
    /// Print only the summary, not every step.
    #[arg(long)]
    quiet: bool,
}

/// Runs one episode and prints its log (or, with `--quiet`, its summary) and outcome.
pub fn run(a: EpisodeArgs) -> Result<()> {
    let spec = spec_of(&a)?;
    let (policies, t) = play(&a, &spec)?;
    print_log(&spec, &t, &policies, a.quiet);
    print_outcome(&t);
    let answer = Answer::of_trajectory(&t, a.heading_hint);
    print!("{}", answer.to_text());
    write_outputs(&a, &spec, &t, &answer)
}

/// The episode the options describe (a generated plan or the user's room).
fn spec_of(a: &EpisodeArgs) -> Result<EpisodeSpec> {
    let rot_bins = a.episode.one_rot_bins(1)?;
    let user_plan = match &a.plan {
        Some(p) => {
            let rooms = planfile::rooms_for_command(Some(p), &[], &a.read)?;
            rooms.and_then(|(mut r, _)| r.pop())
        }
        None => None,
    };
    Ok(EpisodeSpec {
        plan_seed: match &user_plan {
            Some(p) => p.seed(),
            None => a.seed.unwrap_or_default(),
        },
        user_plan,
        episode_seed: a.episode.episode_seed,
        agent: a.agent,
        rot_bins,
        config: a.episode.config(),
        sensor: a.episode.sensor(a.sensor.model()?),
        termination: a.episode.termination,
    })
}

/// Loads the policy the agent needs and plays the episode.
fn play(a: &EpisodeArgs, spec: &EpisodeSpec) -> Result<(Policies, Trajectory)> {
    let mut policies = Policies::default();
    match spec.agent {
        AgentKind::Learnt => {
            policies = Policies::load_for(
                spec.config.instrument,
                a.policy.as_slice(),
                &[spec.rot_bins],
            )?
        }
        AgentKind::LearntInt8 => {
            policies.load_int8_for(spec.config.instrument, a.int8.as_slice(), &[spec.rot_bins])?
        }
        _ => {}
    }
    // The learnt float policy's episodes carry the inspection data (`activesense inspect`).
    let t = match policies.for_rot_bins(spec.rot_bins) {
        Some(p) if spec.agent == AgentKind::Learnt => {
            activesense_lab::inspect::record_episode(spec, p)
        }
        _ => run_agent_episode(spec, &policies)?,
    };
    Ok((policies, t))
}

/// The policies used, the episode's header and truth, and (unless `quiet`) every step.
fn print_log(spec: &EpisodeSpec, t: &Trajectory, policies: &Policies, quiet: bool) {
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
    if !quiet {
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
                (None, activesense_core::episode::Action::Measure) => "no return".into(),
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
}

/// How the episode ended: recognition, coarse and refined estimates, the stop's risk.
fn print_outcome(t: &Trajectory) {
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
    let answer_is_refined = t.spec.termination
        == activesense_instrument::episode::Termination::Confident
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
        println!(
            "{what}  {}  pose distance {:.3} m (model frame)",
            fmt_pose(&c),
            e
        );
    }
    match (&o.refined, o.pose_error) {
        (Some(r), Some(e)) => println!(
            "refined estimate: {}  pose distance {:.4} m (model frame; position and heading in one number, modulo the room's symmetry: the benchmark's score; the answer below gives them apart), registration rms {:.4} m over {} inliers",
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
            "the stop model's raw estimate: {:.2} % (for a stated risk of {:.2} % the confident stop stops where the estimate × 8 / readings is below {:.2} %)",
            100.0 * r,
            100.0 * t.spec.config.stop_risk,
            100.0
                * activesense_core::stop::StopModel::built_in(
                    t.spec.config.instrument,
                    t.spec.rot_bins
                )
                .threshold_for(t.spec.agent, t.spec.config.stop_risk)
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
}

/// The trajectory JSON (`--json`) and the episode picture (`--svg`).
fn write_outputs(
    a: &EpisodeArgs,
    spec: &EpisodeSpec,
    t: &Trajectory,
    answer: &Answer,
) -> Result<()> {
    let o = &t.outcome;
    if let Some(path) = &a.json {
        // The trajectory with the answer beside it (`inspect` reads the trajectory and
        // ignores the extra member).
        #[derive(serde::Serialize)]
        struct WithAnswer<'a> {
            #[serde(flatten)]
            trajectory: &'a Trajectory,
            answer: &'a Answer,
        }
        let value = WithAnswer {
            trajectory: t,
            answer,
        };
        // The inspection arrays (K × 900 floats per step) are written compactly.
        let text = if t.inspection.is_some() {
            serde_json::to_string(&value)?
        } else {
            serde_json::to_string_pretty(&value)?
        };
        write_file(path, &text)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &a.answer_json {
        write_file(path, &serde_json::to_string_pretty(answer)?)?;
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
            trajectory: Some(t),
            estimate: o.refined.map(|r| r.pose),
        };
        write_file(path, &svg::render(&t.plan, &scene))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
