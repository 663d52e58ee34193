//! SE(2) conventions shared by every module.
//!
//! Points are [`Vec2`] (nalgebra `Vector2<f32>`). A [`Pose2`] `(x, y, θ)` maps a point
//! `p` of its *source* frame into its *target* frame as `R(θ)·p + t`. Throughout the
//! crate the **model frame** has its origin at the floor-plan's perimeter centroid
//! (paper §3.2, "we assume the model to be centred at the origin"), and the **scene
//! frame** is the instrument's: origin at the instrument, x axis at encoder bearing 0.
//! The registration the whole pipeline estimates is the model→scene pose.

use crate::world::math::{cos, sin, sqrt, wrap_angle};
use serde::{Deserialize, Serialize};

/// A 2-D point or vector in metres.
pub type Vec2 = nalgebra::Vector2<f32>;

/// Shorthand constructor for [`Vec2`].
#[inline]
pub fn v2(x: f32, y: f32) -> Vec2 {
    Vec2::new(x, y)
}

/// 2-D cross product (z component of the 3-D cross product).
#[inline]
pub fn cross(a: Vec2, b: Vec2) -> f32 {
    a.x * b.y - a.y * b.x
}

/// Euclidean length through libm (nalgebra's `norm` would use its own sqrt path).
#[inline]
pub fn length(a: Vec2) -> f32 {
    sqrt(a.x * a.x + a.y * a.y)
}

/// Unit vector at angle `a` (radians, counter-clockwise from +x).
#[inline]
pub fn unit(a: f32) -> Vec2 {
    v2(cos(a), sin(a))
}

/// Rotates `p` by `a` radians counter-clockwise.
#[inline]
pub fn rotate(p: Vec2, a: f32) -> Vec2 {
    let (s, c) = (sin(a), cos(a));
    v2(c * p.x - s * p.y, s * p.x + c * p.y)
}

/// A rigid transform in SE(2): rotation `theta` (radians) then translation `(x, y)`.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// Translation x (m).
    pub x: f32,
    /// Translation y (m).
    pub y: f32,
    /// Rotation (rad), kept in [-π, π).
    pub theta: f32,
}

impl Pose2 {
    /// The identity transform.
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    /// Builds a pose, wrapping the angle into [-π, π).
    pub fn new(x: f32, y: f32, theta: f32) -> Self {
        Pose2 {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// Translation part.
    pub fn translation(&self) -> Vec2 {
        v2(self.x, self.y)
    }

    /// Maps a point from the source into the target frame.
    pub fn transform(&self, p: Vec2) -> Vec2 {
        rotate(p, self.theta) + self.translation()
    }

    /// Rotates a direction (no translation).
    pub fn rotate_dir(&self, d: Vec2) -> Vec2 {
        rotate(d, self.theta)
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let t = self.transform(other.translation());
        Pose2::new(t.x, t.y, self.theta + other.theta)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Pose2 {
        let t = rotate(-self.translation(), -self.theta);
        Pose2::new(t.x, t.y, -self.theta)
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_inverse_is_identity() {
        let p = Pose2::new(1.5, -2.0, 0.7);
        let q = p.compose(&p.inverse());
        assert!(q.x.abs() < 1e-5 && q.y.abs() < 1e-5 && q.theta.abs() < 1e-5);
        let pt = v2(0.3, 4.0);
        let back = p.inverse().transform(p.transform(pt));
        assert!(length(back - pt) < 1e-5);
    }
}
