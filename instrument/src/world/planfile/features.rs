//! Columns and doors of a plan file's room: what the readers found (columns as rings of
//! the room, doors as segments anywhere in the file) taken through the outline's own shift
//! and scale into the model's metres, the doors kept that lie on this room's outline, and
//! the whole built and validated by [`FloorPlan::with_columns_and_doors`], its errors put in
//! the user's words.

use activesense_core::limits::MAX_RINGS;
use activesense_core::world::floorplan::closest_on_segment;
use activesense_core::world::geometry::{v2, Vec2};
use activesense_core::{FloorPlan, PlanError, MAX_VERTICES};

/// How far (m, after the file's units are applied) a door's ends may lie from an outline
/// wall and still be a door in it: 2 cm, a drawing's usual snapping slack.
pub const DOOR_TOLERANCE: f32 = 0.02;

/// A door as read from a file: a label for messages, its two ends (file units), and the room
/// it names, if any (a room name or 0-based index, as `--room`).
pub(super) struct RawDoor {
    pub label: String,
    pub ends: [[f64; 2]; 2],
    pub room: Option<String>,
}

/// The room `outline` (oriented, shifted by `centre`, scaled; model metres) with its
/// `columns` and those of `doors` that lie on it (file units, shifted and scaled the same
/// way); returns the plan and, per door, whether it lies on this room.
pub(super) fn with_features(
    outline: &[Vec2],
    columns: &[Vec<[f64; 2]>],
    doors: &[&RawDoor],
    centre: [f64; 2],
    scale: f64,
) -> Result<(FloorPlan, Vec<bool>), String> {
    let to_model = |p: [f64; 2]| {
        v2(
            ((p[0] - centre[0]) * scale) as f32,
            ((p[1] - centre[1]) * scale) as f32,
        )
    };
    if columns.len() > MAX_RINGS - 1 {
        return Err(format!(
            "{} columns; a room may have at most {} (docs/PLANS.md, \"Limits\")",
            columns.len(),
            MAX_RINGS - 1
        ));
    }
    let mut rings: Vec<Vec<Vec2>> = Vec::with_capacity(columns.len());
    for (k, c) in columns.iter().enumerate() {
        let mut c = c.clone();
        if c.len() >= 2 && c.first() == c.last() {
            c.pop();
        }
        if c.len() < 3 {
            return Err(format!(
                "column {k} has {} distinct vertices; a column needs at least 3",
                c.len()
            ));
        }
        if c.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
            return Err(format!("column {k} has a non-finite coordinate"));
        }
        rings.push(c.into_iter().map(to_model).collect());
    }
    let on_wall = |p: Vec2, a: Vec2, b: Vec2| (closest_on_segment(p, a, b) - p).norm();
    let mut used = Vec::with_capacity(doors.len());
    let mut segs = Vec::new();
    for d in doors {
        let (p, q) = (to_model(d.ends[0]), to_model(d.ends[1]));
        let n = outline.len();
        let on = (0..n).any(|k| {
            let (a, b) = (outline[k], outline[(k + 1) % n]);
            on_wall(p, a, b) <= DOOR_TOLERANCE && on_wall(q, a, b) <= DOOR_TOLERANCE
        });
        if d.room.is_some() && !on {
            return Err(format!(
                "{} names this room but lies on none of its walls (within {} cm)",
                d.label,
                DOOR_TOLERANCE * 100.0
            ));
        }
        used.push(on);
        if on {
            segs.push((p, q));
        }
    }
    let total = outline.len() + rings.iter().map(Vec::len).sum::<usize>() + 2 * segs.len();
    if total > MAX_VERTICES {
        return Err(format!(
            "{total} vertices in all (outline {}, columns {}, two per door); a room may have at most {MAX_VERTICES} (docs/PLANS.md, \"Limits\")",
            outline.len(),
            total - outline.len() - 2 * segs.len()
        ));
    }
    let refs: Vec<&[Vec2]> = rings.iter().map(Vec::as_slice).collect();
    let plan =
        FloorPlan::with_columns_and_doors(outline, &refs, &segs, DOOR_TOLERANCE).map_err(|pe| {
            match pe {
                PlanError::ColumnOutsideRoom(r) => {
                    format!("column {} is not inside the room", r.saturating_sub(1))
                }
                PlanError::SelfIntersection(..) => {
                    "a column touches or crosses a wall or another column, or two doors overlap"
                        .to_string()
                }
                PlanError::ZeroLengthEdge(_) => {
                    "a column has a wall shorter than 1 cm, or two doors are less than 1 cm apart"
                        .to_string()
                }
                PlanError::CollinearVertex(_) => {
                    "a column vertex lies on the line through its neighbours (remove it)"
                        .to_string()
                }
                PlanError::AdjacentOpenings(_) => {
                    "two doors touch (no wall between them)".to_string()
                }
                other => format!("columns and doors: {other}"),
            }
        })?;
    Ok((plan, used))
}

#[cfg(test)]
mod tests {
    use super::super::{load_plan, load_rooms, LoadOptions};
    use std::path::PathBuf;

    fn fixture(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../cli/tests/fixtures/plans")
            .join(name)
    }

    /// Every vertex of the plan in the file's coordinates (metres, rounded to the mm).
    fn file_points(named: &super::super::NamedPlan, ring: usize) -> Vec<[f64; 2]> {
        named
            .plan
            .ring(ring)
            .map(|i| {
                let v = named.plan.vertex(i);
                let p = named.frame.to_plan([v.x as f64, v.y as f64]);
                let m = named.frame.scale;
                [
                    (p[0] * m * 1000.0).round() / 1000.0,
                    (p[1] * m * 1000.0).round() / 1000.0,
                ]
            })
            .collect()
    }

    /// The room of both fixtures: 6 × 4 m, a 0.5 m column at (4, 1.5), a door in the bottom
    /// wall from x = 1 to 1.9 and one in a side wall.
    fn check_room(named: &super::super::NamedPlan, side_door: [[f64; 2]; 2]) {
        let p = &named.plan;
        assert_eq!(p.ring_count(), 2, "{p:?}");
        assert_eq!(p.openings().count_ones(), 2, "{p:?}");
        let mut column = file_points(named, 1);
        column.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(column, vec![[4.0, 1.5], [4.0, 2.0], [4.5, 1.5], [4.5, 2.0]]);
        assert!(p.ring_area(1) < 0.0, "the column runs clockwise");
        let outline = file_points(named, 0);
        let door_at = |a: [f64; 2], b: [f64; 2]| {
            (0..outline.len()).any(|k| {
                let (s, e) = (outline[k], outline[(k + 1) % outline.len()]);
                p.is_opening(k) && ((s == a && e == b) || (s == b && e == a))
            })
        };
        // The jambs are projected onto the wall (the drawn door was 1 cm off it).
        assert!(door_at([1.0, 0.0], [1.9, 0.0]), "{outline:?}");
        assert!(door_at(side_door[0], side_door[1]), "{outline:?}");
    }

    #[test]
    fn geojson_holes_are_columns_and_doors_and_imdf_openings_are_doors() {
        let named = load_plan(
            &fixture("features/column-door.geojson"),
            &LoadOptions::default(),
        )
        .unwrap()
        .plan;
        assert_eq!(named.name, "column-door.geojson", "the doors are not rooms");
        check_room(&named, [[0.0, 2.5], [0.0, 3.4]]);
        // offices.geojson: office-2's hole is a column now.
        let rooms = load_rooms(&fixture("offices.geojson"), &LoadOptions::default()).unwrap();
        assert_eq!(rooms[1].plan.plan.ring_count(), 2);
        assert!(rooms[1].warnings.iter().all(|w| !w.contains("hole")));
    }

    #[test]
    fn dxf_column_and_door_layers() {
        let named = load_plan(
            &fixture("features/column-door.dxf"),
            &LoadOptions::default(),
        )
        .unwrap()
        .plan;
        assert_eq!(named.frame.unit, "mm");
        check_room(&named, [[6.0, 1.0], [6.0, 1.8]]);
    }

    #[test]
    fn bad_columns_and_doors_are_refused_in_words() {
        let dir = std::env::temp_dir().join(format!("activesense-features-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, text: String| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        let room = |holes: &str, extra: &str| {
            format!(
                r#"{{"type": "FeatureCollection", "features": [
                {{"type": "Feature", "properties": {{"name": "r"}}, "geometry": {{"type": "Polygon",
                  "coordinates": [[[0, 0], [6, 0], [6, 4], [0, 4]]{holes}]}}}}{extra}]}}"#
            )
        };
        let why = |p: PathBuf| load_rooms(&p, &LoadOptions::default()).unwrap_err().reason;
        let off = write(
            "off.geojson",
            room(
                "",
                r#", {"type": "Feature", "properties": {"kind": "door"},
                  "geometry": {"type": "LineString", "coordinates": [[1, 1], [2, 1]]}}"#,
            ),
        );
        assert!(why(off).contains("lies on no room's outline (within 2 cm)"));
        let outside = write("outside.geojson", room(", [[7, 1], [8, 1], [8, 2]]", ""));
        assert_eq!(why(outside), "column 0 is not inside the room");
        let crossing = write(
            "crossing.geojson",
            room(", [[5, 1], [7, 1], [7, 2], [5, 2]]", ""),
        );
        let crossing = why(crossing);
        assert!(crossing.contains("crosses a wall"), "{crossing}");
        let nine: String = (0..9)
            .map(|k| {
                let x = 0.3 + 0.6 * k as f64;
                format!(", [[{x}, 1], [{}, 1], [{}, 1.3]]", x + 0.3, x + 0.3)
            })
            .collect();
        let many = write("many.geojson", room(&nine, ""));
        assert!(why(many).contains("9 columns; a room may have at most 8"));
    }
}
