//! The reading the stop lacks. Past the stop gate the calibrated stop refuses any answer
//! with a direction that rests on one wall ([`crate::registration::precision::rests_on_one_wall`]):
//! a wall off its drawn line, or furniture read as the wall, would move it unseen. No policy
//! was trained on that rule, and a fixed-step policy may turn for the rest of the episode
//! without ever reading a second wall along that direction (heading known, plan 1000033: the
//! far wall 16.5 m away, seventeen readings, none along it, the action limit). So once the
//! kept refinement rests on one wall, the runner aims: it turns to the nearest encoder
//! bearing whose ray, at that refinement, reaches a wall that leaves fewer directions resting
//! on one wall, and measures there ([`crate::pipeline::runner::EpisodeRunner::decide`]).
//!
//! **With the heading unknown, only where the veto holds an answer back.** On the EDM-only
//! profile the stop vetoes an answer that leans on one wall's drawn position
//! ([`stop::LeverageVeto`]); where the estimate would answer but for the veto (for some
//! rival margin, [`Pipeline::should_stop`]), the refinement is the one the stop trusts, and
//! the runner aims at the bearing that brings the worse of the two leverages under its
//! bound ([`stop::LeverageVeto::excess`]). On 1000 validation plans per site level (learnt,
//! K = 10, bounds 1.0 / 0.2) it took right answers on plans from 0.967 to 0.969 and the
//! cost from 0.791 to 0.764 (`docs/lab/stop.md`, "Aiming where the veto holds an answer
//! back"). Everywhere else with the heading unknown the runner does not aim: the
//! refinement a few readings in is often one of several modes; rays planned on it hit other
//! walls than planned, each aim costs a turn of rotations, and the episode runs out of
//! actions: on the 1000 test
//! plans (EDM only, learnt, K = 10, the stop tables of the time) aiming took the right
//! answers from 0.985 to 0.956 on plans, 0.858 to 0.763 furnished and 0.414 to 0.321 on
//! building sites (0.980, 0.817 and 0.365 when aiming only above a peak mass of 0.5), while
//! at K = 1 it took them from 0.960 to 0.988, 0.784 to 0.823 and 0.371 to 0.368 at a lower
//! cost (0.615 → 0.541 on plans; `docs/EVALUATION.md`, "Aiming at the direction the stop
//! lacks").
//!
//! **The wall leverage.** Once no direction rests on one wall, a direction may still rest on
//! one wall and the corners it shares with its neighbours, which move with it; the runner
//! then aims at the bearing that lowers the answer's [`WallLeverage`] below
//! [`stop::MAX_WALL_LEVERAGE`] (with the heading unknown: below the veto's bounds), above
//! which the stop does not answer.
//!
//! Planned rays are cast on the plan at the refined pose, so they are a prediction: the
//! reading may hit furniture, or return nothing (glass, an open door). A bearing whose
//! reading returned nothing is not aimed at again; one that returned is in the readings and
//! is not a candidate either. The search runs once per reading, only while the refinement
//! rests on one wall (when the rival check is skipped, [`Pipeline::should_stop`]) or its
//! leverage is above the bound: at most [`AIM_CANDIDATES`] rays and a 3 × 3
//! determinant (or a 2 × 2 solve) per wall read for each.

use super::Pipeline;
use crate::episode::Termination;
use crate::registration::precision::{planned_row, WallInformation, WallLeverage};
use crate::stop;
use crate::world::geometry::{rotate, unit};
use crate::world::math::{abs, cos, wrap_angle, TAU};

/// Most encoder bearings the search tries (evenly spread over the turn).
pub const AIM_CANDIDATES: u16 = 72;
/// Steepest incidence of a planned ray (rad): reflectorless EDMs lose grazing returns, and
/// the simulated one returns nothing beyond 75° (`docs/WORLD.md`).
pub const AIM_MAX_INCIDENCE: f32 = 60.0 * core::f32::consts::PI / 180.0;
/// Longest planned ray (m).
pub const AIM_MAX_RANGE: f32 = 40.0;

impl Pipeline {
    /// The encoder bearing (index in `[0, steps_per_turn)`) to measure next, or `None`
    /// when the stop does not lack a direction or no bearing gives it one. `from` is the
    /// current bearing (ties go to the fewest rotations), `missed(k)` marks bearings whose
    /// aimed reading returned nothing.
    pub fn aim(&self, steps_per_turn: u16, from: u16, missed: &dyn Fn(u16) -> bool) -> Option<u16> {
        // Not under the oracle (the paper's rule stops on coarse success, not on this
        // stop); under the action limit as under the confident stop, so that what the
        // calibration's episodes read is what a confident episode reads. Only with the
        // heading known: see the module docs.
        let fixed = self.params.heading_known();
        if self.params.termination == Termination::Oracle
            || !(fixed || self.held_by_veto())
            || self.stop_gate().is_none()
        {
            return None;
        }
        let (key, refinement) = self.last_refinement?;
        if key != self.refinement_key() {
            return None;
        }
        let pose = refinement.registration.pose;
        let now = WallInformation::of(&self.plan, &self.observations, &pose, stop::PRECISION_GATE);
        let alone = now.walls_alone(fixed);
        // With no direction resting on one wall, aim at the wall leverage instead: with
        // the heading known at its bound before the estimate, with it unknown at the
        // veto's (the worse of its two leverages as a share of its bound).
        let (excess, bound) = (
            |l: &WallLeverage| {
                if fixed {
                    l.worst(true)
                } else {
                    stop::LeverageVeto::of(l).excess()
                }
            },
            if fixed { stop::MAX_WALL_LEVERAGE } else { 1.0 },
        );
        let lever = WallLeverage::of(&self.plan, &self.observations, &pose, stop::PRECISION_GATE);
        let lever_now = if alone == 0 {
            excess(&lever)
        } else {
            f32::INFINITY
        };
        if alone == 0 && lever_now <= bound {
            return None;
        }
        let n = steps_per_turn.max(1);
        let stride = n.div_ceil(AIM_CANDIDATES);
        let step = TAU / n as f32;
        let cos_max = cos(AIM_MAX_INCIDENCE);
        let a = pose.translation();
        // Ranked by (walls alone, or the leverage where it stays above the bound; turns).
        let mut best: Option<(f32, u16, u16)> = None;
        for k in (0..n).step_by(stride as usize) {
            let bearing = k as f32 * step;
            let read = self
                .observations
                .readings()
                .any(|(b, _)| abs(wrap_angle(b - bearing)) < 0.5 * step);
            if read || missed(k) {
                continue;
            }
            let d = rotate(unit(bearing), pose.theta);
            let Some(hit) = self.plan.ray_cast(a, d) else {
                continue;
            };
            let nrm = self.plan.outward_normal(hit.wall);
            if abs(nrm.x * d.x + nrm.y * d.y) < cos_max || hit.range > AIM_MAX_RANGE {
                continue;
            }
            let turn = {
                let diff = (k as i32 - from as i32).rem_euclid(n as i32) as u16;
                diff.min(n - diff)
            };
            let rank = if alone > 0 {
                let after = now
                    .with(hit.wall, &planned_row(nrm, d, hit.range))
                    .walls_alone(fixed);
                (after < alone).then_some(after as f32)
            } else {
                let after = excess(&lever.with(&self.plan, d, &hit));
                (after < lever_now).then_some(if after <= bound { 0.0 } else { after })
            };
            if let Some(rank) = rank {
                if best.is_none_or(|(r, t, _)| (rank, turn) < (r, t)) {
                    best = Some((rank, turn, k));
                }
            }
        }
        best.map(|(_, _, k)| k)
    }
}
