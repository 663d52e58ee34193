//! The rooms the unit tests share: one definition each, so two tests that mean the same
//! room draw the same one.

use activesense_core::world::geometry::v2;
use activesense_core::FloorPlan;

/// A `w` × `h` rectangle centred on the origin, corners counter-clockwise from (−w/2, −h/2).
pub fn rect(w: f32, h: f32) -> FloorPlan {
    let (x, y) = (w / 2.0, h / 2.0);
    FloorPlan::new(&[v2(-x, -y), v2(x, -y), v2(x, y), v2(-x, y)]).expect("a rectangle is a plan")
}
