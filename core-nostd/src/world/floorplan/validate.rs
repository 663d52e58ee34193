//! The invariants of a [`FloorPlan`], checked once on construction and again after
//! `Deserialize` (which bypasses the constructors): finite, sane extent, walls of at least
//! [`MIN_EDGE_LENGTH`], no collinear vertex (door jambs excepted), no two walls touching
//! that do not share a vertex (across rings too), a counter-clockwise outline, clockwise
//! columns inside it, and openings only on outline walls, never two in a row. A plain
//! plan (one ring, no opening) is checked in exactly the order it always was, so it gets
//! the same error for the same input.

use super::{
    segments_touch, FloorPlan, PlanError, COLLINEAR_SIN_TOLERANCE, MAX_EXTENT, MAX_RINGS,
    MIN_EDGE_LENGTH, MIN_EXTENT,
};
use crate::world::geometry::{cross, length};
use crate::world::math::abs;

impl FloorPlan {
    /// Re-checks every invariant; `Deserialize` bypasses [`FloorPlan::new`], so data
    /// decoded from outside must pass through here (or [`FloorPlan::from_raw`],
    /// [`FloorPlan::from_parts`]).
    pub fn validate(&self) -> Result<(), PlanError> {
        let n = self.vertices.len();
        if n < 3 {
            return Err(PlanError::TooFewVertices);
        }
        self.check_rings()?;
        for (i, v) in self.vertices.iter().enumerate() {
            if !v[0].is_finite() || !v[1].is_finite() {
                return Err(PlanError::NonFiniteCoordinate(i as u8));
            }
        }
        let (lo, hi) = self.bounds();
        let ext = hi - lo;
        if !(ext.x >= MIN_EXTENT
            && ext.y >= MIN_EXTENT
            && ext.x <= MAX_EXTENT
            && ext.y <= MAX_EXTENT)
        {
            return Err(PlanError::BadExtent);
        }
        for i in 0..n {
            let (a, b) = self.wall(i);
            if length(b - a) < MIN_EDGE_LENGTH {
                return Err(PlanError::ZeroLengthEdge(i as u8));
            }
        }
        for i in 0..n {
            let p = self.prev(i);
            // A door's jamb lies on the line of its wall: the opening is what makes it a
            // corner of the solid walls.
            if self.is_opening(p) || self.is_opening(i) {
                continue;
            }
            let a = self.vertex(p);
            let b = self.vertex(i);
            let c = self.vertex(self.next(i));
            let (d0, d1) = (b - a, c - b);
            let s = cross(d0, d1) / (length(d0) * length(d1));
            if abs(s) < COLLINEAR_SIN_TOLERANCE {
                return Err(PlanError::CollinearVertex(i as u8));
            }
        }
        for i in 0..n {
            for j in (i + 1)..n {
                // Adjacent edges share a vertex by construction; skip them.
                if j == self.next(i) || i == self.next(j) {
                    continue;
                }
                let (a, b) = self.wall(i);
                let (c, d) = self.wall(j);
                if segments_touch(a, b, c, d) {
                    return Err(PlanError::SelfIntersection(i as u8, j as u8));
                }
            }
        }
        if self.is_plain() {
            if self.signed_area() <= 0.0 {
                return Err(PlanError::Clockwise);
            }
            return Ok(());
        }
        if self.ring_area(0) <= 0.0 {
            return Err(PlanError::Clockwise);
        }
        self.check_columns()?;
        self.check_openings()
    }

    /// The ring ends rise strictly to the vertex count, each ring has three vertices.
    fn check_rings(&self) -> Result<(), PlanError> {
        if self.rings.is_empty() {
            return Ok(());
        }
        if self.rings.len() > MAX_RINGS {
            return Err(PlanError::TooManyRings);
        }
        let mut start = 0usize;
        for (r, &e) in self.rings.iter().enumerate() {
            let e = e as usize;
            if e <= start {
                return Err(PlanError::BadRingEnds);
            }
            if e - start < 3 {
                return Err(PlanError::RingTooSmall(r as u8));
            }
            start = e;
        }
        if start != self.vertices.len() {
            return Err(PlanError::BadRingEnds);
        }
        Ok(())
    }

    /// Every column runs clockwise and lies inside the outline and outside every other
    /// column. No two walls touch (checked before), so a column is wholly inside or wholly
    /// outside any other ring and its first vertex decides.
    fn check_columns(&self) -> Result<(), PlanError> {
        for r in 1..self.ring_count() {
            if self.ring_area(r) >= 0.0 {
                return Err(PlanError::ColumnNotClockwise(r as u8));
            }
            let p = self.vertex(self.ring(r).start);
            for other in 0..self.ring_count() {
                if other == r {
                    continue;
                }
                let inside = self.ring_contains(other, p);
                if inside != (other == 0) {
                    return Err(PlanError::ColumnOutsideRoom(r as u8));
                }
            }
        }
        Ok(())
    }

    /// Openings only on outline walls, never two adjacent ones.
    fn check_openings(&self) -> Result<(), PlanError> {
        let outline = self.ring(0);
        for i in 0..64usize {
            if self.openings & (1u64 << i) == 0 {
                continue;
            }
            if !outline.contains(&i) {
                return Err(PlanError::OpeningNotOnOutline(i as u8));
            }
            if self.is_opening(self.next(i)) {
                return Err(PlanError::AdjacentOpenings(i as u8));
            }
        }
        Ok(())
    }

    /// Crossing-number test against ring `r` alone.
    fn ring_contains(&self, r: usize, p: crate::world::geometry::Vec2) -> bool {
        let mut inside = false;
        for i in self.ring(r) {
            let (a, b) = self.wall(i);
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }
}
