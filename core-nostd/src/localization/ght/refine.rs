//! The coarse-to-fine argmax: the readings re-voted with finer heading hypotheses (or, with
//! the heading known, unquantised) into the 3 × 3 window around the coarse argmax only,
//! summed incrementally reading by reading, and the window's best cell kept as the
//! localizer's argmax until the next update.

use super::{GhtLocalizer, FINE_SUB_BINS};
use crate::localization::grid::CellIndex;
use crate::localization::vote::{vote_window, vote_window_exact, window_candidates, VOTE_QUANTA};
use crate::localization::MAX_RTABLE_POINTS;
use crate::world::math::cos;

/// The coarse-to-fine argmax's sums ([`GhtLocalizer::refine_argmax`]) for the window
/// around `centre`, over the first `readings` readings: 3 bins × [`FINE_SUB_BINS`]
/// headings × 9 cells (1.7 KiB; a reading adds at most [`VOTE_QUANTA`] to a sum, so u16
/// holds the longest episode), or at `K = 1` the unquantised votes of the 9 cells.
#[derive(Clone, Debug)]
pub(super) struct FineSums {
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

    pub(super) const EMPTY: FineSums = FineSums {
        centre: None,
        readings: 0,
        last: (0, 0),
        sums: [[[0; 9]; FINE_SUB_BINS as usize]; 3],
        exact: [0.0; 9],
    };
}

impl GhtLocalizer {
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
    pub(super) fn best_in_window<T: Copy + Default + PartialOrd>(
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
}
