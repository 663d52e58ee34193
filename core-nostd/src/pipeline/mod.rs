//! The per-episode decision chain of Fig. 1 (paper §3.1–3.4), in one place for the host
//! simulator and the firmware alike: localizer set-up, voting each returned range,
//! the termination rule, and the final refinement of the coarse estimate.
//!
//! Both [`crate::device::Controller`] (on the instrument) and the host's episode runner
//! drive a [`Pipeline`]; that is what makes "the same episode on the host and on the
//! firmware takes the same actions and reports the same poses" true by construction.
//!
//! - **Localization** (§3.2): a [`GhtLocalizer`] with K rotation bins; K = 1 means the
//!   heading is known and supplied.
//! - **Termination** (§3.1): never before the registration is determined
//!   ([`Pipeline::min_measurements`]); then [`Termination::Oracle`] stops on coarse success
//!   against a supplied ground truth (the paper's rule, simulation only); [`Termination::Confident`]
//!   stops when the calibrated estimate of the probability that the registration is wrong
//!   is below [`EpisodeConfig::stop_risk`] ([`crate::stop`]; no ground truth);
//!   [`Termination::ActionLimit`] never stops early.
//! - **Refinement** (§3.3): the multi-hypothesis refinement ([`crate::registration::refine`]): annealed
//!   sparse ICP ([`registration::register_multistart`]) from the belief argmax, kept inside
//!   the region the coarse estimate vouches for ([`TRUST_CELLS`], 1.5 rotation bins), with a
//!   deterministic heading sweep when the heading is unknown ([`REGISTRATION_STARTS`]), over
//!   leave-one/two-out reading sets scored by range likelihood and belief mass.
//!
//! Memory: the localizer dominates (≈ 46 KiB for 30×30×10); [`Pipeline::new_empty`] is a
//! `const fn` so the firmware keeps it in a `static`.
//!
//! This file holds the state, the episode's start and the readings; `termination` the stop
//! rule run after each reading, `answer` the refinement and the episode's answer.

use crate::episode::{AgentKind, EpisodeConfig, EpisodeParams};
use crate::localization::{CellIndex, GhtLocalizer, LocError, LocalizerConfig};
use crate::registration::refine::{self, Refinement};
use crate::registration::{
    self, AnnealParams, Measurement, Observability, Observations, Registration, RegistrationError,
};
use crate::stop::StopFeatures;
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::Pose2;
use crate::world::symmetry::{symmetry_order, SymmetryTolerance};
use serde::{Deserialize, Serialize};

mod aim;
mod answer;
pub mod runner;
mod termination;

pub use aim::{AIM_CANDIDATES, AIM_MAX_INCIDENCE, AIM_MAX_RANGE};

use crate::episode::Termination;

/// Radius of the registration's trust region around the coarse estimate, in grid cells.
/// Coarse success puts the truth within 1.5 cells per axis of the argmax cell centre, but
/// with 2–3 measurements the registration is often underdetermined and drifts to the
/// region's edge; on 300 test plans (heuristic-1, blind-0) a radius of 1 cell gave a mean
/// recognised pose error of 0.12 m vs 0.17 m at 2.1 cells and 0.68 m unbounded, with the
/// same ≈ 1.2 cm median (`activesense eval --agents heuristic-1,blind-0 --plans 300`).
pub const TRUST_CELLS: f32 = 1.0;

/// Fewest measurements before stopping when the heading is known (2 translation unknowns).
pub const MIN_MEASUREMENTS_KNOWN_HEADING: usize = 2;
/// Fewest measurements before stopping when the heading is unknown (3 unknowns).
pub const MIN_MEASUREMENTS_UNKNOWN_HEADING: usize = 3;

/// Heading starts of the registration sweep when the heading is unknown.
pub const REGISTRATION_STARTS: u8 = 9;

/// Why [`Pipeline::start`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PipelineError {
    /// The localizer refused the plan or configuration.
    Localizer(LocError),
    /// K = 1 without a known heading.
    KnownHeadingRequired,
    /// Oracle termination without a ground truth.
    GroundTruthRequired,
}

/// Why the pipeline asks to stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stop {
    /// Coarse success against the ground truth.
    CoarseSuccess,
    /// The belief is confident.
    Confident,
}

/// One decision point of the calibrated stop: what it would read and what it would answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopPoint {
    /// The features the stop's model reads.
    pub features: StopFeatures,
    /// The cell the refined pose lies in ([`Pipeline::answer_cell`]).
    pub cell: CellIndex,
    /// The refined pose (AgentPose), the answer itself.
    pub pose: Pose2,
}

/// The pipeline's answer at the end of an episode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PipelineResult {
    /// Belief argmax (AgentPose), once any vote landed; under the confident stop, the
    /// cell the refined pose lies in when there is one ([`Pipeline::answer_cell`]).
    pub coarse: Option<Pose2>,
    /// The refined registration, when at least two measurements allowed one.
    pub refined: Option<Registration>,
    /// Why there is no refined pose, if there is none.
    pub registration_error: Option<RegistrationError>,
    /// Coarse success of `coarse` against the ground truth, when one was supplied.
    pub recognised: Option<bool>,
    /// Cyclic symmetry order of the plan.
    pub symmetry_order: u8,
    /// How well the readings determine the pose at the coarse estimate.
    pub observability: Option<Observability>,
    /// The winning hypothesis of the multi-hypothesis refinement ([`crate::registration::refine`]);
    /// its registration is `refined`.
    pub refinement: Option<Refinement>,
    /// The calibrated stop's estimate of P(wrong) at the end ([`Pipeline::stop_risk_estimate`]);
    /// `None` below the stop gate.
    pub stop_risk: Option<f32>,
    /// Readings the answer (`coarse`, `refined`, `recognised`, `stop_risk`) is based on: all
    /// of them, except when a confident episode reached its action limit without stopping
    /// and answers with its lowest-risk moment instead ([`Pipeline::finish`]).
    pub answer_readings: u16,
}

impl PipelineResult {
    /// The final AgentPose: refined, else coarse.
    pub fn best(&self) -> Option<Pose2> {
        self.refined.map(|r| r.pose).or(self.coarse)
    }
}

/// Localizer + measurement log + termination rule of one episode.
pub struct Pipeline {
    localizer: GhtLocalizer,
    /// The episode's plan (the observability test ray-casts into it).
    plan: FloorPlan,
    observations: Observations,
    params: EpisodeParams,
    order: u8,
    voted: bool,
    ready: bool,
    /// The last refinement of the episode's plan and the state it saw (readings, localizer
    /// updates): at the stop
    /// step the confident rule and [`Pipeline::finish`] refine the same readings, and on the
    /// instrument one refinement is up to seconds.
    last_refinement: Option<((usize, u32), Refinement)>,
    /// The rival margin of `last_refinement` ([`crate::stop::rivals::check`]), computed with
    /// it (4 bytes of static RAM: the answer itself is `last_refinement`).
    last_margin: Option<f32>,
    /// The belief's entropy and the readings' observability at the argmax for the state
    /// they saw ([`Pipeline::belief_summary`]): the stop's features read them twice per
    /// reading and its kept answer once more, and the entropy is a pass over every cell.
    belief_summary: Option<((usize, u32), f32, Option<Observability>)>,
    /// The last refinements at other belief modes, newest first
    /// ([`refine::keep_alternate`]): a carried re-fit may start from them when the argmax
    /// returns to one.
    alternate_refinements: [Option<Refinement>; refine::ALTERNATE_MODES],
    /// The confident rule's lowest-risk moment so far ([`Pipeline::finish`]).
    best_answer: Option<Answer>,
    /// The state ([`Pipeline::refinement_key`]) at which the calibrated stop's estimate
    /// could have answered but the leverage veto held ([`crate::stop::LeverageVeto`]):
    /// there the runner aims at the reading that lowers the leverage ([`Pipeline::aim`]).
    held_by_veto: Option<(usize, u32)>,
}

/// One moment of a confident episode, kept as its answer should the episode never become
/// confident enough to stop.
#[derive(Clone, Copy, Debug)]
struct Answer {
    risk: f32,
    cell: CellIndex,
    refinement: Refinement,
    observability: Option<Observability>,
    readings: u16,
}

impl Default for Pipeline {
    fn default() -> Self {
        Self::new_empty()
    }
}

impl Pipeline {
    /// An idle pipeline (for a `static`).
    pub const fn new_empty() -> Self {
        Pipeline {
            localizer: GhtLocalizer::new_empty(),
            plan: FloorPlan::empty(),
            observations: Observations::new(),
            params: EpisodeParams {
                agent: AgentKind::Blind0,
                seed: 0,
                rot_bins: 1,
                known_heading: None,
                ground_truth: None,
                initial_scan: 0,
                termination: Termination::ActionLimit,
                config: EpisodeConfig::DEFAULT,
            },
            order: 1,
            voted: false,
            ready: false,
            last_refinement: None,
            last_margin: None,
            belief_summary: None,
            alternate_refinements: [None; refine::ALTERNATE_MODES],
            best_answer: None,
            held_by_veto: None,
        }
    }

    /// The localizer configuration for `rot_bins` (1 = heading known and given).
    pub fn localizer_config(rot_bins: u8, known_heading: f32) -> LocalizerConfig {
        if rot_bins == 1 {
            LocalizerConfig::known_heading(known_heading)
        } else {
            LocalizerConfig {
                rot_bins,
                ..LocalizerConfig::DEFAULT
            }
        }
    }

    /// Prepares an episode on the centred `plan`.
    pub fn start(&mut self, plan: &FloorPlan, params: &EpisodeParams) -> Result<(), PipelineError> {
        self.ready = false;
        let heading = match (params.heading_known(), params.known_heading) {
            (true, None) => return Err(PipelineError::KnownHeadingRequired),
            (true, Some(h)) => h,
            (false, _) => 0.0,
        };
        if params.termination == Termination::Oracle && params.ground_truth.is_none() {
            return Err(PipelineError::GroundTruthRequired);
        }
        self.localizer
            .reset(plan, &Self::localizer_config(params.rot_bins, heading))
            .map_err(PipelineError::Localizer)?;
        self.order = symmetry_order(plan, &SymmetryTolerance::default());
        self.plan = plan.clone();
        self.observations.clear();
        self.last_refinement = None;
        self.last_margin = None;
        self.belief_summary = None;
        self.alternate_refinements = [None; refine::ALTERNATE_MODES];
        self.best_answer = None;
        self.held_by_veto = None;
        self.params = *params;
        self.voted = false;
        self.ready = true;
        Ok(())
    }

    /// Books one returned range at encoder bearing `bearing`. Readings the localizer
    /// refuses (non-finite, not positive) are dropped; returns whether it was used.
    pub fn measure(&mut self, bearing: f32, range: f32) -> bool {
        if !self.ready || self.localizer.update(bearing, range).is_err() {
            return false;
        }
        self.voted = true;
        // Capacity = the protocol's action limit (asserted at compile time in `runner`).
        let _ = self.observations.push(Measurement::new(bearing, range));
        // Coarse-to-fine: the belief argmax decided among its neighbours with finer headings.
        self.localizer.refine_argmax(self.observations.readings());
        true
    }

    /// Fewest measurements before the episode may stop: as many as the registration has
    /// unknowns (2 with the heading known, 3 without). Stopping on a lucky coarse success
    /// after one measurement leaves nothing to refine; on 300 test plans this rule took
    /// heuristic-1 from 2.88 to 3.04 measurements (K = 1) and cut its mean recognised pose
    /// error from 0.157 m to 0.121 m (K = 1) and from 0.433 m to 0.310 m (K = 10).
    pub fn min_measurements(&self) -> usize {
        if self.params.heading_known() {
            MIN_MEASUREMENTS_KNOWN_HEADING
        } else {
            MIN_MEASUREMENTS_UNKNOWN_HEADING
        }
    }

    /// Registration parameters: fixed heading when known; trust region of
    /// [`TRUST_CELLS`] cells and 1.5 rotation bins around the coarse estimate.
    pub fn registration_params(&self) -> AnnealParams {
        let mut p = AnnealParams {
            seed: self.params.registration_seed(),
            ..AnnealParams::default()
        };
        let grid = self.localizer.grid();
        p.icp.fixed_heading = self.params.heading_known();
        p.icp.trust_translation = TRUST_CELLS * grid.cell[0].max(grid.cell[1]);
        p.icp.trust_rotation = if self.params.heading_known() {
            f32::INFINITY
        } else {
            self.heading_span()
        };
        p
    }

    /// Half-width of the registration's heading sweep (0 with a known heading).
    pub fn heading_span(&self) -> f32 {
        if self.params.heading_known() {
            0.0
        } else {
            1.5 * self.localizer.grid().bin_width()
        }
    }

    /// How well the readings so far determine the pose at the belief argmax
    /// ([`registration::observability`]); `None` before any vote.
    pub fn observability(&self) -> Option<Observability> {
        let coarse = if self.voted {
            self.localizer.estimate()
        } else {
            None
        }?;
        Some(registration::observability(
            &self.plan,
            &self.observations,
            &coarse,
            self.params.heading_known(),
        ))
    }

    /// What a refinement depends on besides the plan and the parameters fixed at
    /// [`Pipeline::start`]: the readings and the belief.
    fn refinement_key(&self) -> (usize, u32) {
        (self.observations.len(), self.localizer.updates())
    }

    /// Lends the idle localizer's accumulator memory (see
    /// [`GhtLocalizer::idle_storage`]); the pipeline needs [`Pipeline::start`] afterwards.
    pub fn idle_storage(&mut self) -> &mut [u8] {
        self.ready = false;
        self.voted = false;
        self.localizer.idle_storage()
    }

    /// The localizer (belief, entropy, grid).
    pub fn localizer(&self) -> &GhtLocalizer {
        &self.localizer
    }

    /// The measurements booked so far.
    pub fn observations(&self) -> &Observations {
        &self.observations
    }

    /// Cyclic symmetry order of the plan.
    pub fn symmetry_order(&self) -> u8 {
        self.order
    }

    /// Whether the current state is one where the calibrated stop's estimate could have
    /// answered and only the wall-leverage veto held it back (what the runner aims at with
    /// the heading unknown, [`Pipeline::aim`]).
    pub fn held_by_veto(&self) -> bool {
        self.held_by_veto == Some(self.refinement_key())
    }

    /// True once a vote has landed.
    pub fn has_belief(&self) -> bool {
        self.voted
    }
}

#[cfg(test)]
mod tests;
