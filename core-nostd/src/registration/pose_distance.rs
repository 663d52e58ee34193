//! Symmetry-aware pose distance in SE(2) (paper §3.4, Table 2, equations 7–10, after
//! Brégier, Devernay, Leyrit & Crowley 2018).
//!
//! ## Which transform is compared
//!
//! The paper measures the pose of the floor-plan by the transform `T` that carries the
//! outline from the canonical frame into the object frame. Here that is the
//! **registration** `T: model → scene`, applied to the *centred* outline `S` (model frame
//! M, origin at the perimeter centroid). In the crate-wide conventions the estimators
//! return an [`AgentPose`](crate::world::geometry) `P = (a, h)` = the scene→model transform, so
//! `T = P⁻¹ = (R(−h), −R(−h)·a)`: rotation `θ = −h`, translation `t = −R(−h)·a` (the model
//! centroid seen from the instrument, in scene coordinates). [`PoseDistance::distance`]
//! takes two `T`s; [`PoseDistance::agent_distance`] takes two AgentPoses and inverts them.
//!
//! ## Derivation of the closed form
//!
//! Equation 7 with uniform density along the perimeter (`μ = 1`, total length `L`):
//!
//! ```text
//! d̂²(T₁, T₂) = (1/L) ∫_S ‖T₁(s) − T₂(s)‖² ds,   T(s) = R(θ)·s + t.
//! ```
//!
//! `T₁(s) − T₂(s) = (R₁ − R₂)·s + Δt` with `Δt = t₁ − t₂`. Expanding the square, the cross
//! term `2 Δtᵀ (R₁ − R₂) (1/L)∫ s ds` vanishes because the outline is centred
//! (`∫ s ds = 0`), so `d̂² = ‖Δt‖² + (1/L) ∫ ‖(R₁ − R₂)s‖² ds` (equation 9). In 2-D,
//! `R₁ − R₂ = R₁ (I − R(Δθ))` with `Δθ = θ₂ − θ₁`, and `I − R(Δθ)` is a rotation scaled by
//! `2|sin(Δθ/2)|`, hence `‖(R₁ − R₂)s‖ = 2|sin(Δθ/2)|·‖s‖` and
//!
//! ```text
//! d̂² = ‖Δt‖² + 4 r² sin²(Δθ/2),   r² = Λ² = (1/L) ∫_S ‖s‖² ds   (equation 10),
//! ```
//!
//! `r` being the RMS radius of the perimeter about its centroid. For one wall from `a` to
//! `b` (length `ℓ`), `∫ ‖s‖² ds = ℓ (‖a‖² + a·b + ‖b‖²) / 3`, which [`perimeter_rms_radius`]
//! sums. Equivalently `d̂` is the Euclidean distance between the Table-2 pose
//! representatives `(r cos θ, r sin θ, t_x, t_y) ∈ ℝ⁴`, since
//! `‖r e^{iθ₁} − r e^{iθ₂}‖² = 4 r² sin²(Δθ/2)`.
//!
//! ## Symmetry
//!
//! For a room with cyclic symmetry `C_n` ([`crate::world::symmetry`]) the group `G` is the set of
//! rotations `G_k = R(2πk/n)` about the model origin. `T ∘ G_k` has the same translation
//! `t` and rotation `θ + 2πk/n`, so the minimum of equation 7 over `G₁, G₂ ∈ G` is
//!
//! ```text
//! d² = ‖Δt‖² + 4 r² min_k sin²((Δθ + 2πk/n)/2),   k = 0 … n−1,
//! ```
//!
//! i.e. the distance between the nearest pair of the `n` representatives
//! `(r e^{i(θ + 2πk/n)}, t)`. For AgentPoses, `T ∘ G_k⁻¹ = (G_k ∘ P)⁻¹`: rotating `(a, h)`
//! by `2πk/n` about the model origin gives an equivalent AgentPose (the shared symmetry
//! convention), and [`PoseDistance::agent_distance`] is invariant under it.
//!
//! Note that `‖Δt‖` compares the model centroid *as seen from the instrument*: for equal
//! headings it equals the AgentPose position error `‖a₁ − a₂‖`; with a heading error `δ` the
//! position error is rotated into the scene frame, and the distance grows by the rotation
//! term `2r|sin(δ/2)|`, which is what an error of `δ` displaces the walls by on average.

use crate::world::floorplan::{FloorPlan, MAX_VERTICES};
use crate::world::geometry::{length, Pose2};
use crate::world::math::{cos, sin, sqrt, wrap_angle, TAU};
use crate::world::symmetry::{symmetry_order, SymmetryTolerance};
use heapless::Vec as HVec;

/// Largest symmetry order (a polygon's order divides its vertex count).
pub const MAX_SYMMETRY_ORDER: usize = MAX_VERTICES;

/// A Table-2 pose representative `(r cos θ, r sin θ, t_x, t_y)` of a model→scene transform.
pub type PoseRepresentative = [f32; 4];

/// RMS distance of the solid walls (columns included, door openings not) from their
/// perimeter centroid with uniform density along them: `Λ = r = sqrt((1/L) ∫_S ‖s − c‖² ds)`
/// (equation 10).
pub fn perimeter_rms_radius(plan: &FloorPlan) -> f32 {
    let c = plan.perimeter_centroid();
    let mut acc = 0.0f32;
    let mut total = 0.0f32;
    for i in plan.solid_walls() {
        let (a, b) = plan.wall(i);
        let (a, b) = (a - c, b - c);
        let l = length(b - a);
        acc += l * (a.dot(&a) + a.dot(&b) + b.dot(&b)) / 3.0;
        total += l;
    }
    sqrt(acc / total)
}

/// The symmetry-aware pose distance of one floor-plan: its RMS radius `r` and its cyclic
/// symmetry order `n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseDistance {
    radius: f32,
    order: u8,
}

impl PoseDistance {
    /// Builds the distance for `plan`, detecting its symmetry order with `tol`. The radius
    /// is taken about the perimeter centroid, i.e. the transforms compared must act on the
    /// centred (model-frame) outline.
    pub fn new(plan: &FloorPlan, tol: &SymmetryTolerance) -> Self {
        Self::with_order(plan, symmetry_order(plan, tol))
    }

    /// Builds the distance for `plan` with a given symmetry order (1 = none).
    pub fn with_order(plan: &FloorPlan, order: u8) -> Self {
        Self::from_parts(perimeter_rms_radius(plan), order)
    }

    /// From an RMS radius (m) and a symmetry order; an order of 0 is treated as 1.
    pub fn from_parts(radius: f32, order: u8) -> Self {
        PoseDistance {
            radius,
            order: order.max(1),
        }
    }

    /// The RMS radius `r = Λ` (m).
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// The cyclic symmetry order `n` (1 = no proper symmetry).
    pub fn order(&self) -> u8 {
        self.order
    }

    /// The representative of the model→scene transform `t` (symmetry ignored).
    pub fn representative(&self, t: &Pose2) -> PoseRepresentative {
        [
            self.radius * cos(t.theta),
            self.radius * sin(t.theta),
            t.x,
            t.y,
        ]
    }

    /// The `n` representatives of `t` under the symmetry group (Table 2, cyclic row).
    pub fn representatives(&self, t: &Pose2) -> HVec<PoseRepresentative, MAX_SYMMETRY_ORDER> {
        let n = self.order as usize;
        (0..n.min(MAX_SYMMETRY_ORDER))
            .map(|k| {
                let a = t.theta + TAU * k as f32 / n as f32;
                [self.radius * cos(a), self.radius * sin(a), t.x, t.y]
            })
            .collect()
    }

    /// Squared symmetry-aware distance between two model→scene transforms (m²).
    pub fn distance_squared(&self, t1: &Pose2, t2: &Pose2) -> f32 {
        let dx = t1.x - t2.x;
        let dy = t1.y - t2.y;
        let dth = t2.theta - t1.theta;
        let n = self.order as u32;
        let mut best = f32::INFINITY;
        for k in 0..n {
            let s = sin(0.5 * (dth + TAU * k as f32 / n as f32));
            best = best.min(s * s);
        }
        dx * dx + dy * dy + 4.0 * self.radius * self.radius * best
    }

    /// Symmetry-aware distance between two model→scene transforms `T = AgentPose⁻¹` (m).
    pub fn distance(&self, t1: &Pose2, t2: &Pose2) -> f32 {
        sqrt(self.distance_squared(t1, t2))
    }

    /// Symmetry-aware distance between two AgentPoses (scene→model), computed on their
    /// inverses, the model→scene registrations (m).
    pub fn agent_distance(&self, p1: &Pose2, p2: &Pose2) -> f32 {
        self.distance(&p1.inverse(), &p2.inverse())
    }
}

/// A surveyor's two errors of an answered pose, modulo the room's symmetry: where the
/// instrument is (m) and where it points (rad, absolute). Unlike the pose distance, which
/// folds both into one number of metres, these are what a tolerance is written in.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseErrors {
    /// Distance between the answered and the true instrument position in the model frame (m).
    pub position: f32,
    /// Absolute heading difference, wrapped to `[0, π]` (rad).
    pub heading: f32,
}

/// When an answered pose counts as right: position and heading error both within bounds.
/// The default is the surveyor's ([`Tolerance::SURVEYOR`]); `eval --tolerance` sets it.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Tolerance {
    /// Largest position error of a right answer (m).
    pub position_m: f32,
    /// Largest heading error of a right answer (rad).
    pub heading_rad: f32,
}

impl Tolerance {
    /// 5 cm and 0.5°: a setting-out tolerance a surveyor accepts for a free station before
    /// fine-aiming at control points (the default).
    pub const SURVEYOR: Tolerance = Tolerance {
        position_m: 0.05,
        heading_rad: 0.5 * core::f32::consts::PI / 180.0,
    };

    /// Whether `e` is within the tolerance (NaN errors are not).
    pub fn admits(&self, e: &PoseErrors) -> bool {
        e.position <= self.position_m && e.heading <= self.heading_rad
    }
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance::SURVEYOR
    }
}

impl PoseDistance {
    /// Position and heading error of the AgentPose `answer` against `truth`, taken at the
    /// symmetric equivalent of `answer` whose heading is nearest the truth's (rotating
    /// `(a, h)` by `2πk/n` about the model origin; the shared symmetry convention).
    pub fn agent_errors(&self, answer: &Pose2, truth: &Pose2) -> PoseErrors {
        let n = self.order as u32;
        let mut best = PoseErrors {
            position: f32::INFINITY,
            heading: f32::INFINITY,
        };
        for k in 0..n {
            let g = TAU * k as f32 / n as f32;
            let heading = wrap_angle(answer.theta + g - truth.theta).abs();
            if heading < best.heading {
                let (c, s) = (cos(g), sin(g));
                let (x, y) = (c * answer.x - s * answer.y, s * answer.x + c * answer.y);
                let (dx, dy) = (x - truth.x, y - truth.y);
                best = PoseErrors {
                    position: sqrt(dx * dx + dy * dy),
                    heading,
                };
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{centred, centred_rect, l_room_6x4};
    use crate::world::geometry::{rotate, v2};
    use proptest::prelude::*;

    /// Equation 7 by brute force: midpoint rule with `per_wall` samples per wall (f64),
    /// minimised over the symmetry rotations applied to the first transform.
    fn integrate(p: &FloorPlan, order: u8, t1: &Pose2, t2: &Pose2, per_wall: usize) -> f64 {
        let mut best = f64::INFINITY;
        for k in 0..order as usize {
            let g = core::f64::consts::TAU * k as f64 / order as f64;
            let mut acc = 0.0f64;
            let mut total = 0.0f64;
            for i in p.solid_walls() {
                let (a, b) = p.wall(i);
                let (ax, ay, bx, by) = (a.x as f64, a.y as f64, b.x as f64, b.y as f64);
                let l = ((bx - ax).powi(2) + (by - ay).powi(2)).sqrt();
                let ds = l / per_wall as f64;
                for j in 0..per_wall {
                    let u = (j as f64 + 0.5) / per_wall as f64;
                    let (sx, sy) = (ax + u * (bx - ax), ay + u * (by - ay));
                    let tr = |t: &Pose2, extra: f64, x: f64, y: f64| {
                        let th = t.theta as f64 + extra;
                        (
                            th.cos() * x - th.sin() * y + t.x as f64,
                            th.sin() * x + th.cos() * y + t.y as f64,
                        )
                    };
                    let (x1, y1) = tr(t1, g, sx, sy);
                    let (x2, y2) = tr(t2, 0.0, sx, sy);
                    acc += ((x1 - x2).powi(2) + (y1 - y2).powi(2)) * ds;
                }
                total += l;
            }
            best = best.min(acc / total);
        }
        best.sqrt()
    }

    #[test]
    fn rms_radius_of_square_and_segment_formula() {
        // Square of side 2a centred: (1/L)∫|s|² = a² + a²/3 (each side: x² + y², y uniform).
        let sq = centred_rect(4.0, 4.0);
        let a = 2.0f32;
        let expect = sqrt(a * a + a * a / 3.0);
        assert!((perimeter_rms_radius(&sq) - expect).abs() < 1e-5);
        // Translation invariant (taken about the perimeter centroid).
        let moved = sq.translated(v2(3.0, -7.0));
        assert!((perimeter_rms_radius(&moved) - expect).abs() < 1e-4);
    }

    #[test]
    fn detected_orders() {
        let tol = SymmetryTolerance::default();
        assert_eq!(PoseDistance::new(&centred_rect(4.0, 4.0), &tol).order(), 4);
        assert_eq!(PoseDistance::new(&centred_rect(5.0, 3.0), &tol).order(), 2);
        assert_eq!(PoseDistance::new(&l_room_6x4().centered(), &tol).order(), 1);
    }

    #[test]
    fn matches_numerical_integration() {
        let tol = SymmetryTolerance::default();
        let cases = [
            (Pose2::new(0.3, -0.2, 0.1), Pose2::new(-0.1, 0.4, 1.3)),
            (Pose2::new(1.0, 2.0, -2.9), Pose2::new(1.0, 2.0, 3.0)),
            (Pose2::new(0.0, 0.0, 0.0), Pose2::new(0.0, 0.0, 1.2)),
            (Pose2::new(-2.0, 0.5, 0.7), Pose2::new(2.0, -0.5, -2.2)),
        ];
        for p in [
            l_room_6x4().centered(),
            centred_rect(4.0, 4.0),
            centred_rect(5.0, 3.0),
        ] {
            let d = PoseDistance::new(&p, &tol);
            for (t1, t2) in &cases {
                let num = integrate(&p, d.order(), t1, t2, 2000);
                let closed = d.distance(t1, t2) as f64;
                assert!(
                    (num - closed).abs() < 1e-4 * (1.0 + num),
                    "order {}: {num} vs {closed}",
                    d.order()
                );
            }
        }
    }

    #[test]
    fn square_quarter_turn_is_zero_but_not_for_l_room() {
        let tol = SymmetryTolerance::default();
        let t = Pose2::new(0.5, 0.5, 0.2);
        let g = Pose2::new(0.5, 0.5, 0.2 + core::f32::consts::FRAC_PI_2);
        assert!(PoseDistance::new(&centred_rect(4.0, 4.0), &tol).distance(&t, &g) < 1e-5);
        let dr = PoseDistance::new(&centred_rect(5.0, 3.0), &tol);
        assert!(dr.distance(&t, &g) > 1.0);
        let h = Pose2::new(0.5, 0.5, 0.2 + core::f32::consts::PI);
        assert!(dr.distance(&t, &h) < 1e-5);
        assert!(PoseDistance::new(&l_room_6x4().centered(), &tol).distance(&t, &h) > 1.0);
    }

    #[test]
    fn agent_helper_compares_inverses() {
        let d = PoseDistance::new(&l_room_6x4().centered(), &SymmetryTolerance::default());
        let p1 = Pose2::new(1.0, -0.5, 0.3);
        // Same heading: the distance is the position error.
        let p2 = Pose2::new(1.03, -0.46, 0.3);
        assert!((d.agent_distance(&p1, &p2) - 0.05).abs() < 1e-5);
        let p3 = Pose2::new(-1.0, 0.2, 2.0);
        assert!(
            (d.agent_distance(&p1, &p3) - d.distance(&p1.inverse(), &p3.inverse())).abs() < 1e-6
        );
    }

    #[test]
    fn surveyor_errors_by_hand() {
        let tol = SymmetryTolerance::default();
        let truth = Pose2::new(1.0, -0.5, 0.3);
        // L-shaped room (no symmetry): 3 cm east, 4 cm north, 0.4° off: 5 cm, inside.
        let d = PoseDistance::new(&l_room_6x4().centered(), &tol);
        let deg = core::f32::consts::PI / 180.0;
        let a = Pose2::new(1.03, -0.46, 0.3 + 0.4 * deg);
        let e = d.agent_errors(&a, &truth);
        assert!((e.position - 0.05).abs() < 1e-5, "{e:?}");
        assert!((e.heading - 0.4 * deg).abs() < 1e-6);
        assert!(Tolerance::SURVEYOR.admits(&PoseErrors {
            position: 0.0499,
            heading: 0.4 * deg
        }));
        // 0.6° is outside however close the position.
        let b = Pose2::new(1.0, -0.5, 0.3 - 0.6 * deg);
        assert!(!Tolerance::SURVEYOR.admits(&d.agent_errors(&b, &truth)));
        // 6 cm is outside.
        let c = Pose2::new(1.06, -0.5, 0.3);
        assert!(!Tolerance::SURVEYOR.admits(&d.agent_errors(&c, &truth)));
        // Headings wrap: 359.8° against 0.1° is 0.3° apart.
        let t0 = Pose2::new(0.0, 0.0, 0.1 * deg);
        let w = d.agent_errors(&Pose2::new(0.0, 0.0, 359.8 * deg), &t0);
        assert!((w.heading - 0.3 * deg).abs() < 1e-5, "{w:?}");
        // The L-room's half-turn is a different, wrong answer.
        let q = rotate(v2(truth.x, truth.y), core::f32::consts::PI);
        let twin = Pose2::new(q.x, q.y, truth.theta + core::f32::consts::PI);
        assert!(!Tolerance::SURVEYOR.admits(&d.agent_errors(&twin, &truth)));
    }

    #[test]
    fn symmetric_twin_is_right_in_a_rectangle_and_square() {
        let tol = SymmetryTolerance::default();
        let truth = Pose2::new(0.8, 0.3, -1.0);
        // A rectangle's half-turn twin, 2 cm off: right, and the error is the 2 cm.
        let d = PoseDistance::new(&centred_rect(5.0, 3.0), &tol);
        let q = rotate(v2(truth.x + 0.02, truth.y), core::f32::consts::PI);
        let twin = Pose2::new(q.x, q.y, truth.theta + core::f32::consts::PI);
        let e = d.agent_errors(&twin, &truth);
        assert!((e.position - 0.02).abs() < 1e-4, "{e:?}");
        assert!(e.heading < 1e-5);
        assert!(Tolerance::SURVEYOR.admits(&e));
        // A quarter turn is no twin of a rectangle, but is of a square.
        let q = rotate(v2(truth.x, truth.y), core::f32::consts::FRAC_PI_2);
        let quarter = Pose2::new(q.x, q.y, truth.theta + core::f32::consts::FRAC_PI_2);
        assert!(!Tolerance::SURVEYOR.admits(&d.agent_errors(&quarter, &truth)));
        let ds = PoseDistance::new(&centred_rect(4.0, 4.0), &tol);
        let e = ds.agent_errors(&quarter, &truth);
        assert!(e.position < 1e-4 && e.heading < 1e-5, "{e:?}");
        // NaN is never right.
        assert!(!Tolerance::SURVEYOR.admits(&PoseErrors {
            position: f32::NAN,
            heading: 0.0
        }));
    }

    proptest! {
        #[test]
        fn representatives_give_the_distance(
            x1 in -3.0f32..3.0, y1 in -3.0f32..3.0, a1 in -3.1f32..3.1,
            x2 in -3.0f32..3.0, y2 in -3.0f32..3.0, a2 in -3.1f32..3.1, pick in 0usize..3
        ) {
            let rooms = [l_room_6x4().centered(), centred_rect(4.0, 4.0), centred_rect(5.0, 3.0)];
            let p = rooms[pick].clone();
            let d = PoseDistance::new(&p, &SymmetryTolerance::default());
            let (t1, t2) = (Pose2::new(x1, y1, a1), Pose2::new(x2, y2, a2));
            let r1 = d.representative(&t1);
            let best = d
                .representatives(&t2)
                .iter()
                .map(|r2| sqrt((0..4).map(|i| (r1[i] - r2[i]) * (r1[i] - r2[i])).sum::<f32>()))
                .fold(f32::INFINITY, f32::min);
            prop_assert!((best - d.distance(&t1, &t2)).abs() < 1e-4);
            // Symmetric, non-negative, zero on the diagonal.
            prop_assert!((d.distance(&t1, &t2) - d.distance(&t2, &t1)).abs() < 1e-4);
            prop_assert!(d.distance(&t1, &t1) < 1e-3);
        }

        #[test]
        fn invariant_under_symmetry_group(
            ax in -1.5f32..1.5, ay in -1.5f32..1.5, h in -3.1f32..3.1,
            bx in -1.5f32..1.5, by in -1.5f32..1.5, g in -3.1f32..3.1,
            k in 0u8..4, pick in 0usize..2
        ) {
            // AgentPoses rotated by 2πk/n about the model origin are equivalent.
            let rooms = [(centred_rect(4.0, 4.0), 4u8), (centred_rect(5.0, 3.0), 2u8)];
            let (p, n) = rooms[pick].clone();
            let d = PoseDistance::new(&p, &SymmetryTolerance::default());
            prop_assert_eq!(d.order(), n);
            let rot = TAU * (k % n) as f32 / n as f32;
            let p1 = Pose2::new(ax, ay, h);
            let q1 = rotate(v2(ax, ay), rot);
            let p1g = Pose2::new(q1.x, q1.y, h + rot);
            let p2 = Pose2::new(bx, by, g);
            prop_assert!(d.agent_distance(&p1, &p1g) < 2e-3);
            prop_assert!((d.agent_distance(&p1, &p2) - d.agent_distance(&p1g, &p2)).abs() < 2e-3);
        }
    }

    #[test]
    fn numerical_integration_property_sample() {
        // A denser sweep of random pose pairs on a non-trivial plan (deterministic).
        use rand_core::{RngCore, SeedableRng};
        let p = centred(&[
            (0.0, 0.0),
            (7.0, 0.0),
            (7.0, 1.5),
            (5.0, 3.5),
            (2.0, 3.5),
            (2.0, 5.0),
            (0.0, 5.0),
        ]);
        let d = PoseDistance::new(&p, &SymmetryTolerance::default());
        assert_eq!(d.order(), 1);
        let mut rng = rand_pcg::Pcg32::seed_from_u64(5);
        let mut u = || (rng.next_u32() as f32 / u32::MAX as f32) * 2.0 - 1.0;
        for _ in 0..20 {
            let t1 = Pose2::new(3.0 * u(), 3.0 * u(), 3.1 * u());
            let t2 = Pose2::new(3.0 * u(), 3.0 * u(), 3.1 * u());
            let num = integrate(&p, 1, &t1, &t2, 1000);
            let closed = d.distance(&t1, &t2) as f64;
            assert!(
                (num - closed).abs() < 1e-4 * (1.0 + num),
                "{num} vs {closed}"
            );
        }
        // With an imposed C3 group too (the formula only needs a centred outline).
        let d3 = PoseDistance::with_order(&p, 3);
        let (t1, t2) = (Pose2::new(0.1, 0.2, 0.3), Pose2::new(-0.2, 0.0, 2.9));
        let num = integrate(&p, 3, &t1, &t2, 1000);
        assert!((num - d3.distance(&t1, &t2) as f64).abs() < 1e-4 * (1.0 + num));
    }
}
