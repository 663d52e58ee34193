//! The episode's answer: the coarse estimate and its refinement at the end (or the
//! confident episode's lowest-risk moment), and the refinement of the readings so far
//! that both the answer and the stop read.

use super::{Pipeline, PipelineResult, REGISTRATION_STARTS};
use crate::episode::Termination;
use crate::registration::refine::{self, Budget, RefineInput, Refinement};
use crate::registration::{RangeModel, RegistrationError};
use crate::world::floorplan::FloorPlan;

impl Pipeline {
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
}
