//! Step 1 and 2 of Sparse ICP (Algorithm 4): each observation's correspondent on a
//! feasible wall (facing the ray, within the incidence limit, visible from the instrument;
//! else the plain nearest point at a lower weight), then the percentile outlier rejection,
//! and the error and truncated score of the pairs that are left.

use super::*;

/// Correspondence for one observation at AgentPose `pose`: the nearest point on a feasible
/// wall (facing the ray, incidence within `cos_max`, visible from the instrument), else the
/// plain nearest point with weight `relaxed_w`.
pub(super) fn correspond(
    (plan, sight): (&FloorPlan, &Sightlines),
    o: &ObsPoint,
    pose: &Pose2,
    (sin_h, cos_h): (f32, f32),
    cos_max: f32,
    relaxed_w: f32,
) -> Pair {
    let origin = pose.translation(); // the instrument, in the model frame
                                     // `pose.transform(o.s)` and `pose.rotate_dir(o.d)` with the heading's sine and cosine
                                     // taken once per pose (libm's are software routines on the M4F; the same bits).
    let rot = |v: Vec2| v2(cos_h * v.x - sin_h * v.y, sin_h * v.x + cos_h * v.y);
    let p = rot(o.s) + origin;
    let d = rot(o.d);
    let n = plan.len().min(MAX_VERTICES);
    // The walls facing the ray within the incidence limit, with their nearest points, in
    // wall order; the correspondent is the nearest of them that is visible (the first on
    // equal distances), else the nearest point of any wall. Written as one pass over the
    // walls and then visibility tests in order of distance (a wall's facing does not
    // depend on `p`): the same pairs as scanning every wall again after each hidden one.
    //
    // Distances are compared squared and the facing test is made on the unnormalised
    // normal: on the M4F, libm's `sqrtf` is a software routine, and two of them per wall
    // were most of a correspondence's cost. The square root is taken for the chosen wall.
    let mut feasible = [(0.0f32, v2(0.0, 0.0), 0u8); MAX_VERTICES];
    let mut nf = 0usize;
    let cos2 = cos_max * cos_max;
    // Solid walls only: no reading pairs with a door opening.
    for i in (0..n).filter(|&i| !plan.is_opening(i)) {
        let (a, b) = plan.wall(i);
        let e = b - a;
        // d · (outward normal × |e|), the normal being `e` turned right.
        let c = d.x * e.y - d.y * e.x;
        if c > 0.0 && (cos_max <= 0.0 || c * c >= cos2 * (e.x * e.x + e.y * e.y)) {
            let q = closest_on_segment(p, a, b);
            let r = p - q;
            feasible[nf] = (r.x * r.x + r.y * r.y, q, i as u8);
            nf += 1;
        }
    }
    let mut tried: u64 = 0;
    loop {
        let mut best: Option<usize> = None;
        for (k, f) in feasible[..nf].iter().enumerate() {
            if tried & (1u64 << k) == 0 && best.is_none_or(|b| f.0 < feasible[b].0) {
                best = Some(k);
            }
        }
        let Some(k) = best else { break };
        let (d2, m, i) = feasible[k];
        // `plan.visible(origin, m, VISIBILITY_TOLERANCE)`, the viewpoint's walls worked out
        // once per pass.
        if sight.visible(m, VISIBILITY_TOLERANCE) {
            let nrm = plan.outward_normal(i as usize);
            return Pair {
                m,
                s: o.s,
                dist: sqrt(d2),
                weight: d.x * nrm.x + d.y * nrm.y,
                relaxed: false,
                inlier: true,
            };
        }
        tried |= 1u64 << k;
    }
    let mut any: Option<(Vec2, f32)> = None;
    for i in (0..n).filter(|&i| !plan.is_opening(i)) {
        let (a, b) = plan.wall(i);
        let q = closest_on_segment(p, a, b);
        let r = p - q;
        let d2 = r.x * r.x + r.y * r.y;
        if any.is_none_or(|(_, e)| d2 < e) {
            any = Some((q, d2));
        }
    }
    let any = any.map(|(q, d2)| (q, sqrt(d2)));
    match any {
        Some((m, dist)) => Pair {
            m,
            s: o.s,
            dist,
            weight: relaxed_w,
            relaxed: true,
            inlier: true,
        },
        // A valid plan has at least three walls.
        None => Pair {
            m: p,
            s: o.s,
            dist: 0.0,
            weight: 0.0,
            relaxed: true,
            inlier: false,
        },
    }
}

/// Pair counts up to this sort their distances in a 128-byte buffer, not a 2 KB one.
const SHORT_SORT: usize = 32;

/// The `keep`-th smallest pair distance and the (lower) median, `0` for none, from a
/// buffer of `N` that fits the pairs: zeroing one of `MAX_OBSERVATIONS` (2 KB) per
/// correspondence pass was 2 % of a K = 10 episode's instructions on the device, and the
/// calibrated stop's fits rarely have more than [`SHORT_SORT`] readings. Its own frame
/// (`inline(never)`), so the correspondences' frame does not hold the buffer.
#[inline(never)]
fn order_statistics<const N: usize>(pairs: &Pairs, keep: usize) -> (f32, f32) {
    let n = pairs.len().min(N);
    let mut sorted = [0.0f32; N];
    for (k, p) in pairs.iter().take(n).enumerate() {
        sorted[k] = p.dist;
    }
    let sorted = &mut sorted[..n];
    sorted.sort_unstable_by(|a, b| a.total_cmp(b));
    let threshold = if keep == 0 {
        0.0
    } else {
        sorted[keep.min(n) - 1]
    };
    let median = if n == 0 { 0.0 } else { sorted[(n - 1) / 2] };
    (threshold, median)
}

/// Correspondences + outlier rejection at `pose`; returns `E` and counts. `heading` is a
/// turn by `pose.theta` or its negative where the caller has one (else any: it is then
/// recomputed), `cos_max` is [`IcpParams::cos_max_incidence`].
pub(in crate::registration) fn match_pairs(
    plan: &FloorPlan,
    obs: &Observations,
    (pose, heading): (&Pose2, Turn),
    (params, cos_max): (&IcpParams, f32),
    pairs: &mut Pairs,
) -> ErrorSummary {
    pairs.clear();
    let sc = heading.to(pose.theta).sin_cos();
    let sight = Sightlines::new(plan, pose.translation());
    let doors = plan.openings() != 0;
    for (i, o) in obs.pts.iter().enumerate() {
        if params.excludes(i) {
            continue;
        }
        // A reading through a door has no wall to pair with (`beyond_door`).
        if doors
            && crate::registration::beyond_door(
                plan,
                pose.translation(),
                v2(sc.1 * o.d.x - sc.0 * o.d.y, sc.0 * o.d.x + sc.1 * o.d.y),
                length(o.s),
            )
        {
            continue;
        }
        // Same capacity as the observation set.
        let _ = pairs.push(correspond(
            (plan, &sight),
            o,
            pose,
            sc,
            cos_max,
            params.relaxed_weight,
        ));
    }
    let n = pairs.len();
    // Percentile threshold on the distances.
    let keep = {
        let k = (params.keep_fraction * n as f32 + 0.999) as usize;
        k.max(params.min_pairs.max(2) as usize).min(n)
    };
    let (threshold, median) = if n <= SHORT_SORT {
        order_statistics::<SHORT_SORT>(pairs, keep)
    } else {
        order_statistics::<MAX_OBSERVATIONS>(pairs, keep)
    };
    let floor = params
        .reject_min_distance
        .max(params.reject_median_factor * median);
    // A rejected pair counts in the score as if it lay at the rejection boundary.
    let cap = threshold.max(floor);
    let (mut sw, mut swd2, mut sw_all, mut trunc) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let (mut inliers, mut relaxed) = (0u16, 0u16);
    for p in pairs.iter_mut() {
        p.inlier = p.weight > 0.0 && (p.dist <= threshold || p.dist <= floor);
        relaxed += p.relaxed as u16;
        sw_all += p.weight;
        if p.inlier {
            inliers += 1;
            sw += p.weight;
            swd2 += p.weight * p.dist * p.dist;
        } else {
            trunc += p.weight * cap * cap;
        }
    }
    let error = if sw > 0.0 {
        sqrt(swd2 / sw)
    } else {
        f32::INFINITY
    };
    let score = if sw_all > 0.0 {
        sqrt((swd2 + trunc) / sw_all)
    } else {
        f32::INFINITY
    };
    ErrorSummary {
        error,
        score,
        inliers,
        relaxed,
    }
}
