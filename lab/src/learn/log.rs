//! The trainer's record of a run: one [`LogRow`] per logged update, written as `log.csv`
//! (one line each), printed as a progress line, and drawn as the learning curve
//! (`curve.svg`, [`curve_svg`]).

use super::hyper::HyperParams;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::io::Write as _;
use std::path::Path;

/// One line of the learning curve.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct LogRow {
    /// Update index (1-based).
    pub update: u64,
    /// Environment steps so far.
    pub env_steps: u64,
    /// Episodes finished so far.
    pub episodes: u64,
    /// Wall time so far (s).
    pub wall_s: f64,
    /// "imitation", "critic" (the critic's warm-up) or "a2c".
    pub phase: String,
    /// Mean return of the episodes finished since the last line.
    pub mean_return: f64,
    /// Their coarse-success rate.
    pub recognition: f64,
    /// Their mean measurements.
    pub measurements: f64,
    /// Their mean rotations.
    pub rotations: f64,
    /// Their mean action cost.
    pub cost: f64,
    /// Their mean pose error over recognised episodes (m).
    pub pose_error: Option<f64>,
    /// Mean policy entropy over the last update's samples (nats).
    pub policy_entropy: f64,
    /// Last update's value loss.
    pub value_loss: f64,
    /// Last update's gradient norm before clipping.
    pub grad_norm: f64,
    /// Environment steps per second since the start.
    pub steps_per_s: f64,
}

pub(super) const CSV_HEADER: &str = "update,env_steps,episodes,wall_s,phase,mean_return,recognition,measurements,rotations,cost,pose_error,policy_entropy,value_loss,grad_norm,steps_per_s\n";

pub(super) fn csv_line(r: &LogRow) -> String {
    format!(
        "{},{},{},{:.1},{},{:.4},{:.4},{:.3},{:.3},{:.4},{},{:.4},{:.5},{:.4},{:.1}\n",
        r.update,
        r.env_steps,
        r.episodes,
        r.wall_s,
        r.phase,
        r.mean_return,
        r.recognition,
        r.measurements,
        r.rotations,
        r.cost,
        r.pose_error.map(|e| format!("{e:.4}")).unwrap_or_default(),
        r.policy_entropy,
        r.value_loss,
        r.grad_norm,
        r.steps_per_s
    )
}

pub(super) fn row_line(r: &LogRow) -> String {
    format!(
        "update {:>6} [{}] steps {:>9} eps {:>7} return {:+.3} recognition {:.3} meas {:.2} rot {:.2} cost {:.3} entropy {:.3} vloss {:.4} ({:.0} steps/s)",
        r.update, r.phase, r.env_steps, r.episodes, r.mean_return, r.recognition,
        r.measurements, r.rotations, r.cost, r.policy_entropy, r.value_loss, r.steps_per_s
    )
}

pub(super) fn progress_bar(show: bool, updates: u64) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(updates);
    b.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} updates {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    b
}

/// The learning curve: mean return, recognition and cost against environment steps
/// (drawn by [`crate::plot::curve`]).
pub fn curve_svg(log: &[LogRow], hp: &HyperParams) -> String {
    use crate::plot::curve::{learning_curve_svg, CurvePanel};
    let panel = |title, f: fn(&LogRow) -> f64| CurvePanel {
        title,
        values: log.iter().map(f).collect(),
    };
    learning_curve_svg(
        &format!(
            "Learning curve: K = {}, seed {}, {} envs × {} steps per update",
            hp.rot_bins, hp.seed, hp.num_envs, hp.segment_len
        ),
        &log.iter().map(|r| r.env_steps as f64).collect::<Vec<_>>(),
        &[
            panel("mean return", |r| r.mean_return),
            panel("recognition (coarse success)", |r| r.recognition),
            panel("action cost per episode", |r| r.cost),
        ],
        log.iter()
            .rev()
            .find(|r| r.phase == "imitation")
            .map(|r| r.env_steps as f64),
    )
}

/// Writes `text` to `path`, creating parent directories.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    if let Some(p) = path.parent() {
        std::fs::create_dir_all(p)?;
    }
    let mut f =
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    f.write_all(text.as_bytes())?;
    Ok(())
}
