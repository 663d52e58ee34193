//! The termination rule (paper §3.1) as the pipeline runs it after every reading: the stop
//! gate, the refinement kept up to date past it, the rival check, the calibrated stop's
//! features and estimate of P(wrong), and the lowest-risk moment a confident episode keeps
//! as its fallback answer.

use super::{Answer, Pipeline, Stop, StopPoint};
use crate::episode::Termination;
use crate::localization::CellIndex;
use crate::registration::precision::WallLeverage;
use crate::registration::refine::{self, Budget, Refinement};
use crate::registration::{Observability, RangeModel};
use crate::stop::rivals::{self, RivalCheck};
use crate::stop::{self, StopFeatures, StopModel};
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::Pose2;

impl Pipeline {
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
                    Some((risk, f))
                });
                let model =
                    StopModel::built_in(self.params.config.instrument, self.params.rot_bins);
                let (agent, p) = (self.params.agent, self.params.config.stop_risk);
                // Where only the veto holds the answer back (for some rival margin: the
                // rivals of a vetoed point are not searched), the runner aims at the
                // reading that lowers the leverage ([`Pipeline::aim`]).
                self.held_by_veto = estimate
                    .filter(|(_, f)| f.vetoed() && self.may_stop_with(f))
                    .map(|_| self.refinement_key());
                estimate
                    .filter(|(risk, f)| model.stops_on(agent, f, *risk, p))
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
    /// keeps a reading's update cheap on the instrument.
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
    /// (the rivals are most of an update's instructions). The
    /// calibration's action-limit episodes always search.
    fn may_stop_on(&self, refined: &Refinement) -> bool {
        let Some(peak_mass) = self.stop_gate() else {
            return false;
        };
        // The features but the margin once: the belief's entropy and the readings'
        // observability are whole passes, the same for every margin.
        let Some(f) = self.features_with(peak_mass, refined, 0.0) else {
            return false;
        };
        !f.vetoed() && self.may_stop_with(&f)
    }

    /// Whether the calibrated stop's estimate is below the threshold at `f` for some rival
    /// margin, the veto aside ([`Pipeline::may_stop_on`]).
    fn may_stop_with(&self, f: &StopFeatures) -> bool {
        let model = StopModel::built_in(self.params.config.instrument, self.params.rot_bins);
        [-rivals::MARGIN_CAP, stop::MARGIN_KNEE, rivals::MARGIN_CAP]
            .iter()
            .map(|&m| StopFeatures {
                rival_margin: m,
                ..*f
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
    pub(super) fn stop_gate(&self) -> Option<f32> {
        if !self.voted || self.observations.len() < self.min_measurements() {
            return None;
        }
        let peak_mass = self.localizer.peak_mass(self.order);
        (peak_mass >= stop::GATE_PEAK_MASS).then_some(peak_mass)
    }

    /// [`StopFeatures`] of an already computed refinement.
    pub(super) fn features_of(&self, peak_mass: f32, refined: &Refinement) -> Option<StopFeatures> {
        self.features_with(peak_mass, refined, self.rival_margin(refined))
    }

    /// [`StopFeatures`] of `refined` with the rival margin `rival_margin`.
    fn features_with(
        &self,
        peak_mass: f32,
        refined: &Refinement,
        rival_margin: f32,
    ) -> Option<StopFeatures> {
        // With the heading unknown, no answer that says the room does not match its plan
        // ([`stop::room_mismatch`]): a pose can fit a subset of the readings elsewhere.
        if !self.params.heading_known()
            && stop::room_mismatch(refined.fit.bearings, refined.fit.explained_bearings)
        {
            return None;
        }
        // Nor while the answer turned about the middle of the walls its readings hit
        // explains them as well ([`stop::rivals::turned_image_rivals`]): a rival the belief
        // may not hold.
        if !self.params.heading_known()
            && stop::rivals::turned_image_rivals(
                &self.plan,
                &self.observations,
                &refined.registration.pose,
                refined.fit.log_likelihood,
                &RangeModel::default(),
                &self.registration_params().icp,
                self.order,
                stop::PRECISION_GATE,
            )
        {
            return None;
        }
        // No answer while a direction of it rests on one wall: a reading may be furniture,
        // not the wall, and a wall may stand off its drawn line; a second wall along each
        // direction shows either (`registration::precision::rests_on_one_wall`).
        if crate::registration::precision::rests_on_one_wall(
            &self.plan,
            &self.observations,
            &refined.registration.pose,
            self.params.heading_known(),
            stop::PRECISION_GATE,
        ) {
            return None;
        }
        // With the heading known, nor while one wall's offset, its corners with it, would
        // carry most of itself into the answer ([`stop::MAX_WALL_LEVERAGE`]).
        if self.params.heading_known()
            && WallLeverage::of(
                &self.plan,
                &self.observations,
                &refined.registration.pose,
                stop::PRECISION_GATE,
            )
            .worst(true)
                > stop::MAX_WALL_LEVERAGE
        {
            return None;
        }
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
            leverage: self.leverage_veto(&pose),
        })
    }

    /// The wall leverage the stop vetoes by ([`stop::LeverageVeto`]): with the heading
    /// unknown on the EDM-only profile, where the readings of one wall and its corners can
    /// carry its as-built offset into an answer that explains them all; `None` elsewhere
    /// (with the heading known the same bound is a rule before the estimate; with the
    /// camera the scan tells such poses apart, and the bound cost right answers there:
    /// 0.973 to 0.911 on validation plans).
    fn leverage_veto(&self, pose: &Pose2) -> Option<stop::LeverageVeto> {
        if self.params.heading_known()
            || self.params.config.instrument != crate::episode::InstrumentProfile::Edm
        {
            return None;
        }
        Some(stop::LeverageVeto::of(&WallLeverage::of(
            &self.plan,
            &self.observations,
            pose,
            stop::PRECISION_GATE,
        )))
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
            variance_factor: cov.variance_factor,
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

    pub(super) fn risk_of(&self, f: &StopFeatures) -> f32 {
        StopModel::built_in(self.params.config.instrument, self.params.rot_bins).risk(f)
    }

    /// The cell the confident stop answers with: the one the refined pose lies in (`None`
    /// when it left the grid). The refinement overrules the belief argmax where the two
    /// disagree, and is right far more often there ([`crate::stop`]).
    pub fn answer_cell(&self, refined: &Refinement) -> Option<CellIndex> {
        self.localizer
            .grid()
            .cell_of_pose(&refined.registration.pose)
    }
}
