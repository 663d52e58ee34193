//! The two constructors of a plan with columns and doors. [`FloorPlan::from_parts`] takes
//! the wire form as it is (rings concatenated, ring ends, an opening mask) and only
//! validates it; [`FloorPlan::with_columns_and_doors`] takes what a plan file holds (an
//! outline and columns in either orientation, doors as segments lying on outline walls)
//! and builds that form: the outline counter-clockwise, each column clockwise, and each
//! door's two jambs inserted into its wall with the edge between them an opening.

use super::{closest_on_segment, FloorPlan, PlanError, MAX_RINGS, MAX_VERTICES, MIN_EDGE_LENGTH};
use crate::world::geometry::{cross, length, Vec2};
use heapless::Vec as HVec;

/// Ring ends, as the plan stores them.
type RingEnds = HVec<u8, MAX_RINGS>;

impl FloorPlan {
    /// Validates the wire form: every ring's `[x, y]` vertices concatenated (the outline
    /// counter-clockwise first, then each column clockwise), the exclusive end of each ring
    /// (empty, or one entry equal to the vertex count, for the outline alone), and the
    /// door openings as a bit mask over the walls. Nothing is reoriented.
    pub fn from_parts(
        vertices: &[[f32; 2]],
        rings: &[u8],
        openings: u64,
    ) -> Result<Self, PlanError> {
        let vertices = HVec::from_slice(vertices).map_err(|_| PlanError::TooManyVertices)?;
        let mut ends: RingEnds = HVec::from_slice(rings).map_err(|_| PlanError::TooManyRings)?;
        // One ring is stored as no ring ends: the form a plain plan always had.
        if ends.len() == 1 && ends.first().map(|&e| e as usize) == Some(vertices.len()) {
            ends.clear();
        }
        let plan = FloorPlan {
            vertices,
            rings: ends,
            openings,
        };
        plan.validate()?;
        Ok(plan)
    }

    /// Builds a plan from a plan file's parts: the `outline` and the `columns` in either
    /// orientation (each is normalised: outline counter-clockwise, columns clockwise), and
    /// `doors` as segments lying on outline walls within `tolerance` metres. Each door's
    /// ends become two vertices (jambs) of its wall, the edge between them an opening; an
    /// end within [`MIN_EDGE_LENGTH`] of a corner uses the corner itself. A door on no
    /// outline wall is [`PlanError::DoorOffWalls`]; the rest is [`FloorPlan::validate`]'s.
    pub fn with_columns_and_doors(
        outline: &[Vec2],
        columns: &[&[Vec2]],
        doors: &[(Vec2, Vec2)],
        tolerance: f32,
    ) -> Result<Self, PlanError> {
        if columns.len() + 1 > MAX_RINGS {
            return Err(PlanError::TooManyRings);
        }
        let total = outline.len() + columns.iter().map(|c| c.len()).sum::<usize>();
        if total + 2 * doors.len() > MAX_VERTICES {
            return Err(PlanError::TooManyVertices);
        }
        if outline.len() < 3 {
            return Err(PlanError::TooFewVertices);
        }
        let ccw = ring_area(outline) >= 0.0;
        let corner = |k: usize| {
            if ccw {
                outline[k]
            } else {
                outline[outline.len() - 1 - k]
            }
        };
        // Each door as (wall, t along it of the near jamb, of the far jamb), in wall order.
        let mut placed: HVec<(usize, f32, f32), { MAX_VERTICES / 2 }> = HVec::new();
        for (d, &(p, q)) in doors.iter().enumerate() {
            let wall = (0..outline.len()).find(|&k| {
                let (a, b) = (corner(k), corner((k + 1) % outline.len()));
                length(closest_on_segment(p, a, b) - p) <= tolerance
                    && length(closest_on_segment(q, a, b) - q) <= tolerance
            });
            let Some(k) = wall else {
                return Err(PlanError::DoorOffWalls(d as u8));
            };
            let (a, b) = (corner(k), corner((k + 1) % outline.len()));
            let e = b - a;
            let l2 = e.dot(&e);
            let along = |v: Vec2| ((v - a).dot(&e) / l2).clamp(0.0, 1.0);
            let (t0, t1) = (along(p), along(q));
            let _ = placed.push((k, t0.min(t1), t0.max(t1)));
        }
        placed.sort_unstable_by(|x, y| {
            (x.0, x.1)
                .partial_cmp(&(y.0, y.1))
                .unwrap_or(core::cmp::Ordering::Equal)
        });
        let mut vertices: HVec<[f32; 2], MAX_VERTICES> = HVec::new();
        let mut openings = 0u64;
        let push = |v: Vec2, vs: &mut HVec<[f32; 2], MAX_VERTICES>| {
            vs.push([v.x, v.y]).map_err(|_| PlanError::TooManyVertices)
        };
        for k in 0..outline.len() {
            let (a, b) = (corner(k), corner((k + 1) % outline.len()));
            let wall_len = length(b - a);
            push(a, &mut vertices)?;
            for &(_, t0, t1) in placed.iter().filter(|x| x.0 == k) {
                if t0 * wall_len >= MIN_EDGE_LENGTH {
                    push(a + (b - a) * t0, &mut vertices)?;
                }
                // The edge starting at the last vertex pushed is the opening.
                let start = vertices.len() - 1;
                if start < 64 {
                    openings |= 1u64 << start;
                }
                if (1.0 - t1) * wall_len >= MIN_EDGE_LENGTH {
                    push(a + (b - a) * t1, &mut vertices)?;
                }
            }
        }
        let mut rings: RingEnds = HVec::new();
        if !columns.is_empty() {
            let _ = rings.push(vertices.len() as u8);
        }
        for column in columns {
            let cw = ring_area(column) <= 0.0;
            for k in 0..column.len() {
                let v = if cw {
                    column[k]
                } else {
                    column[column.len() - 1 - k]
                };
                push(v, &mut vertices)?;
            }
            let _ = rings.push(vertices.len() as u8);
        }
        let plan = FloorPlan {
            vertices,
            rings,
            openings,
        };
        plan.validate()?;
        Ok(plan)
    }
}

/// Signed area of a ring given as points (positive counter-clockwise).
fn ring_area(ring: &[Vec2]) -> f32 {
    let n = ring.len();
    (0..n)
        .map(|k| cross(ring[k], ring[(k + 1) % n]))
        .sum::<f32>()
        * 0.5
}
