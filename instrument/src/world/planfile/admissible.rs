//! Can the instrument localize in this room? Checked when a plan file is loaded,
//! so that a hall the EDM cannot span, a sliver the instrument cannot stand in, or a room
//! the 30 × 30 localizer grid cannot resolve is refused (or warned about) with the reason
//! and what to do, instead of failing later with errors of tens of metres and "risk not
//! available".
//!
//! - **Reach** (refused): from no point inside the room are all corners within the EDM's
//!   range ([`SensorModel::max_range`], 50 m): some walls can never be measured, wherever
//!   the instrument stands. Warned when only the room's visual centre (where the simulation
//!   places the instrument) is too far from a corner.
//! - **Width** (refused): the widest circle inside the room is under
//!   [`MIN_ROOM_WIDTH`] across: no room for an instrument on its tripod, and the grid's
//!   cells across the room become narrower than the localizer resolves.
//! - **Grid** (refused / warned): the localizer lays `30 × 30` cells over the bounding box.
//!   Cells thinner than [`MIN_CELL`] (the GHT vote's resolution, a few times its range σ)
//!   cannot be told apart, so the coarse estimate is almost never the right cell (refused);
//!   cells larger than [`MAX_CELL`] make the coarse estimate that coarse (warned). Parts of
//!   the room narrower than a cell hold no cell centre, so the localizer cannot place the
//!   instrument there (warned).

use crate::world::sensor::SensorModel;
use activesense_core::limits::{MAX_NX, MAX_NY};
use activesense_core::world::geometry::{v2, Vec2};
use activesense_core::FloorPlan;

/// Narrowest room (diameter of its widest inscribed circle, m) the instrument can work in.
pub const MIN_ROOM_WIDTH: f32 = 1.0;
/// Thinnest localizer cell (m) the GHT vote resolves (2.5 × its 2 cm range σ).
pub const MIN_CELL: f32 = 0.05;
/// Largest localizer cell (m) before the coarse estimate is too coarse to be useful.
pub const MAX_CELL: f32 = 2.0;
/// Candidate instrument positions per side when searching the best-placed point.
const REACH_SAMPLES: usize = 48;

/// The admissibility warnings of `plan` (model frame), or the reason it is refused.
pub fn check(plan: &FloorPlan) -> Result<Vec<String>, String> {
    let range = SensorModel::default().max_range;
    let (lo, hi) = plan.bounds();
    let size = hi - lo;
    let mut warnings = Vec::new();
    // Reach: the smallest, over interior points, of the distance to the farthest corner
    // (a polygon's farthest point from any point is a vertex).
    let far = |p: Vec2| {
        plan.vertices()
            .map(|v| (v - p).norm())
            .fold(0.0f32, f32::max)
    };
    let mut best = f32::INFINITY;
    for iy in 0..REACH_SAMPLES {
        for ix in 0..REACH_SAMPLES {
            let p = v2(
                lo.x + (ix as f32 + 0.5) * size.x / REACH_SAMPLES as f32,
                lo.y + (iy as f32 + 0.5) * size.y / REACH_SAMPLES as f32,
            );
            if plan.contains(p) {
                best = best.min(far(p));
            }
        }
    }
    let place = crate::world::placement(plan);
    let centre = v2(place.visual_centre[0], place.visual_centre[1]);
    best = best.min(far(centre));
    if best > range {
        return Err(format!(
            "the room ({:.1} m × {:.1} m) is too large for the EDM: from no point inside it are all corners within its {range:.0} m range (the best-placed point is {best:.1} m from the farthest one); crop the plan to the part of the room the instrument stands in",
            size.x, size.y
        ));
    }
    let from_centre = far(centre);
    if from_centre > range {
        warnings.push(format!(
            "from the room's visual centre the farthest corner is {from_centre:.1} m away, beyond the EDM's {range:.0} m: walls there give no return; stand nearer the far end or crop the plan"
        ));
    }
    // Width: the widest inscribed circle is the placement disc.
    let width = 2.0 * place.radius;
    if width < MIN_ROOM_WIDTH {
        return Err(format!(
            "the room is at most {width:.2} m wide (its widest inscribed circle), under the {MIN_ROOM_WIDTH:.1} m an instrument needs to stand and localize in; is it a wall or a corridor sliver drawn as a room? draw the room it belongs to"
        ));
    }
    // Grid: 30 × 30 cells over the bounding box.
    let cell = [size.x / MAX_NX as f32, size.y / MAX_NY as f32];
    let (thin, thick) = (cell[0].min(cell[1]), cell[0].max(cell[1]));
    if thin < MIN_CELL {
        return Err(format!(
            "the localizer's {MAX_NX} × {MAX_NY} grid over this {:.2} m × {:.2} m room has cells of {:.3} m × {:.3} m, thinner than the {MIN_CELL} m its votes resolve: the room is too elongated; split it into parts no more than {:.0} times as long as wide",
            size.x,
            size.y,
            cell[0],
            cell[1],
            thick / MIN_CELL
        ));
    }
    if thick > MAX_CELL {
        warnings.push(format!(
            "the localizer's {MAX_NX} × {MAX_NY} grid over this {:.1} m × {:.1} m room has cells of {:.2} m × {:.2} m: the coarse estimate is only that fine (the refinement still fits to centimetres, but a wrong cell is more likely); crop the plan to the room the instrument stands in",
            size.x, size.y, cell[0], cell[1]
        ));
    }
    // Narrow parts: along each wall, the room's width along the inward normal.
    let mut narrow: Vec<(usize, f32)> = Vec::new();
    // Solid walls only: across a door opening there is no wall to stand against.
    for i in plan.solid_walls() {
        let (a, b) = plan.wall(i);
        let n = -plan.outward_normal(i);
        let len = (b - a).norm();
        let k = ((len / (0.5 * thick)).ceil() as usize).clamp(1, 64);
        let mut min_w = f32::INFINITY;
        for j in 0..k {
            let t = (j as f32 + 0.5) / k as f32;
            let p = a + (b - a) * t + n * 1e-3;
            if let Some(hit) = plan.ray_cast(p, n) {
                min_w = min_w.min(hit.range + 1e-3);
            }
        }
        if min_w < thick {
            narrow.push((i, min_w));
        }
    }
    if !narrow.is_empty() {
        let walls: Vec<String> = narrow
            .iter()
            .take(4)
            .map(|(i, w)| format!("wall {i} ({w:.2} m)"))
            .collect();
        warnings.push(format!(
            "part of the room is narrower than a localizer cell ({thick:.2} m): across from {}{}; the localizer cannot place the instrument there (stand elsewhere, or crop the part off)",
            walls.join(", "),
            if narrow.len() > 4 { ", …" } else { "" }
        ));
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::fixtures::rect;

    #[test]
    fn the_issue_rooms() {
        // Halls the 50 m EDM cannot span, from anywhere inside.
        for (w, h) in [(120.0, 80.0), (400.0, 30.0), (400.0, 300.0)] {
            let e = check(&rect(w, h)).unwrap_err();
            assert!(
                e.contains("too large for the EDM") && e.contains("crop"),
                "{e}"
            );
        }
        // A 10 × 0.6 m sliver.
        let e = check(&rect(10.0, 0.6)).unwrap_err();
        assert!(e.contains("0.60 m wide"), "{e}");
        // An ordinary room passes without remarks; a 60 × 40 m hall is within reach but
        // its cells are 2 m: warned.
        assert_eq!(check(&rect(12.0, 8.0)).unwrap(), Vec::<String>::new());
        let w = check(&rect(70.0, 40.0)).unwrap();
        assert!(w.iter().any(|w| w.contains("cells of 2.33 m")), "{w:?}");
        // 40 × 1.2 m: wide enough to stand in, but its cells are 4 cm thin.
        let e = check(&rect(40.0, 1.2)).unwrap_err();
        assert!(e.contains("too elongated"), "{e}");
    }

    #[test]
    fn a_narrow_part_is_warned_about() {
        // A 20 × 10 m room with a 0.4 m wide, 3 m deep niche.
        let v: Vec<_> = [
            (0.0, 0.0),
            (20.0, 0.0),
            (20.0, 10.0),
            (10.2, 10.0),
            (10.2, 13.0),
            (9.8, 13.0),
            (9.8, 10.0),
            (0.0, 10.0),
        ]
        .iter()
        .map(|&(x, y)| v2(x, y))
        .collect();
        let plan = FloorPlan::new(&v).unwrap().centered();
        let w = check(&plan).unwrap();
        assert!(
            w.iter()
                .any(|w| w.contains("narrower than a localizer cell")),
            "{w:?}"
        );
    }

    #[test]
    fn generated_plans_are_admissible() {
        // The generated rooms (3–30 m) must never be refused: `plan --json` files load back.
        let seeds =
            crate::world::plans::TEST_SEEDS.start..crate::world::plans::TEST_SEEDS.start + 200;
        for seed in seeds {
            let plan = crate::world::plans::generate(seed);
            assert!(check(&plan).is_ok(), "plan {seed}: {:?}", check(&plan));
        }
    }
}
