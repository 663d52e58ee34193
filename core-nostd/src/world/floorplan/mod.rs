//! The polygonal floor-plan model (paper §3, §4.1) and the geometric queries every other
//! module builds on: ray casting (the EDM range sensor), point-in-polygon (the GHT
//! "agent inside the model" precondition), nearest point on the outline (ICP
//! correspondences), outward normals (incidence checks), perimeter length and perimeter
//! centroid (the model frame's origin), and the topological scan (visible wall junctions).
//!
//! A [`FloorPlan`] is a room: a simple, counter-clockwise outline, up to eight columns
//! inside it (each a clockwise ring, so the room lies on the left of every wall and the
//! outward normal of every wall points out of the room), and door openings on outline walls
//! (an opening closes the room for point-in-room tests, but the EDM sees through it). All
//! rings share [`MAX_VERTICES`] vertices. A plan is validated once, on construction
//! ([`validate`]); every query afterwards may assume a valid plan. Invalid input (a plan
//! arriving over the serial link, a bad file) is a [`PlanError`], never a panic. A plain
//! plan (one ring, no opening) runs exactly the arithmetic it ran before rings existed.

use crate::world::geometry::{cross, length, v2, Vec2};
use crate::world::math::{abs, acos, atan2, wrap_angle};
use heapless::Vec as HVec;
use serde::{Deserialize, Serialize};

mod build;
mod validate;

/// Fixed ring capacity of a floor-plan: the outline and up to eight columns.
pub use crate::limits::MAX_RINGS;
/// Fixed vertex capacity of a floor-plan, all rings together (the generator uses at most 32).
pub use crate::limits::MAX_VERTICES;
/// Shortest accepted wall (m).
pub const MIN_EDGE_LENGTH: f32 = 0.01;
/// Smallest accepted bounding-box side (m).
pub const MIN_EXTENT: f32 = 0.5;
/// Largest accepted bounding-box side (m); well beyond any EDM's range.
pub const MAX_EXTENT: f32 = 500.0;
/// |sin| of the angle between consecutive edges below which they count as collinear.
pub const COLLINEAR_SIN_TOLERANCE: f32 = 1e-4;

/// Why an outline is not a valid floor-plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlanError {
    /// Fewer than three vertices.
    TooFewVertices,
    /// More than [`MAX_VERTICES`] vertices.
    TooManyVertices,
    /// A coordinate is NaN or infinite (vertex index).
    NonFiniteCoordinate(u8),
    /// Bounding box smaller than [`MIN_EXTENT`] or larger than [`MAX_EXTENT`].
    BadExtent,
    /// Edge starting at this vertex is shorter than [`MIN_EDGE_LENGTH`].
    ZeroLengthEdge(u8),
    /// This vertex lies on the straight line through its neighbours (redundant, or a spike).
    CollinearVertex(u8),
    /// Two non-adjacent edges (by their start vertices) touch or cross.
    SelfIntersection(u8, u8),
    /// The vertices run clockwise (negative signed area).
    Clockwise,
    /// More than [`MAX_RINGS`] rings (the outline and eight columns).
    TooManyRings,
    /// The ring ends do not rise strictly to the vertex count.
    BadRingEnds,
    /// This ring (0 = the outline, then the columns) has fewer than three vertices.
    RingTooSmall(u8),
    /// This column ring (1-based ring index) is not inside the room (it lies outside the
    /// outline, or inside another column).
    ColumnOutsideRoom(u8),
    /// This column ring runs counter-clockwise (the wire form wants columns clockwise).
    ColumnNotClockwise(u8),
    /// This wall is marked as an opening but is not an outline wall (or does not exist).
    OpeningNotOnOutline(u8),
    /// This wall and the next are both openings (a door needs a jamb between them).
    AdjacentOpenings(u8),
    /// This door (0-based, in the order given) lies on no outline wall within the tolerance.
    DoorOffWalls(u8),
}

impl core::fmt::Display for PlanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PlanError::TooFewVertices => write!(f, "a floor-plan needs at least 3 vertices"),
            PlanError::TooManyVertices => {
                write!(f, "a floor-plan may have at most {MAX_VERTICES} vertices")
            }
            PlanError::NonFiniteCoordinate(i) => write!(f, "vertex {i} has a NaN/inf coordinate"),
            PlanError::BadExtent => write!(
                f,
                "bounding box must be between {MIN_EXTENT} m and {MAX_EXTENT} m on each side"
            ),
            PlanError::ZeroLengthEdge(i) => {
                write!(f, "edge {i} is shorter than {MIN_EDGE_LENGTH} m")
            }
            PlanError::CollinearVertex(i) => {
                write!(f, "vertex {i} is collinear with its neighbours")
            }
            PlanError::SelfIntersection(i, j) => write!(f, "edges {i} and {j} intersect"),
            PlanError::Clockwise => write!(f, "vertices must run counter-clockwise"),
            PlanError::TooManyRings => {
                write!(f, "a floor-plan may have at most {} columns", MAX_RINGS - 1)
            }
            PlanError::BadRingEnds => {
                write!(f, "the ring ends must rise strictly to the vertex count")
            }
            PlanError::RingTooSmall(r) => write!(f, "ring {r} has fewer than 3 vertices"),
            PlanError::ColumnOutsideRoom(r) => {
                write!(f, "column {r} is not inside the room")
            }
            PlanError::ColumnNotClockwise(r) => {
                write!(f, "column {r} must run clockwise")
            }
            PlanError::OpeningNotOnOutline(i) => {
                write!(f, "wall {i} is an opening but not an outline wall")
            }
            PlanError::AdjacentOpenings(i) => {
                write!(f, "walls {i} and the next are both openings")
            }
            PlanError::DoorOffWalls(d) => write!(f, "door {d} lies on no outline wall"),
        }
    }
}

/// The first wall a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Distance from the ray origin to the hit point (m).
    pub range: f32,
    /// Index of the wall (edge `i` runs from vertex `i` to the next vertex of its ring).
    pub wall: usize,
    /// Angle between the ray and the wall's outward normal, in [0, π/2] for hits from
    /// inside the room (0 = perpendicular hit).
    pub incidence: f32,
    /// The hit point.
    pub point: Vec2,
}

/// The closest point of the outline to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearestPoint {
    /// The point on the outline.
    pub point: Vec2,
    /// Wall it lies on.
    pub wall: usize,
    /// Distance from the query point (m).
    pub distance: f32,
}

/// A validated room: a counter-clockwise outline, clockwise columns, door openings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorPlan {
    /// Every ring's vertices, the outline first, then each column.
    vertices: HVec<[f32; 2], MAX_VERTICES>,
    /// Exclusive end index of each ring; empty for a plan of one ring (the form every plan
    /// had before columns, so older JSON files load and write unchanged).
    #[serde(default, skip_serializing_if = "HVec::is_empty")]
    rings: HVec<u8, MAX_RINGS>,
    /// Bit `i` set: wall `i` is a door opening (a gap, not a wall).
    #[serde(default, skip_serializing_if = "is_zero")]
    openings: u64,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

impl FloorPlan {
    /// A plan with no vertices, for `static` storage before a real plan is copied in (it
    /// is not valid: [`FloorPlan::validate`] refuses it and ray casts meet nothing).
    pub const fn empty() -> Self {
        FloorPlan {
            vertices: HVec::new(),
            rings: HVec::new(),
            openings: 0,
        }
    }

    /// Validates `vertices` (counter-clockwise, simple, finite, sane) into a plan.
    pub fn new(vertices: &[Vec2]) -> Result<Self, PlanError> {
        let mut raw: HVec<[f32; 2], MAX_VERTICES> = HVec::new();
        if vertices.len() > MAX_VERTICES {
            return Err(PlanError::TooManyVertices);
        }
        for v in vertices {
            // Capacity checked above.
            let _ = raw.push([v.x, v.y]);
        }
        Self::from_raw(raw)
    }

    /// Like [`FloorPlan::new`], but accepts either orientation and reverses a clockwise
    /// outline (convenient for files drawn by people).
    pub fn new_any_orientation(vertices: &[Vec2]) -> Result<Self, PlanError> {
        match Self::new(vertices) {
            Err(PlanError::Clockwise) => {
                let mut raw: HVec<[f32; 2], MAX_VERTICES> = HVec::new();
                for v in vertices.iter().rev() {
                    let _ = raw.push([v.x, v.y]);
                }
                Self::from_raw(raw)
            }
            other => other,
        }
    }

    /// Validates raw `[x, y]` pairs of one counter-clockwise ring without openings.
    pub fn from_raw(vertices: HVec<[f32; 2], MAX_VERTICES>) -> Result<Self, PlanError> {
        let plan = FloorPlan {
            vertices,
            rings: HVec::new(),
            openings: 0,
        };
        plan.validate()?;
        Ok(plan)
    }

    /// Number of vertices of all rings (= number of walls, openings included).
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// True for a plan of one ring without openings (every plan before columns and doors).
    pub fn is_plain(&self) -> bool {
        self.rings.is_empty() && self.openings == 0
    }

    /// Number of rings (1 = the outline alone).
    pub fn ring_count(&self) -> usize {
        self.rings.len().max(1)
    }

    /// Vertex index range of ring `r` (0 = the outline, then the columns); empty when
    /// there is no such ring.
    pub fn ring(&self, r: usize) -> core::ops::Range<usize> {
        let n = self.vertices.len();
        if self.rings.is_empty() {
            return if r == 0 { 0..n } else { n..n };
        }
        let end = |k: usize| self.rings.get(k).map_or(n, |&e| (e as usize).min(n));
        let start = if r == 0 { 0 } else { end(r - 1) };
        match self.rings.get(r) {
            Some(_) => start.min(end(r))..end(r),
            None => n..n,
        }
    }

    /// The exclusive end index of every ring (the wire form); empty for a one-ring plan.
    pub fn ring_ends(&self) -> &[u8] {
        &self.rings
    }

    /// The door openings as a bit mask over the walls (the wire form).
    pub fn openings(&self) -> u64 {
        self.openings
    }

    /// True when wall `i` is a door opening: rays pass through it, no reading pairs with it.
    #[inline]
    pub fn is_opening(&self, i: usize) -> bool {
        i < 64 && self.openings & (1u64 << i) != 0
    }

    /// The walls the EDM can hit (every wall but the openings), in index order.
    pub fn solid_walls(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.len()).filter(move |&i| !self.is_opening(i))
    }

    /// The vertex after `i` in `i`'s ring (indices wrap around the whole list first).
    #[inline]
    pub fn next(&self, i: usize) -> usize {
        if self.rings.is_empty() {
            return (i + 1) % self.vertices.len().max(1);
        }
        self.next_in_rings(i)
    }

    /// [`FloorPlan::next`] for a plan of several rings: out of line, so the one-ring path
    /// every hot loop inlines stays as small as it was (the firmware's flash).
    #[inline(never)]
    fn next_in_rings(&self, i: usize) -> usize {
        let n = self.vertices.len();
        let i = i % n.max(1);
        let ring = self.ring_of(i);
        if i + 1 >= ring.end {
            ring.start
        } else {
            i + 1
        }
    }

    /// The vertex before `i` in `i`'s ring.
    #[inline]
    pub fn prev(&self, i: usize) -> usize {
        let n = self.vertices.len();
        if self.rings.is_empty() {
            return (i + n.max(1) - 1) % n.max(1);
        }
        let i = i % n.max(1);
        let ring = self.ring_of(i);
        if i <= ring.start {
            ring.end.max(ring.start + 1) - 1
        } else {
            i - 1
        }
    }

    /// The ring holding vertex `i` (the last ring for an out-of-range index).
    fn ring_of(&self, i: usize) -> core::ops::Range<usize> {
        let n = self.vertices.len();
        let mut start = 0;
        for &e in self.rings.iter() {
            let e = (e as usize).min(n);
            if i < e {
                return start..e;
            }
            start = e;
        }
        start.min(n)..n
    }

    /// Always false for a valid plan; present for API completeness.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    /// Vertex `i` (indices wrap around).
    #[inline]
    pub fn vertex(&self, i: usize) -> Vec2 {
        let v = self.vertices[i % self.vertices.len()];
        v2(v[0], v[1])
    }

    /// The raw `[x, y]` vertex list.
    pub fn raw(&self) -> &[[f32; 2]] {
        &self.vertices
    }

    /// Iterator over the vertices.
    pub fn vertices(&self) -> impl Iterator<Item = Vec2> + '_ {
        self.vertices.iter().map(|v| v2(v[0], v[1]))
    }

    /// Wall `i` as `(start, end)`: from vertex `i` to the next vertex of its ring.
    #[inline]
    pub fn wall(&self, i: usize) -> (Vec2, Vec2) {
        if self.rings.is_empty() {
            return (self.vertex(i), self.vertex(i + 1));
        }
        (self.vertex(i), self.vertex(self.next(i)))
    }

    /// Outward unit normal of wall `i`. The room is on the left of every wall (outline
    /// counter-clockwise, columns clockwise), so the normal pointing out of the room (into
    /// a column, for a column's wall) is the edge direction turned right.
    pub fn outward_normal(&self, i: usize) -> Vec2 {
        let (a, b) = self.wall(i);
        let d = b - a;
        v2(d.y, -d.x) / length(d)
    }

    /// Axis-aligned bounding box `(min, max)`.
    pub fn bounds(&self) -> (Vec2, Vec2) {
        let mut lo = v2(f32::INFINITY, f32::INFINITY);
        let mut hi = v2(f32::NEG_INFINITY, f32::NEG_INFINITY);
        for v in self.vertices() {
            lo = v2(lo.x.min(v.x), lo.y.min(v.y));
            hi = v2(hi.x.max(v.x), hi.y.max(v.y));
        }
        (lo, hi)
    }

    /// Signed area (shoelace over every ring): positive for a valid plan, the room's floor
    /// area (the columns' clockwise rings subtract theirs).
    pub fn signed_area(&self) -> f32 {
        let mut s = 0.0;
        for i in 0..self.len() {
            let (a, b) = self.wall(i);
            s += cross(a, b);
        }
        0.5 * s
    }

    /// Signed area of ring `r` alone (positive counter-clockwise).
    pub fn ring_area(&self, r: usize) -> f32 {
        let mut s = 0.0;
        for i in self.ring(r) {
            let (a, b) = self.wall(i);
            s += cross(a, b);
        }
        0.5 * s
    }

    /// Length of the solid walls (m): the wall surface the instrument can measure.
    pub fn perimeter(&self) -> f32 {
        self.solid_walls()
            .map(|i| {
                let (a, b) = self.wall(i);
                length(b - a)
            })
            .sum()
    }

    /// Perimeter centroid: the centre of mass of the solid walls (columns included,
    /// openings not) with uniform density along them. This is the model frame's origin
    /// (paper §3.2, §3.4).
    pub fn perimeter_centroid(&self) -> Vec2 {
        let mut acc = v2(0.0, 0.0);
        let mut total = 0.0;
        for i in self.solid_walls() {
            let (a, b) = self.wall(i);
            let l = length(b - a);
            acc += (a + b) * (0.5 * l);
            total += l;
        }
        acc / total
    }

    /// The same outline translated so that its perimeter centroid is the origin.
    pub fn centered(&self) -> FloorPlan {
        self.translated(-self.perimeter_centroid())
    }

    /// The plan translated by `d` (validity is preserved by translation).
    pub fn translated(&self, d: Vec2) -> FloorPlan {
        let mut plan = self.clone();
        for v in plan.vertices.iter_mut() {
            v[0] += d.x;
            v[1] += d.y;
        }
        plan
    }

    /// Largest distance from the origin to any vertex (the model's "radius" when centred).
    pub fn max_radius(&self) -> f32 {
        self.vertices().map(length).fold(0.0, f32::max)
    }

    /// Point-in-room by crossing number over every edge of every ring, openings included
    /// (a door does not open the room to the outside; a point inside a column is outside
    /// the room). Points exactly on a wall may go either way.
    pub fn contains(&self, p: Vec2) -> bool {
        let mut inside = false;
        let n = self.len();
        for i in 0..n {
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

    /// Casts a ray from `origin` along the unit direction `dir` and returns the first solid
    /// wall (outline or column) it meets at a distance greater than `1e-6` m, or `None` when
    /// it meets none (an origin outside the room looking away from it, or a ray leaving
    /// through a door). A door opening is not a wall: the ray passes through it.
    pub fn ray_cast(&self, origin: Vec2, dir: Vec2) -> Option<RayHit> {
        let (i, t) = self.nearest_wall_along(origin, dir)?;
        let n = self.outward_normal(i);
        let c = dir.x * n.x + dir.y * n.y;
        Some(RayHit {
            range: t,
            wall: i,
            incidence: acos(abs(c)),
            point: origin + dir * t,
        })
    }

    /// The wall a ray meets first and the distance along the ray (the first wall on
    /// equal distances): what [`FloorPlan::ray_cast`] and [`FloorPlan::first_hit`] share.
    fn nearest_wall_along(&self, origin: Vec2, dir: Vec2) -> Option<(usize, f32)> {
        let mut best: Option<(usize, f32)> = None;
        for i in self.solid_walls() {
            let (a, b) = self.wall(i);
            let e = b - a;
            let denom = cross(dir, e);
            if abs(denom) < 1e-12 {
                continue; // parallel
            }
            let w = a - origin;
            let t = cross(w, e) / denom; // along the ray
            let u = cross(w, dir) / denom; // along the wall
            if t > 1e-6 && (0.0..=1.0).contains(&u) && best.is_none_or(|(_, h)| t < h) {
                best = Some((i, t));
            }
        }
        best
    }

    /// Closest point of the solid walls to `p` (never on a door opening).
    pub fn nearest_point(&self, p: Vec2) -> NearestPoint {
        let mut best = NearestPoint {
            point: self.vertex(0),
            wall: 0,
            distance: f32::INFINITY,
        };
        for i in self.solid_walls() {
            let (a, b) = self.wall(i);
            let q = closest_on_segment(p, a, b);
            let d = length(p - q);
            if d < best.distance {
                best = NearestPoint {
                    point: q,
                    wall: i,
                    distance: d,
                };
            }
        }
        best
    }

    /// True when the straight line from `from` to `to` crosses no wall before `to`
    /// (within `tolerance` metres of it). Used for wall-junction visibility. The same as
    /// "[`FloorPlan::first_hit`] along it is no nearer than `to`", decided at the first
    /// wall that blocks (tested against that form in `world::sightlines`, which answers
    /// many sight lines from one viewpoint with this test).
    pub fn visible(&self, from: Vec2, to: Vec2, tolerance: f32) -> bool {
        let d = to - from;
        let dist = length(d);
        if dist <= tolerance {
            return true;
        }
        let (dir, before) = (d / dist, dist - tolerance);
        !self.solid_walls().any(|i| {
            let (a, b) = self.wall(i);
            let (w, e) = (a - from, b - a);
            blocks((w, e, cross(w, e)), dir, before)
        })
    }

    /// Where a ray leaves the room through a door opening: the distance along it to the
    /// first opening it crosses before any solid wall, or `None` (a solid wall comes first,
    /// or the plan has no doors: one test of the mask). What the plan predicts there is
    /// not a range but "beyond this": the registration counts a reading at least that far
    /// as explained, and pairs it with no wall (`registration::beyond_door`).
    pub fn door_exit(&self, origin: Vec2, dir: Vec2) -> Option<f32> {
        if self.openings == 0 {
            return None;
        }
        let mut door: Option<f32> = None;
        for i in (0..self.len()).filter(|&i| self.is_opening(i)) {
            let (a, b) = self.wall(i);
            let e = b - a;
            let denom = cross(dir, e);
            if abs(denom) < 1e-12 {
                continue;
            }
            let w = a - origin;
            let t = cross(w, e) / denom;
            let u = cross(w, dir) / denom;
            if t > 1e-6 && (0.0..=1.0).contains(&u) && door.is_none_or(|h| t < h) {
                door = Some(t);
            }
        }
        let door = door?;
        match self.first_hit(origin, dir) {
            Some(wall) if wall <= door => None,
            _ => Some(door),
        }
    }

    /// The range of [`FloorPlan::ray_cast`]'s hit alone (the same arithmetic, without the
    /// incidence angle and hit point): the visibility test of every ICP correspondence
    /// needs no more.
    pub fn first_hit(&self, origin: Vec2, dir: Vec2) -> Option<f32> {
        self.nearest_wall_along(origin, dir).map(|(_, t)| t)
    }

    /// The topological scan (paper §3.1, §4.1): `N` binary pixels spanning `fov` radians
    /// centred on the scene-frame `bearing`, pixel 0 at the right (clockwise) edge. A pixel
    /// is set when a wall junction (a vertex of any ring, door jambs included) visible from
    /// `origin` lies in its angular bin. Bins are half-open `[lo, hi)` counter-clockwise.
    pub fn topological_scan<const N: usize>(
        &self,
        origin: Vec2,
        bearing: f32,
        fov: f32,
    ) -> [bool; N] {
        let mut pixels = [false; N];
        let half = 0.5 * fov;
        for v in self.vertices() {
            let d = v - origin;
            let rel = wrap_angle(atan2(d.y, d.x) - bearing);
            if rel < -half || rel >= half {
                continue;
            }
            if !self.visible(origin, v, 1e-3) {
                continue;
            }
            let k = ((rel + half) / fov * N as f32) as usize;
            pixels[k.min(N - 1)] = true;
        }
        pixels
    }
}

/// Closest point on segment `ab` to `p`.
pub fn closest_on_segment(p: Vec2, a: Vec2, b: Vec2) -> Vec2 {
    let ab = b - a;
    let l2 = ab.x * ab.x + ab.y * ab.y;
    if l2 <= 0.0 {
        return a;
    }
    let t = (((p - a).x * ab.x + (p - a).y * ab.y) / l2).clamp(0.0, 1.0);
    a + ab * t
}

/// Whether the ray along unit `dir` from a viewpoint crosses wall `a → b` at a distance in
/// `(1e-6, before)`, the wall given as `(a - viewpoint, b - a, their cross product)`: the
/// per-wall test of [`FloorPlan::visible`], with [`FloorPlan::first_hit`]'s arithmetic.
#[inline]
pub(crate) fn blocks((w, e, cross_we): (Vec2, Vec2, f32), dir: Vec2, before: f32) -> bool {
    let denom = cross(dir, e);
    if abs(denom) < 1e-12 {
        return false; // parallel
    }
    let t = cross_we / denom; // along the ray
    if !(t > 1e-6 && t < before) {
        return false;
    }
    let u = cross(w, dir) / denom; // along the wall
    (0.0..=1.0).contains(&u)
}

/// True when closed segments `ab` and `cd` share at least one point.
pub(crate) fn segments_touch(a: Vec2, b: Vec2, c: Vec2, d: Vec2) -> bool {
    let o1 = orient(a, b, c);
    let o2 = orient(a, b, d);
    let o3 = orient(c, d, a);
    let o4 = orient(c, d, b);
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && on_segment(a, b, c))
        || (o2 == 0.0 && on_segment(a, b, d))
        || (o3 == 0.0 && on_segment(c, d, a))
        || (o4 == 0.0 && on_segment(c, d, b))
}

fn orient(a: Vec2, b: Vec2, c: Vec2) -> f32 {
    let v = cross(b - a, c - a);
    if abs(v) < 1e-9 {
        0.0
    } else {
        v
    }
}

fn on_segment(a: Vec2, b: Vec2, p: Vec2) -> bool {
    p.x >= a.x.min(b.x) - 1e-6
        && p.x <= a.x.max(b.x) + 1e-6
        && p.y >= a.y.min(b.y) - 1e-6
        && p.y <= a.y.max(b.y) + 1e-6
}

#[cfg(test)]
mod tests;
