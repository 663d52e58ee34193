//! Algorithm 3: annealed perturbations around Sparse ICP. From the current estimate,
//! Gaussian perturbations (seeded, so a seed fixes the result on host and MCU) are scored,
//! ICP runs from the best, and a lower score is accepted; the perturbation scale follows
//! the score until patience, the error floor or the round cap ends it.

use super::*;

/// Annealed sparse registration (Algorithm 3) from the AgentPose `initial` (the coarse
/// localizer's estimate) against the centred `plan`.
pub fn register(
    plan: &FloorPlan,
    obs: &Observations,
    initial: &Pose2,
    params: &AnnealParams,
) -> Result<Registration, RegistrationError> {
    register_centred(plan, obs, initial, initial, params)
}

/// [`register`] from `initial`, with the trust region centred on `centre` (the refinement
/// starts its final annealing from the screened winner, inside the belief's trust region).
#[inline(never)]
pub fn register_centred(
    plan: &FloorPlan,
    obs: &Observations,
    initial: &Pose2,
    centre: &Pose2,
    params: &AnnealParams,
) -> Result<Registration, RegistrationError> {
    register_centred_with(plan, obs, initial, centre, params, &mut Pairs::new())
}
// The functions that hold a pair buffer (14 KB) are never inlined: inlined, the buffer
// stays in the caller's frame for the caller's whole run, and the refinement's callers
// nest (track → refine → hypothesis → sweep): on the device's 42 KB stack three such
// frames left a few hundred bytes (README, "What is not done yet").

/// [`register_centred`] with the caller's pair buffer: `MAX_OBSERVATIONS` pairs are 14 KB,
/// and the heading sweep that ends in this annealing already holds one; two on the
/// device's 42 KB stack left it a few hundred bytes (README, "What is not done yet").
/// The buffer is scratch: every correspondence pass clears it first.
pub(in crate::registration) fn register_centred_with(
    plan: &FloorPlan,
    obs: &Observations,
    initial: &Pose2,
    centre: &Pose2,
    params: &AnnealParams,
    pairs: &mut Pairs,
) -> Result<Registration, RegistrationError> {
    let icp = &params.icp;
    check_inputs(obs, initial, icp)?;
    let gains_ok = [
        params.min_error,
        params.translation_gain,
        params.rotation_gain,
        params.max_sigma_translation,
        params.max_sigma_rotation,
    ]
    .iter()
    .all(|g| g.is_finite() && *g >= 0.0);
    if !gains_ok {
        return Err(RegistrationError::InvalidParams);
    }
    let mut rng = GaussianRng::new(params.seed);
    let mut pose = *initial;
    let cos_max = icp.cos_max_incidence();
    let mut summary = match_pairs(
        plan,
        obs,
        (&pose, Turn::new(pose.theta)),
        (icp, cos_max),
        pairs,
    );
    let mut iterations = 0u16;
    let sigmas = |e: f32| {
        let r = if e.is_finite() { sqrt(e) } else { 1.0 };
        let st = (params.translation_gain * r).min(params.max_sigma_translation);
        let sr = if icp.fixed_heading {
            0.0
        } else {
            (params.rotation_gain * r).min(params.max_sigma_rotation)
        };
        (st, sr)
    };
    let (mut sigma_t, mut sigma_r) = sigmas(summary.score);
    let mut rounds = 0u16;
    let mut stale = 0u8;
    let mut converged = false;
    while rounds < params.max_rounds {
        if summary.score <= params.min_error || stale >= params.patience {
            converged = true;
            break;
        }
        rounds += 1;
        // Perturbations j = 1..=M around the estimate; j = 0 is the estimate itself.
        let mut pick = (pose, summary);
        for _ in 0..params.perturbations {
            let cand = Pose2::new(
                pose.x + sigma_t * rng.normal(),
                pose.y + sigma_t * rng.normal(),
                pose.theta + sigma_r * rng.normal(),
            );
            if !in_trust_region(&cand, centre, icp) {
                continue;
            }
            let s = match_pairs(
                plan,
                obs,
                (&cand, Turn::new(cand.theta)),
                (icp, cos_max),
                pairs,
            );
            if s.score < pick.1.score {
                pick = (cand, s);
            }
        }
        let refined = icp_inner(plan, obs, &pick.0, centre, icp, pairs);
        iterations = iterations.saturating_add(refined.iterations);
        let next = if refined.score < pick.1.score {
            (
                refined.pose,
                ErrorSummary {
                    error: refined.error,
                    score: refined.score,
                    inliers: refined.inliers,
                    relaxed: refined.relaxed,
                },
            )
        } else {
            pick
        };
        // Improvement test with a small relative margin so float jitter does not reset it.
        if next.1.score < summary.score * (1.0 - 1e-4) {
            stale = 0;
        } else {
            stale = stale.saturating_add(1);
        }
        if next.1.score <= summary.score {
            pose = next.0;
            summary = next.1;
        }
        (sigma_t, sigma_r) = sigmas(summary.score);
    }
    if !converged && (summary.score <= params.min_error || stale >= params.patience) {
        converged = true;
    }
    Ok(Registration {
        pose,
        error: summary.error,
        score: summary.score,
        inliers: summary.inliers,
        relaxed: summary.relaxed,
        iterations,
        rounds,
        converged,
    })
}
