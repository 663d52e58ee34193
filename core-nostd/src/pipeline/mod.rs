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

use crate::episode::{AgentKind, EpisodeConfig, EpisodeParams};
use crate::localization::{CellIndex, GhtLocalizer, LocError, LocalizerConfig};
use crate::registration::refine::{self, Budget, RefineInput, Refinement};
use crate::registration::{
    self, AnnealParams, Measurement, Observability, Observations, RangeModel, Registration,
    RegistrationError,
};
use crate::stop::rivals::{self, RivalCheck};
use crate::stop::{self, StopFeatures, StopModel};
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::Pose2;
use crate::world::symmetry::{symmetry_order, SymmetryTolerance};
use serde::{Deserialize, Serialize};

pub mod runner;

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
    /// The rival margin of `last_refinement` ([`rivals::check`]), computed with it (4 bytes
    /// of static RAM: the answer itself is `last_refinement`).
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

    /// After a measurement: should the episode stop?
    pub fn should_stop(&mut self) -> Option<Stop> {
        if !self.voted || self.observations.len() < self.min_measurements() {
            return None;
        }
        let stop = match self.params.termination {
            Termination::Confident => {
                let estimate = self.stop_gate().and_then(|_| {
                    self.track_refinement();
                    let f = self.stop_features()?;
                    let risk = self.risk_of(&f);
                    self.remember_if_best(risk);
                    Some((risk, f.readings))
                });
                let model = StopModel::for_rot_bins(self.params.rot_bins);
                let (agent, p) = (self.params.agent, self.params.config.stop_risk);
                estimate
                    .filter(|&(risk, bearings)| model.stops(agent, risk, bearings, p))
                    .map(|_| Stop::Confident)?
            }
            Termination::Oracle => self
                .params
                .ground_truth
                .filter(|t| self.localizer.coarse_success(t, self.order))
                .map(|_| Stop::CoarseSuccess)?,
            Termination::ActionLimit => {
                // No stop, but the same refinements as under the confident rule, so that
                // what the calibration sees there ([`Pipeline::stop_point`]) is what the
                // rule will see.
                if self.stop_gate().is_some() {
                    self.track_refinement();
                }
                return None;
            }
        };
        if self.params.config.min_observability > 0.0
            && self
                .observability()
                .is_none_or(|o| o.min_eigenvalue < self.params.config.min_observability)
        {
            return None;
        }
        Some(stop)
    }

    /// Brings the kept refinement up to the readings: carried on ([`refine::refine_after`])
    /// from the last refinement when the belief argmax is still at its mode, or from the
    /// last one at the argmax's mode among the alternates ([`refine::carry_start`]), else
    /// from scratch. Past the stop gate this runs after every reading; the carry is what
    /// keeps a reading's update cheap on the instrument (issue 22).
    fn track_refinement(&mut self) {
        let key = self.refinement_key();
        if self.last_refinement.is_some_and(|(k, _)| k == key) {
            return;
        }
        if self.params.termination == Termination::Confident {
            self.belief_summary = Some((key, self.localizer.entropy(), self.observability()));
        }
        let input = self.refine_input(&self.plan);
        let budget = Budget::per_reading(self.params.heading_known());
        let icp = input.params.icp;
        let last = self.last_refinement.map(|(_, r)| r);
        // Carry from the last refinement, or from an earlier one at the argmax's mode.
        let start = if budget.carry {
            refine::carry_start(&input, last.as_ref(), &self.alternate_refinements)
        } else {
            None
        };
        let refined = match start {
            Some(p) => refine::refine_after(&input, &p, &budget),
            None => refine::refine_within(&input, &budget),
        };
        if let (Some(old), Ok(new)) = (last, &refined) {
            refine::keep_alternate(&mut self.alternate_refinements, &old, new, &icp);
        }
        // The rivals may overrule the argmax's refinement (`rivals::check`): the answer,
        // and what the next reading carries on from, is the one that explains the readings.
        let checked = refined.ok().map(|r| {
            if self.params.termination == Termination::Confident && !self.may_stop_on(&r) {
                RivalCheck::not_searched(&r)
            } else {
                self.rivals_of(&self.plan, &r, &budget)
            }
        });
        self.last_refinement = checked.map(|c| (key, c.answer));
        self.last_margin = checked.map(|c| c.margin);
    }

    /// Whether the calibrated stop could stop on `refined` for some rival margin: its
    /// estimate, lowest over the margins where the model's two linear margin pieces can
    /// take their minimum (both ends and the knee), is below the threshold. Where this is
    /// false no rival search can make the episode stop, and the instrument skips it
    /// (issue 22's budget: the rivals are most of an update's instructions). The
    /// calibration's action-limit episodes always search.
    fn may_stop_on(&self, refined: &Refinement) -> bool {
        let Some(peak_mass) = self.stop_gate() else {
            return false;
        };
        let model = StopModel::for_rot_bins(self.params.rot_bins);
        // The features but the margin once: the belief's entropy and the readings'
        // observability are whole passes, the same for every margin.
        let Some(f) = self.features_with(peak_mass, refined, 0.0) else {
            return false;
        };
        [-rivals::MARGIN_CAP, stop::MARGIN_KNEE, rivals::MARGIN_CAP]
            .iter()
            .map(|&m| StopFeatures {
                rival_margin: m,
                ..f
            })
            .any(|f| {
                let p = self.params.config.stop_risk;
                model.stops(self.params.agent, model.risk(&f), f.readings, p)
            })
    }

    /// The rival check ([`rivals::check`]) of `refined`, a refinement of the readings so far.
    fn rivals_of(&self, plan: &FloorPlan, refined: &Refinement, budget: &Budget) -> RivalCheck {
        rivals::check(&self.refine_input(plan), refined, self.order, budget)
    }

    /// The rival margin of `refined`: the one computed with the kept refinement when it is
    /// that one, else 0 (not searched). Only an episode that kept no refinement gets the
    /// latter, at its end: the oracle stop, whose estimate is for information only. Searching
    /// the rivals there cost the device 18 M more instructions per oracle-stopped K = 10
    /// episode (heuristic-1, `mcu-bench --episodes 20`: 25.8 M on average) for a number
    /// nobody stops on.
    fn rival_margin(&self, refined: &Refinement) -> f32 {
        match (self.last_refinement, self.last_margin) {
            (Some((key, kept)), Some(margin))
                if key == self.refinement_key() && kept == *refined =>
            {
                margin
            }
            _ => RivalCheck::not_searched(refined).margin,
        }
    }

    /// Keeps the current moment as the episode's answer when its estimated risk is the
    /// lowest so far (strictly: of equal risks the earlier moment stays).
    fn remember_if_best(&mut self, risk: f32) {
        let Some((_, refinement)) = self.last_refinement else {
            return;
        };
        if self.best_answer.is_some_and(|b| b.risk <= risk) {
            return;
        }
        let Some(cell) = self.answer_cell(&refinement) else {
            return;
        };
        self.best_answer = Some(Answer {
            risk,
            cell,
            refinement,
            observability: self.belief_summary().1,
            readings: self.observations.len() as u16,
        });
    }

    /// What the calibrated stop looks at ([`crate::stop`]); `None` before the belief's peak
    /// mass reaches [`stop::GATE_PEAK_MASS`], before [`Pipeline::min_measurements`], or when
    /// the readings do not register.
    pub fn stop_features(&self) -> Option<StopFeatures> {
        self.stop_point().map(|p| p.features)
    }

    /// [`Pipeline::stop_features`] together with the answer the stop would give, from one
    /// refinement: the calibration labels it against the truth (the pose by the surveyor's
    /// tolerance; the cell for the grid-based recognition).
    pub fn stop_point(&self) -> Option<StopPoint> {
        let peak_mass = self.stop_gate()?;
        let refined = self.refine(&self.plan).ok()?;
        Some(StopPoint {
            features: self.features_of(peak_mass, &refined)?,
            cell: self.answer_cell(&refined)?,
            pose: refined.registration.pose,
        })
    }

    /// The belief's peak mass when the stop gate is open (enough readings, peak mass at
    /// least [`stop::GATE_PEAK_MASS`]).
    fn stop_gate(&self) -> Option<f32> {
        if !self.voted || self.observations.len() < self.min_measurements() {
            return None;
        }
        let peak_mass = self.localizer.peak_mass(self.order);
        (peak_mass >= stop::GATE_PEAK_MASS).then_some(peak_mass)
    }

    /// [`StopFeatures`] of an already computed refinement.
    fn features_of(&self, peak_mass: f32, refined: &Refinement) -> Option<StopFeatures> {
        self.features_with(peak_mass, refined, self.rival_margin(refined))
    }

    /// [`StopFeatures`] of `refined` with the rival margin `rival_margin`.
    fn features_with(
        &self,
        peak_mass: f32,
        refined: &Refinement,
        rival_margin: f32,
    ) -> Option<StopFeatures> {
        let grid = self.localizer.grid();
        let argmax = self.localizer.argmax()?;
        let answer = self.answer_cell(refined)?;
        let coarse = grid.pose_of(argmax);
        let pose = refined.registration.pose;
        let offset_cells = ((pose.x - coarse.x) / grid.cell[0])
            .abs()
            .max(((pose.y - coarse.y) / grid.cell[1]).abs());
        let offset_bins = if self.params.heading_known() {
            0.0
        } else {
            crate::world::math::abs(crate::world::math::wrap_angle(pose.theta - coarse.theta))
                / grid.bin_width()
        };
        Some(StopFeatures {
            peak_mass,
            entropy: self.belief_summary().0,
            readings: refined.fit.bearings,
            repeats: (self.observations.len() as u16).saturating_sub(refined.fit.bearings),
            explained: refined.fit.explained_bearings,
            unknowns: self.min_measurements() as u8,
            observability: self.belief_summary().1.map_or(0.0, |o| o.min_eigenvalue),
            offset_cells,
            offset_bins,
            edge_margin: {
                let lo = grid.cell_centre(answer.ix as usize, answer.iy as usize);
                let (hx, hy) = (0.5 * grid.cell[0], 0.5 * grid.cell[1]);
                (hx - crate::world::math::abs(pose.x - lo.x))
                    .min(hy - crate::world::math::abs(pose.y - lo.y))
            },
            agrees: grid.cell_of_pose(&pose).is_some_and(|c| {
                c.ix == argmax.ix && c.iy == argmax.iy && grid.bin_distance(c.bin, argmax.bin) <= 1
            }),
            rival_margin,
            precision: self.answer_precision(&pose),
        })
    }

    /// [`stop::AnswerPrecision`] of the answer `pose` from the readings it explains.
    fn answer_precision(&self, pose: &Pose2) -> Option<stop::AnswerPrecision> {
        let cov = crate::registration::precision::pose_covariance(
            &self.plan,
            &self.observations,
            pose,
            self.params.heading_known(),
            stop::PRECISION_SIGMA,
            stop::PRECISION_GATE,
        )
        .ok()?;
        Some(stop::AnswerPrecision {
            position: crate::world::math::sqrt((cov.cov[0][0] + cov.cov[1][1]).max(0.0)),
            heading: cov.sigma_heading(),
        })
    }

    /// The belief's entropy and the readings' observability ([`Pipeline::observability`]):
    /// the ones kept for this state when the confident rule computed them, else computed
    /// (the same values either way).
    fn belief_summary(&self) -> (f32, Option<Observability>) {
        match self.belief_summary {
            Some((key, entropy, observability)) if key == self.refinement_key() => {
                (entropy, observability)
            }
            _ => (self.localizer.entropy(), self.observability()),
        }
    }

    /// The calibrated estimate of the probability that the answer is wrong: that the refined
    /// pose lies outside the surveyor's tolerance of the truth ([`StopModel::for_rot_bins`]
    /// on [`Pipeline::stop_features`]); `None` when there are no features yet.
    pub fn stop_risk_estimate(&self) -> Option<f32> {
        Some(self.risk_of(&self.stop_features()?))
    }

    fn risk_of(&self, f: &StopFeatures) -> f32 {
        StopModel::for_rot_bins(self.params.rot_bins).risk(f)
    }

    /// The cell the confident stop answers with: the one the refined pose lies in (`None`
    /// when it left the grid). The refinement overrules the belief argmax where the two
    /// disagree, and is right far more often there ([`crate::stop`]).
    pub fn answer_cell(&self, refined: &Refinement) -> Option<CellIndex> {
        self.localizer
            .grid()
            .cell_of_pose(&refined.registration.pose)
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

    /// Ends the episode: the coarse estimate and its refinement.
    ///
    /// A confident episode that reached its action limit without stopping answers with its
    /// lowest-risk moment when that moment's risk is below the end's (or the end has no
    /// estimate): a later reading can move the argmax to a neighbouring cell while the
    /// refined pose stays put (heading quantisation, `docs/EVALUATION.md`), and the
    /// instrument should then report the answer it trusted most, not its last.
    pub fn finish(&self, plan: &FloorPlan) -> PipelineResult {
        let end = self.finish_at_end(plan);
        match self.best_answer {
            Some(b)
                if self.params.termination == Termination::Confident
                    && *plan == self.plan
                    && end.stop_risk.is_none_or(|r| b.risk < r) =>
            {
                let grid = self.localizer.grid();
                PipelineResult {
                    coarse: Some(grid.pose_of(b.cell)),
                    refined: Some(b.refinement.registration),
                    refinement: Some(b.refinement),
                    stop_risk: Some(b.risk),
                    registration_error: None,
                    recognised: self
                        .params
                        .ground_truth
                        .map(|t| grid.coarse_success(b.cell, &t, self.order)),
                    symmetry_order: self.order,
                    observability: b.observability,
                    answer_readings: b.readings,
                }
            }
            _ => end,
        }
    }

    /// [`Pipeline::finish`] on the readings as they are at the end.
    fn finish_at_end(&self, plan: &FloorPlan) -> PipelineResult {
        let coarse = if self.voted {
            self.localizer.estimate()
        } else {
            None
        };
        let recognised = self
            .params
            .ground_truth
            .map(|t| self.voted && self.localizer.coarse_success(&t, self.order));
        let (refined, registration_error) = match coarse.map(|_| self.refine_final(plan)) {
            None => (None, Some(RegistrationError::TooFewObservations)),
            Some(Ok(r)) => (Some(r), None),
            Some(Err(e)) => (None, Some(e)),
        };
        // The stop estimate at the end, from the same refinement (no second one).
        let stop_risk = refined.as_ref().and_then(|r| {
            let f = self.features_of(self.stop_gate()?, r)?;
            Some(self.risk_of(&f))
        });
        // The confident stop answers with the refined pose's cell (`Pipeline::answer_cell`).
        let answer = refined
            .as_ref()
            .filter(|_| self.params.termination == Termination::Confident)
            .and_then(|r| self.answer_cell(r));
        let (coarse, recognised) = match answer {
            Some(cell) => (
                Some(self.localizer.grid().pose_of(cell)),
                self.params
                    .ground_truth
                    .map(|t| self.localizer.grid().coarse_success(cell, &t, self.order)),
            ),
            None => (coarse, recognised),
        };
        PipelineResult {
            coarse,
            refined: refined.map(|r| r.registration),
            refinement: refined,
            stop_risk,
            registration_error,
            recognised,
            symmetry_order: self.order,
            observability: self.observability(),
            answer_readings: self.observations.len() as u16,
        }
    }

    /// The multi-hypothesis refinement ([`crate::registration::refine`]) of the readings so far,
    /// as the stop sees it ([`Budget::per_reading`], what the calibration was fitted on).
    /// Deterministic: the confident rule's kept result is returned when the readings have
    /// not changed since.
    pub fn refine(&self, plan: &FloorPlan) -> Result<Refinement, RegistrationError> {
        self.refine_within(plan, &Budget::per_reading(self.params.heading_known()))
    }

    /// The refinement the episode ends with when none is kept (the oracle stop, or a
    /// confident episode whose stop gate never opened): [`Budget::end_of_episode`], once
    /// per episode, so it may spend more than the per-reading one.
    pub fn refine_final(&self, plan: &FloorPlan) -> Result<Refinement, RegistrationError> {
        self.refine_within(plan, &Budget::end_of_episode(self.params.heading_known()))
    }

    fn refine_within(
        &self,
        plan: &FloorPlan,
        budget: &Budget,
    ) -> Result<Refinement, RegistrationError> {
        if let Some((seen, r)) = self.last_refinement {
            if seen == self.refinement_key() && *plan == self.plan {
                return Ok(r);
            }
        }
        refine::refine_within(&self.refine_input(plan), budget)
    }

    /// What [`Pipeline::refine`] hands the refinement (readings, belief, parameters); the
    /// search is [`refine::refine_with`]'s to choose (tests and benches compare them).
    pub fn refine_input<'a>(&'a self, plan: &'a FloorPlan) -> RefineInput<'a> {
        RefineInput {
            plan,
            obs: &self.observations,
            localizer: &self.localizer,
            params: self.registration_params(),
            screen: refine::screening(&self.registration_params()),
            heading_span: self.heading_span(),
            starts: REGISTRATION_STARTS,
            unknowns: self.min_measurements(),
            model: RangeModel::default(),
        }
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

    /// True once a vote has landed.
    pub fn has_belief(&self) -> bool {
        self.voted
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::limits::DEFAULT_STOP_RISK;
    use crate::world::geometry::{unit, v2};

    /// An 8 × 6 m L-shaped room in the model frame (shared by the core's tests).
    pub(crate) fn l_room() -> FloorPlan {
        FloorPlan::new(&[
            v2(0.0, 0.0),
            v2(8.0, 0.0),
            v2(8.0, 3.0),
            v2(4.0, 3.0),
            v2(4.0, 6.0),
            v2(0.0, 6.0),
        ])
        .unwrap()
        .centered()
    }

    #[test]
    fn refuses_incomplete_params() {
        let mut p = Pipeline::new_empty();
        let base = EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 1,
            rot_bins: 1,
            known_heading: None,
            ground_truth: None,
            initial_scan: 0,
            termination: Termination::ActionLimit,
            config: EpisodeConfig {
                min_observability: 0.0,
                stop_risk: DEFAULT_STOP_RISK,
                ..EpisodeConfig::DEFAULT
            },
        };
        assert_eq!(
            p.start(&l_room(), &base),
            Err(PipelineError::KnownHeadingRequired)
        );
        let oracle = EpisodeParams {
            rot_bins: 10,
            termination: Termination::Oracle,
            ..base
        };
        assert_eq!(
            p.start(&l_room(), &oracle),
            Err(PipelineError::GroundTruthRequired)
        );
        assert!(!p.measure(0.0, 1.0), "not started: nothing booked");
    }

    #[test]
    fn noise_free_episode_stops_and_registers() {
        let plan = l_room();
        let truth = Pose2::new(-1.3, -0.6, 0.4);
        let mut p = Pipeline::new_empty();
        p.start(
            &plan,
            &EpisodeParams {
                agent: AgentKind::Heuristic1,
                seed: 3,
                rot_bins: 10,
                known_heading: None,
                ground_truth: Some(truth),
                initial_scan: 0,
                termination: Termination::Oracle,
                config: EpisodeConfig {
                    min_observability: 0.0,
                    stop_risk: DEFAULT_STOP_RISK,
                    ..EpisodeConfig::DEFAULT
                },
            },
        )
        .unwrap();
        let mut stopped = None;
        for k in 0..12 {
            let bearing = k as f32 * 0.55;
            let hit = plan
                .ray_cast(truth.translation(), unit(truth.theta + bearing))
                .unwrap();
            assert!(p.measure(bearing, hit.range));
            if let Some(s) = p.should_stop() {
                stopped = Some((k, s));
                break;
            }
        }
        let (_, why) = stopped.expect("coarse success within 12 measurements");
        assert_eq!(why, Stop::CoarseSuccess);
        let r = p.finish(&plan);
        assert_eq!(r.recognised, Some(true));
        let best = r.best().unwrap();
        assert!(
            (best.translation() - truth.translation()).norm() < 0.05,
            "{best:?} vs {truth:?}"
        );
        let o = r.observability.expect("reported with a belief");
        assert!(o.min_eigenvalue > 0.0 && o.constraints as usize == p.observations().len());
        // The observability threshold holds the stop back: the same readings stop the
        // episode under a threshold they meet and not under one above what they reach.
        p.params.config.min_observability = 0.5 * o.min_eigenvalue;
        assert_eq!(p.should_stop(), Some(Stop::CoarseSuccess));
        p.params.config.min_observability = 2.0 * o.min_eigenvalue;
        assert_eq!(p.should_stop(), None);
    }

    /// Confident termination at K = 10 with the truth known (for scoring) and stop risk `p`.
    fn confident_params(truth: Pose2, p: f32) -> EpisodeParams {
        EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 5,
            rot_bins: 10,
            known_heading: None,
            ground_truth: Some(truth),
            initial_scan: 0,
            termination: Termination::Confident,
            config: EpisodeConfig {
                min_observability: 0.0,
                stop_risk: p,
                ..EpisodeConfig::DEFAULT
            },
        }
    }

    /// A confident episode that never gets sure enough to stop answers with its lowest-risk
    /// moment when the end is riskier; an action-limit episode answers with its end.
    #[test]
    fn an_unsure_confident_episode_answers_with_its_lowest_risk_moment() {
        let plan = l_room();
        let truth = Pose2::new(0.9, -0.4, 2.0);
        let mut params = confident_params(truth, 1e-9);
        let readings = |k: usize| {
            let bearing = k as f32 * 0.77;
            let hit = plan
                .ray_cast(truth.translation(), unit(truth.theta + bearing))
                .unwrap();
            // Every third range from the fifth on is an outlier: the risk goes up and down.
            let range = if k >= 4 && k % 3 == 1 {
                0.55 * hit.range
            } else {
                hit.range
            };
            (bearing, range)
        };
        let mut p = Pipeline::new_empty();
        p.start(&plan, &params).unwrap();
        let mut lowest: Option<(f32, usize)> = None;
        let n = 14;
        for k in 0..n {
            let (bearing, range) = readings(k);
            assert!(p.measure(bearing, range));
            assert_eq!(p.should_stop(), None, "a 1e-9 risk never stops");
            if let Some(r) = p.stop_risk_estimate() {
                if lowest.is_none_or(|(l, _)| r < l) {
                    lowest = Some((r, k + 1));
                }
            }
        }
        let (low, at) = lowest.expect("the gate opened");
        let end = p.stop_risk_estimate();
        assert!(
            end.is_none_or(|e| low < e) && at < n,
            "the readings make an earlier moment the safest: {low} at {at}, end {end:?}"
        );
        let r = p.finish(&plan);
        assert_eq!((r.stop_risk, r.answer_readings), (Some(low), at as u16));

        // The same readings to the action limit answer with the end.
        params.termination = Termination::ActionLimit;
        p.start(&plan, &params).unwrap();
        for k in 0..n {
            let (bearing, range) = readings(k);
            assert!(p.measure(bearing, range));
            assert_eq!(p.should_stop(), None);
        }
        assert_eq!(p.finish(&plan).answer_readings, n as u16);
    }

    /// The calibrated stop on noise-free readings: it stops by itself, on a pose that
    /// agrees with the argmax and is right, and the risk setting moves the stop.
    #[test]
    fn confident_stop_follows_the_stop_risk() {
        let plan = l_room();
        let truth = Pose2::new(0.9, -0.4, 2.0);
        let params = confident_params(truth, DEFAULT_STOP_RISK);
        let mut p = Pipeline::new_empty();
        p.start(&plan, &params).unwrap();
        let mut stopped = false;
        let mut taken: heapless::Vec<(f32, f32), 48> = heapless::Vec::new();
        for k in 0..40 {
            let bearing = k as f32 * 0.77;
            let hit = plan
                .ray_cast(truth.translation(), unit(truth.theta + bearing))
                .unwrap();
            assert!(p.measure(bearing, hit.range));
            taken.push((bearing, hit.range)).unwrap();
            if p.should_stop() == Some(Stop::Confident) {
                stopped = true;
                break;
            }
        }
        assert!(
            stopped,
            "noise-free readings reach a 1 % risk within 40 ranges"
        );
        let f = p.stop_features().expect("stopped on features");
        assert!(
            f.agrees && f.explained as usize == p.observations().len(),
            "{f:?}"
        );
        let risk = p.stop_risk_estimate().expect("features agree");
        let model = StopModel::for_rot_bins(params.rot_bins);
        // What the threshold is compared with: the estimate scaled by the distinct bearings.
        let score = crate::stop::stop_score(risk, f.readings);
        assert!(score < model.threshold_for(params.agent, DEFAULT_STOP_RISK));
        let r = p.finish(&plan);
        assert_eq!(r.recognised, Some(true));
        assert_eq!(
            r.stop_risk,
            Some(risk),
            "finish reports the estimate it stopped on"
        );
        let best = r.best().unwrap();
        assert!(
            (best.translation() - truth.translation()).norm() < 0.02,
            "{best:?}"
        );
        // The same readings do not stop at a stated risk whose threshold is below the
        // score, and stop again at one whose threshold is just above it.
        let stated_with_threshold = |t: f32| {
            // threshold_for() is non-decreasing in the stated risk: bisect in ln p.
            let (mut lo, mut hi) = (1e-9f32, 1.0f32);
            for _ in 0..60 {
                let mid = libm::sqrtf(lo * hi);
                if model.threshold_for(params.agent, mid) < t {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            (lo, hi)
        };
        let (below, above) = stated_with_threshold(score);
        assert!(
            model.threshold_for(params.agent, below) < score
                && model.threshold_for(params.agent, above) >= score
        );
        p.params.config.stop_risk = below;
        assert_eq!(p.should_stop(), None);
        p.params.config.stop_risk = stated_with_threshold(score * 1.01).1;
        assert_eq!(p.should_stop(), Some(Stop::Confident));

        // The kept refinement follows the readings: after one more range the pipeline's
        // refinement equals that of a fresh pipeline fed the same ranges.
        let kept = p.refine(&plan).unwrap();
        let hit = plan
            .ray_cast(truth.translation(), unit(truth.theta + 0.4))
            .unwrap();
        assert!(p.measure(0.4, hit.range));
        taken.push((0.4, hit.range)).unwrap();
        let mut fresh = Pipeline::new_empty();
        fresh.start(&plan, &params).unwrap();
        for &(b, r) in taken.iter() {
            assert!(fresh.measure(b, r));
        }
        let after = p.refine(&plan).unwrap();
        assert_eq!(after, fresh.refine(&plan).unwrap());
        assert_ne!(after.fit.log_likelihood, kept.fit.log_likelihood);
    }
}
