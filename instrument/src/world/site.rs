//! The site: the room as it stands, which the EDM hits, apart from the plan the instrument
//! is given. A surveyor's room is never its plan: cabinets stand against the walls, columns
//! and scaffolding stand free, doors open onto corridors, glass returns nothing, people walk
//! through the beam, and as-built walls sit centimetres off their drawn lines.
//!
//! [`SiteLevel`] names how far the site departs from its plan, and [`Site::generate`] draws
//! one such site from a seed (its own random stream, so a `plan`-level episode draws exactly
//! what it drew before sites existed). What each level puts in the room is listed on
//! [`SiteLevel`] and in `docs/WORLD.md`, "Sites". The instrument never sees the site; only
//! the simulated EDM ([`super::sensor::SensorModel::measure_in`]) and the pictures do.

use activesense_core::world::geometry::{cross, v2, Vec2};
use activesense_core::world::math::{abs, acos, cos, sin, sqrt, TAU};
use activesense_core::FloorPlan;
use rand::Rng;
use rand::SeedableRng;
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};

/// How far the site departs from its plan (`--site`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SiteLevel {
    /// The room is exactly its plan (the paper's world; every result before sites).
    #[default]
    Plan,
    /// Furnished: 1–3 furniture blocks 0.4–0.8 m deep against walls, one free-standing
    /// column 0.3–0.6 m wide, and an open door onto space behind its wall in half the rooms.
    Furnished,
    /// A building site: `furnished`, plus one wall 3–6 cm off its drawn line, two more
    /// free-standing obstacles (scaffolding, stacked material), a glass pane that returns
    /// nothing in half the rooms, and people who cut the beam on 4 % of the shots.
    Site,
    /// Each episode draws one of the three levels above from its seed (training and
    /// calibration on randomised sites).
    Mixed,
}

impl SiteLevel {
    /// Every level a user names, in the order of the help text.
    pub const ALL: [SiteLevel; 4] = [
        SiteLevel::Plan,
        SiteLevel::Furnished,
        SiteLevel::Site,
        SiteLevel::Mixed,
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            SiteLevel::Plan => "plan",
            SiteLevel::Furnished => "furnished",
            SiteLevel::Site => "site",
            SiteLevel::Mixed => "mixed",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Result<SiteLevel, String> {
        SiteLevel::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                format!("--site takes plan, furnished, site or mixed (the room as its plan, furnished, a building site, or one of the three per episode), got {s:?}")
            })
    }

    /// True for the room that is exactly its plan.
    pub fn is_plan(&self) -> bool {
        *self == SiteLevel::Plan
    }
}

/// What stands in the room that the plan does not draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObstacleKind {
    /// A block against a wall (cabinet, desk, shelf).
    Furniture,
    /// A free-standing column.
    Column,
    /// Anything else free-standing (scaffolding, stacked material).
    Obstacle,
}

/// A convex obstacle, counter-clockwise corners in the model frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Obstacle {
    /// What it is.
    pub kind: ObstacleKind,
    /// Its outline (a rectangle, four corners).
    pub corners: Vec<[f32; 2]>,
}

/// A stretch of one wall where the beam does not meet the wall as drawn.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Opening {
    /// The wall (index into the as-built outline, the same as the plan's).
    pub wall: usize,
    /// Where along the wall it starts and ends (fractions of the wall's length).
    pub from: f32,
    /// End, fraction of the wall's length.
    pub to: f32,
    /// A door: the space behind it is this deep (m) before the beam meets a wall there.
    /// `None`: glass, which returns nothing.
    pub depth_behind: Option<f32>,
}

/// One drawn site: the as-built outline, what stands in it, and its openings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Site {
    /// The level drawn (never [`SiteLevel::Mixed`]).
    pub level: SiteLevel,
    /// The walls as built (the plan with one wall moved at level `site`).
    pub as_built: FloorPlan,
    /// The wall moved off its drawn line and by how much (m, along its outward normal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moved_wall: Option<(usize, f32)>,
    /// Furniture, columns and obstacles.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<Obstacle>,
    /// Doors and glass.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub openings: Vec<Opening>,
    /// Chance that a person cuts the beam on one shot.
    #[serde(default)]
    pub people: f32,
}

/// Closest an obstacle may stand to the station (m): the instrument's tripod needs room.
pub const STATION_CLEARANCE: f32 = 0.5;

/// What one beam meets on the site.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SiteHit {
    /// A wall as built, at this range and incidence (rad from the normal).
    Wall { range: f32, incidence: f32 },
    /// Something the plan does not draw (an obstacle or a person), in front of the wall.
    Clutter { range: f32, incidence: f32 },
    /// Through a door: the wall of the space behind it.
    Behind { range: f32, incidence: f32 },
    /// Glass, or nothing at all.
    Nothing,
}

impl Site {
    /// The room exactly as its plan.
    pub fn plain(plan: &FloorPlan) -> Site {
        Site {
            level: SiteLevel::Plan,
            as_built: plan.clone(),
            moved_wall: None,
            obstacles: Vec::new(),
            openings: Vec::new(),
            people: 0.0,
        }
    }

    /// True when the site is its plan.
    pub fn is_plain(&self) -> bool {
        self.level.is_plan()
    }

    /// Draws the site of `plan` at `level` around the station at `station`, from `seed`
    /// (its own stream: the world's placement and noise draws do not move).
    pub fn generate(plan: &FloorPlan, station: Vec2, level: SiteLevel, seed: u64) -> Site {
        let mut rng = Pcg32::seed_from_u64(seed ^ 0x5173_e000_0000_0001);
        let level = match level {
            SiteLevel::Mixed => {
                [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site][rng.gen_range(0..3usize)]
            }
            l => l,
        };
        let mut site = Site::plain(plan);
        site.level = level;
        if level == SiteLevel::Plan {
            return site;
        }
        let blocks = rng.gen_range(1..=3usize);
        for _ in 0..blocks {
            if let Some(o) = furniture(plan, station, &mut rng) {
                site.obstacles.push(o);
            }
        }
        if let Some(o) = free_standing(plan, station, ObstacleKind::Column, 0.3, 0.6, &mut rng) {
            site.obstacles.push(o);
        }
        if rng.gen_bool(0.5) {
            if let Some(o) = opening(plan, 0.8, 1.0, &mut rng) {
                let depth = rng.gen_range(1.5f32..6.0);
                site.openings.push(Opening {
                    depth_behind: Some(depth),
                    ..o
                });
            }
        }
        if level == SiteLevel::Site {
            for _ in 0..2 {
                if let Some(o) =
                    free_standing(plan, station, ObstacleKind::Obstacle, 0.3, 1.0, &mut rng)
                {
                    site.obstacles.push(o);
                }
            }
            if rng.gen_bool(0.5) {
                if let Some(o) = opening(plan, 1.0, 3.0, &mut rng) {
                    site.openings.push(o);
                }
            }
            site.people = 0.04;
            let wall = rng.gen_range(0..plan.len());
            let off = rng.gen_range(0.03f32..0.06) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            if let Some(moved) = move_wall(plan, wall, off) {
                // The station must stay inside the room as built.
                if moved.contains(station) && moved.nearest_point(station).distance > 0.05 {
                    site.as_built = moved;
                    site.moved_wall = Some((wall, off));
                }
            }
        }
        site
    }

    /// What the beam from `origin` along the unit direction `dir` meets first; `person` is
    /// the uniform draw that decides whether someone stands in it (and where).
    pub fn cast(&self, origin: Vec2, dir: Vec2, person: (f32, f32)) -> SiteHit {
        let wall = self.as_built.ray_cast(origin, dir);
        let mut near: Option<(f32, f32)> = None;
        for o in &self.obstacles {
            if let Some((t, inc)) = ray_polygon(&o.corners, origin, dir) {
                if near.is_none_or(|(n, _)| t < n) {
                    near = Some((t, inc));
                }
            }
        }
        let wall_range = wall.map_or(f32::INFINITY, |h| h.range);
        if person.0 < self.people {
            // Someone between 0.5 m and the wall (or 6 m), facing the beam.
            let far = wall_range.min(near.map_or(f32::INFINITY, |n| n.0)).min(6.0);
            if far > 0.6 {
                let r = 0.5 + person.1 * (far - 0.5);
                return SiteHit::Clutter {
                    range: r,
                    incidence: 0.0,
                };
            }
        }
        if let Some((t, inc)) = near {
            if t < wall_range {
                return SiteHit::Clutter {
                    range: t,
                    incidence: inc,
                };
            }
        }
        if let Some((range, incidence)) = through_plan_door(&self.as_built, origin, dir, wall_range)
        {
            return SiteHit::Behind { range, incidence };
        }
        let Some(hit) = wall else {
            return SiteHit::Nothing;
        };
        let (a, b) = self.as_built.wall(hit.wall);
        let e = b - a;
        let u = ((hit.point - a).x * e.x + (hit.point - a).y * e.y) / (e.x * e.x + e.y * e.y);
        for o in &self.openings {
            if o.wall == hit.wall && (o.from..=o.to).contains(&u) {
                return match o.depth_behind {
                    Some(d) => SiteHit::Behind {
                        range: hit.range + d / cos(hit.incidence).max(0.2),
                        incidence: hit.incidence,
                    },
                    None => SiteHit::Nothing,
                };
            }
        }
        SiteHit::Wall {
            range: hit.range,
            incidence: hit.incidence,
        }
    }
}

/// How deep the space behind a door of the plan is (m): a beam through a plan door meets a
/// wall this far behind the door's line (along the door's normal), as in a corridor or the
/// next room. One fixed depth: the plan does not draw what lies behind its doors.
pub const PLAN_DOOR_DEPTH: f32 = 2.5;

/// The beam from `origin` along unit `dir` leaving through a door opening of `plan` before
/// `wall_range`: the range at which it meets the wall [`PLAN_DOOR_DEPTH`] behind the door
/// and its incidence there (taken as at the door), or `None` (always for a plan without
/// doors, which then reads exactly what it always read).
pub fn through_plan_door(
    plan: &FloorPlan,
    origin: Vec2,
    dir: Vec2,
    wall_range: f32,
) -> Option<(f32, f32)> {
    if plan.openings() == 0 {
        return None;
    }
    let mut best: Option<(f32, usize)> = None;
    for i in (0..plan.len()).filter(|&i| plan.is_opening(i)) {
        let (a, b) = plan.wall(i);
        let Some(t) = ray_meets_segment(origin, dir, a, b) else {
            continue;
        };
        if t < wall_range && best.is_none_or(|(h, _)| t < h) {
            best = Some((t, i));
        }
    }
    let (t, i) = best?;
    let n = plan.outward_normal(i);
    let incidence = acos(abs(dir.x * n.x + dir.y * n.y).min(1.0));
    Some((t + PLAN_DOOR_DEPTH / cos(incidence).max(0.2), incidence))
}

/// Distance along the ray from `origin` (unit `dir`) to segment `a → b`, when it crosses it
/// beyond 1e-6 m (parallel segments never): the test doors and obstacles share.
fn ray_meets_segment(origin: Vec2, dir: Vec2, a: Vec2, b: Vec2) -> Option<f32> {
    let e = b - a;
    let denom = cross(dir, e);
    if abs(denom) < 1e-12 {
        return None;
    }
    let w = a - origin;
    let t = cross(w, e) / denom;
    let u = cross(w, dir) / denom;
    (t > 1e-6 && (0.0..=1.0).contains(&u)).then_some(t)
}

/// First crossing of the ray with a convex polygon's edges: range and incidence.
fn ray_polygon(corners: &[[f32; 2]], origin: Vec2, dir: Vec2) -> Option<(f32, f32)> {
    let mut best: Option<(f32, f32)> = None;
    for i in 0..corners.len() {
        let a = v2(corners[i][0], corners[i][1]);
        let b = v2(
            corners[(i + 1) % corners.len()][0],
            corners[(i + 1) % corners.len()][1],
        );
        let e = b - a;
        let Some(t) = ray_meets_segment(origin, dir, a, b) else {
            continue;
        };
        if best.is_none_or(|(h, _)| t < h) {
            let len = sqrt(e.x * e.x + e.y * e.y);
            let c = abs(cross(dir, e)) / len; // |cos| of the angle to the edge's normal
            best = Some((t, acos(c.min(1.0))));
        }
    }
    best
}

/// True when `p` lies inside the convex counter-clockwise polygon `corners`.
pub fn inside_convex(corners: &[[f32; 2]], p: Vec2) -> bool {
    (0..corners.len()).all(|i| {
        let a = v2(corners[i][0], corners[i][1]);
        let j = (i + 1) % corners.len();
        let b = v2(corners[j][0], corners[j][1]);
        cross(b - a, p - a) >= 0.0
    })
}

/// An obstacle may stand here: every corner inside the room and clear of its walls, no
/// corner of the room inside it, and clear of the station.
fn fits(plan: &FloorPlan, corners: &[[f32; 2]], station: Vec2, wall_clearance: f32) -> bool {
    let pts: Vec<Vec2> = corners.iter().map(|c| v2(c[0], c[1])).collect();
    let centre = pts.iter().fold(v2(0.0, 0.0), |s, p| s + p) / pts.len() as f32;
    // Corners pulled 1 cm towards the centre: a block flush with a wall has two corners on it.
    let inner_ok = pts.iter().all(|&p| {
        let q = p + (centre - p) * (0.01 / (centre - p).norm().max(1e-3));
        plan.contains(q) && plan.nearest_point(q).distance >= wall_clearance
    });
    let no_room_corner = !plan.vertices().any(|v| inside_convex(corners, v));
    let clear_of_station = !inside_convex(corners, station)
        && pts.iter().enumerate().all(|(i, &a)| {
            let b = pts[(i + 1) % pts.len()];
            (activesense_core::world::floorplan::closest_on_segment(station, a, b) - station).norm()
                >= STATION_CLEARANCE
        });
    inner_ok && no_room_corner && clear_of_station
}

/// A block against a random wall long enough to hold it.
fn furniture(plan: &FloorPlan, station: Vec2, rng: &mut Pcg32) -> Option<Obstacle> {
    for _ in 0..20 {
        let i = rng.gen_range(0..plan.len());
        if plan.is_opening(i) {
            continue; // no furniture against a door
        }
        let (a, b) = plan.wall(i);
        let len = (b - a).norm();
        let width = rng.gen_range(0.6f32..2.0);
        let depth = rng.gen_range(0.4f32..0.8);
        if len < width + 0.2 {
            continue;
        }
        let s = rng.gen_range(0.1..(len - 0.1 - width).max(0.1 + 1e-3));
        let e = (b - a) / len;
        let inward = -plan.outward_normal(i);
        let p0 = a + e * s;
        let p1 = a + e * (s + width);
        let corners = [p0, p1, p1 + inward * depth, p0 + inward * depth].map(|p| [p.x, p.y]);
        if fits(plan, &corners, station, 0.0) {
            return Some(Obstacle {
                kind: ObstacleKind::Furniture,
                corners: corners.to_vec(),
            });
        }
    }
    None
}

/// A free-standing rectangle, sides in `[lo, hi)` m, at a random angle.
fn free_standing(
    plan: &FloorPlan,
    station: Vec2,
    kind: ObstacleKind,
    lo: f32,
    hi: f32,
    rng: &mut Pcg32,
) -> Option<Obstacle> {
    let (min, max) = plan.bounds();
    for _ in 0..40 {
        let c = v2(rng.gen_range(min.x..max.x), rng.gen_range(min.y..max.y));
        let (w, h) = (rng.gen_range(lo..hi), rng.gen_range(lo..hi));
        let phi = if kind == ObstacleKind::Column {
            0.0
        } else {
            rng.gen_range(0.0..TAU)
        };
        let (s, co) = (sin(phi), cos(phi));
        let corners = [(-w, -h), (w, -h), (w, h), (-w, h)]
            .map(|(x, y)| [c.x + 0.5 * (co * x - s * y), c.y + 0.5 * (s * x + co * y)]);
        if fits(plan, &corners, station, 0.1) {
            return Some(Obstacle {
                kind,
                corners: corners.to_vec(),
            });
        }
    }
    None
}

/// A stretch `[lo, hi)` m wide on a random wall long enough (0.2 m left either side).
fn opening(plan: &FloorPlan, lo: f32, hi: f32, rng: &mut Pcg32) -> Option<Opening> {
    for _ in 0..20 {
        let i = rng.gen_range(0..plan.len());
        // A site opening is a stretch of solid outline wall (glass, a door the plan lacks).
        if plan.is_opening(i) || !plan.ring(0).contains(&i) {
            continue;
        }
        let (a, b) = plan.wall(i);
        let len = (b - a).norm();
        let width = rng.gen_range(lo..hi);
        if len < width + 0.4 {
            continue;
        }
        let s = rng.gen_range(0.2..(len - 0.2 - width).max(0.2 + 1e-3));
        return Some(Opening {
            wall: i,
            from: s / len,
            to: (s + width) / len,
            depth_behind: None,
        });
    }
    None
}

/// The plan with wall `i` moved by `offset` m along its outward normal (both its corners
/// move; the neighbouring walls tilt a little), if that is still a valid plan; its columns
/// and doors are kept (a door opening is not moved).
fn move_wall(plan: &FloorPlan, i: usize, offset: f32) -> Option<FloorPlan> {
    if plan.is_opening(i) {
        return None;
    }
    let n = plan.outward_normal(i) * offset;
    let j = plan.next(i);
    let mut vs: Vec<[f32; 2]> = plan.raw().to_vec();
    for k in [i, j] {
        vs[k] = [vs[k][0] + n.x, vs[k][1] + n.y];
    }
    FloorPlan::from_parts(&vs, plan.ring_ends(), plan.openings()).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{plans, SimWorld};
    use activesense_core::episode::EpisodeConfig;

    fn worlds(level: SiteLevel, n: usize) -> Vec<SimWorld> {
        plans::TEST_SEEDS
            .take(n)
            .map(|seed| {
                let sensor = crate::world::sensor::SensorModel {
                    site: level,
                    ..Default::default()
                };
                SimWorld::new(
                    plans::generate(seed),
                    sensor,
                    EpisodeConfig::default(),
                    seed as u64,
                )
            })
            .collect()
    }

    /// Same seed, same site; every obstacle inside the room, clear of its walls' far side
    /// and of the station; every level puts what it says in the room.
    #[test]
    fn seeded_inside_the_room_and_off_the_station() {
        for level in [SiteLevel::Furnished, SiteLevel::Site] {
            let (mut furniture, mut columns, mut moved) = (0, 0, 0);
            for w in worlds(level, 200) {
                let site = w.site();
                let again = Site::generate(w.plan(), w.position(), level, 17);
                assert_eq!(again, Site::generate(w.plan(), w.position(), level, 17));
                assert_eq!(site.level, level);
                for o in &site.obstacles {
                    for c in &o.corners {
                        let p = v2(c[0], c[1]);
                        let centre = o
                            .corners
                            .iter()
                            .fold(v2(0.0, 0.0), |s, c| s + v2(c[0], c[1]))
                            / 4.0;
                        assert!(w.plan().contains(p + (centre - p) * 0.01), "{o:?}");
                    }
                    assert!(!inside_convex(&o.corners, w.position()));
                    for i in 0..4 {
                        let (a, b) = (o.corners[i], o.corners[(i + 1) % 4]);
                        let q = activesense_core::world::floorplan::closest_on_segment(
                            w.position(),
                            v2(a[0], a[1]),
                            v2(b[0], b[1]),
                        );
                        assert!((q - w.position()).norm() >= STATION_CLEARANCE - 1e-4);
                    }
                    furniture += (o.kind == ObstacleKind::Furniture) as u32;
                    columns += (o.kind == ObstacleKind::Column) as u32;
                }
                assert!(w.site().as_built.contains(w.position()));
                moved += site.moved_wall.is_some() as u32;
            }
            assert!(
                furniture > 200,
                "{level:?}: {furniture} furniture blocks in 200 rooms"
            );
            assert!(columns > 150, "{level:?}: {columns} columns in 200 rooms");
            if level == SiteLevel::Site {
                assert!(moved > 150, "{moved} moved walls");
            } else {
                assert_eq!(moved, 0);
            }
        }
    }

    /// The plan level draws nothing and changes nothing: the world's random stream and its
    /// readings are what they were before sites existed.
    #[test]
    fn plan_level_is_the_plan() {
        for w in worlds(SiteLevel::Plan, 50) {
            assert!(w.site().is_plain());
            assert_eq!(&w.site().as_built, w.plan());
        }
        let mixed: Vec<SiteLevel> = worlds(SiteLevel::Mixed, 60)
            .iter()
            .map(|w| w.site().level)
            .collect();
        for l in [SiteLevel::Plan, SiteLevel::Furnished, SiteLevel::Site] {
            assert!(mixed.iter().filter(|&&m| m == l).count() >= 10, "{l:?}");
        }
    }

    /// A block against the wall the beam points at shortens the reading by its depth; a
    /// door lengthens it by the space behind; glass returns nothing.
    #[test]
    fn cast_meets_clutter_doors_and_glass() {
        let plan = crate::fixtures::rect(10.0, 6.0);
        let mut site = Site::plain(&plan);
        site.level = SiteLevel::Furnished;
        // Wall 1 runs from (5,-3) to (5,3): a 0.5 m deep block on it around y = 0.
        site.obstacles.push(Obstacle {
            kind: ObstacleKind::Furniture,
            corners: vec![[4.5, -0.5], [5.0, -0.5], [5.0, 0.5], [4.5, 0.5]],
        });
        let at = |y: f32| site.cast(v2(0.0, y), v2(1.0, 0.0), (1.0, 0.0));
        assert!(matches!(at(0.0), SiteHit::Clutter { range, .. } if (range - 4.5).abs() < 1e-4));
        assert!(matches!(at(2.0), SiteHit::Wall { range, .. } if (range - 5.0).abs() < 1e-4));
        // Wall 2 runs from (5,3) to (-5,3): a door at x in [1, 2] (fractions 0.3..0.4), 2 m deep.
        site.openings.push(Opening {
            wall: 2,
            from: 0.3,
            to: 0.4,
            depth_behind: Some(2.0),
        });
        let up = |site: &Site, x: f32| site.cast(v2(x, 0.0), v2(0.0, 1.0), (1.0, 0.0));
        assert!(
            matches!(up(&site, 1.5), SiteHit::Behind { range, .. } if (range - 5.0).abs() < 1e-4)
        );
        site.openings[0].depth_behind = None;
        assert_eq!(up(&site, 1.5), SiteHit::Nothing);
        assert!(
            matches!(up(&site, 0.0), SiteHit::Wall { range, .. } if (range - 3.0).abs() < 1e-4)
        );
        // A person: short of the wall.
        site.people = 0.5;
        let p = site.cast(v2(0.0, 2.0), v2(1.0, 0.0), (0.1, 0.5));
        assert!(matches!(p, SiteHit::Clutter { range, .. } if range > 0.5 && range < 5.0));
    }

    /// A plan door is an opening onto space behind it: the beam through it meets a wall
    /// [`PLAN_DOOR_DEPTH`] behind the door's line, beside it the wall itself; a plan column
    /// is a wall the beam meets; a wall moved on site keeps the plan's column and door.
    #[test]
    fn plan_doors_open_onto_space_behind_and_columns_stop_the_beam() {
        let plan = FloorPlan::with_columns_and_doors(
            &[v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)],
            &[&[v2(4.0, 1.5), v2(4.5, 1.5), v2(4.5, 2.0), v2(4.0, 2.0)]],
            &[(v2(1.0, 0.0), v2(2.0, 0.0))],
            0.02,
        )
        .unwrap();
        let site = Site::plain(&plan);
        let down = v2(0.0, -1.0);
        match site.cast(v2(1.5, 2.0), down, (1.0, 0.0)) {
            SiteHit::Behind { range, incidence } => {
                assert!((range - (2.0 + PLAN_DOOR_DEPTH)).abs() < 1e-4, "{range}");
                assert!(incidence.abs() < 1e-3);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            site.cast(v2(2.5, 2.0), down, (1.0, 0.0)),
            SiteHit::Wall { range, .. } if (range - 2.0).abs() < 1e-4
        ));
        assert!(matches!(
            site.cast(v2(1.0, 1.75), v2(1.0, 0.0), (1.0, 0.0)),
            SiteHit::Wall { range, .. } if (range - 3.0).abs() < 1e-4
        ));
        // The sensor reads the same through the plan alone.
        let sensor = crate::world::sensor::SensorModel {
            outlier_prob: 0.0,
            sigma: 0.0,
            ..Default::default()
        };
        let mut rng = Pcg32::seed_from_u64(1);
        let (range, kind) =
            sensor.measure(&plan, v2(1.5, 2.0), -core::f32::consts::FRAC_PI_2, &mut rng);
        assert_eq!(kind, crate::world::sensor::RangeKind::Behind);
        assert!((range.unwrap() - (2.0 + PLAN_DOOR_DEPTH)).abs() < 1e-4);
        let moved = move_wall(&plan, 3, 0.05).unwrap();
        assert_eq!(moved.ring_ends(), plan.ring_ends());
        assert_eq!(moved.openings(), plan.openings());
        assert_eq!(
            move_wall(&plan, 1, 0.05),
            None,
            "a door opening is not moved"
        );
    }
}
