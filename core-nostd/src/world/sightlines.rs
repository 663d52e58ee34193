//! Visibility from one point to many: [`FloorPlan::visible`], bit for bit, with what depends
//! only on the viewpoint worked out once.
//!
//! Sparse ICP's correspondences test, for every reading of every pass, whether the
//! instrument sees the wall point a reading would pair with: one ray cast over every wall
//! per reading. Within a pass the instrument (the pose's translation) is fixed, so each
//! wall's offset from it, its direction and their cross product are the same for every
//! reading; [`Sightlines`] keeps them and runs the plan's own per-wall test on them. A
//! sight line is decided at the first wall that blocks it (the visibility test used to find
//! the nearest of all first). In a many-walled room the correspondences were over half of
//! the device's worst K = 10 update (README, "Instructions per update").

use crate::limits::MAX_VERTICES;
use crate::world::floorplan::{blocks, FloorPlan};
use crate::world::geometry::{cross, length, Vec2};

/// Sight lines from one viewpoint in one plan.
pub struct Sightlines {
    origin: Vec2,
    /// Per wall `a → b`: `a - origin`, `b - a`, and their cross product (filled, not
    /// zeroed first: this is built once per correspondence pass).
    walls: heapless::Vec<(Vec2, Vec2, f32), MAX_VERTICES>,
}

impl Sightlines {
    /// The viewpoint `origin` in `plan`.
    pub fn new(plan: &FloorPlan, origin: Vec2) -> Sightlines {
        let mut walls = heapless::Vec::new();
        // Solid walls only: a sight line passes through a door opening.
        for i in plan.solid_walls() {
            let (a, b) = plan.wall(i);
            let (w, e) = (a - origin, b - a);
            // A plan has at most MAX_VERTICES walls.
            let _ = walls.push((w, e, cross(w, e)));
        }
        Sightlines { origin, walls }
    }

    /// [`FloorPlan::visible`]`(origin, to, tolerance)`: the same arithmetic per wall (the
    /// ray's parameter along itself and along the wall), and "a wall crossed before `to`"
    /// is "the nearest crossing before `to`", tested wall by wall.
    pub fn visible(&self, to: Vec2, tolerance: f32) -> bool {
        let d = to - self.origin;
        let dist = length(d);
        if dist <= tolerance {
            return true;
        }
        let (dir, before) = (d / dist, dist - tolerance);
        !self.walls.iter().any(|&wall| blocks(wall, dir, before))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::geometry::v2;

    /// Random points and plans with many walls: the same answer as the ray cast, always.
    #[test]
    fn equals_the_plans_own_visibility_test() {
        // A 48-gon star (reflex corners everywhere), an L-room and a comb.
        let star: heapless::Vec<Vec2, MAX_VERTICES> = (0..48)
            .map(|k| {
                let a = core::f32::consts::TAU * k as f32 / 48.0;
                let r = if k % 2 == 0 {
                    6.0
                } else {
                    3.5 + 0.1 * (k % 7) as f32
                };
                v2(r * libm::cosf(a), r * libm::sinf(a))
            })
            .collect();
        let mut comb: heapless::Vec<Vec2, MAX_VERTICES> = heapless::Vec::new();
        let _ = comb.push(v2(0.0, 0.0));
        let _ = comb.push(v2(10.0, 0.0));
        for k in 0..5 {
            let x = 10.0 - 2.0 * k as f32;
            let _ = comb.push(v2(x, 4.0));
            let _ = comb.push(v2(x - 1.0, 4.0));
            let _ = comb.push(v2(x - 1.0, 1.5));
            let _ = comb.push(v2(x - 2.0, 1.5));
        }
        let plans = [
            FloorPlan::new(&star).unwrap(),
            crate::fixtures::l_room_6x4(),
            FloorPlan::new(&comb[..comb.len() - 2]).unwrap(),
        ];
        let mut seed = 0x1234_5678u32;
        let mut uniform = |lo: f32, hi: f32| {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            lo + (hi - lo) * (seed >> 8) as f32 / 16_777_216.0
        };
        let (mut blocked, mut seen) = (0, 0);
        for plan in &plans {
            for _ in 0..200 {
                let origin = v2(uniform(-7.0, 11.0), uniform(-7.0, 7.0));
                let sight = Sightlines::new(plan, origin);
                for k in 0..60 {
                    // Wall points (what the ICP asks about), vertices and free points.
                    let to = match k % 3 {
                        0 => {
                            let (a, b) = plan.wall(k % plan.len());
                            a + (b - a) * uniform(0.0, 1.0)
                        }
                        1 => plan.vertex(k),
                        _ => v2(uniform(-7.0, 11.0), uniform(-7.0, 7.0)),
                    };
                    for tol in [1e-3, 0.0, 0.5] {
                        // The definition: the nearest wall along the line is not nearer.
                        let d = to - origin;
                        let dist = length(d);
                        let want = dist <= tol
                            || plan
                                .first_hit(origin, d / dist)
                                .is_none_or(|range| range >= dist - tol);
                        assert_eq!(plan.visible(origin, to, tol), want, "{origin:?} → {to:?}");
                        assert_eq!(sight.visible(to, tol), want, "{origin:?} → {to:?}");
                        if want {
                            seen += 1;
                        } else {
                            blocked += 1;
                        }
                    }
                }
            }
        }
        assert!(blocked > 10_000 && seen > 10_000, "{blocked} {seen}");
    }
}
