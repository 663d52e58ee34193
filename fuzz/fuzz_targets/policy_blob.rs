//! Fuzz target: the int8 policy blob parser (`QuantizedPolicy::parse`) and, for whatever it
//! accepts, one decision on a fixed episode state. Neither may panic on any bytes.
#![no_main]

use activesense_core::agents::{AgentKind, BaselineAgent};
use activesense_core::episode::EpisodeConfig;
use activesense_core::geometry::v2;
use activesense_core::pipeline::{PipelineParams, Termination};
use activesense_core::quantized::{QuantizedPolicy, Scratch};
use activesense_core::runner::EpisodeRunner;
use activesense_core::FloorPlan;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(policy) = QuantizedPolicy::parse(data) else {
        return;
    };
    let plan = FloorPlan::new(&[v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)])
        .expect("square")
        .centered();
    let mut runner = Box::new(EpisodeRunner::new_empty());
    let params = PipelineParams {
        rot_bins: policy.rot_bins().clamp(1, 10),
        known_heading: Some(0.0),
        ground_truth: None,
        termination: Termination::ActionLimit,
        registration_seed: 1,
    };
    if runner
        .start(&plan, &params, EpisodeConfig::default(), 0b101)
        .is_err()
    {
        return;
    }
    let mut scratch = Box::new(Scratch::new());
    let _ = policy.decide(&runner.input(), &mut scratch);
    let _ = BaselineAgent::new(AgentKind::Heuristic1, 1);
});
