//! The GHT localizer: Algorithm 1 (preconditions) and Algorithm 2 (weighted voting) of
//! paper §3.2, a non-destructive accumulator, and a staging area.
//!
//! ## One measurement `(β, r)`
//! For every rotation bin `j` and every rotation hypothesis `h` of that bin
//! ([`LocalizerConfig::sub_bins`]) the ray direction in the model frame is `u = unit(h + β)`.
//! For every R-table point `d` (position `m_d`, outward normal `n_d`):
//!
//! * **Algorithm 1, incidence**: the ray must hit the wall from inside at a feasible angle,
//!   `u·n_d ≥ cos(max_incidence)`.
//! * **Algorithm 1, inside**: the hypothesised agent position `a = m_d − r·u` must lie in a
//!   grid cell whose centre is inside the model (the interior mask, computed once per plan
//!   with the exact point-in-polygon test; O(1) per vote instead of O(walls)).
//! * **Algorithm 2**: `a` votes into the `(2·spread+1)²` neighbourhood of its cell (interior
//!   cells only). For a neighbour centre `c` with offset `δ = c − a`, split into the
//!   component along the ray `δ_∥ = δ·u` and across it `δ_⊥ = u × δ`:
//!   `w = exp(−q)`, `q = δ_∥²/2σ_∥² + δ_⊥²/2σ_⊥²`, read from a table ([`KERNEL_LEN`]
//!   entries over `q ∈ [0, KERNEL_Q_MAX]`, built with libm at `reset`) already quantised to
//!   the u8 vote levels, so the inner loop has no `exp` (the quantisation made the tail
//!   beyond `KERNEL_Q_MAX` zero anyway). A truncated quadratic `1 − q/4.5` was as fast but
//!   lost recognition in episodes (heuristic-1, K = 1, 300 plans: 0.933 vs 0.990), with
//!   
//!   - measurement-model term `σ_∥² = σ_r² + σ_g²` (sensor range noise + grid quantisation,
//!     `σ_g` = half the larger cell side);
//!   - spatial-proximity term `σ_g²` in both directions;
//!   - rotational-proximity term `σ_⊥² = σ_g² + (r·Δ)²/12`: a heading error that is uniform
//!     over the spacing `Δ = 2π/(K·S)` of the rotation hypotheses moves the vote across the
//!     ray by up to `r·Δ/2`, so the kernel widens across the ray in proportion to the range.
//!
//! Within one measurement the votes of one heading hypothesis (slot) are combined by
//! **maximum** in a one-layer scratch buffer (the measurement's evidence for a cell is its
//! best explanation, so a cell crossed by several perimeter points is not counted several
//! times); the scratch layer is then **added** to that slot's accumulator. A cell's weight is
//! its best slot: one heading must explain every measurement. (Max-combining the sub-bins
//! of a bin per measurement, as first done, let a wrong cell collect each measurement from
//! a different heading; tracking them separately raised recognition after 12 measurements
//! at 30 % outliers from 0.37 to 0.60 on 40 test plans, classical 0.475.) Voting only ever
//! adds, so an outlier cannot zero the belief (paper: "non-destructive").
//!
//! The staging area ([`GhtLocalizer::stage`]) runs the same vote into the scratch layer and
//! folds it into an entropy sum without writing the accumulator.
//!
//! This file holds the state, its set-up and the votes (committed and staged); `refine` the
//! coarse-to-fine argmax, `belief` the read-out (probabilities, entropy, argmax, modes) and
//! `export` the policy's belief map.

mod belief;
mod export;
#[cfg(test)]
mod reference;
mod refine;

pub use export::max_u8x4;
use refine::FineSums;

use crate::world::math::{cos, exp};
use crate::FloorPlan;
use serde::{Deserialize, Serialize};

use super::grid::{CellIndex, GridSpec};
use super::rtable::RTable;
use super::vote::{vote_layer, EntropyAcc, QTAB_LEN};
pub use super::vote::{KERNEL_LEN, KERNEL_Q_MAX, VOTE_QUANTA};
use super::{
    LocError, LocalizerConfig, MAX_CELLS, MAX_LAYER_CELLS, MAX_RTABLE_POINTS, MAX_SUB_BINS,
};

/// What one vote (committed or staged) did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VoteStats {
    /// (perimeter point, rotation hypothesis) pairs that passed both preconditions.
    pub votes: u32,
    /// Total weight the measurement adds to the accumulator.
    pub mass: f32,
}

/// Result of evaluating a hypothetical measurement in the staging area.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Staged {
    /// Shannon entropy (nats) the belief would have after committing the measurement.
    pub entropy: f32,
    /// The vote statistics of the hypothetical measurement.
    pub stats: VoteStats,
}

/// Heading hypotheses tracked separately per rotation bin (accumulator slots). With
/// `sub_bins ≤ TRACKED_SUB_BINS` every sub-bin has its own slot; with more, sub-bin `s` of
/// `S` shares slot `s·T/S` (max-combined within a measurement).
pub const TRACKED_SUB_BINS: usize = 4;
const _: () = assert!(
    TRACKED_SUB_BINS == 4,
    "for_each_level walks four slot layers"
);
/// Heading hypotheses per bin of the coarse-to-fine re-vote ([`GhtLocalizer::refine_argmax`]).
pub const FINE_SUB_BINS: u8 = 32;
/// Rebase step: when a slot would overflow, every slot drops by this many quanta and the
/// common offset grows by it (cells that far below the peak have relative probability
/// `≤ e^{−λ·REBASE/Q}`, `e^{−18}` at the default λ).
const REBASE: u8 = 128;

const _: () = assert!(MAX_SUB_BINS >= TRACKED_SUB_BINS);

/// The GHT localizer. One fixed-size value (≤ 48 KiB at capacity), no allocation.
///
/// The accumulator keeps one `u8` evidence count per cell, rotation bin and tracked heading
/// hypothesis (slot), in quanta of `1/VOTE_QUANTA` measurement plus a common offset. A
/// cell's weight is the best slot of its bin: a heading hypothesis must explain *all*
/// measurements (paper §3.2's `LUT(d, ξ)` per rotated model), which the earlier one-float-
/// per-bin accumulator (max over sub-bins per measurement) did not enforce.
#[derive(Clone, Debug)]
pub struct GhtLocalizer {
    cfg: LocalizerConfig,
    grid: GridSpec,
    rtable: RTable,
    interior: [bool; MAX_LAYER_CELLS],
    n_interior: u16,
    /// `[(bin · TRACKED_SUB_BINS + slot) · layer + cell]`, quanta above `base`.
    acc: [u8; MAX_CELLS * TRACKED_SUB_BINS],
    /// Common offset of `acc` (quanta).
    base: u32,
    /// Largest value in `acc`.
    amax: u8,
    /// `exp(−λ·k/Q)`, `k = 0..QTAB_LEN`.
    qtab: [f32; QTAB_LEN],
    /// Quantised vote kernel `round(exp(−q)·Q)` at `q = i·KERNEL_Q_MAX/(KERNEL_LEN−1)`.
    kernel: [u8; KERNEL_LEN],
    total: f32,
    z: f32,
    /// One slot-layer of quantised votes of the current measurement.
    scratch: [u8; MAX_LAYER_CELLS],
    /// Staging: per cell of one bin, the best slot after the hypothetical vote.
    staged: [u16; MAX_LAYER_CELLS],
    updates: u32,
    ready: bool,
    /// The fine argmax ([`GhtLocalizer::refine_argmax`]) and the update count it saw.
    fine: Option<(u32, CellIndex)>,
    /// The coarse-to-fine argmax's running sums.
    fine_sums: FineSums,
}

impl GhtLocalizer {
    /// An empty localizer for a `static` or other in-place storage; call
    /// [`GhtLocalizer::reset`] before use.
    pub const fn new_empty() -> Self {
        GhtLocalizer {
            cfg: LocalizerConfig::DEFAULT,
            grid: GridSpec::EMPTY,
            rtable: RTable::new_empty(),
            interior: [false; MAX_LAYER_CELLS],
            n_interior: 0,
            acc: [0; MAX_CELLS * TRACKED_SUB_BINS],
            base: 0,
            amax: 0,
            qtab: [1.0; QTAB_LEN],
            kernel: [0; KERNEL_LEN],
            total: 0.0,
            z: 0.0,
            scratch: [0; MAX_LAYER_CELLS],
            staged: [0; MAX_LAYER_CELLS],
            updates: 0,
            ready: false,
            fine: None,
            fine_sums: FineSums::EMPTY,
        }
    }

    /// Prepares the localizer for a (centred) plan: validates, builds the grid over the
    /// plan's bounding box, the interior mask and the R-table, and clears the belief.
    /// On error the localizer is left not ready.
    pub fn reset(&mut self, plan: &FloorPlan, cfg: &LocalizerConfig) -> Result<(), LocError> {
        self.ready = false;
        cfg.validate()?;
        plan.validate().map_err(LocError::BadPlan)?;
        let (lo, hi) = plan.bounds();
        let c = plan.perimeter_centroid();
        let ext = (hi - lo).x.max((hi - lo).y);
        if c.x.abs() > 1e-3 * ext || c.y.abs() > 1e-3 * ext {
            return Err(LocError::PlanNotCentred);
        }
        let grid = GridSpec::over_bounds(lo, hi, cfg.nx, cfg.ny, cfg.rot_bins, cfg.known_heading);
        let spacing = if cfg.perimeter_spacing > 0.0 {
            cfg.perimeter_spacing
        } else {
            let auto = 0.5 * grid.cell[0].min(grid.cell[1]);
            // Each wall gets at most len/spacing + 1 points.
            let fit = plan.perimeter() / (MAX_RTABLE_POINTS - plan.len()) as f32;
            auto.max(fit * 1.001)
        };
        self.rtable.rebuild(plan, spacing)?;
        let mut n = 0u16;
        for iy in 0..grid.ny as usize {
            for ix in 0..grid.nx as usize {
                let inside = plan.contains(grid.cell_centre(ix, iy));
                self.interior[iy * grid.nx as usize + ix] = inside;
                n += inside as u16;
            }
        }
        self.n_interior = n;
        for (i, w) in self.kernel.iter_mut().enumerate() {
            let q = i as f32 * KERNEL_Q_MAX / (KERNEL_LEN - 1) as f32;
            *w = (exp(-q) * VOTE_QUANTA as f32 + 0.5) as u8;
        }
        for (k, q) in self.qtab.iter_mut().enumerate() {
            *q = exp(-cfg.evidence_gain * k as f32 / VOTE_QUANTA as f32);
        }
        self.cfg = *cfg;
        self.grid = grid;
        self.clear();
        self.ready = true;
        Ok(())
    }

    /// Forgets all votes (new episode on the same plan); keeps grid and R-table.
    pub fn clear(&mut self) {
        self.acc.fill(0);
        self.scratch.fill(0);
        self.base = 0;
        self.amax = 0;
        self.total = 0.0;
        self.updates = 0;
        self.fine = None;
        self.fine_sums = FineSums::EMPTY;
        self.z = self.normaliser();
    }

    /// Sets the known heading for `K = 1` (new episode on the same plan; clears the votes).
    pub fn set_known_heading(&mut self, h: f32) {
        self.cfg.known_heading = h;
        self.grid.known_heading = crate::world::math::wrap_angle(h);
        self.clear();
    }

    /// The accumulator's memory (36 KB) for another use while no episode runs (the
    /// device stages a policy upload there). The localizer is not ready afterwards:
    /// [`GhtLocalizer::reset`] must run before the next vote.
    pub fn idle_storage(&mut self) -> &mut [u8] {
        self.ready = false;
        self.total = 0.0;
        &mut self.acc
    }

    /// True after a successful [`GhtLocalizer::reset`].
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// The configuration in force.
    pub fn config(&self) -> &LocalizerConfig {
        &self.cfg
    }

    /// The grid geometry.
    pub fn grid(&self) -> &GridSpec {
        &self.grid
    }

    /// The R-table.
    pub fn rtable(&self) -> &RTable {
        &self.rtable
    }

    /// True when the centre of column `ix`, row `iy` lies inside the model.
    pub fn is_interior(&self, ix: usize, iy: usize) -> bool {
        ix < self.grid.nx as usize
            && iy < self.grid.ny as usize
            && self.interior[iy * self.grid.nx as usize + ix]
    }

    /// Number of interior cells per rotation layer.
    pub fn interior_cells(&self) -> usize {
        self.n_interior as usize
    }

    /// Committed measurements so far.
    pub fn updates(&self) -> u32 {
        self.updates
    }

    /// Slots in use per rotation bin.
    #[inline]
    pub(super) fn slots(&self) -> usize {
        (self.cfg.effective_sub_bins() as usize).min(TRACKED_SUB_BINS)
    }

    /// Best slot of flat cell `i` (quanta above `base`).
    #[inline]
    pub(super) fn level(&self, i: usize) -> u8 {
        let l = self.grid.layer_len();
        let (bin, cell) = (i / l, i % l);
        let mut m = 0u8;
        for s in 0..self.slots() {
            m = m.max(self.acc[(bin * TRACKED_SUB_BINS + s) * l + cell]);
        }
        m
    }

    /// The accumulated evidence of flat cell `i` (`i < grid().len()`), in measurements: the
    /// best heading hypothesis of the cell's bin. Voting only ever raises it.
    #[inline]
    pub fn weight(&self, i: usize) -> f32 {
        (self.level(i) as u32 + self.base) as f32 / VOTE_QUANTA as f32
    }

    /// The accumulator in the grid layout ([`GhtLocalizer::weight`] of every cell,
    /// `grid().len()` values).
    pub fn weights(&self) -> impl ExactSizeIterator<Item = f32> + '_ {
        (0..self.grid.len()).map(|i| self.weight(i))
    }

    /// Sum of the accumulator.
    pub fn total_weight(&self) -> f32 {
        self.total
    }

    fn check(&self, bearing: f32, range: f32) -> Result<(), LocError> {
        if !self.ready {
            return Err(LocError::NotReady);
        }
        if !bearing.is_finite() || !range.is_finite() || range <= 0.0 {
            return Err(LocError::BadMeasurement);
        }
        Ok(())
    }

    /// Sub-bins `lo..hi` that vote into slot `s`.
    #[inline]
    fn slot_subs(&self, s: usize) -> (u8, u8) {
        let sub = self.cfg.effective_sub_bins() as usize;
        let t = self.slots();
        // Sub-bin k belongs to slot k·t/sub.
        let lo = (s * sub).div_ceil(t);
        let hi = ((s + 1) * sub).div_ceil(t);
        (lo as u8, hi as u8)
    }

    /// Algorithms 1–2 for rotation bin `j`, accumulator slot `s`: fills the scratch layer
    /// with the measurement's max-combined votes and returns their number. `cos_min` is
    /// `cos(max_incidence)`, taken once per measurement.
    fn vote_slot(&mut self, (j, s): (usize, usize), bearing: f32, range: f32, cos_min: f32) -> u32 {
        let l = self.grid.layer_len();
        let subs = self.slot_subs(s);
        vote_layer(
            &self.grid,
            (&self.cfg, cos_min),
            &self.rtable,
            &self.interior,
            &self.kernel,
            &mut self.scratch[..l],
            j as u8,
            subs,
            bearing,
            range,
            None,
        )
    }

    /// Commits one measurement (encoder bearing `β` rad, range `r` m). A no-return must not
    /// be passed (it carries no range).
    pub fn update(&mut self, bearing: f32, range: f32) -> Result<VoteStats, LocError> {
        self.check(bearing, range)?;
        let l = self.grid.layer_len();
        let slots = self.slots();
        let used = self.grid.rot_bins as usize * TRACKED_SUB_BINS * l;
        if self.amax > u8::MAX - VOTE_QUANTA {
            for a in self.acc[..used].iter_mut() {
                *a = a.saturating_sub(REBASE);
            }
            self.amax -= REBASE;
            self.base += REBASE as u32;
        }
        let mut stats = VoteStats::default();
        let mut added = 0u32;
        let cos_min = cos(self.cfg.max_incidence);
        for j in 0..self.grid.rot_bins as usize {
            for s in 0..slots {
                stats.votes += self.vote_slot((j, s), bearing, range, cos_min);
                let o = (j * TRACKED_SUB_BINS + s) * l;
                for (a, &v) in self.acc[o..o + l].iter_mut().zip(&self.scratch[..l]) {
                    *a += v;
                    added += v as u32;
                    self.amax = self.amax.max(*a);
                }
            }
        }
        stats.mass = added as f32 / VOTE_QUANTA as f32;
        self.total += stats.mass;
        self.updates += 1;
        self.z = self.normaliser();
        Ok(stats)
    }

    /// Evaluates a hypothetical measurement without committing it: the entropy the belief
    /// would have after [`GhtLocalizer::update`] with the same arguments. Only the scratch
    /// layers are written; the committed belief is untouched.
    pub fn stage(&mut self, bearing: f32, range: f32) -> Result<Staged, LocError> {
        self.check(bearing, range)?;
        let l = self.grid.layer_len();
        let slots = self.slots();
        let mut stats = VoteStats::default();
        let mut added = 0u32;
        // Each measurement adds at most Q to a slot, so amax + Q bounds every staged level.
        let reference = self.amax as u16 + VOTE_QUANTA as u16;
        let mut acc = EntropyAcc::new(self.cfg.evidence_gain);
        let cos_min = cos(self.cfg.max_incidence);
        for j in 0..self.grid.rot_bins as usize {
            self.staged[..l].fill(0);
            for s in 0..slots {
                stats.votes += self.vote_slot((j, s), bearing, range, cos_min);
                let o = (j * TRACKED_SUB_BINS + s) * l;
                for ((m, &a), &v) in self.staged[..l]
                    .iter_mut()
                    .zip(&self.acc[o..o + l])
                    .zip(&self.scratch[..l])
                {
                    *m = (*m).max(a as u16 + v as u16);
                    added += v as u32;
                }
            }
            for (&m, &inside) in self.staged[..l].iter().zip(&self.interior[..l]) {
                if inside {
                    acc.add(&self.qtab, reference - m, m as u32 + self.base);
                }
            }
        }
        stats.mass = added as f32 / VOTE_QUANTA as f32;
        Ok(Staged {
            entropy: acc.entropy(self.uniform_entropy()),
            stats,
        })
    }
}

impl Default for GhtLocalizer {
    fn default() -> Self {
        Self::new_empty()
    }
}
