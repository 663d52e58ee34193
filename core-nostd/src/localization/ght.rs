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

use crate::world::math::{cos, exp, ln};
use crate::{FloorPlan, Pose2};
use heapless::Vec as HVec;
use serde::{Deserialize, Serialize};

use super::grid::{self, CellIndex, GridSpec, Mode};
use super::rtable::RTable;
use super::vote::{
    vote_layer, vote_window, vote_window_exact, window_candidates, EntropyAcc, QTAB_LEN,
};
pub use super::vote::{KERNEL_LEN, KERNEL_Q_MAX, VOTE_QUANTA};
use super::{
    Confidence, LocError, LocalizerConfig, MAX_CELLS, MAX_LAYER_CELLS, MAX_RTABLE_POINTS,
    MAX_SUB_BINS,
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

/// The coarse-to-fine argmax's sums ([`GhtLocalizer::refine_argmax`]) for the window
/// around `centre`, over the first `readings` readings: 3 bins × [`FINE_SUB_BINS`]
/// headings × 9 cells (1.7 KiB; a reading adds at most [`VOTE_QUANTA`] to a sum, so u16
/// holds the longest episode), or at `K = 1` the unquantised votes of the 9 cells.
#[derive(Clone, Debug)]
struct FineSums {
    centre: Option<CellIndex>,
    readings: u16,
    /// Bits of the last reading summed.
    last: (u32, u32),
    sums: [[[u16; 9]; FINE_SUB_BINS as usize]; 3],
    /// `K = 1`: Σ `exp(−q)` per window cell, summed in reading order.
    exact: [f32; 9],
}

// Every reading of the longest episode fits a u16 sum.
const _: () = assert!(crate::limits::MAX_OBSERVATIONS * VOTE_QUANTA as usize <= u16::MAX as usize);

impl FineSums {
    fn reset(&mut self, centre: CellIndex) {
        *self = FineSums::EMPTY;
        self.centre = Some(centre);
    }

    const EMPTY: FineSums = FineSums {
        centre: None,
        readings: 0,
        last: (0, 0),
        sums: [[[0; 9]; FINE_SUB_BINS as usize]; 3],
        exact: [0.0; 9],
    };
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
    fn slots(&self) -> usize {
        (self.cfg.effective_sub_bins() as usize).min(TRACKED_SUB_BINS)
    }

    /// Best slot of flat cell `i` (quanta above `base`).
    #[inline]
    fn level(&self, i: usize) -> u8 {
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

    /// Coarse-to-fine argmax (`K > 1`): re-votes `readings` (all committed `(bearing, range)`
    /// pairs) with [`FINE_SUB_BINS`] heading hypotheses per bin, for the 3 × 3 cells and the 3
    /// bins around [`GhtLocalizer::coarse_argmax`] only, and keeps the best of those cells
    /// (its best heading summed over the readings; the coarse argmax on ties) as
    /// [`GhtLocalizer::argmax`] until the next update.
    ///
    /// Why: the accumulator tracks 4 headings per 36° bin, and a heading up to 4.5° off
    /// shifts a reading's vote by up to `r·0.08` m, so the argmax often lands in the cell
    /// next to the truth (docs/localization.md). Eight tracked headings fixed that in
    /// episodes but need 36 KB more RAM; the fine re-vote needs none (the scratch layer and
    /// 1.7 KB of stack) and costs `3 · FINE_SUB_BINS` windowed votes per reading.
    ///
    /// Incremental: the sums are per reading, so while the coarse argmax (the window) stays
    /// where it was, only the readings added since the last call are voted
    /// (`FineSums`); a moved window re-votes them all. Each windowed vote keeps only the
    /// 3 × 3 window (`vote::vote_window`). Both leave the result bit for bit what the full
    /// re-vote gives (`fine_argmax_is_incremental_and_exact` in the tests); on the 20
    /// mcu-bench episodes (heuristic-1, K = 10) the measurement update went from 10.6 M to
    /// the figure in `results/mcu-bench/` (module docs of [`crate::registration::refine`]).
    pub fn refine_argmax(&mut self, readings: impl Iterator<Item = (f32, f32)> + Clone) {
        self.fine = None;
        let Some(c0) = self.coarse_argmax() else {
            return;
        };
        let known_heading = self.grid.rot_bins <= 1;
        let mut cfg = self.cfg;
        if !known_heading {
            cfg.sub_bins = FINE_SUB_BINS;
        }
        let (cx, cy) = (c0.ix as i32, c0.iy as i32);
        let k = self.grid.rot_bins.max(1) as i32;
        let bins = [0i32, -1, 1].map(|d| (c0.bin as i32 + d).rem_euclid(k) as u8);
        let sums = &mut self.fine_sums;
        if sums.centre != Some(c0) {
            sums.reset(c0);
        }
        let all = readings.clone();
        let cos_min = cos(cfg.max_incidence);
        let mut count = 0usize;
        for (i, (bearing, range)) in readings.enumerate() {
            count = i + 1;
            if i < sums.readings as usize {
                // The readings summed must still be the first ones (the last is checked).
                if i + 1 == sums.readings as usize
                    && (bearing.to_bits(), range.to_bits()) != sums.last
                {
                    self.fine_sums.reset(c0);
                    return self.refine_argmax(all);
                }
                continue;
            }
            let mut cand = [0u16; MAX_RTABLE_POINTS];
            let nc = window_candidates(&self.grid, &cfg, &self.rtable, range, (cx, cy), &mut cand);
            if known_heading {
                let win = vote_window_exact(
                    &self.grid,
                    (&cfg, cos_min),
                    &self.rtable,
                    &cand[..nc],
                    &self.interior,
                    bearing,
                    range,
                    (cx, cy),
                );
                for (sum, &v) in sums.exact.iter_mut().zip(win.iter()) {
                    *sum += v;
                }
            } else {
                for (b, &bin) in bins.iter().enumerate() {
                    for f in 0..FINE_SUB_BINS {
                        let win = vote_window(
                            &self.grid,
                            (&cfg, cos_min),
                            &self.rtable,
                            &cand[..nc],
                            &self.interior,
                            &self.kernel,
                            bin,
                            f,
                            bearing,
                            range,
                            (cx, cy),
                        );
                        for (sum, &v) in sums.sums[b][f as usize].iter_mut().zip(win.iter()) {
                            // ≤ VOTE_QUANTA per reading: no overflow below 4096 readings.
                            *sum = sum.saturating_add(v as u16);
                        }
                    }
                }
            }
            sums.readings = count as u16;
            sums.last = (bearing.to_bits(), range.to_bits());
        }
        if count < sums.readings as usize {
            self.fine_sums.reset(c0);
            return self.refine_argmax(all);
        }
        let best = if known_heading {
            let exact = &self.fine_sums.exact;
            self.best_in_window(c0, &[c0.bin], |_, w| exact[w])
        } else {
            let sums = &self.fine_sums.sums;
            self.best_in_window(c0, &bins, |b, w| {
                sums[b].iter().map(|h| h[w] as u32).max().unwrap_or(0)
            })
        };
        self.fine = Some((self.updates, best));
    }

    /// The interior cell of the 3 × 3 × 3 window around `c0` (bins `bins`) with the most
    /// votes, `votes(b, w)` being window cell `w`'s in bin `bins[b]` at its best fine
    /// heading; the coarse argmax `c0` keeps ties.
    fn best_in_window<T: Copy + Default + PartialOrd>(
        &self,
        c0: CellIndex,
        bins: &[u8],
        votes: impl Fn(usize, usize) -> T,
    ) -> CellIndex {
        let (nx, ny) = (self.grid.nx as i32, self.grid.ny as i32);
        let (cx, cy) = (c0.ix as i32, c0.iy as i32);
        let mut best = (T::default(), c0);
        for (b, &bin) in bins.iter().enumerate() {
            for w in 0..9 {
                let (x, y) = (cx + w as i32 % 3 - 1, cy + w as i32 / 3 - 1);
                if x < 0 || y < 0 || x >= nx || y >= ny || !self.interior[(y * nx + x) as usize] {
                    continue;
                }
                let v = votes(b, w);
                let c = CellIndex {
                    ix: x as u8,
                    iy: y as u8,
                    bin,
                };
                // The coarse argmax (first in this order) keeps ties.
                if v > best.0 || (c == c0 && v == best.0) {
                    best = (v, c);
                }
            }
        }
        best.1
    }

    /// The coarse-to-fine argmax as it was first written (every reading re-voted into a
    /// full scratch layer): the reference the incremental one is tested against.
    #[cfg(test)]
    pub(crate) fn refine_argmax_reference(
        &mut self,
        readings: impl Iterator<Item = (f32, f32)> + Clone,
    ) {
        self.fine = None;
        if self.grid.rot_bins <= 1 {
            // Heading known: every reading's exact window votes, summed from scratch.
            let Some(c0) = self.coarse_argmax() else {
                return;
            };
            let cos_min = cos(self.cfg.max_incidence);
            let window = (c0.ix as i32, c0.iy as i32);
            let mut exact = [0f32; 9];
            for (bearing, range) in readings {
                let mut cand = [0u16; MAX_RTABLE_POINTS];
                let nc = window_candidates(
                    &self.grid,
                    &self.cfg,
                    &self.rtable,
                    range,
                    window,
                    &mut cand,
                );
                let win = vote_window_exact(
                    &self.grid,
                    (&self.cfg, cos_min),
                    &self.rtable,
                    &cand[..nc],
                    &self.interior,
                    bearing,
                    range,
                    window,
                );
                for (sum, v) in exact.iter_mut().zip(win) {
                    *sum += v;
                }
            }
            let best = self.best_in_window(c0, &[c0.bin], |_, w| exact[w]);
            self.fine = Some((self.updates, best));
            return;
        }
        let Some(c0) = self.coarse_argmax() else {
            return;
        };
        let mut cfg = self.cfg;
        cfg.sub_bins = FINE_SUB_BINS;
        let l = self.grid.layer_len();
        let (nx, ny) = (self.grid.nx as i32, self.grid.ny as i32);
        let (cx, cy) = (c0.ix as i32, c0.iy as i32);
        let k = self.grid.rot_bins as i32;
        let bins = [0i32, -1, 1].map(|d| (c0.bin as i32 + d).rem_euclid(k) as u8);
        // Summed quanta per (bin, fine heading, window cell).
        let mut sums = [[[0u32; 9]; FINE_SUB_BINS as usize]; 3];
        let cos_min = cos(cfg.max_incidence);
        for (bearing, range) in readings {
            for (b, &bin) in bins.iter().enumerate() {
                for f in 0..FINE_SUB_BINS {
                    vote_layer(
                        &self.grid,
                        (&cfg, cos_min),
                        &self.rtable,
                        &self.interior,
                        &self.kernel,
                        &mut self.scratch[..l],
                        bin,
                        (f, f + 1),
                        bearing,
                        range,
                        Some((cx, cy)),
                    );
                    for (w, sum) in sums[b][f as usize].iter_mut().enumerate() {
                        let (x, y) = (cx + w as i32 % 3 - 1, cy + w as i32 / 3 - 1);
                        if x >= 0 && y >= 0 && x < nx && y < ny {
                            *sum += self.scratch[(y * nx + x) as usize] as u32;
                        }
                    }
                }
            }
        }
        let best = self.best_in_window(c0, &bins, |b, w| {
            sums[b].iter().map(|h| h[w]).max().unwrap_or(0)
        });
        self.fine = Some((self.updates, best));
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

    fn uniform_entropy(&self) -> f32 {
        let n = self.n_interior as usize * self.grid.rot_bins as usize;
        if n == 0 {
            0.0
        } else {
            ln(n as f32)
        }
    }

    /// Unnormalised probability of flat cell `i` (see [`LocalizerConfig::evidence_gain`]).
    #[inline]
    fn q(&self, i: usize) -> f32 {
        let l = self.grid.layer_len();
        if l == 0 || !self.interior[i % l] {
            return 0.0;
        }
        self.q_of_level(self.level(i))
    }

    /// [`GhtLocalizer::q`] of an interior cell whose best slot is `level` quanta above `base`.
    #[inline]
    fn q_of_level(&self, level: u8) -> f32 {
        if self.cfg.evidence_gain > 0.0 {
            self.qtab[self.amax.saturating_sub(level) as usize]
        } else if self.total > 0.0 {
            (level as u32 + self.base) as f32 / VOTE_QUANTA as f32
        } else {
            1.0
        }
    }

    /// The normalised probability of a cell from its level alone (`None`: outside the
    /// room): the same arithmetic as [`GhtLocalizer::prob`], bit for bit. A cell's
    /// probability depends on nothing else, so a caller that needs every cell's value (the
    /// policy's belief map) computes at most 256 of them and looks the rest up.
    pub fn prob_of_level(&self, level: Option<u8>) -> f32 {
        match level {
            Some(m) if self.z > 0.0 => self.q_of_level(m) / self.z,
            _ => 0.0,
        }
    }

    /// The largest level of any interior cell (`None` without interior cells): votes land
    /// only in interior cells, so it is the accumulator's running maximum, kept exact
    /// through rebasing.
    pub fn max_level(&self) -> Option<u8> {
        (self.n_interior > 0).then_some(self.amax)
    }

    /// Calls `f(i, level)` for every flat cell `i` in order, `level` as in
    /// [`GhtLocalizer::prob_of_level`]; no division per cell.
    pub fn for_each_level(&self, mut f: impl FnMut(usize, Option<u8>)) {
        let l = self.grid.layer_len();
        if l == 0 || l > MAX_LAYER_CELLS {
            return;
        }
        let slots = self.slots().clamp(1, TRACKED_SUB_BINS);
        let interior = &self.interior[..l];
        let mut i = 0;
        // One bin's slots are `TRACKED_SUB_BINS` consecutive layers: walk them side by side
        // (the instrument builds the policy's belief map from this every decision).
        for bin_acc in self
            .acc
            .chunks_exact(TRACKED_SUB_BINS * l)
            .take(self.grid.rot_bins as usize)
        {
            let (s0, rest) = bin_acc.split_at(l);
            let (s1, rest) = rest.split_at(l);
            let (s2, s3) = rest.split_at(l);
            // Unused slots stay 0, so the maximum over all four is the maximum over the
            // used ones: one loop, no per-cell branching on the slot count.
            debug_assert!(slots <= TRACKED_SUB_BINS);
            for ((((&a, &b), &c), &d), &inside) in s0.iter().zip(s1).zip(s2).zip(s3).zip(interior) {
                f(i, inside.then(|| a.max(b).max(c).max(d)));
                i += 1;
            }
        }
    }

    /// Every cell's level mapped through `table` (`outside` for a cell outside the room),
    /// written channel-interleaved: cell `(bin, y, x)` at `out[((y + 1)·side + x + 1)·K + bin]`
    /// for `x, y < max_side` (the int8 policy's padded belief layout). The values of
    /// [`GhtLocalizer::for_each_level`], row by row with no call per cell: at K = 10 this is
    /// 9 000 cells every policy decision on the instrument.
    pub fn write_levels_interleaved<T: Copy + PartialEq>(
        &self,
        out: &mut [T],
        side: usize,
        max_side: usize,
        table: &[T; 256],
        outside: T,
    ) {
        self.write_levels_interleaved_with(out, side, max_side, table, outside, max_u8x4)
    }

    /// [`GhtLocalizer::write_levels_interleaved`] with the per-byte maximum of two words
    /// supplied by the caller (`max4(a, b)`: each byte the larger of `a`'s and `b`'s; the
    /// int8 policy passes its DSP kernel on the M4). Any correct `max4` gives the same
    /// output.
    pub fn write_levels_interleaved_with<T: Copy + PartialEq>(
        &self,
        out: &mut [T],
        side: usize,
        max_side: usize,
        table: &[T; 256],
        outside: T,
        max4: impl Fn(u32, u32) -> u32,
    ) {
        let l = self.grid.layer_len();
        if l == 0 || l > MAX_LAYER_CELLS {
            return;
        }
        let (nx, ny, k) = (
            self.grid.nx as usize,
            self.grid.ny as usize,
            self.grid.rot_bins as usize,
        );
        let (w, h) = (nx.min(max_side), ny.min(max_side));
        if w == 0 {
            return;
        }
        let interior = &self.interior[..l];
        let zero_is_outside = table[0] == outside;
        for (bin, bin_acc) in self
            .acc
            .chunks_exact(TRACKED_SUB_BINS * l)
            .take(k)
            .enumerate()
        {
            let (s0, rest) = bin_acc.split_at(l);
            let (s1, rest) = rest.split_at(l);
            let (s2, s3) = rest.split_at(l);
            for y in 0..h {
                let r = y * nx..y * nx + w;
                let (r0, r1, r2, r3) = (
                    &s0[r.clone()],
                    &s1[r.clone()],
                    &s2[r.clone()],
                    &s3[r.clone()],
                );
                let inside = &interior[r];
                let start = ((y + 1) * side + 1) * k + bin;
                let Some(dst) = out.get_mut(start..start + (w - 1) * k + 1) else {
                    return;
                };
                // Four cells at a time: their four heading slots read as words and reduced
                // with `max4` (the caller's per-byte maximum: two DSP instructions on the
                // M4, [`crate::policy::int8::dot::Dot::max_u8x4`]), then one look-up and
                // one strided store per cell, inside the room or not (the cells outside are
                // set below).
                let quads = w / 4;
                let rows = [r0, r1, r2, r3];
                // The stride as a constant for the two localizers we ship (K = 1, 10): the
                // strided stores then take immediate offsets, which frees the registers the
                // loop otherwise spills (issue 22: the decision's worst case).
                match k {
                    10 => write_quads::<_, 10>(rows, dst, 10, quads, &max4, table),
                    1 => write_quads::<_, 1>(rows, dst, 1, quads, &max4, table),
                    _ => write_quads::<_, 0>(rows, dst, k, quads, &max4, table),
                }
                // Plain indices (the row slices are `w` long, so only the strided store is
                // checked): an iterator chain with `step_by` cost twice the instructions.
                for x in 4 * quads..w {
                    let v = if inside[x] {
                        table[r0[x].max(r1[x]).max(r2[x]).max(r3[x]) as usize]
                    } else {
                        outside
                    };
                    if let Some(o) = dst.get_mut(x * k) {
                        *o = v;
                    }
                }
            }
        }
        // A cell outside the room never holds a vote (level 0), so where level 0 maps to
        // `outside` the quads above wrote it already. Otherwise its pixel gets `outside` in
        // every bin now: the K planes of a pixel are adjacent, so this reads the interior
        // mask once per pixel rather than once per cell (issue 22: 5 % of a K = 10 decision
        // went to the test per cell).
        if zero_is_outside {
            return;
        }
        let quads = w / 4;
        for y in 0..h {
            let start = ((y + 1) * side + 1) * k;
            for (x, _) in interior[y * nx..y * nx + 4 * quads]
                .iter()
                .enumerate()
                .filter(|(_, &inside)| !inside)
            {
                if let Some(px) = out.get_mut(start + x * k..start + x * k + k) {
                    // (A one-cell pixel without the call to `memset` that `fill` makes.)
                    match px {
                        [one] => *one = outside,
                        _ => px.fill(outside),
                    }
                }
            }
        }
    }

    fn normaliser(&self) -> f32 {
        // In flat-index order without the division per cell of `level` (bit-identical to
        // the sum of `q(i)`; issue 22: this runs after every reading).
        let mut z = 0.0;
        self.for_each_level(|_, level| {
            z += level.map_or(0.0, |m| self.q_of_level(m));
        });
        z
    }

    /// Normalised probability of flat cell `i` (`i < grid().len()`).
    #[inline]
    pub fn prob(&self, i: usize) -> f32 {
        if self.z > 0.0 {
            self.q(i) / self.z
        } else {
            0.0
        }
    }

    /// Shannon entropy (nats) of the normalised belief. Before any vote the belief is
    /// uniform over the interior cells: `ln(interior cells × K)`.
    pub fn entropy(&self) -> f32 {
        let mut acc = EntropyAcc::new(self.cfg.evidence_gain);
        self.for_each_level(|_, level| {
            if let Some(m) = level {
                acc.add(&self.qtab, (self.amax - m) as u16, m as u32 + self.base);
            }
        });
        acc.entropy(self.uniform_entropy())
    }

    /// Normalised probability of one cell (uniform over interior cells before any vote).
    pub fn pmf(&self, c: CellIndex) -> f32 {
        self.prob(self.grid.index(c))
    }

    /// Writes the normalised PMF (grid layout, `grid().len()` values) into `out`; returns
    /// the number of values written (`min(out.len(), grid().len())`; a short buffer gets
    /// the first values). `Err(NotReady)` before [`GhtLocalizer::reset`].
    pub fn pmf_into(&self, out: &mut [f32]) -> Result<usize, LocError> {
        if !self.ready {
            return Err(LocError::NotReady);
        }
        let n = self.grid.len().min(out.len());
        for (i, o) in out[..n].iter_mut().enumerate() {
            *o = self.prob(i);
        }
        Ok(n)
    }

    /// The belief argmax: the fine argmax when [`GhtLocalizer::refine_argmax`] ran after the
    /// last update, else [`GhtLocalizer::coarse_argmax`]; `None` before any vote.
    pub fn argmax(&self) -> Option<CellIndex> {
        match self.fine {
            Some((seen, c)) if seen == self.updates && self.ready && self.total > 0.0 => Some(c),
            _ => self.coarse_argmax(),
        }
    }

    /// The most voted cell of the accumulator (first on ties); `None` before any vote.
    pub fn coarse_argmax(&self) -> Option<CellIndex> {
        if !self.ready || self.total <= 0.0 {
            return None;
        }
        let mut best = 0;
        let mut bv = 0u8;
        // Cells outside the room hold no votes (level 0), and only a level above 0 wins.
        self.for_each_level(|i, level| {
            let v = level.unwrap_or(0);
            if v > bv {
                bv = v;
                best = i;
            }
        });
        Some(self.grid.cell_at(best))
    }

    /// The AgentPose of the most voted cell; `None` before any vote.
    pub fn estimate(&self) -> Option<Pose2> {
        self.argmax().map(|c| self.grid.pose_of(c))
    }

    /// Up to `N` modes, strongest first, separated by more than `min_separation` cells /
    /// bins (see [`grid::top_modes`]).
    ///
    /// The same modes as [`grid::top_modes_by`] over [`GhtLocalizer::weight`], found by
    /// comparing levels in [`GhtLocalizer::for_each_level`]'s walk: the weight is
    /// `(level + base) / VOTE_QUANTA`, increasing in the level, and a cell outside the room
    /// holds level 0, so the same cell wins every comparison, without a division per cell
    /// (issue 22: the rival search takes four modes after every reading past the stop gate,
    /// four passes over 9 000 cells at K = 10; `top_modes_match_the_weight_scan` in the
    /// tests).
    pub fn top_modes<const N: usize>(&self, min_separation: u8) -> HVec<Mode, N> {
        let mut out: HVec<Mode, N> = HVec::new();
        while !out.is_full() {
            let mut best: Option<(usize, u8)> = None;
            self.for_each_level(|i, level| {
                let v = level.unwrap_or(0);
                if v as u32 + self.base == 0 || best.is_some_and(|(_, b)| v <= b) {
                    return;
                }
                let c = self.grid.cell_at(i);
                if out
                    .iter()
                    .any(|m| self.grid.near(m.cell, c, min_separation))
                {
                    return;
                }
                best = Some((i, v));
            });
            let Some((i, _)) = best else { break };
            let cell = self.grid.cell_at(i);
            let _ = out.push(Mode {
                cell,
                pose: self.grid.pose_of(cell),
                mass: self.prob(i),
            });
        }
        out
    }

    /// The coarse-success test of the argmax against a ground-truth AgentPose
    /// ([`GridSpec::coarse_success`]); false before any vote.
    pub fn coarse_success(&self, truth: &Pose2, symmetry_order: u8) -> bool {
        self.argmax()
            .is_some_and(|c| self.grid.coarse_success(c, truth, symmetry_order))
    }

    /// [`GhtLocalizer::coarse_success`] with an explicit translation tolerance (cells).
    pub fn coarse_success_within(&self, truth: &Pose2, symmetry_order: u8, tolerance: i16) -> bool {
        self.argmax().is_some_and(|c| {
            self.grid
                .coarse_success_within(c, truth, symmetry_order, tolerance)
        })
    }

    /// PMF mass within the coarse tolerance of the argmax and its C_n equivalents.
    pub fn peak_mass(&self, symmetry_order: u8) -> f32 {
        match self.argmax() {
            Some(c) => grid::mass_near(&self.grid, self.grid.len(), c, symmetry_order, |i| {
                self.prob(i)
            }),
            None => 0.0,
        }
    }

    /// The no-ground-truth test: peak mass ≥ `min_peak_mass` and entropy ≤ `max_entropy`.
    pub fn is_confident(&self, crit: &Confidence, symmetry_order: u8) -> bool {
        self.total > 0.0
            && self.peak_mass(symmetry_order) >= crit.min_peak_mass
            && self.entropy() <= crit.max_entropy
    }
}

/// The first `4 · quads` cells of one row of one bin into `dst` at stride `k` (cell `x` at
/// `dst[x · k]`): `table[level]` of the cell's best slot, the slots `rows` reduced four
/// cells at a time by `max4`. One bounds check per quad; the row slices are at least
/// `4 · quads` long (a shorter `dst` ends the row early). `K` is `k` as a constant, or 0
/// for a stride known only at run time.
#[inline(always)]
fn write_quads<T: Copy, const K: usize>(
    rows: [&[u8]; 4],
    dst: &mut [T],
    k: usize,
    quads: usize,
    max4: &impl Fn(u32, u32) -> u32,
    table: &[T; 256],
) {
    let [r0, r1, r2, r3] = rows;
    let k = if K == 0 { k } else { K };
    let word = |r: &[u8], x: usize| match r.get(x..x + 4) {
        Some(c) => u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
        None => 0,
    };
    for q in 0..quads {
        let x = 4 * q;
        let m = max4(
            max4(word(r0, x), word(r1, x)),
            max4(word(r2, x), word(r3, x)),
        );
        let Some(d) = dst.get_mut(x * k..x * k + 3 * k + 1) else {
            return;
        };
        let [b0, b1, b2, b3] = m.to_le_bytes();
        d[0] = table[b0 as usize];
        d[k] = table[b1 as usize];
        d[2 * k] = table[b2 as usize];
        d[3 * k] = table[b3 as usize];
    }
}

/// Each byte of the result the larger of the corresponding bytes of `a` and `b`.
#[inline]
pub fn max_u8x4(a: u32, b: u32) -> u32 {
    u32::from_le_bytes(core::array::from_fn(|j| {
        ((a >> (8 * j)) as u8).max((b >> (8 * j)) as u8)
    }))
}

impl Default for GhtLocalizer {
    fn default() -> Self {
        Self::new_empty()
    }
}
