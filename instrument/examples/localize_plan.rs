//! Localize in the room of your own plan file: one simulated episode, the answer printed.
//!
//! `cargo run --release -p activesense-instrument --example localize_plan -- cli/tests/fixtures/plans/l-room.dxf`

use activesense_core::episode::{AgentKind, Termination};
use activesense_instrument::agents::{run_agent_episode, Policies};
use activesense_instrument::answer::Answer;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::world::planfile::{load_plan, LoadOptions};

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .expect("usage: localize_plan PLAN_FILE");
    // JSON, GeoJSON or DXF (docs/PLANS.md); a refused plan says why.
    let room = load_plan(path.as_ref(), &LoadOptions::default())?.plan;
    // The station stands somewhere in the room, heading unknown (K = 10); the agent
    // decides where to point, the calibrated stop when the answer is good enough.
    let mut spec = EpisodeSpec::new(room.seed(), AgentKind::Heuristic1);
    spec.rot_bins = 10;
    spec.termination = Termination::Confident;
    spec.user_plan = Some(room);
    let trajectory = run_agent_episode(&spec, &Policies::default())?;
    // In the plan's own coordinates, with its precision and stated risk.
    print!("{}", Answer::of_trajectory(&trajectory, None).to_text());
    Ok(())
}
