//! Fixed-grid localization by the Generalized Hough Transform (paper §3.2, Algorithms 1
//! and 2, Table 1).
//!
//! The belief over the agent pose lives on a fixed `Nx × Ny × Nξ` grid (defaults 30 × 30 ×
//! {1, 10}; capacity [`MAX_NX`] × [`MAX_NY`] × [`MAX_ROT_BINS`]). Instead of ray-casting
//! every interior cell up front (the classical Markov grid localizer, Fox et al. 1998), the
//! model's *perimeter* is discretised into an R-table ([`rtable`]) and every range
//! measurement votes, from the outside in, for the agent positions that would explain it
//! ([`ght`]).
//!
//! ## Frames and conventions
//! * **Model frame M**: the plan translated so its perimeter centroid is the origin
//!   ([`crate::FloorPlan::centered`]). [`GhtLocalizer::reset`] requires a centred plan.
//! * **Scene frame S**: the instrument's; a measurement is `(β, r)`, encoder bearing `β`
//!   (rad) and range `r` (m).
//! * **AgentPose** `(a, h)` = `Pose2 { x: a.x, y: a.y, theta: h }`: agent position `a` in M
//!   and initial heading `h` (the M-angle of encoder bearing 0); the scene→model transform.
//!   A measurement `(β, r)` travels along `unit(h + β)` in M and hits `a + r·unit(h + β)`.
//! * Grid axes ([`grid`]): translation = `a` over the plan's bounding box (the agent's
//!   offset from the model centroid); rotation = `h` (bin `j` centred at `j·2π/K`, or the
//!   caller's `known_heading` when `K = 1`).
//! * Symmetry: a plan with cyclic symmetry `C_n` about the centroid makes `(R(2πk/n)a,
//!   h + 2πk/n)` equivalent; [`GridSpec::coarse_success`] takes `symmetry_order: u8`.
//!
//! ## Memory (the MCU has 128 KiB of RAM)
//! [`GhtLocalizer`] is one fixed-size value, `size_of::<GhtLocalizer>()` = 46 912 bytes
//! (≤ 48 KiB) at capacity 30 × 30 × 10 with a 384-point R-table: accumulator 36 000 B
//! (`u8` per cell, bin and tracked heading hypothesis, [`ght::TRACKED_SUB_BINS`] = 4, in
//! quanta of 1/16 measurement above a common offset), vote scratch layer 900 B, staging layer
//! 1 800 B, `exp` table 1 088 B, R-table 6 144 B, interior mask 900 B. Build it with the
//! `const fn` [`GhtLocalizer::new_empty`] (e.g. in a
//! `static`) and fill it with [`GhtLocalizer::reset`]; nothing is allocated.

pub mod ght;
pub mod grid;
pub mod rtable;
mod vote;

pub use ght::{GhtLocalizer, Staged, VoteStats};
pub use grid::{CellIndex, GridSpec, Mode};
pub use rtable::{RPoint, RTable};

use crate::PlanError;
use serde::{Deserialize, Serialize};

pub use crate::limits::{MAX_NX, MAX_NY, MAX_ROT_BINS};
/// Cells of one rotation layer at capacity.
pub const MAX_LAYER_CELLS: usize = MAX_NX * MAX_NY;
/// Cells of the whole grid at capacity.
pub const MAX_CELLS: usize = MAX_LAYER_CELLS * MAX_ROT_BINS;
/// Largest number of rotation hypotheses per bin ([`LocalizerConfig::sub_bins`]).
pub const MAX_SUB_BINS: usize = 8;
/// R-table capacity (perimeter points).
pub const MAX_RTABLE_POINTS: usize = 384;
/// Largest vote neighbourhood radius (cells).
pub const MAX_SPREAD: u8 = 2;

/// Which configuration value is bad.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ConfigError {
    /// `nx`/`ny` is 0 or above [`MAX_NX`]/[`MAX_NY`].
    GridSize,
    /// `rot_bins` is 0 or above [`MAX_ROT_BINS`].
    RotBins,
    /// `sub_bins` is 0 or above [`MAX_SUB_BINS`].
    SubBins,
    /// `perimeter_spacing` is NaN or infinite.
    Spacing,
    /// `max_incidence` outside (0, π/2].
    Incidence,
    /// `range_sigma` negative or not finite.
    RangeSigma,
    /// `spread` above [`MAX_SPREAD`].
    Spread,
    /// `known_heading` not finite.
    KnownHeading,
    /// `evidence_gain` negative, not finite, or above 20.
    EvidenceGain,
}

/// Why the localizer refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LocError {
    /// A configuration value is out of range.
    BadConfig(ConfigError),
    /// The plan failed validation.
    BadPlan(PlanError),
    /// The plan is not in the model frame (perimeter centroid not at the origin).
    PlanNotCentred,
    /// The perimeter needs more R-table points than the fixed capacity at this spacing.
    PlanTooLarge {
        /// Points the plan needs.
        needed: u32,
        /// [`MAX_RTABLE_POINTS`].
        capacity: u32,
    },
    /// `update`/`stage` before a successful `reset`.
    NotReady,
    /// The measurement has a NaN/inf bearing or a range that is not positive and finite.
    BadMeasurement,
}

impl core::fmt::Display for LocError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LocError::BadConfig(c) => write!(f, "bad localizer configuration: {c:?}"),
            LocError::BadPlan(p) => write!(f, "bad floor-plan: {p}"),
            LocError::PlanNotCentred => write!(f, "plan is not centred on its perimeter centroid"),
            LocError::PlanTooLarge { needed, capacity } => write!(
                f,
                "plan needs {needed} R-table points, capacity is {capacity}"
            ),
            LocError::NotReady => write!(f, "localizer used before reset"),
            LocError::BadMeasurement => write!(f, "measurement is not finite/positive"),
        }
    }
}

/// Localizer configuration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalizerConfig {
    /// Translation cells along x (default 30).
    pub nx: u8,
    /// Translation cells along y (default 30).
    pub ny: u8,
    /// Rotation bins `K` (default 10; 1 = orientation known).
    pub rot_bins: u8,
    /// The known initial heading (rad, model frame), used only when `rot_bins == 1`.
    pub known_heading: f32,
    /// Rotation hypotheses evaluated inside each bin when `rot_bins > 1` (default 4): bin
    /// `j` is tried at headings `j·W − W/2 + (s + ½)·W/S`, `W = 2π/K`, `s = 0..S`. This
    /// counters the rotation smear (a 36° bin displaces a vote from a wall 5 m away by up
    /// to 1.6 m; with S = 4 by at most 0.39 m). Ignored when `rot_bins == 1`.
    pub sub_bins: u8,
    /// Perimeter discretisation (m). `≤ 0` = automatic: half the smaller cell side,
    /// enlarged as needed to fit [`MAX_RTABLE_POINTS`]. A positive value is used as is, and
    /// a plan that then needs too many points is [`LocError::PlanTooLarge`].
    pub perimeter_spacing: f32,
    /// Algorithm 1 incidence precondition: the angle between the ray and the hypothesised
    /// wall's outward normal must not exceed this (rad, default 80°: the simulated EDM returns up to 75°, plus slack for the
    /// rotation-hypothesis spacing).
    pub max_incidence: f32,
    /// Range noise σ of the sensor (m, default 0.02); the vote kernel along the ray.
    pub range_sigma: f32,
    /// Vote neighbourhood radius in cells (default 1: 3 × 3).
    pub spread: u8,
    /// How the accumulator `V` is normalised into the PMF. With `λ > 0`, `p ∝ exp(λ·V)`
    /// over the interior cells: the posterior under the model "each measurement either fits
    /// a cell (likelihood one) or is an outlier (likelihood e^−λ)". A measurement that does
    /// not fit a cell costs it a factor e^λ, never more, so no outlier can zero it (default
    /// `ln 10`). With `λ = 0` the PMF is the plain normalised accumulator `V / ΣV`, which is
    /// flat: its peak share stays roughly constant as evidence grows.
    pub evidence_gain: f32,
}

impl LocalizerConfig {
    /// The defaults listed field by field (30 × 30 × 10, 4 sub-bins, auto spacing, 80°,
    /// 2 cm, 3 × 3, λ = ln 10).
    pub const DEFAULT: LocalizerConfig = LocalizerConfig {
        nx: 30,
        ny: 30,
        rot_bins: 10,
        known_heading: 0.0,
        sub_bins: 4,
        perimeter_spacing: 0.0,
        max_incidence: 80.0 * core::f32::consts::PI / 180.0,
        range_sigma: 0.02,
        spread: 1,
        evidence_gain: core::f32::consts::LN_10,
    };

    /// Defaults with orientation known (`K = 1`, heading `h`).
    pub fn known_heading(h: f32) -> Self {
        LocalizerConfig {
            rot_bins: 1,
            known_heading: h,
            ..Self::DEFAULT
        }
    }

    /// Checks every field against its range and the fixed capacities.
    pub fn validate(&self) -> Result<(), LocError> {
        let bad = |e| Err(LocError::BadConfig(e));
        if self.nx == 0 || self.nx as usize > MAX_NX || self.ny == 0 || self.ny as usize > MAX_NY {
            return bad(ConfigError::GridSize);
        }
        if self.rot_bins == 0 || self.rot_bins as usize > MAX_ROT_BINS {
            return bad(ConfigError::RotBins);
        }
        if self.sub_bins == 0 || self.sub_bins as usize > MAX_SUB_BINS {
            return bad(ConfigError::SubBins);
        }
        if !self.perimeter_spacing.is_finite() {
            return bad(ConfigError::Spacing);
        }
        if !(self.max_incidence > 0.0 && self.max_incidence <= core::f32::consts::FRAC_PI_2) {
            return bad(ConfigError::Incidence);
        }
        if !(self.range_sigma >= 0.0 && self.range_sigma.is_finite()) {
            return bad(ConfigError::RangeSigma);
        }
        if self.spread > MAX_SPREAD {
            return bad(ConfigError::Spread);
        }
        if !self.known_heading.is_finite() {
            return bad(ConfigError::KnownHeading);
        }
        if !(self.evidence_gain >= 0.0 && self.evidence_gain <= 20.0) {
            return bad(ConfigError::EvidenceGain);
        }
        Ok(())
    }

    /// Rotation hypotheses per bin actually used (1 when `rot_bins == 1`).
    pub fn effective_sub_bins(&self) -> u8 {
        if self.rot_bins <= 1 {
            1
        } else {
            self.sub_bins
        }
    }
}

impl Default for LocalizerConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod window_tests;
