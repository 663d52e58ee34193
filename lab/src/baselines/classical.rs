//! The classical grid Markov localizer (Fox, Burgard & Thrun 1998 style), the yardstick
//! for the GHT localizer of `activesense_core::localization` (paper §3.2, Table 1).
//!
//! Same grid ([`GridSpec`] over the plan's bounding box, `Nx × Ny × K`), same rotation
//! hypotheses (`K` bins × `sub_bins` headings per bin, exactly the GHT's), same frames. It
//! works from the inside out:
//!
//! * **Up front** (Table 1, "ray-casting precomputations", `O(|E||A||Nξ|)`): for every
//!   interior cell (centre inside the model), every rotation hypothesis `h` and every
//!   reachable encoder bearing `β_b = b·2π/steps` (`b = 0..steps`, default 54), the expected
//!   range `r̂ = ray_cast(centre, unit(h + β_b))`.
//! * **Per measurement** (`O(|A||Nξ|)`): the multiplicative Bayes update
//!   `bel(x) ← bel(x)·p(r | x)` with the robust likelihood
//!   `p(r | x) = (1 − ε)·N(r; r̂, σ²) + ε / r_max` (the additive uniform outlier floor),
//!   followed by normalisation. `σ² = σ_r² + σ_g² + (r̂·Δ)²/12` uses the same
//!   discretisation terms as the GHT vote kernel (`σ_g` = half the larger cell side, `Δ`
//!   the spacing of the rotation hypotheses).
//!
//! The belief is kept per rotation hypothesis (finer than the grid when `sub_bins > 1`, which
//! is the strongest classical variant: it keeps the heading consistent across measurements)
//! and marginalised onto the `K` bins for the PMF. There is no motion model: the
//! instrument only rotates in place, which moves the encoder bearing, not the pose.

use activesense_core::localization::grid::{self, CellIndex, GridSpec};
use activesense_core::localization::LocalizerConfig;
use activesense_core::world::geometry::unit;
use activesense_core::world::math::{exp, TAU};
use activesense_core::{FloorPlan, Pose2};
use anyhow::{ensure, Result};
use serde::{Deserialize, Serialize};

/// Parameters of the classical sensor model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassicalConfig {
    /// Outlier floor ε (probability that a reading is an outlier). Default 0.1.
    pub outlier_floor: f32,
    /// Range of the uniform outlier density (m). Default 50 (the simulated EDM's range).
    pub max_range: f32,
    /// Encoder steps per turn: the reachable bearings. Default 54.
    pub steps_per_turn: u16,
}

impl Default for ClassicalConfig {
    fn default() -> Self {
        ClassicalConfig {
            outlier_floor: 0.1,
            max_range: 50.0,
            steps_per_turn: 54,
        }
    }
}

/// The classical grid localizer (host only: its tables are megabytes).
#[derive(Clone, Debug)]
pub struct ClassicalLocalizer {
    grid: GridSpec,
    cfg: LocalizerConfig,
    ccfg: ClassicalConfig,
    /// Layer index of each interior cell.
    interior: Vec<u32>,
    /// Heading of each rotation hypothesis, and its bin.
    hyps: Vec<(f32, u8)>,
    /// Expected ranges, `[(hyp · n_interior + cell) · steps + bearing]`.
    expected: Vec<f32>,
    /// Belief per hypothesis and interior cell, `[hyp · n_interior + cell]`, normalised.
    belief: Vec<f32>,
    updates: u32,
}

impl ClassicalLocalizer {
    /// Builds the grid and runs the ray-casting precomputation for a centred plan.
    pub fn new(plan: &FloorPlan, cfg: &LocalizerConfig, ccfg: &ClassicalConfig) -> Result<Self> {
        cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        ensure!(ccfg.steps_per_turn > 0, "steps_per_turn must be positive");
        ensure!(
            (0.0..1.0).contains(&ccfg.outlier_floor) && ccfg.max_range > 0.0,
            "bad outlier model"
        );
        let (lo, hi) = plan.bounds();
        let grid = GridSpec::over_bounds(lo, hi, cfg.nx, cfg.ny, cfg.rot_bins, cfg.known_heading);
        let interior: Vec<u32> = (0..grid.layer_len() as u32)
            .filter(|&i| {
                let (ix, iy) = (i as usize % grid.nx as usize, i as usize / grid.nx as usize);
                plan.contains(grid.cell_centre(ix, iy))
            })
            .collect();
        let sub = cfg.effective_sub_bins();
        let mut hyps = Vec::new();
        for j in 0..grid.rot_bins {
            for s in 0..sub {
                let h = if grid.rot_bins > 1 {
                    let w = grid.bin_width();
                    j as f32 * w - 0.5 * w + (s as f32 + 0.5) * w / sub as f32
                } else {
                    grid.known_heading
                };
                hyps.push((h, j));
            }
        }
        let steps = ccfg.steps_per_turn as usize;
        let step = TAU / steps as f32;
        let mut expected = Vec::with_capacity(hyps.len() * interior.len() * steps);
        for &(h, _) in &hyps {
            for &c in &interior {
                let p =
                    grid.cell_centre(c as usize % grid.nx as usize, c as usize / grid.nx as usize);
                for b in 0..steps {
                    let r = plan
                        .ray_cast(p, unit(h + b as f32 * step))
                        .map_or(ccfg.max_range, |hit| hit.range);
                    expected.push(r);
                }
            }
        }
        let n = hyps.len() * interior.len();
        Ok(ClassicalLocalizer {
            grid,
            cfg: *cfg,
            ccfg: *ccfg,
            interior,
            hyps,
            expected,
            belief: vec![1.0 / n.max(1) as f32; n],
            updates: 0,
        })
    }

    /// Resets the belief to uniform (new episode on the same plan).
    pub fn clear(&mut self) {
        let n = self.belief.len().max(1);
        self.belief.fill(1.0 / n as f32);
        self.updates = 0;
    }

    /// The grid.
    pub fn grid(&self) -> &GridSpec {
        &self.grid
    }

    /// Bytes held by the tables and the belief (heap).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + 4 * (self.expected.len() + self.belief.len() + self.interior.len())
            + 8 * self.hyps.len()
    }

    /// Number of ray casts done up front.
    pub fn ray_casts(&self) -> usize {
        self.expected.len()
    }

    /// One measurement: encoder bearing `β` (rounded to the nearest reachable bearing) and
    /// range `r`.
    pub fn update(&mut self, bearing: f32, range: f32) -> Result<()> {
        ensure!(
            bearing.is_finite() && range.is_finite() && range > 0.0,
            "bad measurement"
        );
        let steps = self.ccfg.steps_per_turn as usize;
        let b = (bearing / (TAU / steps as f32)).round() as i64;
        let b = b.rem_euclid(steps as i64) as usize;
        let sg = 0.5 * self.grid.cell[0].max(self.grid.cell[1]);
        let delta = if self.grid.rot_bins > 1 {
            self.grid.bin_width() / self.cfg.effective_sub_bins() as f32
        } else {
            0.0
        };
        let base_var = sg * sg + self.cfg.range_sigma * self.cfg.range_sigma;
        let eps = self.ccfg.outlier_floor;
        let floor = eps / self.ccfg.max_range;
        let norm = (1.0 - eps) / (TAU).sqrt();
        let n_int = self.interior.len();
        let mut z = 0.0f32;
        for (k, bel) in self.belief.iter_mut().enumerate() {
            let rh = self.expected[k * steps + b];
            let var = base_var + rh * rh * delta * delta / 12.0;
            let d = range - rh;
            let lik = norm / var.sqrt() * exp(-0.5 * d * d / var) + floor;
            *bel *= lik;
            z += *bel;
        }
        debug_assert!(self.belief.len() == self.hyps.len() * n_int);
        if z > 0.0 && z.is_finite() {
            for bel in self.belief.iter_mut() {
                *bel /= z;
            }
        }
        self.updates += 1;
        Ok(())
    }

    /// The PMF marginalised onto the `Nx × Ny × K` grid (grid layout).
    pub fn pmf(&self) -> Vec<f32> {
        let l = self.grid.layer_len();
        let mut out = vec![0.0f32; self.grid.len()];
        let n_int = self.interior.len();
        for (hk, &(_, bin)) in self.hyps.iter().enumerate() {
            for (ci, &c) in self.interior.iter().enumerate() {
                out[bin as usize * l + c as usize] += self.belief[hk * n_int + ci];
            }
        }
        out
    }

    /// Most probable cell of the marginal PMF.
    pub fn argmax(&self) -> CellIndex {
        self.grid.cell_at(grid::argmax(&self.pmf()))
    }

    /// Shannon entropy (nats) of the marginal PMF.
    pub fn entropy(&self) -> f32 {
        grid::entropy(&self.pmf())
    }

    /// The symmetry-aware coarse-success test of the argmax ([`GridSpec::coarse_success`]).
    pub fn coarse_success(&self, truth: &Pose2, symmetry_order: u8) -> bool {
        self.grid
            .coarse_success(self.argmax(), truth, symmetry_order)
    }
}
