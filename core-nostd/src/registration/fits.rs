//! How well readings fit and determine a pose, without moving it: the observability test
//! (the smallest eigenvalue of the readings' normalised information matrix) and
//! the range fit under the EDM's range model (what the refinement scores hypotheses with).

use super::*;

/// How well a set of readings determines the pose (the observability test): the
/// smallest eigenvalue of the normalised information matrix of the point-to-wall
/// constraints the readings would give at a pose.
///
/// At `pose`, reading `i` (bearing `βᵢ`) casts a ray into the model; the wall it hits, with
/// outward normal `nᵢ`, constrains the pose along `nᵢ` only. A small pose change
/// `(δx, δy, δθ)` moves that reading's residual by `nᵢ·(δx, δy) + nᵢ·⊥(R(h)sᵢ)·δθ`. With
/// the rotation expressed as the displacement it causes at the readings' RMS range `L`
/// (`δφ = L·δθ`), the rows `Jᵢ = (nᵢ, nᵢ·⊥(R(h)sᵢ)/L)` are unitless and
/// `A = (1/N) Σ JᵢᵀJᵢ` has eigenvalues in `[0, 1]`. Its smallest eigenvalue is the
/// fraction of the readings' information along the worst-determined direction:
/// 0 for a fan onto one wall (nothing fixes the position along the wall), ½ for readings
/// split evenly between two perpendicular walls with the heading known. The heading is a
/// column of its own only when it is unknown (`fixed_heading == false`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observability {
    /// Smallest eigenvalue of the normalised information matrix (0 = undetermined).
    pub min_eigenvalue: f32,
    /// Readings whose ray hits a wall at the pose (the others add nothing).
    pub constraints: u16,
}

/// [`Observability`] of `obs` at `pose` (ranges are not used: only which wall each
/// bearing's ray meets, and how).
pub fn observability(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    fixed_heading: bool,
) -> Observability {
    let a = pose.translation();
    let mut rows: HVec<[f32; 3], MAX_OBSERVATIONS> = HVec::new();
    let mut sum_r2 = 0.0f32;
    for p in obs.pts.iter() {
        let d = rotate(p.d, pose.theta);
        if let Some(hit) = plan.ray_cast(a, d) {
            let n = plan.outward_normal(hit.wall);
            let rs = d * hit.range; // R(h)·s for the predicted point
            let rot = n.x * -rs.y + n.y * rs.x;
            sum_r2 += hit.range * hit.range;
            let _ = rows.push([n.x, n.y, rot]);
        }
    }
    let m = rows.len();
    if m == 0 {
        return Observability {
            min_eigenvalue: 0.0,
            constraints: 0,
        };
    }
    let l = sqrt(sum_r2 / m as f32).max(1e-6);
    let mut info = [[0.0f32; 3]; 3];
    for r in rows.iter() {
        let j = [r[0], r[1], r[2] / l];
        for (u, ju) in j.iter().enumerate() {
            for (v, jv) in j.iter().enumerate() {
                info[u][v] += ju * jv / m as f32;
            }
        }
    }
    let min_eigenvalue = if fixed_heading {
        min_eigen_2x2(info[0][0], info[0][1], info[1][1])
    } else {
        min_eigen_3x3(&info)
    };
    Observability {
        min_eigenvalue: min_eigenvalue.max(0.0),
        constraints: m as u16,
    }
}

/// The EDM's range model, used to score a pose against the readings: a reading either is
/// explained (its range residual along the ray is Gaussian) or is an outlier (its range is
/// uniform over `(0, max_range]`). This is the sensor model of the simulation (`host-sim`
/// `SensorModel`: σ = 1 cm, 5 % outliers, 50 m), with σ widened to cover the fit's own
/// imprecision: the registration minimises point-to-wall distances, not range residuals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RangeModel {
    /// Standard deviation of an explained reading's range residual (m).
    pub sigma: f32,
    /// Probability that a reading is an outlier.
    pub outlier_prob: f32,
    /// Extent of the outliers' uniform density (m).
    pub max_range: f32,
}

impl Default for RangeModel {
    fn default() -> Self {
        RangeModel {
            sigma: 0.03,
            outlier_prob: 0.05,
            max_range: 50.0,
        }
    }
}

/// How well a pose explains the readings under a [`RangeModel`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RangeFit {
    /// `Σᵢ ln((1−ε)·N(rᵢ; 0, σ²) + ε/R)` over all readings, `rᵢ` the measured minus the
    /// ray-cast range at the pose (a ray that meets no wall explains nothing); `ln(1/R)`
    /// for a reading [`beyond_door`].
    pub log_likelihood: f32,
    /// Readings within 3σ of the ray-cast range, or [`beyond_door`].
    pub explained: u16,
    /// Distinct bearings among the readings (a bearing measured twice is one direction).
    pub bearings: u16,
    /// Distinct bearings with at least one explained reading: the independent checks the
    /// pose passed (repeating a range at one bearing re-checks the same wall point).
    pub explained_bearings: u16,
}

/// How far short of a door a reading through it may end and still count as through it
/// (m): 3σ of the default [`RangeModel`], for a jamb the beam grazes or a door leaf ajar.
pub const DOOR_MARGIN: f32 = 0.09;

/// True when the plan predicts this reading "beyond a door": from `origin` along unit `dir`
/// the ray leaves the room through a door opening before any solid wall
/// ([`FloorPlan::door_exit`]) and the `measured` range reaches the door (less
/// [`DOOR_MARGIN`]). Such a reading is explained, and no wall is its correspondent: it
/// neither confirms nor pulls a pose (a station set up by a door would otherwise see
/// every reading through it as a misfit, and never answer). False for a plan without doors.
#[inline]
pub fn beyond_door(plan: &FloorPlan, origin: Vec2, dir: Vec2, measured: f32) -> bool {
    // The mask first, inline: this runs for every reading of every fit, and generated
    // plans (and most rooms) have no doors.
    plan.openings() != 0
        && plan
            .door_exit(origin, dir)
            .is_some_and(|door| measured >= door - DOOR_MARGIN)
}

/// The centre of the bounding box of the wall points that the readings explained at
/// `pose` hit (ray-cast range within `gate` of the measured one; readings through a door
/// hit no wall and are left out), or `None` with fewer than three such readings. A room
/// whose readings all fall on the walls of one rectangle looks the same from the answer
/// turned about this point by a half turn (a square: a quarter turn too), whatever the
/// rest of the plan holds: [`crate::stop::rivals::turned_image_rivals`] turns it there.
pub fn explained_hits_centre(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    gate: f32,
) -> Option<Vec2> {
    let origin = pose.translation();
    let (mut lo, mut hi) = (
        v2(f32::INFINITY, f32::INFINITY),
        v2(f32::NEG_INFINITY, f32::NEG_INFINITY),
    );
    let turn = crate::world::geometry::Turn::new(pose.theta);
    let mut hits = 0usize;
    for p in obs.pts.iter() {
        let dir = turn.apply(p.d);
        let Some(t) = plan.first_hit(origin, dir) else {
            continue;
        };
        if abs(length(p.s) - t) <= gate {
            let q = origin + dir * t;
            lo = v2(lo.x.min(q.x), lo.y.min(q.y));
            hi = v2(hi.x.max(q.x), hi.y.max(q.y));
            hits += 1;
        }
    }
    (hits >= 3).then(|| (lo + hi) * 0.5)
}

/// [`RangeFit`] of every reading of `obs` at AgentPose `pose` (excluded or not: the
/// refinement compares hypotheses on the same readings).
pub fn range_fit(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    model: &RangeModel,
) -> RangeFit {
    let a = pose.translation();
    let sigma = model.sigma.max(1e-6);
    let outlier = model.outlier_prob.clamp(0.0, 1.0) / model.max_range.max(1e-6);
    let peak = (1.0 - model.outlier_prob.clamp(0.0, 1.0)) / (sigma * sqrt(TAU));
    let (mut log_likelihood, mut explained) = (0.0f32, 0u16);
    let (mut bearings, mut explained_bearings) = (0u16, 0u16);
    let (sin_h, cos_h) = (sin(pose.theta), cos(pose.theta));
    let rot = |v: Vec2| v2(cos_h * v.x - sin_h * v.y, sin_h * v.x + cos_h * v.y);
    // Whether reading i was explained (for the per-bearing counts).
    let mut ok = [false; MAX_OBSERVATIONS];
    // A reading through a door of the plan, at least as far as the door: the plan says
    // "beyond", not where, so it is explained at a flat density over the EDM's range.
    let beyond = 1.0 / model.max_range.max(1e-6);
    for (i, p) in obs.pts.iter().enumerate() {
        let measured = length(p.s);
        if beyond_door(plan, a, rot(p.d), measured) {
            explained += 1;
            ok[i] = true;
            log_likelihood += ln(beyond);
            continue;
        }
        let predicted = plan.first_hit(a, rot(p.d));
        let density = match predicted {
            Some(r) => {
                let z = (measured - r) / sigma;
                if abs(z) <= 3.0 {
                    explained += 1;
                    ok[i] = true;
                }
                // exp underflows to 0 far out, leaving the outlier density: no NaN.
                peak * exp(-0.5 * z * z) + outlier
            }
            None => outlier,
        };
        log_likelihood += ln(density.max(f32::MIN_POSITIVE));
    }
    // Encoder bearings repeat exactly, so equal directions are the same bearing.
    for (i, p) in obs.pts.iter().enumerate() {
        let same = |j: usize| obs.pts[j].d == p.d;
        if !(0..i).any(same) {
            bearings += 1;
        }
        if ok[i] && !(0..i).any(|j| ok[j] && same(j)) {
            explained_bearings += 1;
        }
    }
    RangeFit {
        log_likelihood,
        explained,
        bearings,
        explained_bearings,
    }
}

/// The readings `pose` leaves unexplained (range residual beyond 3σ of [`RangeModel`], or a
/// ray that meets no wall), worst first (ties: the earlier reading), skipping `skip`: the
/// refinement's candidates for leaving out. At most `N`.
pub fn unexplained_readings<const N: usize>(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    model: &RangeModel,
    skip: &[u16],
) -> HVec<u16, N> {
    let a = pose.translation();
    let sigma = model.sigma.max(1e-6);
    let mut worst: HVec<(f32, u16), N> = HVec::new();
    let (sin_h, cos_h) = (sin(pose.theta), cos(pose.theta));
    let rot = |v: Vec2| v2(cos_h * v.x - sin_h * v.y, sin_h * v.x + cos_h * v.y);
    for (i, p) in obs.pts.iter().enumerate() {
        if skip.contains(&(i as u16)) || beyond_door(plan, a, rot(p.d), length(p.s)) {
            continue;
        }
        let z = match plan.first_hit(a, rot(p.d)) {
            Some(r) => abs((length(p.s) - r) / sigma),
            None => f32::INFINITY,
        };
        // A NaN residual fails the test: unexplained.
        if z <= 3.0 {
            continue;
        }
        let z = if z.is_nan() { f32::INFINITY } else { z };
        // Insertion into the short, worst-first list.
        let at = worst
            .iter()
            .position(|&(w, _)| z > w)
            .unwrap_or(worst.len());
        if at < N {
            if worst.len() == N {
                worst.pop();
            }
            let _ = worst.insert(at, (z, i as u16));
        }
    }
    worst.iter().map(|&(_, i)| i).collect()
}

/// Smallest eigenvalue of the symmetric `[[a, b], [b, c]]`.
pub(super) fn min_eigen_2x2(a: f32, b: f32, c: f32) -> f32 {
    let mean = 0.5 * (a + c);
    let half = sqrt(0.25 * (a - c) * (a - c) + b * b);
    mean - half
}

/// Smallest eigenvalue of a symmetric 3×3 matrix (trigonometric solution of the
/// characteristic cubic, Smith 1961).
pub(super) fn min_eigen_3x3(m: &[[f32; 3]; 3]) -> f32 {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
    if p1 <= 1e-12 {
        return m[0][0].min(m[1][1]).min(m[2][2]);
    }
    let p2 = (m[0][0] - q) * (m[0][0] - q)
        + (m[1][1] - q) * (m[1][1] - q)
        + (m[2][2] - q) * (m[2][2] - q)
        + 2.0 * p1;
    let p = sqrt(p2 / 6.0);
    let b = |i: usize, j: usize| (m[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = crate::world::math::acos(r) / 3.0;
    // Eigenvalues q + 2p·cos(φ + 2πk/3); k = 1 gives the smallest.
    q + 2.0 * p * cos(phi + TAU / 3.0)
}
