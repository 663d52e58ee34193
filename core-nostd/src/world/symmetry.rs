//! Rotational-symmetry detection of a floor-plan outline (paper §3.4, after Wolter,
//! Woo & Volz 1985).
//!
//! The outline is encoded as an **edge chain**: one link per vertex `i`, holding the
//! interior angle `φᵢ` at vertex `i` (between the walls `i−1` and `i`, in `(0, 2π)` for a
//! counter-clockwise outline) and the length `ρᵢ` of the wall that *follows* it (from vertex
//! `i` to vertex `i+1`). A proper (orientation-preserving) self-congruence of a polygon
//! maps vertices to vertices and preserves the cyclic order, so it is a cyclic shift of the
//! chain; conversely, a shift by `k` that leaves the chain unchanged is realised by the
//! rotation about the perimeter centroid that maps vertex `i` to vertex `i+k`.
//!
//! Detection is string matching of the chain `[s₀ … s_{N−1}]` against the doubled chain
//! `[s₀ … s_{N−1}, s₀ … s_{N−2}]` (length `2N−1`): the chain occurs at offset `k` iff the
//! shift by `k` is a symmetry. Two links are equal up to the tolerances `ε_φ` (absolute
//! angle difference, modulo 2π) and `ε_ρ` (relative length difference,
//! `|ρ̂ − ρ| ≤ ε_ρ · max(ρ̂, ρ)`), which lets *near* symmetries count (the paper's
//! equivalence classes). Exact symmetries form the subgroup of shifts by multiples of
//! `N/n`; with tolerances the matching shifts need not form a group, so only shifts `k`
//! that divide `N` are tried and the smallest matching one gives the **cyclic order**
//! `n = N / k` (rotation by `2π/n` about the perimeter centroid). `n = 1` means no proper
//! symmetry. Reflections are not considered (only proper symmetries matter for the pose
//! distance, Table 2). A polygon cannot be circularly symmetric, so the `SO(2)` row of
//! Table 2 never arises.
//!
//! **Columns and doors.** A symmetry must map the set of solid walls onto itself. For a plan
//! with columns or doors the chain is the outline's alone, and a shift counts only when it
//! also maps openings onto openings (link by link: a door breaks the symmetry of the wall
//! it is in unless the image wall has a door in the same place) and when the rotation about
//! the outline's centre maps every column onto a column with the same number of vertices,
//! each vertex within `ε_ρ` times that column's shortest wall of a vertex of the image.
//! A centred column keeps a rectangle's order 2; an off-centre one makes it 1. A plain plan
//! (one ring, no opening) takes exactly the path it always did.

use crate::world::floorplan::{FloorPlan, MAX_VERTICES};
use crate::world::geometry::{cross, length, rotate, v2, Vec2};
use crate::world::math::{abs, atan2, wrap_angle, TAU};
use core::f32::consts::PI;
use heapless::Vec as HVec;

/// One link of the edge chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainLink {
    /// Interior angle at the vertex (rad, in `(0, 2π)`).
    pub angle: f32,
    /// Length of the wall leaving the vertex (m).
    pub length: f32,
}

/// Matching tolerances `ε_φ` and `ε_ρ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SymmetryTolerance {
    /// `ε_φ`: largest absolute difference of interior angles (rad).
    pub angle: f32,
    /// `ε_ρ`: largest relative difference of wall lengths (fraction of the longer one).
    pub length: f32,
}

impl Default for SymmetryTolerance {
    /// 2° and 2 %.
    fn default() -> Self {
        SymmetryTolerance {
            angle: 2.0 * PI / 180.0,
            length: 0.02,
        }
    }
}

impl SymmetryTolerance {
    /// True when two links are equivalent under these tolerances.
    pub fn links_match(&self, a: &ChainLink, b: &ChainLink) -> bool {
        abs(wrap_angle(a.angle - b.angle)) <= self.angle
            && abs(a.length - b.length) <= self.length * a.length.max(b.length)
    }
}

/// The edge chain of `plan`'s outline: link `i` is (interior angle at vertex `i`, length of
/// wall `i`), openings included (a door's jambs are links of angle π).
pub fn edge_chain(plan: &FloorPlan) -> HVec<ChainLink, MAX_VERTICES> {
    let n = plan.ring(0).len();
    let mut chain = HVec::new();
    for i in 0..n {
        let prev = plan.vertex(plan.prev(i));
        let cur = plan.vertex(i);
        let next = plan.vertex(plan.next(i));
        let (d0, d1) = (cur - prev, next - cur);
        // Signed turning angle (left turns positive for a counter-clockwise outline).
        let turn = atan2(cross(d0, d1), d0.x * d1.x + d0.y * d1.y);
        // A plan has at most MAX_VERTICES vertices, so the push cannot fail.
        let _ = chain.push(ChainLink {
            angle: PI - turn,
            length: length(d1),
        });
    }
    chain
}

/// True when shifting `chain` by `k` links leaves it unchanged within `tol`, i.e. the
/// chain occurs at offset `k` of the doubled chain.
pub fn shift_matches(chain: &[ChainLink], k: usize, tol: &SymmetryTolerance) -> bool {
    let n = chain.len();
    (0..n).all(|i| tol.links_match(&chain[i], &chain[(i + k) % n]))
}

/// Cyclic symmetry order `n ≥ 1` of `plan` (rotation by `2π/n` about the perimeter
/// centroid maps the outline onto itself within `tol`); 1 when it has none.
pub fn symmetry_order(plan: &FloorPlan, tol: &SymmetryTolerance) -> u8 {
    let chain = edge_chain(plan);
    let n = chain.len();
    let plain = plan.is_plain();
    for k in 1..n {
        if n % k == 0
            && shift_matches(&chain, k, tol)
            && (plain || (openings_match(plan, k) && columns_match(plan, n / k, tol)))
        {
            return (n / k) as u8;
        }
    }
    1
}

/// True when the shift by `k` outline links maps every opening onto an opening.
fn openings_match(plan: &FloorPlan, k: usize) -> bool {
    let n = plan.ring(0).len();
    (0..n).all(|i| plan.is_opening(i) == plan.is_opening((i + k) % n))
}

/// True when the rotation by `2π / order` about the outline's vertex mean (fixed by any
/// rotation that maps the outline onto itself) maps every column onto a column.
fn columns_match(plan: &FloorPlan, order: usize, tol: &SymmetryTolerance) -> bool {
    let outline = plan.ring(0);
    let mut c = v2(0.0, 0.0);
    for i in outline.clone() {
        c += plan.vertex(i);
    }
    let c = c / outline.len().max(1) as f32;
    let angle = TAU / order as f32;
    (1..plan.ring_count()).all(|r| {
        let ring = plan.ring(r);
        let shortest = ring
            .clone()
            .map(|i| {
                let (a, b) = plan.wall(i);
                length(b - a)
            })
            .fold(f32::INFINITY, f32::min);
        let eps = tol.length * shortest;
        (1..plan.ring_count()).any(|s| {
            let image = plan.ring(s);
            image.len() == ring.len()
                && ring.clone().all(|i| {
                    let p: Vec2 = rotate(plan.vertex(i) - c, angle) + c;
                    image.clone().any(|j| length(plan.vertex(j) - p) <= eps)
                })
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{l_room_6x4, polygon};
    use crate::world::geometry::{rotate, v2, Vec2};
    use crate::world::math::{cos, sin, TAU};
    use proptest::prelude::*;

    fn regular(n: usize, r: f32, phase: f32) -> FloorPlan {
        let v: HVec<Vec2, MAX_VERTICES> = (0..n)
            .map(|i| {
                let a = phase + TAU * i as f32 / n as f32;
                v2(r * cos(a), r * sin(a))
            })
            .collect();
        FloorPlan::new(&v).unwrap()
    }

    fn tol() -> SymmetryTolerance {
        SymmetryTolerance::default()
    }

    #[test]
    fn chain_of_rectangle() {
        let c = edge_chain(&polygon(&[(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (0.0, 2.0)]));
        assert_eq!(c.len(), 4);
        for l in &c {
            assert!(abs(l.angle - PI / 2.0) < 1e-6);
        }
        assert_eq!(c[0].length, 4.0);
        assert_eq!(c[1].length, 2.0);
        // L-room: the notch vertex is reflex (270°).
        let l = edge_chain(&l_room_6x4());
        assert!(abs(l[3].angle - 1.5 * PI) < 1e-6);
        assert!(abs(l[2].angle - 0.5 * PI) < 1e-6);
    }

    #[test]
    fn canonical_shapes() {
        let square = polygon(&[(0.0, 0.0), (3.0, 0.0), (3.0, 3.0), (0.0, 3.0)]);
        assert_eq!(symmetry_order(&square, &tol()), 4);
        let rect = polygon(&[(0.0, 0.0), (4.0, 0.0), (4.0, 2.5), (0.0, 2.5)]);
        assert_eq!(symmetry_order(&rect, &tol()), 2);
        let l_room = l_room_6x4();
        assert_eq!(symmetry_order(&l_room, &tol()), 1);
        assert_eq!(symmetry_order(&regular(6, 3.0, 0.3), &tol()), 6);
        assert_eq!(symmetry_order(&regular(5, 3.0, 0.0), &tol()), 5);
        assert_eq!(symmetry_order(&regular(3, 3.0, 0.0), &tol()), 3);
        // A rhombus (not a square) is C2.
        let rhombus = polygon(&[(0.0, 0.0), (4.0, 0.0), (6.0, 3.0), (2.0, 3.0)]);
        assert_eq!(symmetry_order(&rhombus, &tol()), 2);
        // A kite (mirror symmetric only) has no proper symmetry.
        let kite = polygon(&[(0.0, -1.0), (3.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]);
        assert_eq!(symmetry_order(&kite, &tol()), 1);
    }

    #[test]
    fn plus_shaped_room_is_c4_and_z_room_c2() {
        // Plus / cross-shaped room: 12 vertices, C4.
        let plus = polygon(&[
            (1.0, -3.0),
            (1.0, -1.0),
            (3.0, -1.0),
            (3.0, 1.0),
            (1.0, 1.0),
            (1.0, 3.0),
            (-1.0, 3.0),
            (-1.0, 1.0),
            (-3.0, 1.0),
            (-3.0, -1.0),
            (-1.0, -1.0),
            (-1.0, -3.0),
        ]);
        assert_eq!(symmetry_order(&plus, &tol()), 4);
        // Z / S-shaped room: C2 (point symmetric), not mirror symmetric.
        let z = polygon(&[
            (0.0, 0.0),
            (4.0, 0.0),
            (4.0, 2.0),
            (6.0, 2.0),
            (6.0, 4.0),
            (2.0, 4.0),
            (2.0, 2.0),
            (0.0, 2.0),
        ]);
        assert_eq!(symmetry_order(&z, &tol()), 2);
    }

    #[test]
    fn near_symmetry_within_and_outside_tolerance() {
        let t = SymmetryTolerance {
            angle: 0.02,
            length: 0.02,
        };
        // Rectangle 4 x 2 with one side stretched by 1 % (a trapezoid-ish quad whose
        // angles change by ~0.005 rad): still C2 within 2 %.
        let near = polygon(&[(0.0, 0.0), (4.0, 0.0), (4.01, 2.0), (0.0, 2.0)]);
        assert_eq!(symmetry_order(&near, &t), 2);
        // 5 cm off: length 4.05 vs 4 is 1.2 % but the angles change by 0.025 rad > 0.02.
        let far = polygon(&[(0.0, 0.0), (4.0, 0.0), (4.05, 2.0), (0.0, 2.0)]);
        assert_eq!(symmetry_order(&far, &t), 1);
        // Near-square 3 x 3.04 (1.3 % longer): C4 within 2 %, only C2 within 1 %.
        let sq = polygon(&[(0.0, 0.0), (3.0, 0.0), (3.0, 3.04), (0.0, 3.04)]);
        assert_eq!(symmetry_order(&sq, &t), 4);
        let strict = SymmetryTolerance {
            angle: 0.02,
            length: 0.01,
        };
        assert_eq!(symmetry_order(&sq, &strict), 2);
        // Near-regular hexagon, one vertex pushed 1 % outwards radially.
        let mut v: HVec<Vec2, MAX_VERTICES> = regular(6, 3.0, 0.0).vertices().collect();
        v[2] *= 1.01;
        let hex = FloorPlan::new(&v).unwrap();
        let loose = SymmetryTolerance {
            angle: 0.05,
            length: 0.05,
        };
        assert_eq!(symmetry_order(&hex, &loose), 6);
        // The push changes interior angles by up to 0.017 rad and walls by 0.5 %.
        let strict = SymmetryTolerance {
            angle: 0.005,
            length: 0.002,
        };
        assert_eq!(symmetry_order(&hex, &strict), 1);
    }

    proptest! {
        /// The order is invariant under rigid motions and under the choice of the
        /// starting vertex.
        #[test]
        fn order_invariant_under_rigid_motion_and_relabel(
            n in 3usize..9, a in -3.0f32..3.0, tx in -5.0f32..5.0, ty in -5.0f32..5.0,
            start in 0usize..9, pick in 0usize..4
        ) {
            let shapes = [
                regular(n, 2.5, 0.1),
                polygon(&[(0.0, 0.0), (4.0, 0.0), (4.0, 2.5), (0.0, 2.5)]),
                l_room_6x4(),
                polygon(&[(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (6.0, 2.0), (6.0, 4.0), (2.0, 4.0),
                       (2.0, 2.0), (0.0, 2.0)]),
            ];
            let expect = [n as u8, 2, 1, 2][pick];
            let p = &shapes[pick];
            let m = p.len();
            let v: HVec<Vec2, MAX_VERTICES> = (0..m)
                .map(|i| rotate(p.vertex(i + start), a) + v2(tx, ty))
                .collect();
            let q = FloorPlan::new(&v).unwrap();
            prop_assert_eq!(symmetry_order(&q, &tol()), expect);
        }
    }

    #[test]
    fn columns_and_doors_break_or_keep_symmetry() {
        let outline = [v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)];
        let plain = FloorPlan::new(&outline).unwrap();
        assert_eq!(symmetry_order(&plain, &tol()), 2);
        let sq = |x: f32, y: f32| {
            [
                v2(x, y),
                v2(x + 1.0, y),
                v2(x + 1.0, y + 1.0),
                v2(x, y + 1.0),
            ]
        };
        let build = |cols: &[&[Vec2]], doors: &[(Vec2, Vec2)]| {
            FloorPlan::with_columns_and_doors(&outline, cols, doors, 0.02).unwrap()
        };
        // A centred column keeps the half turn.
        assert_eq!(symmetry_order(&build(&[&sq(2.5, 1.5)], &[]), &tol()), 2);
        // An off-centre one breaks it.
        assert_eq!(symmetry_order(&build(&[&sq(3.5, 1.5)], &[]), &tol()), 1);
        // Two columns that swap under the half turn keep it.
        let pair = build(&[&sq(1.0, 1.0), &sq(4.0, 2.0)], &[]);
        assert_eq!(symmetry_order(&pair, &tol()), 2);
        // A door breaks it; a second door opposite it restores it.
        let one = build(&[], &[(v2(1.0, 0.0), v2(2.0, 0.0))]);
        assert_eq!(symmetry_order(&one, &tol()), 1);
        let two = build(
            &[],
            &[(v2(1.0, 0.0), v2(2.0, 0.0)), (v2(5.0, 4.0), v2(4.0, 4.0))],
        );
        assert_eq!(symmetry_order(&two, &tol()), 2);
    }
}
