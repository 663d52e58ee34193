//! The polygonal floor-plan model (paper §3, §4.1) and the geometric queries every other
//! module builds on: ray casting (the EDM range sensor), point-in-polygon (the GHT
//! "agent inside the model" precondition), nearest point on the outline (ICP
//! correspondences), outward normals (incidence checks), perimeter length and perimeter
//! centroid (the model frame's origin), and the topological scan (visible wall junctions).
//!
//! A [`FloorPlan`] is a simple, counter-clockwise polygon of at most [`MAX_VERTICES`]
//! vertices. It is validated once, on construction; every query afterwards may assume a
//! valid outline. Invalid input (a polygon arriving over the serial link, a bad JSON file)
//! is a [`PlanError`], never a panic.

use crate::world::geometry::{cross, length, v2, Vec2};
use crate::world::math::{abs, acos, atan2, wrap_angle};
use heapless::Vec as HVec;
use serde::{Deserialize, Serialize};

/// Fixed vertex capacity of a floor-plan (the generator uses at most 32).
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
        }
    }
}

/// The first wall a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Distance from the ray origin to the hit point (m).
    pub range: f32,
    /// Index of the wall (edge `i` runs from vertex `i` to vertex `i+1`).
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

/// A validated, simple, counter-clockwise polygon.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorPlan {
    vertices: HVec<[f32; 2], MAX_VERTICES>,
}

impl FloorPlan {
    /// A plan with no vertices, for `static` storage before a real plan is copied in (it
    /// is not valid: [`FloorPlan::validate`] refuses it and ray casts meet nothing).
    pub const fn empty() -> Self {
        FloorPlan {
            vertices: HVec::new(),
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

    /// Validates raw `[x, y]` pairs (the wire representation).
    pub fn from_raw(vertices: HVec<[f32; 2], MAX_VERTICES>) -> Result<Self, PlanError> {
        let plan = FloorPlan { vertices };
        plan.validate()?;
        Ok(plan)
    }

    /// Re-checks every invariant; `Deserialize` bypasses [`FloorPlan::new`], so data
    /// decoded from outside must pass through here (or [`FloorPlan::from_raw`]).
    pub fn validate(&self) -> Result<(), PlanError> {
        let n = self.vertices.len();
        if n < 3 {
            return Err(PlanError::TooFewVertices);
        }
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
            if length(self.vertex(i + 1) - self.vertex(i)) < MIN_EDGE_LENGTH {
                return Err(PlanError::ZeroLengthEdge(i as u8));
            }
        }
        for i in 0..n {
            let a = self.vertex(i + n - 1);
            let b = self.vertex(i);
            let c = self.vertex(i + 1);
            let (d0, d1) = (b - a, c - b);
            let s = cross(d0, d1) / (length(d0) * length(d1));
            if abs(s) < COLLINEAR_SIN_TOLERANCE {
                return Err(PlanError::CollinearVertex(i as u8));
            }
        }
        for i in 0..n {
            for j in (i + 1)..n {
                // Adjacent edges share a vertex by construction; skip them.
                if j == i + 1 || (i == 0 && j == n - 1) {
                    continue;
                }
                if segments_touch(
                    self.vertex(i),
                    self.vertex(i + 1),
                    self.vertex(j),
                    self.vertex(j + 1),
                ) {
                    return Err(PlanError::SelfIntersection(i as u8, j as u8));
                }
            }
        }
        if self.signed_area() <= 0.0 {
            return Err(PlanError::Clockwise);
        }
        Ok(())
    }

    /// Number of vertices (= number of walls).
    pub fn len(&self) -> usize {
        self.vertices.len()
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

    /// Wall `i` as `(start, end)`.
    #[inline]
    pub fn wall(&self, i: usize) -> (Vec2, Vec2) {
        (self.vertex(i), self.vertex(i + 1))
    }

    /// Outward unit normal of wall `i`. For a counter-clockwise outline the interior is on
    /// the left of each edge, so the outward normal is the edge direction turned right.
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

    /// Signed area (shoelace); positive for counter-clockwise outlines.
    pub fn signed_area(&self) -> f32 {
        let mut s = 0.0;
        for i in 0..self.len() {
            s += cross(self.vertex(i), self.vertex(i + 1));
        }
        0.5 * s
    }

    /// Perimeter length (m).
    pub fn perimeter(&self) -> f32 {
        (0..self.len())
            .map(|i| length(self.vertex(i + 1) - self.vertex(i)))
            .sum()
    }

    /// Perimeter centroid: the centre of mass of the outline with uniform density along
    /// the walls. This is the model frame's origin (paper §3.2, §3.4).
    pub fn perimeter_centroid(&self) -> Vec2 {
        let mut acc = v2(0.0, 0.0);
        let mut total = 0.0;
        for i in 0..self.len() {
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

    /// The outline translated by `d` (validity is preserved by translation).
    pub fn translated(&self, d: Vec2) -> FloorPlan {
        let mut vertices = self.vertices.clone();
        for v in vertices.iter_mut() {
            v[0] += d.x;
            v[1] += d.y;
        }
        FloorPlan { vertices }
    }

    /// Largest distance from the origin to any vertex (the model's "radius" when centred).
    pub fn max_radius(&self) -> f32 {
        self.vertices().map(length).fold(0.0, f32::max)
    }

    /// Point-in-polygon by crossing number. Points exactly on a wall may go either way.
    pub fn contains(&self, p: Vec2) -> bool {
        let mut inside = false;
        let n = self.len();
        for i in 0..n {
            let a = self.vertex(i);
            let b = self.vertex(i + 1);
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Casts a ray from `origin` along the unit direction `dir` and returns the first wall
    /// it meets at a distance greater than `1e-6` m, or `None` when it meets none (an
    /// origin outside the room looking away from it).
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
        for i in 0..self.len() {
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

    /// Closest point of the outline to `p`.
    pub fn nearest_point(&self, p: Vec2) -> NearestPoint {
        let mut best = NearestPoint {
            point: self.vertex(0),
            wall: 0,
            distance: f32::INFINITY,
        };
        for i in 0..self.len() {
            let q = closest_on_segment(p, self.vertex(i), self.vertex(i + 1));
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
        !(0..self.len()).any(|i| {
            let (a, b) = self.wall(i);
            let (w, e) = (a - from, b - a);
            blocks((w, e, cross(w, e)), dir, before)
        })
    }

    /// The range of [`FloorPlan::ray_cast`]'s hit alone (the same arithmetic, without the
    /// incidence angle and hit point): the visibility test of every ICP correspondence
    /// needs no more.
    pub fn first_hit(&self, origin: Vec2, dir: Vec2) -> Option<f32> {
        self.nearest_wall_along(origin, dir).map(|(_, t)| t)
    }

    /// The topological scan (paper §3.1, §4.1): `N` binary pixels spanning `fov` radians
    /// centred on the scene-frame `bearing`, pixel 0 at the right (clockwise) edge. A pixel
    /// is set when a wall junction visible from `origin` lies in its angular bin. Bins are
    /// half-open `[lo, hi)` counter-clockwise.
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
fn segments_touch(a: Vec2, b: Vec2, c: Vec2, d: Vec2) -> bool {
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
mod tests {
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
}
