//! THE one parameter type of an episode, [`EpisodeParams`]: what the host sends in the
//! protocol's `StartEpisode`, what the device's controller hands straight to
//! [`crate::pipeline::runner::EpisodeRunner::start`], and what the host's in-process
//! episode builds from its `EpisodeSpec` (one conversion per side). With it: the stop rule
//! ([`Termination`]), the one validity check ([`EpisodeParams::check`], typed
//! [`ParamError`]s) and the registration seed's derivation ([`registration_seed`]).
//!
//! **Wire form.** Its serde form is the `StartEpisode` payload: postcard fields in the
//! order agent, seed, steps_per_turn, max_actions, rot_bins, known_heading, ground_truth,
//! initial_scan, termination, stop_risk, min_observability (protocol v5's payload, byte for
//! byte) and, since protocol v9, the instrument profile. The action costs are not on the
//! wire (the device uses [`ActionCosts::default`]), so the (de)serialisation is written by
//! hand (a test vector from protocol v5 pins the bytes before the profile).

use super::{ActionCosts, AgentKind, EpisodeConfig};
use crate::limits::{MAX_EPISODE_ACTIONS, MAX_ROT_BINS};
use crate::world::geometry::Pose2;
use crate::world::math::splitmix64;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeStruct, Serializer};
use serde::{Deserialize, Serialize};

/// Largest accepted `steps_per_turn` (rotation step 0.1°).
pub const MAX_STEPS_PER_TURN: u16 = 3600;

/// When an episode stops (besides the action limit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Termination {
    /// On coarse success against the ground truth (the paper's rule; simulation only).
    Oracle,
    /// When the calibrated estimate of P(wrong registration) is below
    /// [`EpisodeConfig::stop_risk`] ([`crate::stop`]); no ground truth used. The answer is
    /// the refined pose, scored by the cell it lies in
    /// ([`crate::pipeline::Pipeline::answer_cell`]).
    Confident,
    /// Never: run to the action limit.
    ActionLimit,
}

impl Termination {
    /// Lowercase name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Termination::Oracle => "oracle",
            Termination::Confident => "confident",
            Termination::ActionLimit => "action-limit",
        }
    }
}

/// Why an [`EpisodeParams`] was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ParamError {
    /// `steps_per_turn` is 0 or above 3600.
    StepsPerTurn,
    /// `max_actions` is 0 or above [`MAX_EPISODE_ACTIONS`].
    MaxActions,
    /// `rot_bins` is 0 or above [`MAX_ROT_BINS`].
    RotBins,
    /// `rot_bins == 1` without a `known_heading`.
    KnownHeadingRequired,
    /// `known_heading` or `ground_truth` is NaN/inf.
    NonFinite,
    /// The ground-truth position lies outside the plan.
    GroundTruthOutside,
    /// Oracle termination without a ground truth.
    GroundTruthRequired,
    /// The localizer cannot take this plan (not centred on its perimeter centroid, or
    /// more perimeter than its R-table holds).
    PlanNotLocalizable,
    /// The requested agent does not run on this device (the learnt policy, until the
    /// device carries one).
    AgentUnavailable,
    /// `stop_risk` is NaN, infinite, not above 0 or above 1.
    InvalidStopRisk,
    /// `min_observability` is NaN, infinite, below 0 or above 1.
    InvalidObservability,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ParamError::StepsPerTurn => "steps per turn must be 1..=3600",
            ParamError::MaxActions => "the action limit is 0 or above the device's maximum",
            ParamError::RotBins => "rotation bins out of the localizer's range",
            ParamError::KnownHeadingRequired => "K = 1 needs the known heading",
            ParamError::NonFinite => "known heading or ground truth is NaN or infinite",
            ParamError::GroundTruthOutside => "the ground-truth position lies outside the plan",
            ParamError::GroundTruthRequired => "oracle termination needs a ground truth",
            ParamError::PlanNotLocalizable => {
                "the localizer cannot take this plan (not centred, or too much perimeter)"
            }
            ParamError::AgentUnavailable => "this agent does not run on the device",
            ParamError::InvalidStopRisk => "stop risk must be finite, above 0 and at most 1",
            ParamError::InvalidObservability => {
                "minimum observability must be finite and within 0..=1"
            }
        })
    }
}

/// Parameters of one episode (besides the plan).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpisodeParams {
    /// The deciding agent.
    pub agent: AgentKind,
    /// Seed of the agent's PRNG; the registration seed derives from it
    /// ([`EpisodeParams::registration_seed`]).
    pub seed: u64,
    /// Rotation bins K of the localizer, 1..=[`MAX_ROT_BINS`]; K = 1 means the heading is
    /// known and needs `known_heading`.
    pub rot_bins: u8,
    /// The model-frame heading of encoder bearing 0 when orientation is known (K = 1).
    pub known_heading: Option<f32>,
    /// Simulation only: the true AgentPose (scene→model): oracle termination and the
    /// `recognised` statistic need it.
    pub ground_truth: Option<Pose2>,
    /// The instrument's topological scan before the first action.
    pub initial_scan: u32,
    /// When the episode stops early ([`Termination::Oracle`] needs `ground_truth`).
    pub termination: Termination,
    /// Rotation step, action limit (1..=[`MAX_EPISODE_ACTIONS`]), costs and the stop rule's
    /// settings (`stop_risk`: finite, 0 < P <= 1; `min_observability`: finite,
    /// 0 <= τ <= 1, 0 = off; both on the wire since protocol v4).
    pub config: EpisodeConfig,
}

/// The registration seed both sides derive from the episode's agent seed (SplitMix64 of a
/// tagged seed, so it is decorrelated from the agent's own stream).
pub const fn registration_seed(agent_seed: u64) -> u64 {
    splitmix64(agent_seed ^ 0x7265_6769_7374_6572) // "register"
}

impl EpisodeParams {
    /// True when the heading is known (K = 1).
    pub fn heading_known(&self) -> bool {
        self.rot_bins == 1
    }

    /// The known heading when K = 1 (0 otherwise, or when it is missing).
    pub fn heading(&self) -> f32 {
        match (self.heading_known(), self.known_heading) {
            (true, Some(h)) => h,
            _ => 0.0,
        }
    }

    /// Seed of the registration's perturbations ([`registration_seed`] of `seed`).
    pub fn registration_seed(&self) -> u64 {
        registration_seed(self.seed)
    }

    /// The one validity check of the parameters alone (the device adds the checks that
    /// need its state: agent availability, ground truth inside the loaded plan):
    /// [`EpisodeParams::check_limits`], then [`EpisodeParams::check_poses`].
    pub fn check(&self) -> Result<(), ParamError> {
        self.check_limits()?;
        self.check_poses()
    }

    /// Rotation step, action limit, K range and the stop rule (the first half of
    /// [`EpisodeParams::check`]; the device checks the agent between the two halves).
    pub fn check_limits(&self) -> Result<(), ParamError> {
        let c = &self.config;
        if c.steps_per_turn == 0 || c.steps_per_turn > MAX_STEPS_PER_TURN {
            return Err(ParamError::StepsPerTurn);
        }
        if c.max_actions == 0 || c.max_actions > MAX_EPISODE_ACTIONS {
            return Err(ParamError::MaxActions);
        }
        if self.rot_bins == 0 || self.rot_bins as usize > MAX_ROT_BINS {
            return Err(ParamError::RotBins);
        }
        self.check_stop_rule()
    }

    /// The check of [`EpisodeConfig::stop_risk`] and [`EpisodeConfig::min_observability`]
    /// (NaN and infinities are refused).
    pub fn check_stop_rule(&self) -> Result<(), ParamError> {
        let c = &self.config;
        if !(c.stop_risk.is_finite() && c.stop_risk > 0.0 && c.stop_risk <= 1.0) {
            return Err(ParamError::InvalidStopRisk);
        }
        if !(c.min_observability.is_finite() && (0.0..=1.0).contains(&c.min_observability)) {
            return Err(ParamError::InvalidObservability);
        }
        Ok(())
    }

    /// The known heading (finite, and present when K = 1) and the ground truth (finite).
    /// A heading sent with K > 1 is ignored, as in protocol v5.
    pub fn check_poses(&self) -> Result<(), ParamError> {
        match self.known_heading {
            Some(h) if !h.is_finite() => return Err(ParamError::NonFinite),
            None if self.heading_known() => return Err(ParamError::KnownHeadingRequired),
            _ => {}
        }
        if self.ground_truth.is_some_and(|gt| !gt.is_finite()) {
            return Err(ParamError::NonFinite);
        }
        Ok(())
    }
}

const FIELDS: [&str; 12] = [
    "agent",
    "seed",
    "steps_per_turn",
    "max_actions",
    "rot_bins",
    "known_heading",
    "ground_truth",
    "initial_scan",
    "termination",
    "stop_risk",
    "min_observability",
    "instrument",
];

impl Serialize for EpisodeParams {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("EpisodeParams", FIELDS.len())?;
        st.serialize_field(FIELDS[0], &self.agent)?;
        st.serialize_field(FIELDS[1], &self.seed)?;
        st.serialize_field(FIELDS[2], &self.config.steps_per_turn)?;
        st.serialize_field(FIELDS[3], &self.config.max_actions)?;
        st.serialize_field(FIELDS[4], &self.rot_bins)?;
        st.serialize_field(FIELDS[5], &self.known_heading)?;
        st.serialize_field(FIELDS[6], &self.ground_truth)?;
        st.serialize_field(FIELDS[7], &self.initial_scan)?;
        st.serialize_field(FIELDS[8], &self.termination)?;
        st.serialize_field(FIELDS[9], &self.config.stop_risk)?;
        st.serialize_field(FIELDS[10], &self.config.min_observability)?;
        st.serialize_field(FIELDS[11], &self.config.instrument)?;
        st.end()
    }
}

impl<'de> Deserialize<'de> for EpisodeParams {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = EpisodeParams;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("the 12 fields of a StartEpisode")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<EpisodeParams, A::Error> {
                let mut i = 0;
                let mut next = || {
                    i += 1;
                    i - 1
                };
                macro_rules! field {
                    () => {{
                        let n = next();
                        a.next_element()?
                            .ok_or_else(|| de::Error::invalid_length(n, &self))?
                    }};
                }
                let agent = field!();
                let seed = field!();
                let steps_per_turn = field!();
                let max_actions = field!();
                let rot_bins = field!();
                let known_heading = field!();
                let ground_truth = field!();
                let initial_scan = field!();
                let termination = field!();
                let stop_risk = field!();
                let min_observability = field!();
                let instrument = field!();
                Ok(EpisodeParams {
                    agent,
                    seed,
                    rot_bins,
                    known_heading,
                    ground_truth,
                    initial_scan,
                    termination,
                    config: EpisodeConfig {
                        steps_per_turn,
                        max_actions,
                        costs: ActionCosts::default(),
                        min_observability,
                        stop_risk,
                        instrument,
                    },
                })
            }
        }
        d.deserialize_struct("EpisodeParams", &FIELDS, V)
    }
}

#[cfg(test)]
mod tests;
