//! What an episode is (§3.1, §4.2), shared by the host runner and the firmware session:
//! the actions and their costs ([`actions`]), what the instrument reports ([`Observation`],
//! [`ObservationError`]), the episode's fixed configuration ([`EpisodeConfig`], with the
//! [`InstrumentProfile`] it runs on), THE one
//! parameter type of an episode ([`EpisodeParams`], in [`params`]: what the host sends in
//! `StartEpisode` and what [`crate::pipeline::Pipeline::start`] takes) and the
//! instrument-side bookkeeping ([`EpisodeState`]). Imports only [`crate::limits`] and
//! [`crate::world`].
//!
//! An episode is a sequence of discrete actions (rotate-left, rotate-right, measure), each
//! with a cost, until the coarse localization succeeds or the action limit is reached.
//! [`EpisodeState`] tracks what the *instrument* knows: its encoder bearing (an integer
//! number of rotation steps), the counts and the accumulated cost. It does not know the
//! ground truth. Both sides use it, so host and device agree on every bearing bit for bit.

pub mod actions;
pub mod params;

pub use crate::limits::{DEFAULT_STEPS_PER_TURN, EVAL_MAX_ACTIONS, SCAN_PIXELS, TRAIN_MAX_ACTIONS};
pub use actions::{Action, ActionCosts, AgentKind};
pub use params::{registration_seed, EpisodeParams, ParamError, Termination};

use crate::world::math::{wrap_angle, TAU};
use serde::{Deserialize, Serialize};

/// Field of view of one topological scan (§4.1): 45°.
pub const SCAN_FOV: f32 = core::f32::consts::FRAC_PI_4;

/// What the instrument reports after one action.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// Range (m) for a measurement action that returned; `None` for a rotation or a
    /// measurement without return (beyond maximum range or incidence).
    pub range: Option<f32>,
    /// Topological scan at the bearing *after* the action: bit `i` is pixel `i`
    /// (pixel 0 at the clockwise edge of the field of view).
    pub scan: u32,
}

/// Why an observation was rejected (the episode stays at the same step).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObservationError {
    /// The range is NaN or infinite.
    NonFiniteRange,
    /// The range is negative.
    NegativeRange,
    /// A rotation action reported a range.
    RangeOnRotation,
    /// Scan bits beyond [`SCAN_PIXELS`] are set.
    ScanBits,
}

impl core::fmt::Display for ObservationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ObservationError::NonFiniteRange => "the range is NaN or infinite",
            ObservationError::NegativeRange => "the range is negative",
            ObservationError::RangeOnRotation => "a rotation reported a range",
            ObservationError::ScanBits => "scan bits beyond the scan's pixels are set",
        })
    }
}

impl Observation {
    /// Checks an instrument answer to `action`: no scan bits beyond [`SCAN_PIXELS`], a
    /// range only after a measurement, and then finite and not negative.
    pub fn validate(&self, action: Action) -> Result<(), ObservationError> {
        if self.scan >> SCAN_PIXELS != 0 {
            return Err(ObservationError::ScanBits);
        }
        if let Some(range) = self.range {
            if action != Action::Measure {
                return Err(ObservationError::RangeOnRotation);
            }
            if !range.is_finite() {
                return Err(ObservationError::NonFiniteRange);
            }
            if range < 0.0 {
                return Err(ObservationError::NegativeRange);
            }
        }
        Ok(())
    }

    /// Packs scan pixels into the bit mask.
    pub fn pack_scan(pixels: &[bool; SCAN_PIXELS]) -> u32 {
        pixels
            .iter()
            .enumerate()
            .fold(0u32, |m, (i, &p)| if p { m | (1 << i) } else { m })
    }
}

/// What the instrument senses, which decides the policy and the stop's tables that belong to
/// it. The total stations surveyors own (Leica TPS over GeoCOM) have a motor and a
/// reflectorless EDM and no camera: [`InstrumentProfile::Edm`]. The paper's sensor adds the
/// topological camera scan: [`InstrumentProfile::EdmScan`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum InstrumentProfile {
    /// EDM ranges and the topological scan (the paper's sensor).
    #[default]
    EdmScan,
    /// EDM ranges only: the scan is always empty.
    Edm,
}

impl InstrumentProfile {
    /// Both profiles, in wire order.
    pub const ALL: [InstrumentProfile; 2] = [InstrumentProfile::EdmScan, InstrumentProfile::Edm];

    /// The name on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            InstrumentProfile::EdmScan => "edm+scan",
            InstrumentProfile::Edm => "edm",
        }
    }

    /// The profile called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The byte that names the profile in an int8 policy blob (`docs/policy-blob.md`).
    pub const fn code(self) -> u8 {
        match self {
            InstrumentProfile::EdmScan => 0,
            InstrumentProfile::Edm => 1,
        }
    }

    /// The profile of blob byte `code`.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(InstrumentProfile::EdmScan),
            1 => Some(InstrumentProfile::Edm),
            _ => None,
        }
    }

    /// Whether the instrument has the camera that makes the topological scan.
    pub const fn has_scan(self) -> bool {
        matches!(self, InstrumentProfile::EdmScan)
    }

    /// The paper's sensor (left out of JSON, the default).
    pub fn is_edm_scan(&self) -> bool {
        *self == InstrumentProfile::EdmScan
    }
}

/// Fixed parameters of one episode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeConfig {
    /// Rotation steps per full turn (rotation step = 2π / this).
    pub steps_per_turn: u16,
    /// Episode ends after this many actions at the latest.
    pub max_actions: u16,
    /// Per-action costs.
    pub costs: ActionCosts,
    /// The pipeline's observability stop test
    /// ([`crate::pipeline::Pipeline::observability`]); 0 = off (the default; the
    /// protocol carries it since v4, so the instrument runs the same). Left out of JSON when 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub min_observability: f32,
    /// The confident stop's stated risk ([`crate::stop`]): [`Termination::Confident`] stops
    /// once the estimated probability that the registration is wrong is below the threshold
    /// calibrated for it ([`crate::stop::StopModel::threshold_for`]). Finite, in (0, 1].
    #[serde(default = "default_stop_risk")]
    pub stop_risk: f32,
    /// What the instrument senses (the scan is empty without a camera), and so which
    /// policy and stop tables belong to the episode. Left out of JSON for the paper's sensor.
    #[serde(default, skip_serializing_if = "InstrumentProfile::is_edm_scan")]
    pub instrument: InstrumentProfile,
}

fn default_stop_risk() -> f32 {
    crate::limits::DEFAULT_STOP_RISK
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

impl Default for EpisodeConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl EpisodeConfig {
    /// The evaluation defaults (Table 4): 2π/54 rotation step, 100 actions, the §4.2
    /// costs, the observability test off, [`crate::limits::DEFAULT_STOP_RISK`]. A `const`
    /// so an idle runner can live in a `static`.
    pub const DEFAULT: EpisodeConfig = EpisodeConfig {
        steps_per_turn: DEFAULT_STEPS_PER_TURN,
        max_actions: EVAL_MAX_ACTIONS,
        costs: ActionCosts::DEFAULT,
        min_observability: 0.0,
        stop_risk: crate::limits::DEFAULT_STOP_RISK,
        instrument: InstrumentProfile::EdmScan,
    };

    /// This configuration on `instrument`.
    pub const fn on(mut self, instrument: InstrumentProfile) -> Self {
        self.instrument = instrument;
        self
    }

    /// Rotation step in radians.
    pub fn rot_step(&self) -> f32 {
        TAU / self.steps_per_turn.max(1) as f32
    }
}

/// The instrument-side state of a running episode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeState {
    /// The configuration the episode runs under.
    pub config: EpisodeConfig,
    /// Encoder position in rotation steps, kept in `[0, steps_per_turn)`.
    pub bearing_index: u16,
    /// Actions taken so far.
    pub actions: u16,
    /// Measurement actions taken.
    pub measurements: u16,
    /// Rotation actions taken.
    pub rotations: u16,
    /// Sum of action costs.
    pub cost: f32,
}

impl EpisodeState {
    /// A new episode at encoder bearing 0.
    pub fn new(config: EpisodeConfig) -> Self {
        EpisodeState {
            config,
            bearing_index: 0,
            actions: 0,
            measurements: 0,
            rotations: 0,
            cost: 0.0,
        }
    }

    /// The current encoder bearing in the scene frame, in [-π, π). Computed from the
    /// integer index so it never accumulates rounding error.
    pub fn bearing(&self) -> f32 {
        wrap_angle(self.bearing_index as f32 * self.config.rot_step())
    }

    /// True once the action limit is reached.
    pub fn exhausted(&self) -> bool {
        self.actions >= self.config.max_actions
    }

    /// Books one action: counts, cost, and the new encoder bearing.
    pub fn apply(&mut self, action: Action) {
        let n = self.config.steps_per_turn.max(1) as i32;
        self.bearing_index =
            (self.bearing_index as i32 + action.bearing_delta()).rem_euclid(n) as u16;
        self.actions = self.actions.saturating_add(1);
        match action {
            Action::Measure => self.measurements += 1,
            _ => self.rotations += 1,
        }
        self.cost += self.config.costs.of(action);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bearing_wraps_and_counts() {
        let mut s = EpisodeState::new(EpisodeConfig::default());
        s.apply(Action::RotateRight);
        assert_eq!(s.bearing_index, 53);
        assert!((s.bearing() + TAU / 54.0).abs() < 1e-6);
        for _ in 0..56 {
            s.apply(Action::RotateLeft);
        }
        assert_eq!(s.bearing_index, 1);
        s.apply(Action::Measure);
        assert_eq!((s.actions, s.rotations, s.measurements), (58, 57, 1));
        assert!((s.cost - (57.0 * 0.005 + 0.05)).abs() < 1e-4);
        assert!(!s.exhausted());
    }

    #[test]
    fn scan_packing() {
        let mut p = [false; SCAN_PIXELS];
        p[0] = true;
        p[19] = true;
        assert_eq!(Observation::pack_scan(&p), 1 | (1 << 19));
    }
}
