//! The evaluation harness (paper §4.2, Table 4): every agent on the fixed test plans, for
//! every rotation setting, in parallel, deterministic for its seeds.
//!
//! Outputs, in `--out DIR`:
//! - `results.json` — one object per (agent, rot_bins), plus the full configuration. It is a
//!   pure function of the options: two runs give byte-identical files (wall times are kept
//!   out of it, in `timing.json`).
//! - `results.md` — the Table-4 layout with 95 % confidence intervals, the coarse (pre-ICP)
//!   error and wall time, next to the paper's numbers.
//! - `budget.svg` — recognition rate and pose error against the measurement budget.
//!
//! Definitions (also in `docs/EVALUATION.md`):
//! - *recognition rate*: fraction of episodes whose belief argmax reached coarse success
//!   (within one translation cell and one rotation bin of the truth or a symmetric
//!   equivalent) by the end of the episode;
//! - *pose error*: symmetry-aware pose distance (Brégier et al.) between the refined
//!   registration and the truth, in metres, averaged over the **recognised** episodes. The
//!   paper does not say; its numbers only fit this reading (heuristic-1 with 10 bins: 0.94
//!   recognition and 0.092 m mean error, whereas an unrecognised episode registers metres
//!   away). The mean over all registered episodes (`pose_error_all`) and the median over
//!   recognised ones are reported beside it;
//! - *measurements / rotations*: mean counts per episode, including failed episodes that
//!   ran to the action limit;
//! - *right / wrong / unanswered* (the no-oracle table): an episode is answered when its
//!   termination rule ended it; an answer is right when its final pose is within the
//!   tolerance (`--tolerance`, default 5 cm and 0.5°) of the truth modulo symmetry.

//!
//! Modules, lowest first: [`record`] (one episode's row and curve), [`stats`] (intervals and
//! the per-group aggregation), [`harness`] (options, the parallel run, the report),
//! [`paper`] (the paper's Table 4, quoted), [`report`] (results.md and the output files),
//! [`experiments`] (the extra-measurements analysis), [`frontier`] (the stop's risk–cost
//! frontier over several `--stop-risk` settings), [`redraw`] (every committed chart drawn
//! again from its JSON). The charts are drawn by [`crate::plot`] from plain numbers.

pub mod experiments;
pub mod frontier;
pub mod harness;
pub mod paper;
pub mod record;
pub mod redraw;
pub mod report;
pub mod stats;

#[cfg(test)]
mod tests;
