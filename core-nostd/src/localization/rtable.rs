//! The R-table `LUT(d, ξ)` of the Generalized Hough Transform (paper §3.2).
//!
//! The perimeter of the (centred) model is discretised at a fixed spacing: every wall of
//! length `L` gets `max(1, ceil(L / spacing))` points at the centres of equal sub-segments.
//! Each entry stores the point's position `m_d` in the model frame (so the model centroid
//! relative to the point is `−m_d`, the paper's `(−x_m^d, −y_m^d)`) and the wall's outward
//! unit normal `n_d`.
//!
//! **Store the base table, rotate the measurement.** The paper repeats the table for each of
//! the `Nξ` rotated models. Rotating the model by `ξ` and voting with a scene-frame
//! measurement is the same as voting with the base table and the measurement rotated by
//! `−ξ` into the model frame, so only the base table is stored: `16 B × D` (6 KiB for the
//! 384-point capacity) instead of `16 B × D × Nξ × sub-bins` (240 KiB for 384 × 10 × 4,
//! twice the MCU's RAM). Rotating the *ray* costs one `sin`/`cos` per rotation hypothesis
//! per update, rotating the *table* would cost `4 D` multiplications per hypothesis;
//! storing it all would save nothing at run time.

use crate::world::geometry::length;
use crate::world::math::floor;
use crate::FloorPlan;

use super::{LocError, MAX_RTABLE_POINTS};

/// One R-table entry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RPoint {
    /// Position of the perimeter point in the model frame (m).
    pub m: [f32; 2],
    /// Outward unit normal of its wall.
    pub n: [f32; 2],
}

impl RPoint {
    const ZERO: RPoint = RPoint {
        m: [0.0; 2],
        n: [0.0; 2],
    };
}

/// Base R-table of one plan (fixed capacity [`MAX_RTABLE_POINTS`]).
#[derive(Clone, Debug)]
pub struct RTable {
    points: [RPoint; MAX_RTABLE_POINTS],
    len: u16,
    spacing: f32,
}

impl RTable {
    /// An empty table (usable in `const` / `static` initialisers).
    pub const fn new_empty() -> Self {
        RTable {
            points: [RPoint::ZERO; MAX_RTABLE_POINTS],
            len: 0,
            spacing: 0.0,
        }
    }

    /// Number of points the plan needs at `spacing` (m).
    pub fn points_needed(plan: &FloorPlan, spacing: f32) -> u32 {
        plan.solid_walls()
            .map(|i| {
                let (a, b) = plan.wall(i);
                wall_points(length(b - a), spacing)
            })
            .sum()
    }

    /// Rebuilds the table in place for `plan` at `spacing` (m). Errors when the plan needs
    /// more than [`MAX_RTABLE_POINTS`] points.
    pub fn rebuild(&mut self, plan: &FloorPlan, spacing: f32) -> Result<(), LocError> {
        let needed = Self::points_needed(plan, spacing);
        if needed as usize > MAX_RTABLE_POINTS {
            return Err(LocError::PlanTooLarge {
                needed,
                capacity: MAX_RTABLE_POINTS as u32,
            });
        }
        let mut k = 0usize;
        // Solid walls only (a door opening is not a surface the EDM can hit).
        for i in plan.solid_walls() {
            let (a, b) = plan.wall(i);
            let n = plan.outward_normal(i);
            let cnt = wall_points(length(b - a), spacing);
            for s in 0..cnt {
                let t = (s as f32 + 0.5) / cnt as f32;
                let p = a + (b - a) * t;
                self.points[k] = RPoint {
                    m: [p.x, p.y],
                    n: [n.x, n.y],
                };
                k += 1;
            }
        }
        self.len = k as u16;
        self.spacing = spacing;
        Ok(())
    }

    /// The entries.
    #[inline]
    pub fn points(&self) -> &[RPoint] {
        &self.points[..self.len as usize]
    }

    /// Number of entries `D`.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// True before the first [`RTable::rebuild`].
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The spacing the table was built with (m).
    pub fn spacing(&self) -> f32 {
        self.spacing
    }
}

fn wall_points(len: f32, spacing: f32) -> u32 {
    let q = len / spacing;
    let c = floor(q);
    let n = if q > c { c + 1.0 } else { c };
    (n as u32).max(1)
}
