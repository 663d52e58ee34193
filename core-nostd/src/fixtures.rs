//! The rooms the core's unit tests share, each defined once: the 6 × 4 m and the 8 × 6 m
//! L-rooms, rectangles in their own frame, centred on their perimeter centroid or placed
//! about the origin, and the two ways the tests turn a vertex list into a plan (as given,
//! or in the model frame). A test that needs a room of its own writes it inline; a room two
//! test modules use lives here, under a name that says which room it is. Compiled for the
//! tests only.

use crate::protocol::MAX_WIRE_VERTICES;
use crate::world::floorplan::MAX_VERTICES;
use crate::world::geometry::{v2, Vec2};
use crate::FloorPlan;
use heapless::Vec as HVec;

/// The polygon `pts` as a plan in its own frame (vertices as given).
pub(crate) fn polygon(pts: &[(f32, f32)]) -> FloorPlan {
    let v: HVec<Vec2, MAX_VERTICES> = pts.iter().map(|&(x, y)| v2(x, y)).collect();
    FloorPlan::new(&v).unwrap()
}

/// The polygon `pts` as a plan in the model frame: translated so its perimeter centroid is
/// the origin ([`FloorPlan::centered`]), as the localizer and the registration take it.
pub(crate) fn centred(pts: &[(f32, f32)]) -> FloorPlan {
    polygon(pts).centered()
}

/// The 6 × 4 m L-room, the top-right 3 × 2 m corner cut away, in its own frame: the room
/// whose hand-worked coordinates the geometry, symmetry and registration tests share.
pub(crate) fn l_room_6x4() -> FloorPlan {
    FloorPlan::new(&[
        v2(0.0, 0.0),
        v2(6.0, 0.0),
        v2(6.0, 2.0),
        v2(3.0, 2.0),
        v2(3.0, 4.0),
        v2(0.0, 4.0),
    ])
    .unwrap()
}

/// The 8 × 6 m L-room, the top-right 4 × 3 m corner cut away, in the model frame: the
/// room of the localization, pipeline, stop and policy tests.
pub(crate) fn l_room_8x6() -> FloorPlan {
    centred(&[
        (0.0, 0.0),
        (8.0, 0.0),
        (8.0, 3.0),
        (4.0, 3.0),
        (4.0, 6.0),
        (0.0, 6.0),
    ])
}

/// A `w × h` m rectangle with a corner at the origin, in its own frame.
pub(crate) fn rect(w: f32, h: f32) -> FloorPlan {
    FloorPlan::new(&[v2(0.0, 0.0), v2(w, 0.0), v2(w, h), v2(0.0, h)]).unwrap()
}

/// A `w × h` m rectangle in the model frame: [`rect`] translated so its perimeter centroid
/// is the origin.
pub(crate) fn centred_rect(w: f32, h: f32) -> FloorPlan {
    centred(&[(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)])
}

/// A `w × h` m rectangle placed about the origin by its vertices (`±w/2`, `±h/2`), with no
/// centroid computed.
pub(crate) fn rect_about_origin(w: f32, h: f32) -> FloorPlan {
    let v: HVec<Vec2, MAX_VERTICES> = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
        .iter()
        .map(|&(x, y)| v2(x - 0.5 * w, y - 0.5 * h))
        .collect();
    FloorPlan::new(&v).unwrap()
}

/// The 4 × 3 m rectangle about the origin as a `LoadPlan` request carries it (the
/// vertices of [`rect_about_origin`]`(4.0, 3.0)`).
pub(crate) fn rect_4x3_wire() -> HVec<[f32; 2], MAX_WIRE_VERTICES> {
    HVec::from_slice(&[[-2.0, -1.5], [2.0, -1.5], [2.0, 1.5], [-2.0, 1.5]]).unwrap()
}
