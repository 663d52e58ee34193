//! The one episode loop (paper Fig. 1, §3.1): policy → action → observation → localizer →
//! termination, then refinement. The host simulator, the evaluation harness, the trainer
//! and the instrument's [`crate::device::Controller`] all drive an [`EpisodeRunner`], so a
//! policy sees bit-identical [`PolicyInput`]s wherever it runs and an episode takes the
//! same actions on the host and on the device.
//!
//! The runner owns the [`Pipeline`] (GHT localizer, measurement log, stop rule), the
//! instrument-side [`EpisodeState`] (encoder bearing, counts, cost) and the policy's
//! [`History`]. It does not own the policy (the device keeps its agent with the protocol
//! state; the trainer batches many runners through one network) nor the world (the
//! sensors answer from outside: a simulated room, or the real instrument).
//!
//! One step: [`EpisodeRunner::decide`] (or [`EpisodeRunner::input`] and a policy of the
//! caller's choice), the instrument performs the action, then
//! [`EpisodeRunner::observe`] validates and books the answer. [`EpisodeRunner::is_over`]
//! turns true on a stop or at the action limit; [`EpisodeRunner::finish`] registers.

use crate::episode::Action;
use crate::episode::{EpisodeConfig, EpisodeParams, EpisodeState, Observation, ObservationError};
use crate::pipeline::{Pipeline, PipelineError, PipelineResult, Stop};
use crate::policy::{History, Policy, PolicyInput};
use crate::world::floorplan::FloorPlan;

/// What booking an observation did to the episode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Booked {
    /// A rotation.
    Rotation,
    /// A measurement that returned a range, voted into the localizer.
    Vote,
    /// A measurement without a usable return.
    NoReturn,
}

/// Pipeline + episode bookkeeping + policy history of one episode.
pub struct EpisodeRunner {
    pipeline: Pipeline,
    state: EpisodeState,
    history: History,
    stop: Option<Stop>,
    no_returns: u16,
    /// Rotations since the last measurement (for the never-stall rule).
    rotations_in_a_row: u16,
    heading_offset: f32,
    /// The bearing the stop lacks a reading at ([`Pipeline::aim`]), if any.
    aim: Option<u16>,
    /// Aimed bearings whose reading returned nothing (not aimed at again).
    aim_missed: heapless::Vec<u16, AIM_MISSES>,
}

/// Aimed bearings without a return remembered per episode; past it the runner stops aiming.
const AIM_MISSES: usize = 8;

impl Default for EpisodeRunner {
    fn default() -> Self {
        Self::new_empty()
    }
}

impl EpisodeRunner {
    /// An idle runner (for a `static`; ≈ the localizer's size).
    pub const fn new_empty() -> Self {
        EpisodeRunner {
            pipeline: Pipeline::new_empty(),
            state: EpisodeState {
                config: EpisodeConfig::DEFAULT,
                bearing_index: 0,
                actions: 0,
                measurements: 0,
                rotations: 0,
                cost: 0.0,
            },
            history: History::new(),
            stop: None,
            no_returns: 0,
            rotations_in_a_row: 0,
            heading_offset: 0.0,
            aim: None,
            aim_missed: heapless::Vec::new(),
        }
    }

    /// Starts an episode on the centred `plan` under `params` (its `config` fixes the
    /// rotation step, action limit and costs; its `initial_scan` is the scan before the
    /// first action).
    pub fn start(&mut self, plan: &FloorPlan, params: &EpisodeParams) -> Result<(), PipelineError> {
        self.pipeline.start(plan, params)?;
        self.state = EpisodeState::new(params.config);
        self.history.start(params.initial_scan);
        self.stop = None;
        self.no_returns = 0;
        self.rotations_in_a_row = 0;
        self.heading_offset = params.heading();
        self.aim = None;
        self.aim_missed.clear();
        Ok(())
    }

    /// True once the stop rule fired or the action limit is reached.
    pub fn is_over(&self) -> bool {
        self.stop.is_some() || self.state.exhausted()
    }

    /// What a policy sees now.
    pub fn input(&self) -> PolicyInput<'_> {
        PolicyInput {
            localizer: self.pipeline.localizer(),
            history: &self.history,
            step: self.state.actions,
            measurements: self.pipeline.observations().len() as u16,
            bearing: self.state.bearing(),
            heading_offset: self.heading_offset,
        }
    }

    /// The policy's next action; `None` once the episode is over. **Never stall:** after a
    /// whole turn of rotations without a measurement ([`Self::stall_limit`]) the next action
    /// is a measurement whatever the policy says: every bearing has passed, so turning on
    /// cannot show the policy anything new, and a reading can still help. **Aim:** while the
    /// confident stop lacks a reading along some direction ([`Pipeline::aim`]) the runner
    /// turns the shortest way to the bearing that gives it and measures there. (The policy
    /// is asked all the same, so a stateful or random policy's stream stays as it was.)
    pub fn decide(&self, policy: &mut dyn Policy) -> Option<Action> {
        if self.is_over() {
            return None;
        }
        let action = policy.act(&self.input());
        if let Some(target) = self.aim {
            let n = self.state.config.steps_per_turn.max(1) as i32;
            let ahead = (target as i32 - self.state.bearing_index as i32).rem_euclid(n);
            return Some(match ahead {
                0 => Action::Measure,
                a if a <= n / 2 => Action::RotateLeft,
                _ => Action::RotateRight,
            });
        }
        Some(
            if action != Action::Measure && self.rotations_in_a_row >= self.stall_limit() {
                Action::Measure
            } else {
                action
            },
        )
    }

    /// The encoder bearing the runner is turning to and will measure at ([`Pipeline::aim`]),
    /// if it aims.
    pub fn aim_target(&self) -> Option<u16> {
        self.aim
    }

    /// Rotations in a row after which [`Self::decide`] measures: one whole turn.
    pub fn stall_limit(&self) -> u16 {
        self.state.config.steps_per_turn
    }

    /// Checks an instrument answer to `action` without booking it.
    pub fn validate(action: Action, obs: &Observation) -> Result<(), ObservationError> {
        obs.validate(action)
    }

    /// Books the instrument's answer to `action`: encoder bearing, counts and cost, the
    /// history, the GHT vote of a returned range and the stop rule. A rejected answer
    /// changes nothing.
    pub fn observe(
        &mut self,
        action: Action,
        obs: &Observation,
    ) -> Result<Booked, ObservationError> {
        Self::validate(action, obs)?;
        self.state.apply(action);
        self.history.push(action, obs.scan);
        self.rotations_in_a_row = match action {
            Action::Measure => 0,
            _ => self.rotations_in_a_row.saturating_add(1),
        };
        Ok(match (action, obs.range) {
            (Action::Measure, Some(range)) => {
                // A range of exactly 0 is valid on the wire but not a vote: it counts as
                // no return (the localizer refuses it).
                if self.pipeline.measure(self.state.bearing(), range) {
                    self.stop = self.pipeline.should_stop();
                    self.aim_after(true);
                    Booked::Vote
                } else {
                    self.no_returns = self.no_returns.saturating_add(1);
                    self.aim_after(false);
                    Booked::NoReturn
                }
            }
            (Action::Measure, None) => {
                self.no_returns = self.no_returns.saturating_add(1);
                self.aim_after(false);
                Booked::NoReturn
            }
            _ => Booked::Rotation,
        })
    }

    /// After a measurement: the bearing the stop lacks a reading at, if any. An aimed
    /// reading that returned nothing is remembered and not aimed at again; after
    /// [`AIM_MISSES`] of them the runner leaves the bearings to the policy.
    fn aim_after(&mut self, voted: bool) {
        if self.stop.is_some() {
            self.aim = None;
            return;
        }
        let here = self.state.bearing_index;
        if !voted {
            // A reading that voted nothing changed nothing the aim rests on; only an
            // aimed bearing that returned nothing is struck off.
            if self.aim != Some(here) {
                return;
            }
            if self.aim_missed.push(here).is_err() {
                self.aim = None;
                return;
            }
        }
        let missed = &self.aim_missed;
        self.aim = self
            .pipeline
            .aim(self.state.config.steps_per_turn, here, &|k| {
                missed.contains(&k)
            });
    }

    /// Ends the episode: the coarse estimate and its refinement.
    pub fn finish(&self, plan: &FloorPlan) -> PipelineResult {
        self.pipeline.finish(plan)
    }

    /// Why the episode stopped early, if it did.
    pub fn stop(&self) -> Option<Stop> {
        self.stop
    }

    /// Counts, bearing and cost so far.
    pub fn state(&self) -> &EpisodeState {
        &self.state
    }

    /// Measurement actions without a usable return.
    pub fn no_returns(&self) -> u16 {
        self.no_returns
    }

    /// The pipeline (localizer, measurements).
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// Lends the idle localizer's memory for another use between episodes (the device
    /// stages policy uploads there); the next [`EpisodeRunner::start`] takes it back.
    pub fn idle_storage(&mut self) -> &mut [u8] {
        self.pipeline.idle_storage()
    }

    /// The policy's history.
    pub fn history(&self) -> &History {
        &self.history
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::AgentKind;
    use crate::limits::SCAN_PIXELS;
    use crate::pipeline::Termination;
    use crate::policy::BaselineAgent;

    /// A heuristic-1 episode with K = 10, no truth, run to the action limit of `config`.
    fn action_limit_params(config: EpisodeConfig) -> EpisodeParams {
        EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 1,
            rot_bins: 10,
            known_heading: None,
            ground_truth: None,
            initial_scan: 0,
            termination: Termination::ActionLimit,
            config,
        }
    }

    /// A policy that only ever rotates still measures once every whole turn: the runner
    /// overrides the rotation after `stall_limit` rotations in a row, and only then.
    #[test]
    fn a_policy_that_only_turns_is_made_to_measure_once_a_turn() {
        struct Spinner;
        impl Policy for Spinner {
            fn act(&mut self, _: &PolicyInput<'_>) -> Action {
                Action::RotateLeft
            }
        }
        let plan = crate::fixtures::centred_rect(6.0, 4.0);
        let mut r = EpisodeRunner::new_empty();
        let params = action_limit_params(EpisodeConfig {
            steps_per_turn: 12,
            max_actions: 60,
            ..EpisodeConfig::DEFAULT
        });
        r.start(&plan, &params).unwrap();
        assert_eq!(r.stall_limit(), 12);
        let mut taken = [Action::RotateRight; 60];
        let mut n = 0;
        while let Some(a) = r.decide(&mut Spinner) {
            let obs = Observation {
                range: (a == Action::Measure).then_some(2.0),
                scan: 0,
            };
            r.observe(a, &obs).unwrap();
            taken[n] = a;
            n += 1;
        }
        assert_eq!(n, 60);
        for (i, a) in taken.iter().enumerate() {
            let want = if i % 13 == 12 {
                Action::Measure
            } else {
                Action::RotateLeft
            };
            assert_eq!(*a, want, "action {i}");
        }
    }

    #[test]
    fn rejects_bad_answers_and_keeps_state() {
        let plan = crate::fixtures::centred_rect(6.0, 4.0);
        let mut r = EpisodeRunner::new_empty();
        let params = action_limit_params(EpisodeConfig {
            min_observability: 0.0,
            stop_risk: crate::limits::DEFAULT_STOP_RISK,
            ..EpisodeConfig::DEFAULT
        });
        r.start(&plan, &params).unwrap();
        let mut agent = BaselineAgent::new(AgentKind::Heuristic1, 1);
        assert_eq!(r.decide(&mut agent), Some(Action::Measure));
        let bad = [
            Observation {
                range: Some(f32::NAN),
                scan: 0,
            },
            Observation {
                range: Some(-1.0),
                scan: 0,
            },
            Observation {
                range: Some(1.0),
                scan: 1 << SCAN_PIXELS,
            },
        ];
        for o in &bad {
            assert!(r.observe(Action::Measure, o).is_err());
        }
        assert!(r
            .observe(
                Action::RotateLeft,
                &Observation {
                    range: Some(1.0),
                    scan: 0
                }
            )
            .is_err());
        assert_eq!(r.state().actions, 0);
        assert_eq!(r.history().action(0), None);
        let ok = Observation {
            range: Some(2.0),
            scan: 3,
        };
        assert_eq!(r.observe(Action::Measure, &ok), Ok(Booked::Vote));
        assert_eq!(r.state().measurements, 1);
        assert_eq!(r.history().scan(0), Some(3));
        assert_eq!(r.input().measurements, 1);
        let zero = Observation {
            range: Some(0.0),
            scan: 0,
        };
        assert_eq!(r.observe(Action::Measure, &zero), Ok(Booked::NoReturn));
        assert_eq!(r.no_returns(), 1);
    }
}
