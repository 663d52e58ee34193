//! What one evaluated episode leaves behind: its summary row ([`EpisodeRow`]) and its state
//! sampled on the utility curve's cost grid (`EpisodeCurve`, recorded by
//! `CurveRecorder` while the episode runs), with the grids themselves (the measurement
//! budgets, the cost points). The lowest layer of [`crate::eval`]: [`super::stats`]
//! aggregates these, [`super::harness`] produces them.

use activesense_instrument::episode::{score, EpisodeView, Trajectory};
use serde::{Deserialize, Serialize};

/// Summary of one episode kept for aggregation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EpisodeRow {
    /// Plan seed.
    pub plan_seed: u32,
    /// The user's room name (`--plans-from` evaluations only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<String>,
    /// Coarse success at the end.
    pub recognised: bool,
    /// Measurement actions.
    pub measurements: u16,
    /// Rotation actions.
    pub rotations: u16,
    /// Accumulated cost.
    pub cost: f32,
    /// Pose error after refinement (m).
    pub pose_error: Option<f32>,
    /// Pose error of the coarse estimate (m).
    pub coarse_error: Option<f32>,
    /// Position error of the final pose, modulo symmetry (m): with `heading_error_deg`, what
    /// the tolerance judges.
    #[serde(default)]
    pub position_error: Option<f32>,
    /// Heading error of the final pose, modulo symmetry (degrees).
    #[serde(default)]
    pub heading_error_deg: Option<f32>,
    /// Room symmetry order.
    pub symmetry_order: u8,
    /// Measurements taken at an encoder bearing already measured in the episode.
    #[serde(default)]
    pub repeated_bearings: u16,
    /// The belief's stated confidence at the end: PMF mass within the coarse tolerance of
    /// the argmax and its symmetric equivalents (0 without a vote).
    #[serde(default)]
    pub final_peak_mass: f32,
    /// The termination rule ended the episode (not the action limit).
    #[serde(default)]
    pub stopped_by_rule: bool,
    /// With `--termination confident`: the calibrated estimate of P(wrong) the episode
    /// stopped on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub risk_at_stop: Option<f32>,
}

impl EpisodeRow {
    pub(crate) fn of(t: &Trajectory) -> Self {
        EpisodeRow {
            plan_seed: t.spec.plan_seed,
            plan: t.spec.user_plan.as_ref().map(|p| p.name.clone()),
            recognised: t.outcome.recognised,
            measurements: t.summary.measurements,
            rotations: t.summary.rotations,
            cost: t.summary.cost,
            pose_error: t.outcome.pose_error,
            coarse_error: t.outcome.coarse_error,
            position_error: t.outcome.errors.map(|e| e.position),
            heading_error_deg: t.outcome.errors.map(|e| e.heading.to_degrees()),
            symmetry_order: t.outcome.symmetry_order,
            final_peak_mass: 0.0,
            stopped_by_rule: t.end != activesense_instrument::episode::EndReason::ActionLimit,
            risk_at_stop: (t.end == activesense_instrument::episode::EndReason::Confident)
                .then_some(t.outcome.stop_risk)
                .flatten(),
            repeated_bearings: {
                let mut seen = std::collections::BTreeSet::new();
                t.steps
                    .iter()
                    .filter(|st| st.action == activesense_core::episode::Action::Measure)
                    .filter(|st| !seen.insert(st.bearing_index))
                    .count() as u16
            },
        }
    }
}

/// Largest measurement budget plotted.
pub const MAX_BUDGET: usize = 30;

/// Points of the utility-vs-cost curves: accumulated cost `0, Δ, …, CURVE_MAX_COST`.
pub const CURVE_POINTS: usize = 81;

/// Largest accumulated action cost on the curves (80 rotations and 8 measurements).
pub const CURVE_MAX_COST: f64 = 0.8;

/// Cost of curve point `i`.
pub fn curve_cost(i: usize) -> f64 {
    CURVE_MAX_COST * i as f64 / (CURVE_POINTS - 1) as f64
}

/// One episode's state sampled on the curve's cost grid (the state after the last action
/// whose accumulated cost is within the grid value; after the episode ended, its final
/// state).
#[derive(Clone, Debug, Default)]
pub(crate) struct EpisodeCurve {
    pub(crate) entropy: Vec<f32>,
    pub(crate) recognised: Vec<bool>,
    pub(crate) pose_error: Vec<Option<f32>>,
}

/// Records an episode's state after every action for [`EpisodeCurve`]; registers after
/// every returned range when `register` is set.
pub(crate) struct CurveRecorder {
    pub(crate) register: bool,
    /// (cost, entropy, recognised, pose error so far).
    pub(crate) samples: Vec<(f32, f32, bool, Option<f32>)>,
    /// The belief's peak mass (its stated confidence) after the last vote.
    pub(crate) peak_mass: f32,
}

impl CurveRecorder {
    pub(crate) fn observe(&mut self, v: EpisodeView<'_>) {
        let pipe = v.runner.pipeline();
        let loc = pipe.localizer();
        let last = self.samples.last().and_then(|s| s.3);
        let (cost, recognised) = match v.step {
            None => (0.0, false),
            Some(st) => (st.cost, st.coarse_success),
        };
        let measured = v.step.is_some_and(|st| st.range.is_some());
        if measured {
            // The belief changes only when a range is voted.
            self.peak_mass = loc.peak_mass(pipe.symmetry_order());
        }
        let pose_error = if self.register && measured {
            score(v.plan, v.truth, &v.runner.finish(v.plan)).pose_error
        } else {
            last
        };
        self.samples
            .push((cost, loc.entropy(), recognised, pose_error));
    }

    pub(crate) fn curve(&self) -> EpisodeCurve {
        let mut c = EpisodeCurve::default();
        let mut k = 0;
        for i in 0..CURVE_POINTS {
            let x = curve_cost(i) as f32 + 1e-6;
            while k + 1 < self.samples.len() && self.samples[k + 1].0 <= x {
                k += 1;
            }
            let s = self
                .samples
                .get(k)
                .copied()
                .unwrap_or((0.0, 0.0, false, None));
            c.entropy.push(s.1);
            c.recognised.push(s.2);
            c.pose_error.push(s.3);
        }
        c
    }
}
