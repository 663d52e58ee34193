//! Drive a GeoCOM total station from code: here the simulated one, on a local TCP port;
//! give `TcpTransport` your instrument's Bluetooth/Wi-Fi bridge (or `SerialTransport` its
//! serial port) to drive a real one.
//!
//! `cargo run --release -p activesense-instrument --example geocom_station -- cli/tests/fixtures/plans/l-room.dxf`

use activesense_core::episode::{AgentKind, EpisodeConfig};
use activesense_instrument::agents::Policies;
use activesense_instrument::geocom::client::{Client, ClientConfig, TcpTransport};
use activesense_instrument::geocom::instrument::{
    run_session, with_policy, GeoComInstrument, SessionSetup,
};
use activesense_instrument::geocom::sim::{serve_tcp, GeoComSim, SimConfig};
use activesense_instrument::world::planfile::{load_plan, LoadOptions};

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .expect("usage: geocom_station PLAN_FILE");
    let room = load_plan(path.as_ref(), &LoadOptions::default())?.plan;
    let config = EpisodeConfig::default();

    // The instrument: a simulator playing the room, served on a free local port.
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    let addr = listener.local_addr()?.to_string();
    let sim = GeoComSim::new(SimConfig {
        plan: room.plan.clone(),
        sensor: Default::default(),
        config,
        world_seed: room.seed() as u64,
        motor_speed: 0.0,
        edm_time: std::time::Duration::ZERO,
        faults: Vec::new(),
    });
    std::thread::spawn(move || serve_tcp(listener, sim));

    // Connect, then let the core decide where to point and when to stop.
    let client = Client::new(
        Box::new(TcpTransport::connect(&addr)?),
        ClientConfig::default(),
    );
    let (mut station, info) = GeoComInstrument::connect(client, config, None)
        .map_err(|failed| anyhow::anyhow!("{}", failed.1))?;
    println!("connected to {} (serial {})", info.name, info.serial);
    let setup = SessionSetup {
        plan: room.plan.clone(),
        agent: AgentKind::Heuristic1,
        agent_seed: 0,
        config,
        sensor: Default::default(),
    };
    let outcome = with_policy(&setup, &Policies::default(), |policy| {
        run_session(&setup, policy, &mut station, &mut |_| {})
    })?
    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let r = outcome.result;
    println!(
        "{} steps; station (room frame) {:?}; stated risk {:?}",
        outcome.steps.len(),
        r.refined.map(|g| g.pose),
        r.stop_risk
    );
    Ok(())
}
