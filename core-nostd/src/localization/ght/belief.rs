//! Reading the belief out of the accumulator: a cell's level and probability, the
//! normaliser and the entropy, the PMF, the coarse and the refined argmax, the modes and
//! the coarse-success and peak-mass tests. Everything here only reads the votes
//! [`super::GhtLocalizer::update`] added, in the flat-index order the host and the MCU share.

use super::{GhtLocalizer, TRACKED_SUB_BINS};
use crate::localization::grid::{self, CellIndex, Mode};
use crate::localization::vote::{EntropyAcc, VOTE_QUANTA};
use crate::localization::{LocError, MAX_LAYER_CELLS};
use crate::world::math::ln;
use crate::Pose2;
use heapless::Vec as HVec;

impl GhtLocalizer {
    pub(super) fn uniform_entropy(&self) -> f32 {
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

    pub(super) fn normaliser(&self) -> f32 {
        // In flat-index order without the division per cell of `level` (bit-identical to
        // the sum of `q(i)`): this runs after every reading.
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
    /// bins: a cell within `min_separation` (Chebyshev in x, y and circular in bins,
    /// [`GridSpec::near`](grid::GridSpec::near)) of an already chosen mode is not a new mode,
    /// and a cell without weight never is.
    ///
    /// The same modes as a scan of [`GhtLocalizer::weight`] over every cell per mode, found
    /// by comparing levels in [`GhtLocalizer::for_each_level`]'s walk: the weight is
    /// `(level + base) / VOTE_QUANTA`, increasing in the level, and a cell outside the room
    /// holds level 0, so the same cell wins every comparison, without a division per cell
    /// (the rival search takes four modes after every reading past the stop gate, four
    /// passes over 9 000 cells at K = 10; `top_modes_match_the_weight_scan` in the tests).
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
    /// ([`GridSpec::coarse_success`](grid::GridSpec::coarse_success)); false before any vote.
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
}
