//! The heading sweep before the annealed registration (Algorithm 3): with the heading
//! unknown the coarse localizer's heading can be off by more than a rotation bin, which the
//! annealing's local perturbations rarely bridge with a handful of readings; plain sparse
//! ICPs from several start headings pick where it starts. Split from [`super::icp`], whose
//! ICP, correspondences and annealing it calls.

use super::icp::{check_inputs, icp_inner, match_pairs, register_centred_with, Pairs};
use super::*;
use crate::world::geometry::Turn;

/// Annealed registration after a heading sweep: sparse ICP from `starts` headings spread
/// evenly over `initial.theta ± heading_span`, then Algorithm 3 from the one with the lowest
/// score. With the heading unknown, the coarse localizer's heading can be off by more than a
/// rotation bin (36° for K = 10), which local perturbations rarely bridge with a handful of
/// measurements; a deterministic sweep does, and running the annealing once keeps the cost
/// near that of [`register`] (it matters on the MCU). The trust region stays centred on
/// `initial`. `starts ≤ 1`, a fixed heading or a non-positive span is plain [`register`].
pub fn register_multistart(
    plan: &FloorPlan,
    obs: &Observations,
    initial: &Pose2,
    params: &AnnealParams,
    heading_span: f32,
    starts: u8,
) -> Result<Registration, RegistrationError> {
    register_multistart_capped(
        plan,
        obs,
        initial,
        params,
        heading_span,
        starts,
        u16::MAX,
        0,
    )
}

/// [`register_multistart`] with each sweep start's ICP cut at `sweep_iterations` (the
/// sweep only picks the start of the annealing, and sweep ICPs run to a 10 µm tolerance
/// were most of the refinement's cost), after which the `keep` best
/// starts are run on to convergence and the best of all is the annealing's start: a short
/// sweep alone ranks some starts before they reach their basin. Never inlined: its pair
/// buffer (14 KB) would stay in the caller's frame (`register_centred_with`).
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub fn register_multistart_capped(
    plan: &FloorPlan,
    obs: &Observations,
    initial: &Pose2,
    params: &AnnealParams,
    heading_span: f32,
    starts: u8,
    sweep_iterations: u16,
    keep: u8,
) -> Result<Registration, RegistrationError> {
    if starts <= 1 || params.icp.fixed_heading || !(heading_span > 0.0 && heading_span.is_finite())
    {
        return register(plan, obs, initial, params);
    }
    check_inputs(obs, initial, &params.icp)?;
    // Cheap sweep: plain sparse ICP from every start heading; the annealing (the expensive
    // part) then runs once, from the best of them.
    let mut pairs = Pairs::new();
    let sweep = IcpParams {
        max_iterations: params.icp.max_iterations.min(sweep_iterations),
        ..params.icp
    };
    let mut swept: heapless::Vec<(Pose2, f32, u8), MAX_SWEEP_STARTS> = heapless::Vec::new();
    let cos_max = params.icp.cos_max_incidence();
    let run = |start: &Pose2, icp: &IcpParams, pairs: &mut Pairs| {
        let r = icp_inner(plan, obs, start, initial, icp, pairs);
        let pose = if in_trust_region(&r.pose, initial, &params.icp) {
            r.pose
        } else {
            *start
        };
        (
            pose,
            match_pairs(
                plan,
                obs,
                (&pose, Turn::new(pose.theta)),
                (&params.icp, cos_max),
                pairs,
            )
            .score,
        )
    };
    for k in 0..starts.min(MAX_SWEEP_STARTS as u8) {
        let offset = -heading_span + 2.0 * heading_span * (k as f32 + 0.5) / starts as f32;
        let start = Pose2::new(initial.x, initial.y, initial.theta + offset);
        let (pose, score) = run(&start, &sweep, &mut pairs);
        let _ = swept.push((pose, score, k));
    }
    // Best first; of equal scores the earlier start.
    swept.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.2.cmp(&b.2)));
    let mut best = swept.first().map(|&(p, s, _)| (p, s));
    if sweep_iterations < params.icp.max_iterations {
        for &(pose, _, _) in swept.iter().take(keep as usize) {
            let c = run(&pose, &params.icp, &mut pairs);
            if best.is_none_or(|(_, s)| c.1 < s) {
                best = Some(c);
            }
        }
    }
    let start = best.map(|(p, _)| p).unwrap_or(*initial);
    register_centred_with(plan, obs, &start, initial, params, &mut pairs)
}

/// Most heading starts a sweep runs ([`register_multistart_capped`]).
pub const MAX_SWEEP_STARTS: usize = 16;
