//! The episode runner (paper §3.1, §4.2): one agent in one simulated room, action by
//! action, until the action limit (or, once a localizer is attached, coarse success), with
//! the full trajectory recorded for inspection (the paper's §3.5 "minimal state
//! trajectory") and serialised as JSON.
//!
//! Seeds: an episode is fully determined by its [`EpisodeSpec`]. The world (placement and
//! sensor noise) and the agent draw from independent streams derived from
//! `(plan_seed, episode_seed)` by SplitMix64, so changing the agent never changes the room or
//! the noise it meets.

use crate::plans;
use crate::sensor::{RangeKind, SensorModel};
use crate::world::{Placement, SimWorld};
use activesense_core::agents::{Action, AgentKind, BaselineAgent};
use activesense_core::episode::{EpisodeConfig, EpisodeState};
use activesense_core::{FloorPlan, Pose2};
use serde::{Deserialize, Serialize};

/// Everything that determines one episode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeSpec {
    /// Floor-plan seed (see [`plans`]).
    pub plan_seed: u32,
    /// Episode seed (placement, noise, agent randomness).
    pub episode_seed: u64,
    /// The acting agent.
    pub agent: AgentKind,
    /// Rotation bins of the localizer (1 = heading known).
    pub rot_bins: u8,
    /// Episode configuration (rotation step, action limit, costs).
    pub config: EpisodeConfig,
    /// Sensor parameters.
    pub sensor: SensorModel,
}

impl EpisodeSpec {
    /// Evaluation defaults (Table 4): 100 actions, 2π/54 rotation step, default sensor.
    pub fn new(plan_seed: u32, agent: AgentKind) -> Self {
        EpisodeSpec {
            plan_seed,
            episode_seed: 0,
            agent,
            rot_bins: 1,
            config: EpisodeConfig::default(),
            sensor: SensorModel::default(),
        }
    }

    /// Seed of the world stream.
    pub fn world_seed(&self) -> u64 {
        splitmix64(splitmix64(self.plan_seed as u64) ^ self.episode_seed ^ 0x0077_6f72_6c64)
    }

    /// Seed of the agent stream.
    pub fn agent_seed(&self) -> u64 {
        splitmix64(splitmix64(self.plan_seed as u64 ^ 0xa9e7) ^ self.episode_seed)
    }
}

/// SplitMix64 finaliser: decorrelates nearby seeds.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// One recorded step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// 0-based step index.
    pub step: u16,
    /// The action taken.
    pub action: Action,
    /// Encoder bearing index after the action.
    pub bearing_index: u16,
    /// Encoder bearing after the action (rad, scene frame).
    pub bearing: f32,
    /// Range returned (measurements with a return only).
    pub range: Option<f32>,
    /// How the range arose (simulation truth; the device never sees it).
    pub range_kind: Option<RangeKind>,
    /// Topological scan after the action, one bit per pixel.
    pub scan: u32,
    /// Model-frame beam direction after the action (simulation truth).
    pub world_bearing: f32,
    /// Accumulated cost after the action.
    pub cost: f32,
}

/// Why an episode ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EndReason {
    /// The action limit was reached.
    ActionLimit,
}

/// A complete episode.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Trajectory {
    /// What was run.
    pub spec: EpisodeSpec,
    /// The room (model frame).
    pub plan: FloorPlan,
    /// Visual centre and placement radius.
    pub placement: Placement,
    /// Ground-truth AgentPose (scene→model).
    pub truth: Pose2,
    /// Scan at the start, before any action.
    pub initial_scan: u32,
    /// Every step.
    pub steps: Vec<StepRecord>,
    /// Final counts and cost.
    pub summary: EpisodeState,
    /// Why it ended.
    pub end: EndReason,
}

/// Runs one episode to its end and records it.
pub fn run_episode(spec: &EpisodeSpec) -> Trajectory {
    let plan = plans::generate(spec.plan_seed);
    let mut world = SimWorld::new(plan.clone(), spec.sensor, spec.config, spec.world_seed());
    let mut agent = BaselineAgent::new(spec.agent, spec.agent_seed());
    let mut state = EpisodeState::new(spec.config);
    let initial_scan = world.scan();
    let mut steps = Vec::with_capacity(spec.config.max_actions as usize);
    while !state.exhausted() {
        let action = agent.next_action();
        state.apply(action);
        let (obs, truth) = world.act(action);
        steps.push(StepRecord {
            step: state.actions - 1,
            action,
            bearing_index: state.bearing_index,
            bearing: state.bearing(),
            range: obs.range,
            range_kind: truth.range_kind,
            scan: obs.scan,
            world_bearing: truth.world_bearing,
            cost: state.cost,
        });
    }
    Trajectory {
        spec: spec.clone(),
        truth: world.truth(),
        placement: world.placement(),
        plan,
        initial_scan,
        steps,
        summary: state,
        end: EndReason::ActionLimit,
    }
}

/// Renders a scan bit mask as 20 characters, pixel 0 (clockwise edge) on the right so the
/// picture reads like the view: `#` = junction, `.` = none.
pub fn scan_string(mask: u32) -> String {
    (0..activesense_core::episode::SCAN_PIXELS)
        .rev()
        .map(|i| if mask & (1 << i) != 0 { '#' } else { '.' })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_complete() {
        let mut spec = EpisodeSpec::new(plans::TEST_SEEDS.start + 3, AgentKind::Blind2);
        spec.episode_seed = 9;
        let a = serde_json::to_string(&run_episode(&spec)).unwrap();
        let b = serde_json::to_string(&run_episode(&spec)).unwrap();
        assert_eq!(a, b);
        let t = run_episode(&spec);
        assert_eq!(t.steps.len(), 100);
        assert_eq!(
            t.summary.measurements as usize,
            t.steps
                .iter()
                .filter(|s| s.action == Action::Measure)
                .count()
        );
        spec.episode_seed = 10;
        assert_ne!(a, serde_json::to_string(&run_episode(&spec)).unwrap());
    }

    #[test]
    fn measurements_match_geometry() {
        // With no noise and no outliers every returned range equals the ray cast along the
        // true beam direction.
        let mut spec = EpisodeSpec::new(plans::TEST_SEEDS.start, AgentKind::Heuristic0);
        spec.sensor.sigma = 0.0;
        spec.sensor.outlier_prob = 0.0;
        let t = run_episode(&spec);
        let a = t.truth.translation();
        let mut checked = 0;
        for s in &t.steps {
            if let Some(r) = s.range {
                let hit = t
                    .plan
                    .ray_cast(a, activesense_core::geometry::unit(s.world_bearing))
                    .unwrap();
                assert!((hit.range - r).abs() < 1e-3, "{} vs {r}", hit.range);
                checked += 1;
            }
        }
        assert!(checked > 10);
    }
}
