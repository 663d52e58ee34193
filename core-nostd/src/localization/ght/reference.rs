//! The coarse-to-fine argmax as it was first written, every reading re-voted into a full
//! scratch layer: the reference the incremental [`GhtLocalizer::refine_argmax`] is tested
//! against, bit for bit. Compiled for the tests only.

use super::{GhtLocalizer, FINE_SUB_BINS};
use crate::localization::vote::{vote_layer, vote_window_exact, window_candidates};
use crate::localization::MAX_RTABLE_POINTS;
use crate::world::math::cos;

impl GhtLocalizer {
    /// The coarse-to-fine argmax as it was first written (every reading re-voted into a
    /// full scratch layer): the reference the incremental one is tested against.
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
}
