//! Rival belief modes: does anywhere else in the room explain the readings as
//! well as the answer does?
//!
//! The refinement fits the readings around the belief argmax only, so its own fit says how
//! well the answer explains the readings, not whether another pose explains them as well.
//! The voting belief answers that question poorly: it sharpens slowly, so the old stop gate
//! (peak mass 0.5) opened only after four or five ranges with the heading known and six to
//! nine without, though the answer was often already right; and its argmax can sit on the
//! wrong one of two modes (`docs/LEARNING.md`, "The stop that reads rivals", has the
//! measurements). The range likelihood answers it well. So after each reading the strongest
//! other modes of the belief are each fitted with one screened hypothesis (every reading, no
//! leave-out, [`RIVAL_STARTS`](refine::RIVAL_STARTS) heading starts:
//! [`refine::rival_fit`]) and scored by the same likelihood as the answer; the stop reads the
//! **margin**, `ln p(readings | answer) − ln p(readings | best rival)` in nats. One reading
//! that the rival cannot explain costs it about 9.4 nats under
//! [`RangeModel`](crate::registration::RangeModel)'s outlier mixture, so a margin above ~10
//! means every rival fails at least one reading the answer explains. A rival that explains
//! the readings better than the answer by [`SWITCH_MARGIN`] becomes the answer: where the
//! argmax sits on the wrong mode, the instrument need not wait for the votes to move it.
//!
//! A mode is the answer's own when its pose, or the refined rival pose, lies within the
//! refinement's trust region of the answer or of one of its symmetric equivalents (a
//! symmetric room's twin is the same answer, [`crate::registration::pose_distance`]).
//! Rivals are fitted only when the answer explains more bearings than the pose has
//! unknowns, and (under the calibrated stop) only when some margin could let the stop stop
//! (`Pipeline::may_stop_on`): elsewhere the fits would cost the instrument time for nothing.
//!
//! The belief need not hold every rival. When all the readings fall on the four walls of
//! one rectangle of the plan (the main room of an L, say), the answer turned by a half turn
//! about that rectangle's centre predicts every range as well, though the plan as a whole
//! has no such symmetry and the belief may show no mode there (a 180° flip answered at a
//! stated 1 % on a building site). [`turned_image_rivals`] scores those turned images
//! directly: with the heading unknown the stop does not answer while one of them lies in
//! the room and scores within [`SWITCH_MARGIN`] of the answer.

use crate::localization::{GhtLocalizer, Mode};
use crate::registration::refine::{self, Budget, RefineInput, Refinement};
use crate::registration::{explained_hits_centre, range_fit, IcpParams, Observations, RangeModel};
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::Pose2;
use crate::world::math::{abs, cos, sin, wrap_angle};
use core::f32::consts::TAU;
use heapless::Vec as HVec;

/// Belief modes fitted as rivals at most (each is one screened registration). Two, not
/// four: the third and fourth strongest modes rarely hold the best rival, and their fits
/// were a third of a K = 10 update on the device. On 1000 validation plans (seeds from
/// 1001000, before the stop was refitted) the learnt policy's cost and wrong answers moved
/// by less than their noise (K = 10: 0.652 → 0.650, 4 → 5 wrong of 990), while
/// `mcu-bench` (learnt-int8, calibrated stop, K = 10) fell from 12.8 M / 59.0 M to
/// 11.1 M / 39.1 M instructions per update (mean / worst). One rival was too few: 8 wrong
/// of 990 at K = 10 under the same stop (`docs/LEARNING.md`, "What it costs the instrument").
pub const MAX_RIVALS: usize = 2;

/// Separation (cells / bins) between the belief modes considered ([`GhtLocalizer::top_modes`]).
pub const MODE_SEPARATION: u8 = 2;

/// Largest margin reported (nats): no rival, or rivals that explain nothing, read as this.
pub const MARGIN_CAP: f32 = 30.0;

/// Likelihood (nats) by which a rival must beat the answer to become the answer: one
/// third of a reading's worth, so float jitter between two fits of one basin never flips it.
pub const SWITCH_MARGIN: f32 = 3.0;

/// What the rival search found: the answer (the argmax's refinement, or a rival that
/// explains the readings better) and its margin over everything else.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RivalCheck {
    /// The answer after the search.
    pub answer: Refinement,
    /// `ln p(readings | answer) − ln p(readings | best other fit)`, clamped to
    /// `[−MARGIN_CAP, MARGIN_CAP]`; `0` when the rivals were not searched.
    pub margin: f32,
    /// Rivals fitted.
    pub fitted: u8,
    /// The answer is a rival's refinement, not the argmax's.
    pub switched: bool,
}

impl RivalCheck {
    /// The check when the rivals are not searched: the answer stands, margin 0.
    pub fn not_searched(answer: &Refinement) -> RivalCheck {
        RivalCheck {
            answer: *answer,
            margin: 0.0,
            fitted: 0,
            switched: false,
        }
    }
}

/// Whether `p` lies within the trust region (`icp`) of `answer` or of one of its
/// `order`-fold symmetric equivalents (rotations by `2πk/order` about the model origin).
pub fn same_mode(p: &Pose2, answer: &Pose2, icp: &IcpParams, order: u8) -> bool {
    let n = order.max(1) as u32;
    (0..n).any(|k| {
        let g = TAU * k as f32 / n as f32;
        let (c, s) = (cos(g), sin(g));
        let (x, y) = (c * answer.x - s * answer.y, s * answer.x + c * answer.y);
        let (dx, dy) = (p.x - x, p.y - y);
        dx * dx + dy * dy <= icp.trust_translation * icp.trust_translation
            && abs(wrap_angle(p.theta - (answer.theta + g))) <= icp.trust_rotation
    })
}

/// The rival search after `answer`, the refinement of `input`'s readings around the belief
/// argmax (module docs). When the best rival beats it by more than [`SWITCH_MARGIN`], that
/// rival's fit becomes the answer (and the next reading's refinement carries on from it).
pub fn check(
    input: &RefineInput<'_>,
    answer: &Refinement,
    order: u8,
    budget: &Budget,
) -> RivalCheck {
    if (answer.fit.explained_bearings as usize) <= input.unknowns {
        return RivalCheck::not_searched(answer);
    }
    let icp = &input.params.icp;
    let mut rivals: HVec<Refinement, MAX_RIVALS> = HVec::new();
    let mut fitted = 0u8;
    for m in modes_of(input.localizer).iter() {
        if fitted as usize >= MAX_RIVALS {
            break;
        }
        if same_mode(&m.pose, &answer.registration.pose, icp, order) {
            continue;
        }
        fitted += 1;
        let Ok(r) = refine::rival_fit(input, &m.pose, budget) else {
            continue;
        };
        if !same_mode(&r.registration.pose, &answer.registration.pose, icp, order) {
            // Capacity MAX_RIVALS: at most that many are fitted.
            let _ = rivals.push(r);
        }
    }
    let ll = |r: &Refinement| r.fit.log_likelihood;
    // The strongest rival (the earlier on ties).
    let best = rivals
        .iter()
        .fold(None::<&Refinement>, |b, r| match b {
            Some(b) if ll(b) >= ll(r) => Some(b),
            _ => Some(r),
        })
        .copied();
    let switched = best.filter(|b| ll(b) > ll(answer) + SWITCH_MARGIN);
    let chosen = switched.unwrap_or(*answer);
    // Everything else: the argmax's refinement (when it was overruled) and the rivals.
    let others = rivals.iter().chain(switched.map(|_| answer));
    let other_best = others
        .filter(|r| !same_mode(&r.registration.pose, &chosen.registration.pose, icp, order))
        .map(ll)
        .fold(f32::NEG_INFINITY, f32::max);
    let margin = ll(&chosen) - other_best;
    RivalCheck {
        answer: chosen,
        // A NaN likelihood (never expected) reads as a tie: no stop on it.
        margin: if margin.is_nan() {
            0.0
        } else {
            margin.clamp(-MARGIN_CAP, MARGIN_CAP)
        },
        fitted,
        switched: switched.is_some(),
    }
}

/// True when the answer at `pose` (log-likelihood `answer_ll` of the readings under `model`),
/// turned by a quarter, half or three-quarter turn about the centre of the wall points its
/// explained readings hit ([`explained_hits_centre`], readings within `gate`), lies in the
/// room, is not the answer's own mode or a symmetric twin of it ([`same_mode`]), and
/// explains the readings within [`SWITCH_MARGIN`] of the answer (module docs). Such an
/// image is a rival the belief may not hold: the readings cannot tell the two apart.
#[allow(clippy::too_many_arguments)]
pub fn turned_image_rivals(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    answer_ll: f32,
    model: &RangeModel,
    icp: &IcpParams,
    order: u8,
    gate: f32,
) -> bool {
    let Some(centre) = explained_hits_centre(plan, obs, pose, gate) else {
        return false;
    };
    let arm = pose.translation() - centre;
    (1..4).any(|quarter| {
        let g = quarter as f32 * core::f32::consts::FRAC_PI_2;
        let (s, c) = (sin(g), cos(g));
        let image = Pose2::new(
            centre.x + c * arm.x - s * arm.y,
            centre.y + s * arm.x + c * arm.y,
            pose.theta + g,
        );
        !same_mode(&image, pose, icp, order)
            && plan.contains(image.translation())
            && range_fit(plan, obs, &image, model).log_likelihood >= answer_ll - SWITCH_MARGIN
    })
}

/// The belief's strongest modes, the answer's among them (skipped by [`check`]).
fn modes_of(loc: &GhtLocalizer) -> HVec<Mode, { MAX_RIVALS + 2 }> {
    loc.top_modes::<{ MAX_RIVALS + 2 }>(MODE_SEPARATION)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::l_room_8x6;
    use crate::registration::refine::tests::{known_heading_input, readings};
    use crate::registration::AnnealParams;

    /// An answer fitted in the wrong part of the room loses to the rival at the belief's
    /// argmax, which explains every reading: the check switches to it, and the margin says
    /// by how much it explains them better than the wrong one.
    #[test]
    fn a_rival_that_explains_the_readings_better_becomes_the_answer() {
        let plan = l_room_8x6();
        let truth = Pose2::new(-1.2, -0.9, 0.3);
        let (obs, loc) = readings(&plan, &truth, &[-0.3, 0.9, 1.7, 2.6, 3.3, 4.4]);
        let mut params = AnnealParams::default();
        params.icp.fixed_heading = true;
        params.icp.trust_translation = loc.grid().cell[0].max(loc.grid().cell[1]);
        let input = known_heading_input(&plan, &obs, &loc, params);
        let budget = Budget::per_reading(true);
        let right = refine::refine_within(&input, &budget).unwrap();
        let err = |r: &Refinement| (r.registration.pose.translation() - truth.translation()).norm();
        assert!(
            err(&right) < 0.02,
            "the argmax's refinement is right: {right:?}"
        );
        // Answered in the other leg of the L, where it explains fewer readings (its count
        // of explained bearings raised to three, so that the search runs: a wrong answer
        // that explains some readings by coincidence).
        let mut wrong =
            refine::refine_at(&input, &Pose2::new(2.5, -1.5, truth.theta), &budget).unwrap();
        assert!(err(&wrong) > 1.0 && wrong.fit.log_likelihood < right.fit.log_likelihood);
        wrong.fit.explained_bearings = 3;
        let c = check(&input, &wrong, 1, &budget);
        assert!(c.switched && c.fitted >= 1, "{c:?}");
        assert!(err(&c.answer) < 0.05, "{c:?}");
        assert!(c.margin > SWITCH_MARGIN, "{c:?}");
        // Below that nothing is searched: the answer stands, margin 0.
        let mut unchecked = wrong;
        unchecked.fit.explained_bearings = 2;
        assert_eq!(
            check(&input, &unchecked, 1, &budget),
            RivalCheck::not_searched(&unchecked)
        );
        // The right answer keeps its place, with no rival near it.
        let c = check(&input, &right, 1, &budget);
        assert!(!c.switched && c.answer == right && c.margin > 0.0, "{c:?}");
    }

    /// Plan 1000203's building-site flip, drawn small: an L whose main rectangle (12 × 14 m)
    /// holds every reading. The answer turned by a half turn about that rectangle's centre
    /// predicts each range exactly, though the L has no symmetry: a rival. One reading into
    /// the L's other leg, which the turned image cannot explain, settles it.
    #[test]
    fn a_turned_image_that_explains_every_reading_is_a_rival() {
        use crate::registration::Measurement;
        use crate::world::geometry::{unit, v2, Vec2};
        let plan = FloorPlan::new(&[
            v2(0.0, 0.0),
            v2(16.0, 0.0),
            v2(16.0, 4.0),
            v2(12.0, 4.0),
            v2(12.0, 14.0),
            v2(0.0, 14.0),
        ])
        .unwrap();
        let truth = Pose2::new(4.0, 9.0, 0.3);
        let hit = |b: f32| {
            plan.ray_cast(truth.translation(), unit(truth.theta + b))
                .unwrap()
        };
        // Bearings whose walls the half-turned image sees too: the main rectangle's, away
        // from where its mirror image would fall into the other leg.
        let on_main_walls =
            |q: Vec2| q.x <= 12.001 && (q.x > 0.001 || q.y <= 10.0) && (q.x < 11.999 || q.y >= 4.0);
        let mut obs = Observations::new();
        for k in 0..16 {
            let b = k as f32 * 0.39;
            let h = hit(b);
            if on_main_walls(h.point) {
                obs.push(Measurement::new(b, h.range)).unwrap();
            }
        }
        assert!(obs.len() >= 6, "{} readings on the main walls", obs.len());
        let model = RangeModel::default();
        let rivals = |obs: &Observations| {
            let ll = range_fit(&plan, obs, &truth, &model).log_likelihood;
            turned_image_rivals(&plan, obs, &truth, ll, &model, &icp(), 1, 0.09)
        };
        assert!(rivals(&obs), "the half-turned image explains every reading");
        // Two readings give no centre to turn about.
        let mut two = Observations::new();
        for (b, r) in obs.readings().take(2) {
            two.push(Measurement::new(b, r)).unwrap();
        }
        assert!(!rivals(&two));
        // Bearing −1.0 looks through the leg's mouth (x = 12, y < 4) to its far end.
        let leg = hit(-1.0);
        assert!(leg.point.x > 12.5, "{leg:?}");
        obs.push(Measurement::new(-1.0, leg.range)).unwrap();
        assert!(
            !rivals(&obs),
            "a reading into the other leg tells them apart"
        );
    }

    fn icp() -> IcpParams {
        IcpParams {
            trust_translation: 0.3,
            trust_rotation: 0.5,
            ..IcpParams::default()
        }
    }

    #[test]
    fn a_symmetric_twin_is_the_same_mode() {
        let answer = Pose2::new(1.0, 0.5, 0.2);
        // The 180° twin of the answer in a 2-fold symmetric room.
        let twin = Pose2::new(-1.0, -0.5, 0.2 + core::f32::consts::PI);
        assert!(same_mode(&twin, &answer, &icp(), 2));
        assert!(!same_mode(&twin, &answer, &icp(), 1));
        // Near the answer itself, whatever the order.
        assert!(same_mode(&Pose2::new(1.1, 0.6, 0.3), &answer, &icp(), 1));
        // Too far, or turned too far.
        assert!(!same_mode(&Pose2::new(1.5, 0.5, 0.2), &answer, &icp(), 1));
        assert!(!same_mode(&Pose2::new(1.0, 0.5, 0.8), &answer, &icp(), 1));
    }
}
