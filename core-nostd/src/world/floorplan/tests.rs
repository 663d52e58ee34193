//! Unit tests of the floor-plan model: validation, metrics, ray casts, nearest points and
//! the topological scan on hand-worked rooms, then rooms with columns and doors.

use super::*;
use crate::fixtures::{l_room_6x4, rect};
use crate::world::geometry::unit;
use core::f32::consts::{FRAC_PI_2, PI};

#[test]
fn rejects_invalid() {
    let z = v2(0.0, 0.0);
    assert_eq!(
        FloorPlan::new(&[z, v2(1.0, 0.0)]),
        Err(PlanError::TooFewVertices)
    );
    assert_eq!(
        FloorPlan::new(&[v2(0.0, 0.0), v2(0.0, 4.0), v2(4.0, 4.0), v2(4.0, 0.0)]),
        Err(PlanError::Clockwise)
    );
    assert!(FloorPlan::new_any_orientation(&[
        v2(0.0, 0.0),
        v2(0.0, 4.0),
        v2(4.0, 4.0),
        v2(4.0, 0.0)
    ])
    .is_ok());
    assert_eq!(
        FloorPlan::new(&[v2(0.0, 0.0), v2(f32::NAN, 0.0), v2(4.0, 4.0)]),
        Err(PlanError::NonFiniteCoordinate(1))
    );
    // bow-tie
    assert!(matches!(
        FloorPlan::new(&[v2(0.0, 0.0), v2(4.0, 4.0), v2(4.0, 0.0), v2(0.0, 4.0)]),
        Err(PlanError::SelfIntersection(_, _))
    ));
    // collinear middle vertex
    assert_eq!(
        FloorPlan::new(&[
            v2(0.0, 0.0),
            v2(2.0, 0.0),
            v2(4.0, 0.0),
            v2(4.0, 4.0),
            v2(0.0, 4.0)
        ]),
        Err(PlanError::CollinearVertex(1))
    );
    // duplicate vertex
    assert_eq!(
        FloorPlan::new(&[
            v2(0.0, 0.0),
            v2(4.0, 0.0),
            v2(4.0, 0.0),
            v2(4.0, 4.0),
            v2(0.0, 4.0)
        ]),
        Err(PlanError::ZeroLengthEdge(1))
    );
    assert_eq!(
        FloorPlan::new(&[v2(0.0, 0.0), v2(0.1, 0.0), v2(0.1, 0.1)]),
        Err(PlanError::BadExtent)
    );
    let many = [v2(0.0, 0.0); MAX_VERTICES + 1];
    assert_eq!(FloorPlan::new(&many), Err(PlanError::TooManyVertices));
}

#[test]
fn rectangle_metrics() {
    let r = rect(4.0, 2.0);
    assert_eq!(r.perimeter(), 12.0);
    assert_eq!(r.signed_area(), 8.0);
    let c = r.perimeter_centroid();
    assert!((c - v2(2.0, 1.0)).norm() < 1e-6);
    assert_eq!(r.outward_normal(0), v2(0.0, -1.0));
    assert_eq!(r.outward_normal(1), v2(1.0, 0.0));
    assert!(r.contains(v2(1.0, 1.0)) && !r.contains(v2(5.0, 1.0)));
}

#[test]
fn ray_cast_rectangle_analytic() {
    let r = rect(4.0, 2.0);
    let o = v2(1.0, 0.5);
    let h = r.ray_cast(o, unit(0.0)).unwrap();
    assert!((h.range - 3.0).abs() < 1e-5 && h.wall == 1 && h.incidence.abs() < 1e-3);
    let h = r.ray_cast(o, unit(FRAC_PI_2)).unwrap();
    assert!((h.range - 1.5).abs() < 1e-5 && h.wall == 2);
    let h = r.ray_cast(o, unit(PI)).unwrap();
    assert!((h.range - 1.0).abs() < 1e-5 && h.wall == 3);
    // 30 degrees: hits the top wall (y = 2) at x = 1 + 1.5 / tan(30°) = 3.598
    let a = PI / 6.0;
    let h = r.ray_cast(o, unit(a)).unwrap();
    assert!((h.range - 3.0).abs() < 1e-4, "{h:?}");
    assert_eq!(h.wall, 2);
    assert!((h.incidence - (FRAC_PI_2 - a)).abs() < 1e-3);
}

#[test]
fn ray_cast_l_room_occlusion() {
    let l = l_room_6x4();
    // From the lower arm looking up-right at 45°, the ray hits the inner wall x = 3.
    let o = v2(1.0, 1.0);
    let d = unit(PI / 4.0);
    let h = l.ray_cast(o, d).unwrap();
    // y = 2 at x = 2 -> passes the inner corner (3,2)? At x=3, y=3: inner wall x=3 spans y in [2,4]
    assert_eq!(h.wall, 3, "{h:?}");
    assert!((h.range - 2.0 * 2f32.sqrt()).abs() < 1e-4);
    // From the lower-right arm looking left along y = 1 we cross the whole room.
    let h = l.ray_cast(v2(5.0, 1.0), unit(PI)).unwrap();
    assert!((h.range - 5.0).abs() < 1e-5 && h.wall == 5);
    // From (5,1) towards the upper-left corner: blocked by the notch wall y = 2.
    assert!(!l.visible(v2(5.0, 1.0), v2(0.0, 4.0), 1e-3));
    assert!(l.visible(v2(1.0, 1.0), v2(0.0, 4.0), 1e-3));
}

#[test]
fn nearest_point_on_outline() {
    let r = rect(4.0, 2.0);
    let n = r.nearest_point(v2(3.5, 1.0));
    assert_eq!(n.wall, 1);
    assert!((n.distance - 0.5).abs() < 1e-6);
    let n = r.nearest_point(v2(5.0, 3.0));
    assert!((n.point - v2(4.0, 2.0)).norm() < 1e-6);
}

#[test]
fn topological_scan_hand_worked() {
    let r = rect(4.0, 4.0);
    // From the centre, the corner (4,4) lies at 45°. Looking at 45° with a 45° FOV
    // and 20 pixels, it is exactly at the centre: bin index 10 (bins are [lo, hi)).
    let s: [bool; 20] = r.topological_scan(v2(2.0, 2.0), PI / 4.0, PI / 4.0);
    assert_eq!(s.iter().filter(|&&b| b).count(), 1);
    assert!(s[10]);
    // Looking along +x, no corner is within ±22.5°.
    let s: [bool; 20] = r.topological_scan(v2(2.0, 2.0), 0.0, PI / 4.0);
    assert!(s.iter().all(|&b| !b));
    // From (1, 2) the corner (4, 4) is at atan2(2, 3) = 33.69°, (4, 0) at -33.69°.
    // Looking at +x they are outside the ±22.5° FOV; at 33.69° - 10° the corner sits
    // 10° left of centre: bin floor((10 + 22.5) / 45 * 20) = 14.
    let b = libm::atan2f(2.0, 3.0) - 10f32.to_radians();
    let s: [bool; 20] = r.topological_scan(v2(1.0, 2.0), b, PI / 4.0);
    assert!(s[14] && s.iter().filter(|&&b| b).count() == 1, "{s:?}");
}

#[test]
fn topological_scan_occlusion() {
    let l = l_room_6x4();
    // From (5, 1) the far upper-left corner (0, 4) is hidden behind the notch, but the
    // inner corner (3, 2) is visible. Bearing toward (0, 4):
    let o = v2(5.0, 1.0);
    let to_hidden = libm::atan2f(3.0, -5.0);
    let s: [bool; 20] = l.topological_scan(o, to_hidden, 0.1);
    assert!(s.iter().all(|&b| !b), "hidden corner must not show: {s:?}");
    let to_inner = libm::atan2f(1.0, -2.0);
    let s: [bool; 20] = l.topological_scan(o, to_inner, 0.1);
    assert!(s.iter().any(|&b| b), "inner corner must show: {s:?}");
}

/// The 6 × 4 m room with a 1 × 1 m column at (3.5..4.5, 1.5..2.5) and a 1 m door in the
/// bottom wall from x = 1 to x = 2, built the way a plan file builds it (the column given
/// counter-clockwise, normalised to clockwise).
fn room_with_column_and_door() -> FloorPlan {
    let outline = [v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)];
    let column = [v2(3.5, 1.5), v2(4.5, 1.5), v2(4.5, 2.5), v2(3.5, 2.5)];
    let door = (v2(2.0, 0.005), v2(1.0, -0.005));
    FloorPlan::with_columns_and_doors(&outline, &[&column], &[door], 0.02).unwrap()
}

#[test]
fn columns_and_doors_are_stored_in_the_wire_form() {
    let p = room_with_column_and_door();
    // Outline 0, jamb 1 (x = 1), jamb 2 (x = 2), 3 corners, then the column's 4.
    assert_eq!(p.len(), 10);
    assert_eq!(p.ring_ends(), &[6, 10]);
    assert_eq!(p.openings(), 1 << 1);
    assert_eq!(p.vertex(1), v2(1.0, 0.0));
    assert_eq!(p.vertex(2), v2(2.0, 0.0));
    assert!(p.ring_area(1) < 0.0, "the column runs clockwise");
    assert_eq!(
        p.wall(9),
        (p.vertex(9), p.vertex(6)),
        "the column's ring closes"
    );
    assert_eq!(
        p.wall(5),
        (p.vertex(5), p.vertex(0)),
        "the outline's ring closes"
    );
    assert!((p.signed_area() - 23.0).abs() < 1e-4);
    // Solid walls: 6 + 4 + 4 + 4 + 1 (the bottom wall less the door) + 4 (column).
    assert!((p.perimeter() - 23.0).abs() < 1e-4, "{}", p.perimeter());
    // The wire form round-trips.
    let q = FloorPlan::from_parts(p.raw(), p.ring_ends(), p.openings()).unwrap();
    assert_eq!(p, q);
    // A plain plan keeps its plain form through the wire constructor.
    let r = rect(4.0, 2.0);
    let s = FloorPlan::from_parts(r.raw(), &[4], 0).unwrap();
    assert_eq!(r, s);
    assert!(s.is_plain());
}

#[test]
fn a_ray_hits_a_column() {
    let p = room_with_column_and_door();
    let h = p.ray_cast(v2(1.0, 2.0), unit(0.0)).unwrap();
    assert!((h.range - 2.5).abs() < 1e-5, "{h:?}");
    // The column's west face runs from (3.5, 2.5) down to (3.5, 1.5): its last wall.
    assert_eq!(h.wall, 9);
    assert_eq!(p.outward_normal(9), v2(1.0, 0.0), "into the column");
    assert!(h.incidence.abs() < 1e-3);
    assert!(!p.visible(v2(1.0, 2.0), v2(5.5, 2.0), 1e-3));
}

#[test]
fn contains_is_false_inside_a_column() {
    let p = room_with_column_and_door();
    assert!(!p.contains(v2(4.0, 2.0)));
    assert!(p.contains(v2(1.0, 2.0)));
    assert!(p.contains(v2(1.5, 0.2)), "beside the door");
    assert!(!p.contains(v2(1.5, -0.2)), "through the door is outside");
}

#[test]
fn a_ray_passes_through_a_door() {
    let p = room_with_column_and_door();
    // Straight down through the door: nothing.
    assert_eq!(p.ray_cast(v2(1.5, 2.0), unit(-FRAC_PI_2)), None);
    assert_eq!(p.first_hit(v2(1.5, 2.0), unit(-FRAC_PI_2)), None);
    // Beside it, the bottom wall.
    let h = p.ray_cast(v2(2.5, 2.0), unit(-FRAC_PI_2)).unwrap();
    assert!((h.range - 2.0).abs() < 1e-5 && h.wall == 2, "{h:?}");
    assert!(p.visible(v2(1.5, 2.0), v2(1.5, -1.0), 1e-3));
}

#[test]
fn door_exit_is_where_a_ray_leaves_through_a_door() {
    let p = room_with_column_and_door();
    // Straight down from (1.5, 2): the door, 2 m away (its line sits within 5 mm of y = 0).
    let t = p.door_exit(v2(1.5, 2.0), unit(-FRAC_PI_2)).unwrap();
    assert!((t - 2.0).abs() < 0.01, "{t}");
    // Beside it the bottom wall comes first; towards the column, the column.
    assert_eq!(p.door_exit(v2(2.5, 2.0), unit(-FRAC_PI_2)), None);
    assert_eq!(p.door_exit(v2(1.0, 2.0), unit(0.0)), None);
    // From above the column, aimed at the door's middle: the column is met first.
    let d = v2(1.5, 0.0) - v2(4.0, 3.0);
    let aimed = d / crate::world::geometry::length(d);
    assert!(p.first_hit(v2(4.0, 3.0), aimed).unwrap() < 1.0);
    assert_eq!(p.door_exit(v2(4.0, 3.0), aimed), None);
    // A plan without doors never has an exit.
    assert_eq!(rect(6.0, 4.0).door_exit(v2(0.0, 0.0), unit(0.3)), None);
}

#[test]
fn nearest_point_skips_a_door() {
    let p = room_with_column_and_door();
    // Just above the door's middle: the door is nearest, but it is no wall; the jambs are.
    let n = p.nearest_point(v2(1.5, 0.1));
    assert!(
        (n.distance - (0.5f32 * 0.5 + 0.1 * 0.1).sqrt()).abs() < 1e-5,
        "{n:?}"
    );
    assert!(n.wall == 0 || n.wall == 2);
}

#[test]
fn validation_refuses_bad_columns_and_doors() {
    let outline = [v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)];
    let sq = |x: f32, y: f32, s: f32| [v2(x, y), v2(x + s, y), v2(x + s, y + s), v2(x, y + s)];
    let build = |cols: &[&[Vec2]], doors: &[(Vec2, Vec2)]| {
        FloorPlan::with_columns_and_doors(&outline, cols, doors, 0.02)
    };
    // A column outside the room.
    assert_eq!(
        build(&[&sq(8.0, 1.0, 1.0)], &[]),
        Err(PlanError::ColumnOutsideRoom(1))
    );
    // A column crossing the outline.
    assert!(matches!(
        build(&[&sq(5.5, 1.0, 1.0)], &[]),
        Err(PlanError::SelfIntersection(..))
    ));
    // A column inside another column.
    assert_eq!(
        build(&[&sq(1.0, 1.0, 2.0), &sq(1.5, 1.5, 0.5)], &[]),
        Err(PlanError::ColumnOutsideRoom(2))
    );
    // Nine columns are too many.
    let cols: [[Vec2; 4]; 9] = core::array::from_fn(|k| sq(0.3 + 0.6 * k as f32, 1.0, 0.3));
    let refs: [&[Vec2]; 9] = core::array::from_fn(|k| &cols[k][..]);
    assert_eq!(build(&refs, &[]), Err(PlanError::TooManyRings));
    assert!(build(&refs[..8], &[]).is_ok());
    // A door off every wall.
    assert_eq!(
        build(
            &[],
            &[(v2(1.0, 0.0), v2(2.0, 0.0)), (v2(1.0, 1.0), v2(2.0, 1.0))]
        ),
        Err(PlanError::DoorOffWalls(1))
    );
    // The wire form: a column counter-clockwise, an opening on a column, two in a row.
    let good = room_with_column_and_door();
    let mut ccw: heapless::Vec<[f32; 2], MAX_VERTICES> = good.raw().iter().copied().collect();
    ccw[6..].reverse();
    assert_eq!(
        FloorPlan::from_parts(&ccw, good.ring_ends(), good.openings()),
        Err(PlanError::ColumnNotClockwise(1))
    );
    assert_eq!(
        FloorPlan::from_parts(good.raw(), good.ring_ends(), good.openings() | 1 << 7),
        Err(PlanError::OpeningNotOnOutline(7))
    );
    assert_eq!(
        FloorPlan::from_parts(good.raw(), good.ring_ends(), 0b11 << 1),
        Err(PlanError::AdjacentOpenings(1))
    );
    assert_eq!(
        FloorPlan::from_parts(good.raw(), &[6, 8, 10], 0),
        Err(PlanError::RingTooSmall(1))
    );
    assert_eq!(
        FloorPlan::from_parts(good.raw(), &[6, 9], 0),
        Err(PlanError::BadRingEnds)
    );
    // Without the opening the jambs are collinear vertices.
    assert_eq!(
        FloorPlan::from_parts(good.raw(), good.ring_ends(), 0),
        Err(PlanError::CollinearVertex(1))
    );
}

#[test]
fn translation_and_centring_keep_rings_and_openings() {
    let p = room_with_column_and_door();
    let c = p.centered();
    assert_eq!(c.ring_ends(), p.ring_ends());
    assert_eq!(c.openings(), p.openings());
    assert!(c.perimeter_centroid().norm() < 1e-4);
    assert!(c.validate().is_ok());
}
