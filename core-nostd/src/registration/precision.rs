//! The precision of a registered pose: the covariance of the AgentPose `(x, y, θ)` from the
//! information matrix of the readings the pose explains. What a surveyor reads
//! as "± so many millimetres" next to the station's coordinates.
//!
//! At `pose`, reading `i` (encoder bearing `βᵢ`, model direction `dᵢ = R(h)·unit(βᵢ)`) hits
//! the wall with outward normal `nᵢ` at the predicted range `ρᵢ`, the root of
//! `nᵢ·(a + ρ·dᵢ) = const`. Its derivatives, with `cᵢ = nᵢ·dᵢ` (the cosine of the incidence)
//! and `⊥d = (−d_y, d_x)`, are `∂ρ/∂a = −nᵢ/cᵢ` and `∂ρ/∂h = −ρᵢ·(nᵢ·⊥dᵢ)/cᵢ`. With range
//! noise σ the information is `I = Σ JᵢᵀJᵢ / σ²` and the covariance of the least-squares pose
//! is `I⁻¹` (the heading row and column are left out, and zero, when it is known). Only the
//! readings the pose explains (range residual within the gate) count: an outlier the fit
//! left out carries no information about where the instrument stands.
//!
//! A fit with fewer explained readings than unknowns, or whose readings leave one
//! direction free (a fan onto one wall: the information matrix is singular), has no
//! precision: [`PrecisionError`] says which, and the caller must print that instead of a
//! number. Nothing here panics or allocates.

use super::*;
use crate::world::floorplan::RayHit;

/// The covariance of a registered AgentPose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseCovariance {
    /// Covariance of `(x, y, θ)` in the model frame (m², m·rad, rad²); with a known heading
    /// the third row and column are zero.
    pub cov: [[f32; 3]; 3],
    /// Readings the precision rests on (explained by the pose).
    pub used: u16,
    /// Readings left out (no wall on their ray at the pose, or residual beyond the gate).
    pub left_out: u16,
    /// Unknowns of the pose (2 with the heading known, 3 without).
    pub unknowns: u8,
    /// The a-posteriori variance factor `σ̂₀² = Σ rᵢ² / σ² / (used − unknowns)` of the
    /// explained readings' range residuals `rᵢ` at the pose (1 when no reading is
    /// redundant): about 1 when the readings scatter as the EDM's noise does, well above it
    /// when the room is not where the plan draws it (a wall a few cm off its line: the
    /// global test of a least-squares adjustment). The covariance above does not include
    /// it: it is what the readings' geometry allows, this is how well they agree.
    pub variance_factor: f32,
}

impl PoseCovariance {
    /// Standard deviation of `x` (m).
    pub fn sigma_x(&self) -> f32 {
        sqrt(self.cov[0][0].max(0.0))
    }
    /// Standard deviation of `y` (m).
    pub fn sigma_y(&self) -> f32 {
        sqrt(self.cov[1][1].max(0.0))
    }
    /// Standard deviation of the heading (rad; 0 when it is known).
    pub fn sigma_heading(&self) -> f32 {
        sqrt(self.cov[2][2].max(0.0))
    }
    /// True when no reading is redundant (as many as unknowns): the precision then comes
    /// from the sensor model alone, nothing checked the fit.
    pub fn exactly_determined(&self) -> bool {
        self.used as usize <= self.unknowns as usize
    }
}

/// The range's derivatives `∂ρ/∂(x, y, θ)` of reading `p` at the pose `(a, theta)`, when
/// the pose explains it (a wall on its ray, range residual within `gate`); see the module
/// documentation.
fn explained_row(
    plan: &FloorPlan,
    a: Vec2,
    theta: f32,
    p: &ObsPoint,
    gate: f32,
) -> Option<[f64; 3]> {
    explained_row_on(plan, a, theta, p, gate).map(|(_, _, j)| j)
}

/// [`explained_row`] with the wall the reading hits and its range residual (m, measured
/// minus predicted).
fn explained_row_on(
    plan: &FloorPlan,
    a: Vec2,
    theta: f32,
    p: &ObsPoint,
    gate: f32,
) -> Option<(usize, f32, [f64; 3])> {
    let d = rotate(p.d, theta);
    let hit = plan.ray_cast(a, d)?;
    let residual = length(p.s) - hit.range;
    if abs(residual) > gate {
        return None;
    }
    let n = plan.outward_normal(hit.wall);
    Some((hit.wall, residual, planned_row(n, d, hit.range)))
}

/// True when `rest`, what is left of the information matrix `whole` with some readings
/// taken out, leaves a direction free: its determinant relative to the product of
/// `whole`'s diagonal (the test [`pose_covariance`] applies, scaled by what the readings
/// gave before any were taken out).
///
/// **Why `whole`'s diagonal.** A direction only the removed readings fixed leaves a
/// rounding residue of about 1e-16 on `rest`'s diagonal, not a zero (the subtraction
/// is in another order than the sum). Scaled by `rest`'s own diagonal, that residue
/// cancels out of the ratio and the free direction looked fixed: a wall 5 cm off its
/// line then answered 5.9 cm off, with the heading unknown, the position across it
/// resting on two readings of that wall (`--site site`, plan 1000065, K = 10).
fn singular(rest: &[[f64; 3]; 3], whole: &[[f64; 3]; 3], fixed_heading: bool) -> bool {
    let m = rest;
    let det = if fixed_heading {
        m[0][0] * m[1][1] - m[0][1] * m[1][0]
    } else {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            + m[0][1] * (m[1][2] * m[2][0] - m[1][0] * m[2][2])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let w = whole;
    let scale = if fixed_heading {
        w[0][0] * w[1][1]
    } else {
        w[0][0] * w[1][1] * w[2][2]
    };
    det.is_nan() || det <= SINGULAR_RATIO * scale
}

/// True when some direction of the answer `pose` rests on one reading alone: with any one
/// of the readings the pose explains left out, the others leave a direction free (or there
/// are too few of them).
///
/// **Why.** A room is never its plan: a reading may have hit a cabinet in front of a wall,
/// and the pose that explains that reading as the wall is off by the cabinet's depth
/// along the one direction the reading fixes. Every other reading explains that pose as
/// well, so nothing the stop reads can tell it from the right one, unless a second reading
/// checks that direction. In furnished rooms (`--site furnished`) most of the confident
/// wrong answers with the heading known were of this kind: three readings, two on one wall,
/// the third, on a cabinet, the only one to fix the position along that wall
/// (`docs/EVALUATION.md`, "Rooms that are not their plans"). Two passes, no buffer: the
/// device's stack stays as it was.
pub fn rests_on_one_reading(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    fixed_heading: bool,
    gate: f32,
) -> bool {
    let a = pose.translation();
    let mut info = [[0.0f64; 3]; 3];
    let mut used = 0usize;
    for p in obs.pts.iter() {
        if let Some(j) = explained_row(plan, a, pose.theta, p, gate) {
            for (u, ju) in j.iter().enumerate() {
                for (v, jv) in j.iter().enumerate() {
                    info[u][v] += ju * jv;
                }
            }
            used += 1;
        }
    }
    let unknowns = if fixed_heading { 2 } else { 3 };
    if used <= unknowns {
        return true;
    }
    obs.pts.iter().any(|p| {
        explained_row(plan, a, pose.theta, p, gate).is_some_and(|j| {
            let mut rest = info;
            for (u, ju) in j.iter().enumerate() {
                for (v, jv) in j.iter().enumerate() {
                    rest[u][v] -= ju * jv;
                }
            }
            singular(&rest, &info, fixed_heading)
        })
    })
}

/// True when some direction of the answer `pose` rests on one wall alone: with every
/// reading on any one wall left out, the others leave a direction free (or there are too
/// few of them). Implies [`rests_on_one_reading`] (fewer readings never fix more).
///
/// **Why.** As-built walls stand a few centimetres off their drawn lines
/// (`--site site` moves one by 3–6 cm). Readings on one wall agree with each other
/// however far that wall is off, so a direction fixed by one wall alone carries the
/// wall's error into the answer unseen; a second wall along that direction either
/// halves it or shows it as residuals. One accumulator per wall (six `f32`, 1.5 KiB of
/// stack at [`crate::limits::MAX_VERTICES`] walls), one ray cast per reading.
pub fn rests_on_one_wall(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    fixed_heading: bool,
    gate: f32,
) -> bool {
    WallInformation::of(plan, obs, pose, gate).walls_alone(fixed_heading) > 0
}

/// How an as-built wall offset would carry into the answer: the information of the readings
/// a pose explains and, per wall, `Σ Jᵀ Δρ` for that wall moved one metre along its outward
/// normal, its two neighbours turning about their far corners (the corners it shares move
/// with it). [`WallLeverage::worst`] is the largest position shift over the walls, per
/// metre of offset, from the least-squares fit of the readings.
///
/// **Why.** On building sites (`--site site`, one wall 3–6 cm off its line) most confident
/// wrong answers with the heading known were 5–7 cm off with every reading explained and
/// no direction resting on one wall: the readings lay on the moved wall and on its two
/// neighbours near the shared corners, which move with it, so the fit followed the offset
/// (`activesense episode --seed 1000241 --rot-bins 1 --instrument edm --site site
/// --termination confident`: walls 5, 6, 6 and 7, wall 6 moved 5.8 cm, the answer 5.4 cm
/// off at 0.04 % risk). With the heading known the stop does not answer above
/// [`crate::stop::MAX_WALL_LEVERAGE`], and [`crate::pipeline::aim`] aims at the bearing that
/// lowers it. One accumulator of three `f32` per wall (768 B of stack at
/// [`crate::limits::MAX_VERTICES`] walls).
pub struct WallLeverage {
    /// `Σ JᵢᵀJᵢ` over every explained reading.
    info: [[f64; 3]; 3],
    /// Per wall, `Σ Jᵢᵀ ∂ρᵢ/∂offset` of that wall's offset.
    per_wall: [[f32; 3]; crate::limits::MAX_VERTICES],
    /// Explained readings.
    used: usize,
}

impl WallLeverage {
    /// The readings of `obs` the pose explains (range residual within `gate`).
    pub fn of(plan: &FloorPlan, obs: &Observations, pose: &Pose2, gate: f32) -> Self {
        let a = pose.translation();
        let mut w = WallLeverage {
            info: [[0.0f64; 3]; 3],
            per_wall: [[0.0f32; 3]; crate::limits::MAX_VERTICES],
            used: 0,
        };
        for p in obs.pts.iter() {
            let d = rotate(p.d, pose.theta);
            let Some(hit) = plan.ray_cast(a, d) else {
                continue;
            };
            if abs(length(p.s) - hit.range) > gate {
                continue;
            }
            w.add(plan, d, &hit);
        }
        w
    }

    /// With one more reading along the model direction `d` that hits `hit`: what a planned
    /// reading would make of it.
    pub fn with(&self, plan: &FloorPlan, d: Vec2, hit: &RayHit) -> Self {
        let mut w = WallLeverage {
            info: self.info,
            per_wall: self.per_wall,
            used: self.used,
        };
        w.add(plan, d, hit);
        w
    }

    /// Books one reading along `d` that hits `hit`: its range grows by `1 / cos(incidence)`
    /// per metre its wall moves out, and by the share of a neighbour's move that reaches
    /// the hit point (linear along the wall: all of it at the shared corner, none at the
    /// far one) projected on its own wall's normal.
    fn add(&mut self, plan: &FloorPlan, d: Vec2, hit: &RayHit) {
        let wall = hit.wall;
        let n = plan.outward_normal(wall);
        let row = planned_row(n, d, hit.range);
        let c = abs(n.x * d.x + n.y * d.y).max(MIN_COS_INCIDENCE);
        for (u, ju) in row.iter().enumerate() {
            for (v, jv) in row.iter().enumerate() {
                self.info[u][v] += ju * jv;
            }
        }
        self.used += 1;
        let (a, b) = plan.wall(wall);
        let e = b - a;
        let along = ((hit.point.x - a.x) * e.x + (hit.point.y - a.y) * e.y)
            / (e.x * e.x + e.y * e.y).max(1e-12);
        let t = along.clamp(0.0, 1.0);
        let (next, prev) = (plan.next(wall), plan.prev(wall));
        let (nn, np) = (plan.outward_normal(next), plan.outward_normal(prev));
        for (moved, dr) in [
            (wall, 1.0 / c),
            (next, t * (n.x * nn.x + n.y * nn.y) / c),
            (prev, (1.0 - t) * (n.x * np.x + n.y * np.y) / c),
        ] {
            if let Some(acc) = self.per_wall.get_mut(moved) {
                for (k, jk) in row.iter().enumerate() {
                    acc[k] += *jk as f32 * dr;
                }
            }
        }
    }

    /// The shift `(dx, dy, dθ)` (m, m, rad) of the least-squares answer per metre of
    /// `wall`'s offset (`dθ = 0` with the heading fixed); `None` when the readings leave a
    /// direction free (or are too few).
    pub fn shift(&self, wall: usize, fixed_heading: bool) -> Option<(f64, f64, f64)> {
        let acc = self.per_wall.get(wall)?;
        let unknowns = if fixed_heading { 2 } else { 3 };
        if self.used <= unknowns {
            return None;
        }
        let m = &self.info;
        let g = [acc[0] as f64, acc[1] as f64, acc[2] as f64];
        if fixed_heading {
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            if det.is_nan() || det <= SINGULAR_RATIO * m[0][0] * m[1][1] {
                return None;
            }
            return Some((
                (m[1][1] * g[0] - m[0][1] * g[1]) / det,
                (m[0][0] * g[1] - m[1][0] * g[0]) / det,
                0.0,
            ));
        }
        let det = det3(m);
        if det.is_nan() || det <= SINGULAR_RATIO * m[0][0] * m[1][1] * m[2][2] {
            return None;
        }
        let solve = |col: usize| {
            let mut mm = *m;
            for (row, gr) in mm.iter_mut().zip(g) {
                row[col] = gr;
            }
            det3(&mm) / det
        };
        Some((solve(0), solve(1), solve(2)))
    }

    /// The largest heading shift over the walls read (rad per metre of one wall's offset).
    pub fn worst_heading(&self) -> f32 {
        self.worst_by(false, |_, _, dt| abs(dt as f32))
    }

    /// The largest position shift over the walls read (m per metre of one wall's offset);
    /// infinite when the readings leave a direction free.
    pub fn worst(&self, fixed_heading: bool) -> f32 {
        self.worst_by(fixed_heading, |dx, dy, _| sqrt((dx * dx + dy * dy) as f32))
    }

    fn worst_by(&self, fixed_heading: bool, size: impl Fn(f64, f64, f64) -> f32) -> f32 {
        let mut worst = 0.0f32;
        for (wall, acc) in self.per_wall.iter().enumerate() {
            if acc.iter().all(|&x| x == 0.0) {
                continue;
            }
            let Some((dx, dy, dt)) = self.shift(wall, fixed_heading) else {
                return f32::INFINITY;
            };
            let l = size(dx, dy, dt);
            if l.is_nan() {
                return f32::INFINITY;
            }
            worst = worst.max(l);
        }
        if self.used == 0 {
            f32::INFINITY
        } else {
            worst
        }
    }
}

/// Determinant of a 3 × 3 matrix.
fn det3(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        + m[0][1] * (m[1][2] * m[2][0] - m[1][0] * m[2][2])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// The information of the readings a pose explains, whole and per wall: what
/// [`rests_on_one_wall`] tests, and what [`crate::pipeline::aim`] adds a planned reading
/// to.
pub struct WallInformation {
    /// Per wall, the upper triangle ([`UPPER`]) of its readings' `Σ JᵢᵀJᵢ`.
    per_wall: [[f32; 6]; crate::limits::MAX_VERTICES],
    /// `Σ JᵢᵀJᵢ` over every explained reading.
    info: [[f64; 3]; 3],
    /// Explained readings.
    used: usize,
}

impl WallInformation {
    /// The readings of `obs` the pose explains (range residual within `gate`).
    pub fn of(plan: &FloorPlan, obs: &Observations, pose: &Pose2, gate: f32) -> Self {
        let a = pose.translation();
        let mut w = WallInformation {
            per_wall: [[0.0f32; 6]; crate::limits::MAX_VERTICES],
            info: [[0.0f64; 3]; 3],
            used: 0,
        };
        for p in obs.pts.iter() {
            if let Some((wall, _, j)) = explained_row_on(plan, a, pose.theta, p, gate) {
                w.add(wall, &j);
            }
        }
        w
    }

    /// Books one reading on `wall` with range derivatives `j`.
    fn add(&mut self, wall: usize, j: &[f64; 3]) {
        let Some(acc) = self.per_wall.get_mut(wall) else {
            return;
        };
        for (u, ju) in j.iter().enumerate() {
            for (v, jv) in j.iter().enumerate() {
                self.info[u][v] += ju * jv;
            }
        }
        for (k, (u, v)) in UPPER.iter().enumerate() {
            acc[k] += (j[*u] * j[*v]) as f32;
        }
        self.used += 1;
    }

    /// The information with one more reading on `wall` (derivatives `j`): what a planned
    /// reading would make of it.
    pub fn with(&self, wall: usize, j: &[f64; 3]) -> Self {
        let mut w = WallInformation {
            per_wall: self.per_wall,
            info: self.info,
            used: self.used,
        };
        w.add(wall, j);
        w
    }

    /// How many walls some direction rests on alone: walls whose readings, left out, leave
    /// a direction free. Too few readings for the unknowns count as `usize::MAX`.
    pub fn walls_alone(&self, fixed_heading: bool) -> usize {
        let unknowns = if fixed_heading { 2 } else { 3 };
        if self.used <= unknowns {
            return usize::MAX;
        }
        let info = &self.info;
        self.per_wall
            .iter()
            .filter(|acc| acc.iter().any(|&x| x != 0.0))
            .filter(|acc| {
                let mut rest = *info;
                for (k, (u, v)) in UPPER.iter().enumerate() {
                    rest[*u][*v] -= acc[k] as f64;
                    if u != v {
                        rest[*v][*u] -= acc[k] as f64;
                    }
                }
                singular(&rest, info, fixed_heading)
            })
            .count()
    }
}

/// The range derivatives `∂ρ/∂(x, y, θ)` of a planned reading along the model direction
/// `d` from `a` onto `wall` (outward normal `n`) at range `range` (see the module docs).
pub fn planned_row(n: Vec2, d: Vec2, range: f32) -> [f64; 3] {
    let c = abs(n.x * d.x + n.y * d.y).max(MIN_COS_INCIDENCE) as f64;
    let perp = n.x * -d.y + n.y * d.x;
    [
        -(n.x as f64) / c,
        -(n.y as f64) / c,
        -(range as f64) * perp as f64 / c,
    ]
}

/// The upper triangle of a symmetric 3 × 3 matrix, row by row.
const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Why a pose has no precision.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PrecisionError {
    /// Fewer explained readings than unknowns.
    Underdetermined {
        /// Readings the pose explains.
        readings: u16,
        /// Unknowns of the pose.
        unknowns: u8,
    },
    /// Enough readings, but they leave a direction of the pose free (singular
    /// information matrix, e.g. every ray onto one wall).
    Singular {
        /// Readings the pose explains.
        readings: u16,
    },
    /// The pose or a parameter is not finite or not positive.
    InvalidInput,
}

impl core::fmt::Display for PrecisionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PrecisionError::Underdetermined { readings, unknowns } => write!(
                f,
                "underdetermined: {readings} explained reading(s) for {unknowns} unknowns"
            ),
            PrecisionError::Singular { readings } => write!(
                f,
                "underdetermined: the {readings} readings leave a direction of the pose free"
            ),
            PrecisionError::InvalidInput => write!(f, "pose or noise not finite"),
        }
    }
}

/// Relative determinant below which the information matrix counts as singular
/// (`det / Π diagonal`, scale-free: 1 for independent directions, 0 for a free one).
pub const SINGULAR_RATIO: f64 = 1e-6;

/// Smallest incidence cosine used in the Jacobian (a grazing ray: ≈ 87°), so that a ray
/// nearly parallel to its wall cannot blow the matrix up.
const MIN_COS_INCIDENCE: f32 = 0.05;

/// [`PoseCovariance`] of `pose` from the readings of `obs` it explains: range residual
/// (measured minus ray-cast) within `gate` metres. `sigma` is the range noise (m).
pub fn pose_covariance(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    fixed_heading: bool,
    sigma: f32,
    gate: f32,
) -> Result<PoseCovariance, PrecisionError> {
    if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite())
        || !(sigma.is_finite() && sigma > 0.0 && gate.is_finite() && gate > 0.0)
    {
        return Err(PrecisionError::InvalidInput);
    }
    let a = pose.translation();
    let unknowns: u8 = if fixed_heading { 2 } else { 3 };
    let mut info = [[0.0f64; 3]; 3];
    let (mut used, mut left_out) = (0u16, 0u16);
    let mut sum_sq = 0.0f64;
    for p in obs.pts.iter() {
        let Some((_, residual, j)) = explained_row_on(plan, a, pose.theta, p, gate) else {
            left_out += 1;
            continue;
        };
        sum_sq += (residual as f64) * (residual as f64);
        for (u, ju) in j.iter().enumerate() {
            for (v, jv) in j.iter().enumerate() {
                info[u][v] += ju * jv;
            }
        }
        used += 1;
    }
    if (used as usize) < unknowns as usize {
        return Err(PrecisionError::Underdetermined {
            readings: used,
            unknowns,
        });
    }
    let s2 = (sigma as f64) * (sigma as f64);
    let mut cov = [[0.0f32; 3]; 3];
    if fixed_heading {
        let (p, q, r) = (info[0][0], info[0][1], info[1][1]);
        let det = p * r - q * q;
        if det.is_nan() || det <= SINGULAR_RATIO * p * r {
            return Err(PrecisionError::Singular { readings: used });
        }
        cov[0][0] = (s2 * r / det) as f32;
        cov[0][1] = (-s2 * q / det) as f32;
        cov[1][0] = cov[0][1];
        cov[1][1] = (s2 * p / det) as f32;
    } else {
        let m = &info;
        let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
        let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
        let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
        let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
        if det.is_nan() || det <= SINGULAR_RATIO * m[0][0] * m[1][1] * m[2][2] {
            return Err(PrecisionError::Singular { readings: used });
        }
        let adj = [
            [
                c00,
                m[0][2] * m[2][1] - m[0][1] * m[2][2],
                m[0][1] * m[1][2] - m[0][2] * m[1][1],
            ],
            [
                c01,
                m[0][0] * m[2][2] - m[0][2] * m[2][0],
                m[0][2] * m[1][0] - m[0][0] * m[1][2],
            ],
            [
                c02,
                m[0][1] * m[2][0] - m[0][0] * m[2][1],
                m[0][0] * m[1][1] - m[0][1] * m[1][0],
            ],
        ];
        for (row, arow) in cov.iter_mut().zip(adj.iter()) {
            for (c, v) in row.iter_mut().zip(arow.iter()) {
                *c = (s2 * v / det) as f32;
            }
        }
    }
    let redundancy = used.saturating_sub(unknowns as u16);
    let variance_factor = if redundancy == 0 {
        1.0
    } else {
        (sum_sq / s2 / redundancy as f64) as f32
    };
    Ok(PoseCovariance {
        cov,
        used,
        left_out,
        unknowns,
        variance_factor,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::rect_about_origin;
    use core::f32::consts::{FRAC_PI_2, PI};

    fn obs_at(plan: &FloorPlan, pose: &Pose2, bearings: &[f32]) -> Observations {
        let mut o = Observations::new();
        for &b in bearings {
            let hit = plan
                .ray_cast(pose.translation(), rotate(unit(b), pose.theta))
                .unwrap();
            o.push(Measurement::new(b, hit.range)).unwrap();
        }
        o
    }

    /// Three readings with the heading known, two onto one wall: the third alone fixes the
    /// position along that wall, so a cabinet in front of its wall could move the answer
    /// unnoticed. A fourth onto the opposite wall checks it.
    #[test]
    fn a_direction_resting_on_one_reading_is_found() {
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(1.0, -1.0, 0.0);
        let bottom = [-FRAC_PI_2 - 0.3, -FRAC_PI_2 + 0.4];
        let three = obs_at(&plan, &pose, &[bottom[0], bottom[1], 0.2]);
        assert!(rests_on_one_reading(&plan, &three, &pose, true, 0.09));
        let four = obs_at(&plan, &pose, &[bottom[0], bottom[1], 0.2, PI + 0.1]);
        assert!(!rests_on_one_reading(&plan, &four, &pose, true, 0.09));
        // Unknown heading: three readings are no more than the unknowns; the four above, two
        // per direction and the heading from the pair on one wall, check every direction.
        assert!(rests_on_one_reading(&plan, &three, &pose, false, 0.09));
        assert!(!rests_on_one_reading(&plan, &four, &pose, false, 0.09));
        // A reading the pose does not explain (a cabinet 0.6 m in front of the east wall)
        // checks nothing: the direction it would have checked rests on the other one.
        let mut cabinet = obs_at(&plan, &pose, &[bottom[0], bottom[1], PI + 0.1]);
        let hit = plan.ray_cast(pose.translation(), unit(0.2)).unwrap();
        cabinet
            .push(Measurement::new(0.2, hit.range - 0.6))
            .unwrap();
        assert!(rests_on_one_reading(&plan, &cabinet, &pose, true, 0.09));
    }

    /// Four readings with the heading known, two on the south wall and two on the east:
    /// each direction rests on one wall, so a wall off its drawn line would move the
    /// answer unseen, though no single reading is alone. Readings on the north and west
    /// walls check both.
    #[test]
    fn a_direction_resting_on_one_wall_is_found() {
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(1.0, -1.0, 0.0);
        let two_walls = [-FRAC_PI_2 - 0.3, -FRAC_PI_2 + 0.4, -0.2, 0.2];
        let four = obs_at(&plan, &pose, &two_walls);
        assert!(!rests_on_one_reading(&plan, &four, &pose, true, 0.09));
        assert!(rests_on_one_wall(&plan, &four, &pose, true, 0.09));
        let all = [two_walls.as_slice(), &[FRAC_PI_2 + 0.1, PI + 0.1]].concat();
        let six = obs_at(&plan, &pose, &all);
        assert!(!rests_on_one_wall(&plan, &six, &pose, true, 0.09));
        assert!(!rests_on_one_wall(&plan, &six, &pose, false, 0.09));
        // What rests on one reading rests on one wall.
        let three = obs_at(&plan, &pose, &[-FRAC_PI_2 - 0.3, -FRAC_PI_2 + 0.4, 0.2]);
        assert!(rests_on_one_wall(&plan, &three, &pose, true, 0.09));
    }

    /// The readings of a site-level episode that answered 5.9 cm off (plan 1000065, K = 10,
    /// `--site site`): three on one wall of a 6.8 m square, two on the next, the heading
    /// unknown. The position across the second wall rests on its two readings alone; the
    /// rounding residue the subtraction leaves must not hide that.
    #[test]
    fn a_direction_resting_on_one_wall_is_found_across_rounding() {
        let plan = rect_about_origin(6.8, 6.8);
        let pose = Pose2::new(-2.2137468, 0.4935022, 0.17146479);
        let step = core::f32::consts::TAU / 54.0;
        let mut o = Observations::new();
        for (i, r) in [
            (3, 5.8398485),
            (8, 3.2613099),
            (13, 2.9232314),
            (18, 1.8525529),
            (23, 1.2392758),
        ] {
            o.push(Measurement::new(i as f32 * step, r)).unwrap();
        }
        assert!(rests_on_one_wall(&plan, &o, &pose, false, 0.09));
    }

    /// Readings that hit the plan's walls exactly have a variance factor near 0; moving
    /// the east wall 5 cm (readings 5 cm long there) against a 1 cm EDM raises it far
    /// above 1, though every reading stays within the 9 cm gate.
    #[test]
    fn a_wall_off_its_line_raises_the_variance_factor() {
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(1.0, -1.0, 0.0);
        let bearings = [
            -FRAC_PI_2 - 0.3,
            -FRAC_PI_2 + 0.4,
            -0.2,
            0.2,
            FRAC_PI_2 + 0.1,
            PI + 0.1,
        ];
        let exact = obs_at(&plan, &pose, &bearings);
        let cov = pose_covariance(&plan, &exact, &pose, true, 0.01, 0.09).unwrap();
        assert!(cov.variance_factor < 1e-3, "{}", cov.variance_factor);
        let mut moved = Observations::new();
        for &b in &bearings {
            let hit = plan.ray_cast(pose.translation(), unit(b)).unwrap();
            let off = if hit.point.x > 5.9 {
                0.05 / cos(b)
            } else {
                0.0
            };
            moved.push(Measurement::new(b, hit.range + off)).unwrap();
        }
        let cov = pose_covariance(&plan, &moved, &pose, true, 0.01, 0.09).unwrap();
        assert_eq!(cov.used, 6);
        assert!(cov.variance_factor > 5.0, "{}", cov.variance_factor);
    }

    /// The leverage's first-order model against the plan itself: move one wall of a
    /// pentagon 1 mm out (its two corners with it, its neighbours turning about their far
    /// corners, as `--site site` builds a wall off its line), ray-cast the readings again,
    /// and solve the least-squares shift of the position; it is what [`WallLeverage::shift`]
    /// says, for every wall, the heading known and not.
    #[test]
    fn the_leverage_is_the_least_squares_shift_of_a_moved_wall() {
        let corners = [
            v2(-5.0, -4.0),
            v2(5.0, -4.0),
            v2(6.0, 2.0),
            v2(0.0, 5.0),
            v2(-6.0, 1.0),
        ];
        let plan = FloorPlan::new(&corners).unwrap();
        let pose = Pose2::new(0.5, 0.2, 0.3);
        let bearings = [0.1, 0.9, 1.7, 2.4, 3.1, 3.9, 4.6, 5.4, 5.9];
        let obs = obs_at(&plan, &pose, &bearings);
        let lever = WallLeverage::of(&plan, &obs, &pose, 0.09);
        let eps = 1e-3f32;
        for wall in 0..corners.len() {
            let n = plan.outward_normal(wall);
            let mut moved = corners;
            moved[wall] += n * eps;
            let next = (wall + 1) % corners.len();
            moved[next] += n * eps;
            let moved = FloorPlan::new(&moved).unwrap();
            for fixed in [true, false] {
                let (mut info, mut g) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
                for &b in &bearings {
                    let d = rotate(unit(b), pose.theta);
                    let hit = plan.ray_cast(pose.translation(), d).unwrap();
                    let after = moved.ray_cast(pose.translation(), d).unwrap();
                    let j = planned_row(plan.outward_normal(hit.wall), d, hit.range);
                    let dr = ((after.range - hit.range) / eps) as f64;
                    for u in 0..3 {
                        g[u] += j[u] * dr;
                        for v in 0..3 {
                            info[u][v] += j[u] * j[v];
                        }
                    }
                }
                let k = if fixed { 2 } else { 3 };
                // Gaussian elimination on the k × k system.
                let mut a = [[0.0f64; 4]; 3];
                for u in 0..k {
                    a[u][..k].copy_from_slice(&info[u][..k]);
                    a[u][3] = g[u];
                }
                for c in 0..k {
                    for r in c + 1..k {
                        let f = a[r][c] / a[c][c];
                        let pivot = a[c];
                        for (x, p) in a[r].iter_mut().zip(pivot).skip(c) {
                            *x -= f * p;
                        }
                    }
                }
                let mut x = [0.0f64; 3];
                for c in (0..k).rev() {
                    let tail: f64 = (c + 1..k).map(|q| a[c][q] * x[q]).sum();
                    x[c] = (a[c][3] - tail) / a[c][c];
                }
                let (dx, dy, _) = lever.shift(wall, fixed).unwrap();
                let err = ((dx - x[0]).powi(2) + (dy - x[1]).powi(2)).sqrt();
                assert!(err < 0.02, "wall {wall} fixed {fixed}: {dx} {dy} vs {x:?}");
            }
        }
        let worst = lever.worst(true);
        assert!(worst > 0.2 && worst < 1.0, "{worst}");
    }

    /// Readings on one wall and its two neighbours near the shared corners follow that
    /// wall's offset (leverage about 1), though no direction rests on one wall; a reading
    /// on the far wall brings it below the stop's bound ([`crate::stop::MAX_WALL_LEVERAGE`]).
    #[test]
    fn readings_by_one_walls_corners_follow_its_offset_and_the_far_wall_checks_it() {
        // A room narrowing to the east: the south and north walls slant, so their readings
        // fix the position along x too, and they share their east corners with the east wall.
        let plan =
            FloorPlan::new(&[v2(-6.0, -4.0), v2(6.0, -2.0), v2(6.0, 2.0), v2(-6.0, 4.0)]).unwrap();
        let pose = Pose2::new(3.0, 0.3, 0.0);
        // The east wall straight ahead, and the slanting walls close to it.
        let near = obs_at(&plan, &pose, &[0.0, -1.0, 1.0, -0.8]);
        assert!(!rests_on_one_wall(&plan, &near, &pose, true, 0.09));
        let lever = WallLeverage::of(&plan, &near, &pose, 0.09);
        let before = lever.worst(true);
        assert!(before > 0.9, "{before}");
        let d = unit(PI);
        let hit = plan.ray_cast(pose.translation(), d).unwrap();
        let after = lever.with(&plan, d, &hit).worst(true);
        assert!(after < 0.8, "{before} → {after}");
        // Too few readings, or a free direction: infinite.
        let two = obs_at(&plan, &pose, &[0.0, 1.3]);
        assert_eq!(
            WallLeverage::of(&plan, &two, &pose, 0.09).worst(true),
            f32::INFINITY
        );
        let fan = obs_at(&plan, &pose, &[-0.2, 0.0, 0.2]);
        assert_eq!(
            WallLeverage::of(&plan, &fan, &pose, 0.09).worst(true),
            f32::INFINITY
        );
    }

    #[test]
    fn perpendicular_walls_give_sigma_per_axis() {
        // Heading known, one reading onto the east wall, one onto the north wall, both
        // head-on: each fixes one coordinate to the range noise.
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(1.0, -1.0, 0.0);
        let o = obs_at(&plan, &pose, &[0.0, FRAC_PI_2]);
        let c = pose_covariance(&plan, &o, &pose, true, 0.01, 0.1).unwrap();
        assert!((c.sigma_x() - 0.01).abs() < 1e-5, "{c:?}");
        assert!((c.sigma_y() - 0.01).abs() < 1e-5, "{c:?}");
        assert_eq!(c.sigma_heading(), 0.0);
        assert!(c.exactly_determined());
        // Four readings, two per axis: σ / √2.
        let o = obs_at(&plan, &pose, &[0.0, FRAC_PI_2, PI, -FRAC_PI_2]);
        let c = pose_covariance(&plan, &o, &pose, true, 0.01, 0.1).unwrap();
        assert!((c.sigma_x() - 0.01 / 2f32.sqrt()).abs() < 1e-4, "{c:?}");
        assert!(!c.exactly_determined());
    }

    #[test]
    fn too_few_or_parallel_readings_have_no_precision() {
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(1.0, -1.0, 0.3);
        let o = obs_at(&plan, &pose, &[0.0, 1.6]);
        assert_eq!(
            pose_covariance(&plan, &o, &pose, false, 0.01, 0.1),
            Err(PrecisionError::Underdetermined {
                readings: 2,
                unknowns: 3
            })
        );
        // A fan onto the east wall only, heading known: the position along the wall is free.
        let pose = Pose2::new(1.0, -1.0, 0.0);
        let o = obs_at(&plan, &pose, &[0.0, 0.05, -0.05]);
        assert!(matches!(
            pose_covariance(&plan, &o, &pose, true, 0.01, 0.1),
            Err(PrecisionError::Singular { .. })
        ));
        // An outlier is left out, not used.
        let mut o = obs_at(&plan, &pose, &[0.0, FRAC_PI_2, 3.0]);
        o.push(Measurement::new(-FRAC_PI_2, 0.5)).unwrap();
        let c = pose_covariance(&plan, &o, &pose, true, 0.01, 0.1).unwrap();
        assert_eq!((c.used, c.left_out), (3, 1));
        // NaN never panics.
        let bad = Pose2::new(f32::NAN, 0.0, 0.0);
        assert_eq!(
            pose_covariance(&plan, &o, &bad, true, 0.01, 0.1),
            Err(PrecisionError::InvalidInput)
        );
    }

    #[test]
    fn heading_unknown_readings_on_every_wall_determine_every_axis() {
        let plan = rect_about_origin(12.0, 8.0);
        let pose = Pose2::new(0.5, 0.5, 0.4);
        let o = obs_at(&plan, &pose, &[0.0, 1.2, 2.4, 3.6, 4.8]);
        let c = pose_covariance(&plan, &o, &pose, false, 0.01, 0.1).unwrap();
        assert_eq!(c.unknowns, 3);
        assert!(c.sigma_heading() > 0.0 && c.sigma_heading() < 0.01, "{c:?}");
        assert!(c.sigma_x() > 0.003 && c.sigma_x() < 0.05, "{c:?}");
        // Symmetric.
        assert!((c.cov[0][2] - c.cov[2][0]).abs() < 1e-9);
    }
}
