//! The calibrated stop (issue 12): an instrument has no ground truth, so it stops when the
//! *estimated probability that its registration is wrong* falls below the user's risk
//! `P` ([`crate::episode::EpisodeConfig::stop_risk`], default 1 %).
//!
//! **What "wrong" means.** Under this stop the instrument answers with its refined pose,
//! so the answer is right when the cell that pose lies in is a coarse success (the
//! paper's criterion, applied to the answered pose instead of the belief argmax). The two
//! differ where the refinement leaves the argmax's cell: heuristic-1 at K = 10 on 300 test
//! plans, in 256 such moments the refined pose's cell was right 198 times and the argmax
//! 37 times (`cargo run --release -p activesense-sim --example stop_trace -- 300 10`).
//!
//! The belief's peak mass alone over-states its confidence once the heading is unknown
//! (K = 10: heuristic-1 stated 0.94 and was right 0.80 of the time, `docs/EVALUATION.md`).
//! What the belief cannot see, the readings can: a wrong pose leaves readings it does not
//! explain. So the estimate is a logistic model `P(wrong) = σ(w·x + b)` over
//! [`StopFeatures`] (belief and readings together), one per rotation setting, fitted on
//! training plans (seeds below the test set) by `activesense calibrate`, which writes
//! [`crate::stop::calibration`]. The features are computed only once the belief's peak mass
//! reaches [`GATE_PEAK_MASS`] (below it the instrument keeps measuring without running the
//! refinement); the calibration data is gathered under the same gate.

pub mod calibration;

use crate::world::math::{exp, ln};
use serde::{Deserialize, Serialize};

/// Peak mass from which the stop features are computed (and the stop considered).
pub const GATE_PEAK_MASS: f32 = 0.5;

/// Length scale (m) of the edge feature: about the registration's own error.
pub const EDGE_SCALE: f32 = 0.02;

/// Number of features of [`StopFeatures::to_vector`].
pub const FEATURES: usize = 12;

/// What the stop estimate looks at, after a measurement.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StopFeatures {
    /// Belief mass around the argmax and its symmetric equivalents
    /// ([`crate::localization::GhtLocalizer::peak_mass`]).
    pub peak_mass: f32,
    /// Entropy of the belief (nats).
    pub entropy: f32,
    /// Distinct bearings measured so far (a range repeated at one bearing checks nothing new:
    /// counting readings let an agent that repeats itself look certain).
    pub readings: u16,
    /// Readings taken at a bearing already measured. Repeating a range sharpens the voting
    /// belief without adding evidence, so a belief built on repeats over-states itself.
    pub repeats: u16,
    /// Distinct bearings whose readings the refined pose explains (within 3σ,
    /// [`crate::registration::RangeFit::explained_bearings`]).
    pub explained: u16,
    /// Unknowns of the pose (2 with the heading known, 3 without).
    pub unknowns: u8,
    /// Smallest eigenvalue of the readings' normalised information matrix at the argmax
    /// ([`crate::registration::observability`]).
    pub observability: f32,
    /// How far the refined pose lies from the argmax cell's centre, in cells (Chebyshev):
    /// above 1.5 the refinement says the argmax is not where the readings are.
    pub offset_cells: f32,
    /// How far the refined heading lies from the argmax bin's heading, in bins (0 with the
    /// heading known).
    pub offset_bins: f32,
    /// Distance (m) from the refined position to the nearest edge of the cell it lies in
    /// (the answer's cell). Coarse success asks the truth to lie in that cell, so a right
    /// registration a centimetre from the edge is a coin toss.
    pub edge_margin: f32,
    /// The refined pose lies in the argmax's cell, its heading within one bin of the
    /// argmax's: the coarse and the fine estimate agree. Where they do not, the refinement
    /// has overruled the belief, which is usually right but less certain.
    pub agrees: bool,
}

impl StopFeatures {
    /// The model's input vector: logit of the peak mass, entropy, ln(readings), readings
    /// left unexplained, explained readings beyond the unknowns (capped at 10: the checks
    /// the fit passed), observability, the refined pose's offsets from the argmax (cells,
    /// bins), closeness to the cell's edge `exp(−margin / 2 cm)`, the fraction of
    /// bearings left unexplained, repeated readings per distinct bearing, and whether the
    /// refined pose and the argmax disagree.
    pub fn to_vector(&self) -> [f32; FEATURES] {
        let p = self.peak_mass.clamp(1e-4, 1.0 - 1e-4);
        let unexplained = self.readings.saturating_sub(self.explained) as f32;
        let checks = (self.explained as f32 - self.unknowns as f32).clamp(-3.0, 10.0);
        [
            ln(p / (1.0 - p)),
            self.entropy,
            ln((self.readings as f32).max(1.0)),
            unexplained,
            checks,
            self.observability,
            self.offset_cells,
            self.offset_bins,
            exp(-self.edge_margin.max(0.0) / EDGE_SCALE),
            unexplained / (self.readings as f32).max(1.0),
            self.repeats as f32 / (self.readings as f32).max(1.0),
            if self.agrees { 0.0 } else { 1.0 },
        ]
    }
}

/// A fitted logistic model of `P(wrong)` for one rotation setting.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StopModel {
    /// Rotation bins K it was fitted for.
    pub rot_bins: u8,
    /// Weights of [`StopFeatures::to_vector`].
    pub weights: [f32; FEATURES],
    /// Bias.
    pub bias: f32,
}

impl StopModel {
    /// The estimated probability that the answered pose's cell is wrong.
    pub fn risk(&self, f: &StopFeatures) -> f32 {
        let x = f.to_vector();
        let z = self
            .weights
            .iter()
            .zip(x.iter())
            .fold(self.bias, |acc, (w, v)| acc + w * v);
        // σ(z), written so that neither branch overflows.
        if z >= 0.0 {
            1.0 / (1.0 + exp(-z))
        } else {
            let e = exp(z);
            e / (1.0 + e)
        }
    }

    /// The built-in model for `rot_bins` ([`crate::stop::calibration::MODELS`]): the one fitted
    /// for that K, else the one fitted for the nearest K.
    pub fn for_rot_bins(rot_bins: u8) -> &'static StopModel {
        let models = crate::stop::calibration::MODELS;
        let mut best = &models[0];
        for m in models.iter() {
            if m.rot_bins.abs_diff(rot_bins) < best.rot_bins.abs_diff(rot_bins) {
                best = m;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(peak: f32, readings: u16, explained: u16) -> StopFeatures {
        StopFeatures {
            peak_mass: peak,
            entropy: 2.0,
            readings,
            repeats: 0,
            explained,
            unknowns: 3,
            observability: 0.2,
            offset_cells: 0.3,
            offset_bins: 0.1,
            edge_margin: 0.1,
            agrees: true,
        }
    }

    #[test]
    fn risk_is_a_probability_and_follows_the_weights() {
        let m = StopModel {
            rot_bins: 10,
            weights: [-1.0, 0.0, 0.0, 2.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            bias: 0.5,
        };
        let sure = m.risk(&features(0.999, 8, 8));
        let unsure = m.risk(&features(0.6, 8, 5));
        assert!((0.0..=1.0).contains(&sure) && (0.0..=1.0).contains(&unsure));
        assert!(sure < 0.01 && unsure > 0.9, "{sure} {unsure}");
        // Extreme inputs stay finite.
        let extreme = StopModel {
            weights: [1e6; FEATURES],
            ..m
        };
        assert_eq!(extreme.risk(&features(1.0, 500, 0)), 1.0);
        let extreme = StopModel {
            weights: [-1e6; FEATURES],
            ..m
        };
        assert_eq!(extreme.risk(&features(1.0, 500, 500)), 0.0);
    }

    #[test]
    fn every_setting_has_a_model() {
        for k in [1u8, 2, 5, 10, 36] {
            let m = StopModel::for_rot_bins(k);
            assert!(m.weights.iter().all(|w| w.is_finite()) && m.bias.is_finite());
        }
        assert_eq!(StopModel::for_rot_bins(1).rot_bins, 1);
        assert_eq!(StopModel::for_rot_bins(10).rot_bins, 10);
    }
}
