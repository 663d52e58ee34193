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
    Turn::new(a).apply(p)
}

/// An angle with its sine and cosine, for chains of rotations by one angle and its
/// negative. Sparse ICP rotates by the same heading three times per iteration (the solve,
/// the inverse, the correspondences); on the M4F libm's `sinf` and `cosf` are
/// software double-precision routines of about 800 instructions each, so a [`Turn`] takes
/// them once. Reusing them is exact: libm's `sinf` is odd and `cosf` even on every
/// non-NaN f32 (checked exhaustively by `sinf_is_odd_and_cosf_even_on_every_f32`, an
/// ignored test of this module; README, "Instructions per update").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Turn {
    angle: f32,
    sin: f32,
    cos: f32,
}

impl Turn {
    /// The turn by `angle` (rad).
    #[inline]
    pub fn new(angle: f32) -> Turn {
        Turn {
            angle,
            sin: sin(angle),
            cos: cos(angle),
        }
    }

    /// The turn by `angle`, from this turn's sine and cosine when `angle` is this turn's
    /// angle or its negative (bit for bit), else computed afresh.
    #[inline]
    pub fn to(self, angle: f32) -> Turn {
        if angle.to_bits() == self.angle.to_bits() {
            self
        } else if angle.to_bits() == (-self.angle).to_bits() && !angle.is_nan() {
            Turn {
                angle,
                sin: -self.sin,
                cos: self.cos,
            }
        } else {
            Turn::new(angle)
        }
    }

    /// The angle (rad).
    #[inline]
    pub fn angle(&self) -> f32 {
        self.angle
    }

    /// `(sin, cos)` of the angle.
    #[inline]
    pub fn sin_cos(&self) -> (f32, f32) {
        (self.sin, self.cos)
    }

    /// `p` rotated by the angle.
    #[inline]
    pub fn apply(&self, p: Vec2) -> Vec2 {
        let (s, c) = (self.sin, self.cos);
        v2(c * p.x - s * p.y, s * p.x + c * p.y)
    }
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

    /// [`Pose2::inverse`] from `turn`, a turn by this pose's heading or its negative (any
    /// other is recomputed), and the turn by the inverse's heading: the same bits, without
    /// libm's sine and cosine where they are known.
    pub fn inverse_with(&self, turn: Turn) -> (Pose2, Turn) {
        let back = turn.to(-self.theta);
        let t = back.apply(-self.translation());
        let inverse = Pose2::new(t.x, t.y, -self.theta);
        (inverse, back.to(inverse.theta))
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What [`Turn::to`] relies on: libm's `sinf` is odd and `cosf` even, bit for bit, on
    /// every non-NaN f32 (2^31 magnitudes, both signs). About 4 min on two cores in
    /// release: `cargo test --release -p activesense-core -- --ignored every_f32`.
    #[test]
    #[ignore]
    fn sinf_is_odd_and_cosf_even_on_every_f32() {
        extern crate std;
        let halves: [std::thread::JoinHandle<u64>; 2] = [0u32, 1].map(|t| {
            std::thread::spawn(move || {
                let mut checked = 0u64;
                for b in t * 0x4000_0000..(t + 1) * 0x4000_0000 {
                    let x = f32::from_bits(b);
                    if x.is_nan() {
                        continue;
                    }
                    let (s, sn) = (sin(x), sin(-x));
                    let (c, cn) = (cos(x), cos(-x));
                    assert!(
                        (sn.to_bits() == (-s).to_bits() || (s.is_nan() && sn.is_nan()))
                            && (cn.to_bits() == c.to_bits() || (c.is_nan() && cn.is_nan())),
                        "{b:#x}"
                    );
                    checked += 1;
                }
                checked
            })
        });
        let checked: u64 = halves.into_iter().map(|h| h.join().unwrap()).sum();
        assert_eq!(checked, 0x7F80_0001);
    }

    #[test]
    fn a_turn_reuses_its_sine_and_cosine_for_the_same_and_the_negated_angle() {
        for a in [0.0f32, -0.0, 0.3, -2.9, core::f32::consts::PI, 1e-20, 40.0] {
            let t = Turn::new(a);
            assert_eq!(t.to(a), t);
            assert_eq!(t.to(-a), Turn::new(-a));
            assert_eq!(t.to(a + 0.5), Turn::new(a + 0.5));
            let p = v2(1.25, -0.5);
            assert_eq!(t.apply(p), rotate(p, a));
        }
        // The inverse from a turn equals the plain one, whatever turn is passed.
        let p = Pose2::new(1.5, -2.0, 0.7);
        for hint in [Turn::new(0.7), Turn::new(-0.7), Turn::new(0.1)] {
            let (inv, turn) = p.inverse_with(hint);
            assert_eq!(inv, p.inverse());
            assert_eq!(turn, Turn::new(inv.theta));
        }
    }

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
