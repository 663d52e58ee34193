//! The station on rooms that are not generated plans: every room of the plan files given
//! (default: the fixtures `cli/tests/fixtures/plans/` and `plans/features/` (columns and
//! doors), and the hand-drawn `lab/fixtures/rooms/`, one of them in national-grid
//! coordinates), `--episodes N` setups
//! each (episode seeds 0..N: where the instrument stands, the noise), played by the GeoCOM
//! station session against the GeoCOM simulator's world in process (the TCP path gives the
//! same answers bit for bit: `tests/tests/geocom.rs`), on `--instrument` (default `edm`,
//! what GeoCOM instruments are), calibrated stop at `--stop-risk` (default 1 %), K = 10.
//! Prints, per agent: right, wrong (of answered), unanswered, measurements, cost; on stderr
//! each wrong and each unanswered setup (room, episode seed, and for the unanswered the
//! measurements and actions it took).
//!
//! `--site furnished|site` plays each room furnished or as a building site (the simulator's
//! world; the station is given the plan, `docs/WORLD.md`, "Sites").
//!
//! `cargo run --release -p activesense-lab --example station_sweep -- [--episodes 10] [--agents learnt-int8,heuristic-1] [--instrument edm] [--site plan] [FILES...]`

use activesense_core::episode::{AgentKind, EpisodeConfig, InstrumentProfile};
use activesense_core::registration::pose_distance::{PoseDistance, Tolerance};
use activesense_core::world::symmetry::SymmetryTolerance;
use activesense_instrument::agents::Policies;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::geocom::instrument::{reference_session, SessionSetup, ROT_BINS};
use activesense_instrument::world::planfile::{load_rooms, LoadOptions};
use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::site::SiteLevel;
use activesense_instrument::world::SimWorld;
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut episodes = 10u64;
    let mut agents = vec![AgentKind::LearntInt8, AgentKind::Heuristic1];
    let mut instrument = InstrumentProfile::Edm;
    let mut stop_risk = activesense_core::limits::DEFAULT_STOP_RISK;
    let mut site = SiteLevel::Plan;
    let mut files: Vec<PathBuf> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .ok_or_else(|| anyhow::anyhow!("{a} needs a value"))
        };
        match a.as_str() {
            "--episodes" => episodes = value()?.parse()?,
            "--stop-risk" => stop_risk = value()?.parse()?,
            "--site" => site = SiteLevel::parse(&value()?).map_err(anyhow::Error::msg)?,
            "--instrument" => {
                let v = value()?;
                instrument = InstrumentProfile::from_name(&v)
                    .ok_or_else(|| anyhow::anyhow!("unknown instrument {v}"))?
            }
            "--agents" => {
                agents = value()?
                    .split(',')
                    .map(|n| {
                        AgentKind::from_name(n).ok_or_else(|| anyhow::anyhow!("unknown agent {n}"))
                    })
                    .collect::<anyhow::Result<_>>()?
            }
            _ => files.push(a.into()),
        }
    }
    if files.is_empty() {
        for dir in [
            "cli/tests/fixtures/plans",
            "cli/tests/fixtures/plans/features",
            "lab/fixtures/rooms",
        ] {
            let mut f: Vec<PathBuf> = std::fs::read_dir(dir)?
                .map(|e| e.map(|e| e.path()))
                .collect::<Result<_, _>>()?;
            f.retain(|p| p.extension().is_some_and(|x| x != "md"));
            f.sort();
            files.extend(f);
        }
    }
    let mut rooms = Vec::new();
    for f in &files {
        for r in load_rooms(f, &LoadOptions::default())? {
            rooms.push((format!("{} {}", f.display(), r.plan.name), r.plan));
        }
    }
    let mut policies = Policies::default();
    if agents.contains(&AgentKind::Learnt) {
        policies = Policies::load_for(instrument, &[], &[ROT_BINS])?;
    }
    if agents.contains(&AgentKind::LearntInt8) {
        policies.load_int8_for(instrument, &[], &[ROT_BINS])?;
    }
    let mut config = EpisodeConfig::default().on(instrument);
    config.stop_risk = stop_risk;
    println!(
        "{} rooms from {} files, {episodes} setups each, --instrument {}, --site {}, --stop-risk {stop_risk}, K = {ROT_BINS}\n",
        rooms.len(),
        files.len(),
        instrument.name(),
        site.name()
    );
    println!("| agent | setups | right | wrong (of answered) | unanswered | measurements | cost |");
    println!("|---|---|---|---|---|---|---|");
    for &agent in &agents {
        let (mut right, mut wrong, mut unanswered, mut meas, mut cost, mut n) =
            (0u32, 0u32, 0u32, 0u64, 0f64, 0u32);
        for (label, room) in &rooms {
            let distance = PoseDistance::new(&room.plan, &SymmetryTolerance::default());
            for e in 0..episodes {
                let mut spec = EpisodeSpec::new(room.seed(), agent);
                spec.episode_seed = e;
                let setup = SessionSetup {
                    plan: room.plan.clone(),
                    agent,
                    agent_seed: spec.agent_seed(),
                    config,
                    sensor: SensorModel {
                        site,
                        ..Default::default()
                    },
                };
                let o = reference_session(&setup, &policies, spec.world_seed())
                    .map_err(|err| anyhow::anyhow!("{label}: {err}"))?;
                let truth =
                    SimWorld::new(room.plan.clone(), setup.sensor, config, spec.world_seed())
                        .truth();
                n += 1;
                meas += u64::from(o.state.measurements);
                cost += f64::from(o.state.cost);
                if o.stop.is_none() {
                    eprintln!(
                        "unanswered: {label}, episode seed {e}, {}, {} measurements, {} actions",
                        agent.name(),
                        o.state.measurements,
                        o.state.actions
                    );
                    unanswered += 1;
                    continue;
                }
                let ok = o.result.refined.is_some_and(|r| {
                    Tolerance::SURVEYOR.admits(&distance.agent_errors(&r.pose, &truth))
                });
                if ok {
                    right += 1;
                } else {
                    wrong += 1;
                    eprintln!("wrong: {label}, episode seed {e}, {}", agent.name());
                }
            }
        }
        let answered = right + wrong;
        println!(
            "| {} | {n} | {:.3} | {wrong} ({:.1} %) | {:.3} | {:.2} | {:.3} |",
            agent.name(),
            f64::from(right) / f64::from(n.max(1)),
            100.0 * f64::from(wrong) / f64::from(answered.max(1)),
            f64::from(unanswered) / f64::from(n.max(1)),
            meas as f64 / f64::from(n.max(1)),
            cost / f64::from(n.max(1)),
        );
    }
    Ok(())
}
