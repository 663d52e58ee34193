//! Sparse registration (paper §3.3): Sparse ICP (Algorithm 4) with constrained,
//! incidence-weighted correspondences, percentile outlier rejection and the closed-form
//! weighted SE(2) solve of equation 6, wrapped in annealed perturbations (Algorithm 3,
//! after Arun Srivatsan et al. 2019).
//!
//! ## Frames and inputs
//!
//! * The model is the **centred** [`FloorPlan`] (model frame M, origin at the perimeter
//!   centroid).
//! * Observations are EDM measurements `(β, r)`: bearing `β` in the scene frame S
//!   (instrument at the origin, x axis at encoder bearing 0) and range `r`; the scene point
//!   is `sᵢ = r·unit(β)` and the ray direction `unit(β)`. No-returns must not be passed in.
//! * Poses are **AgentPoses** `P = (a, h)`: the scene→model transform (`P(s) = R(h)s + a`).
//!   Equation 6 estimates the registration `T = P⁻¹` (model→scene); the functions here take
//!   and return AgentPoses and invert internally.
//!
//! ## Sparse ICP (Algorithm 4)
//!
//! Each iteration, with the current estimate `P_k`:
//!
//! 1. **Correspondences.** Every observation is mapped into the model, `mᵢ' = P_k(sᵢ)`, with
//!    its ray direction `dᵢ = R(h_k)·unit(βᵢ)`. Its correspondent is the nearest point of the
//!    outline among the walls satisfying the constraints `C`: the wall's outward normal
//!    `n` faces the ray (`dᵢ·n > 0`: the ray reaches the wall from inside the room) and the
//!    incidence angle `acos(dᵢ·n)` is at most [`IcpParams::max_incidence`], and the point
//!    is visible from the hypothesised instrument position `a_k` (no other wall on the line
//!    of sight, [`VISIBILITY_TOLERANCE`]; so an instrument placed outside the room or behind
//!    a corner finds no feasible wall). The pair is
//!    weighted by the cosine of the incidence, `wᵢ = dᵢ·n`. If no wall is feasible the
//!    constraints are relaxed to the plain nearest point with the lower weight
//!    [`IcpParams::relaxed_weight`].
//! 2. **Outlier rejection** (Rusinkiewicz & Levoy 2001): pairs whose distance lies above the
//!    [`IcpParams::keep_fraction`] percentile of the distances are dropped, except that a
//!    pair closer than [`IcpParams::reject_min_distance`] (converged, noise-level
//!    residuals) or than [`IcpParams::reject_median_factor`] times the median distance (a
//!    set that is uniformly far from converged) is always kept, and at least
//!    [`IcpParams::min_pairs`] pairs survive.
//! 3. **Solve** (equation 6) for `T = argmin Σ wᵢ ‖T(mᵢ) − sᵢ‖²` in closed form:
//!    `Γ = (M − m̄)ᵀ W (O − ō)`, `ϑ = atan2(Γ₀₁ − Γ₁₀, tr Γ)`, `t = ō − R(ϑ) m̄` (weighted
//!    centroids; `atan2` instead of `arctan` gives the full angle range). The solve is
//!    absolute (model points against scene points), so no increments accumulate.
//!    With [`IcpParams::fixed_heading`] the rotation is kept and only `t` is solved (the
//!    K = 1 case where the heading is known exactly).
//!    Point-to-point steps on foot points converge only linearly, and very slowly along
//!    weakly observable directions (a rotation about the instrument when the rays meet the
//!    walls nearly head-on), so the step test below would stop early, millimetres off.
//!    With [`IcpParams::accelerate`] (default) the Besl & McKay (1992) extrapolation is
//!    applied: when two consecutive steps point the same way (cosine > 0.99, rotation
//!    scaled by the RMS range) and shrink by a ratio `ρ < 1`, the pose jumps by
//!    `ρ/(1−ρ)` (≤ 50) times the last step, kept only if it lowers the score.
//! 4. **Convergence** when the pose changes by less than
//!    [`IcpParams::translation_tolerance`] and [`IcpParams::rotation_tolerance`], or after
//!    [`IcpParams::max_iterations`].
//!
//! The **registration error** `E(P)` ([`registration_error`]) is the weighted RMS distance
//! of the inlier pairs found at `P` (steps 1–2): `E = sqrt(Σ wᵢ dᵢ² / Σ wᵢ)`. Because
//! rejection is a percentile, `E` of two poses may be taken over different pairs, and with
//! six measurements a wrong pose that fits five of them beats the right one. Poses are
//! therefore *compared* by the truncated **score** ([`ErrorSummary::score`]): the same
//! weighted RMS over all pairs, a rejected pair counting as if it lay at the rejection
//! boundary (a truncated quadratic). ICP returns the visited pose with the smallest score
//! (normally the last one); Algorithm 3 selects, accepts and anneals by the score
//! (`σ ∝ √score`). Both are reported.
//!
//! ## Annealed perturbation (Algorithm 3)
//!
//! From the current estimate `P_k` (starting with the coarse `P_0`), `M` perturbations `P_k ⊕ ε` with
//! `ε ~ N(0, diag(σ_t², σ_t², σ_θ²))` (position in the model frame, heading) are drawn;
//! together with `P_k` itself (j = 0) the one with the smallest score is picked, ICP is run
//! from it, and its result is accepted if it lowers the score, else the picked perturbation
//! is kept. Then `σ_t = g_t·√E`, `σ_θ = g_θ·√E` (capped; `E` here is the score). The
//! defaults (16 perturbations, `g_t = 0.2 √m`, `g_θ = 0.3 rad/√m`, patience 6) were tuned
//! with `activesense bench-registration` on the test plans. (Refining `P_0` by one ICP
//! before the first round was tried and is worse: K = 10 p90 position error 26.8 cm
//! instead of 4.3 cm, because it commits early to the coarse pose's basin.) The loop stops after
//! [`AnnealParams::patience`] rounds without improvement, when `E` falls below
//! [`AnnealParams::min_error`], or after [`AnnealParams::max_rounds`]. Gaussian noise comes
//! from a seeded [`Pcg32`] through Box–Muller in f32 (libm; [`gaussian`]), so a seed fixes the
//! result bit for bit on host and MCU. Nothing is allocated; the per-call scratch is a few KiB
//! of stack ([`MAX_OBSERVATIONS`] pairs, ≈ 14 KiB at 500: one buffer per registration, lent
//! from the heading sweep to the annealing it ends in, README "The stack").

pub mod budget;
pub mod fits;
pub mod gaussian;
pub mod icp;
pub mod pose_distance;
pub mod precision;
pub mod refine;
pub mod sweep;

pub use fits::*;
pub use gaussian::*;
pub use icp::*;
pub use sweep::*;

use crate::world::floorplan::{closest_on_segment, FloorPlan};
use crate::world::geometry::{length, rotate, unit, v2, Pose2, Vec2};
use crate::world::math::{abs, atan2, cos, exp, ln, sin, sqrt, wrap_angle, TAU};
use heapless::Vec as HVec;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};

/// Fixed capacity of an observation set: every measurement of the longest episode the
/// protocol accepts ([`crate::protocol::MAX_EPISODE_ACTIONS`] actions, all of them measurements
/// at worst), so no reading is ever dropped (checked at compile time in [`crate::pipeline::runner`]).
pub use crate::limits::MAX_OBSERVATIONS;

/// Longest accepted range (m); far beyond any EDM and any valid plan.
pub const MAX_RANGE: f32 = 1000.0;

/// Slack (m) of the visibility constraint: a correspondent counts as visible from the
/// instrument when the first wall on the line of sight is no nearer than this before it.
pub const VISIBILITY_TOLERANCE: f32 = 1e-3;

/// Why a registration could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RegistrationError {
    /// More than [`MAX_OBSERVATIONS`] observations.
    TooManyObservations,
    /// Fewer than two observations (the rotation is undetermined).
    TooFewObservations,
    /// Measurement `i` has a non-finite bearing or a range outside `(0, MAX_RANGE]`.
    InvalidObservation(u8),
    /// The initial pose is not finite.
    InvalidPose,
    /// A parameter is out of range (non-finite, negative, or an empty fraction).
    InvalidParams,
}

impl core::fmt::Display for RegistrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RegistrationError::TooManyObservations => {
                write!(f, "at most {MAX_OBSERVATIONS} observations")
            }
            RegistrationError::TooFewObservations => {
                write!(f, "registration needs at least 2 observations")
            }
            RegistrationError::InvalidObservation(i) => {
                write!(f, "observation {i} has a bad bearing or range")
            }
            RegistrationError::InvalidPose => write!(f, "initial pose is not finite"),
            RegistrationError::InvalidParams => write!(f, "registration parameter out of range"),
        }
    }
}

/// One EDM measurement in the scene frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Encoder bearing `β` (rad, scene frame).
    pub bearing: f32,
    /// Measured range `r` (m).
    pub range: f32,
}

impl Measurement {
    /// A measurement `(β, r)`.
    pub fn new(bearing: f32, range: f32) -> Self {
        Measurement { bearing, range }
    }

    /// The scene point `r·unit(β)`.
    pub fn scene_point(&self) -> Vec2 {
        unit(self.bearing) * self.range
    }
}

#[derive(Clone, Copy, Debug)]
struct ObsPoint {
    /// Scene point.
    s: Vec2,
    /// Unit ray direction in the scene frame.
    d: Vec2,
}

/// A validated, fixed-capacity set of observations (scene points and ray directions
/// precomputed).
#[derive(Clone, Debug, Default)]
pub struct Observations {
    pts: HVec<ObsPoint, MAX_OBSERVATIONS>,
}

impl Observations {
    /// An empty set.
    pub const fn new() -> Self {
        Observations { pts: HVec::new() }
    }

    /// Validates and collects `obs`.
    pub fn from_slice(obs: &[Measurement]) -> Result<Self, RegistrationError> {
        let mut set = Self::new();
        for o in obs {
            set.push(*o)?;
        }
        Ok(set)
    }

    /// Adds one measurement.
    pub fn push(&mut self, o: Measurement) -> Result<(), RegistrationError> {
        let i = self.pts.len();
        if i >= MAX_OBSERVATIONS {
            return Err(RegistrationError::TooManyObservations);
        }
        if !(o.bearing.is_finite() && o.range > 0.0 && o.range <= MAX_RANGE) {
            return Err(RegistrationError::InvalidObservation(i as u8));
        }
        let d = unit(o.bearing);
        // Capacity checked above.
        let _ = self.pts.push(ObsPoint { s: d * o.range, d });
        Ok(())
    }

    /// The `(bearing, range)` pairs back, recovered from the stored scene points (libm, so
    /// the host and the instrument recover the same bits).
    pub fn readings(&self) -> impl Iterator<Item = (f32, f32)> + Clone + '_ {
        self.pts
            .iter()
            .map(|p| (crate::world::math::atan2(p.d.y, p.d.x), p.s.norm()))
    }

    /// Number of observations.
    pub fn len(&self) -> usize {
        self.pts.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.pts.is_empty()
    }

    /// Removes all observations.
    pub fn clear(&mut self) {
        self.pts.clear();
    }
}
