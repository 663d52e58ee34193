//! The GHT's inner loops (paper §3.2, Algorithms 1 and 2): one measurement's votes into
//! one rotation layer, and the running entropy accumulator the committed and the staged
//! belief share. Split from [`super::ght`], which owns the state they work on.

use super::grid::GridSpec;
use super::rtable::RTable;
use super::{LocalizerConfig, MAX_LAYER_CELLS};
use crate::world::geometry::{unit, Vec2};
use crate::world::math::{exp, ln, sqrt};

/// Vote quantum: a measurement adds `round(w·VOTE_QUANTA)` (`w ∈ [0, 1]`) to a slot.
pub const VOTE_QUANTA: u8 = 16;

/// Table index per unit of `q`.
pub(crate) const KERNEL_SCALE: f32 = (KERNEL_LEN - 1) as f32 / KERNEL_Q_MAX;

/// Entries of the vote-kernel table (`q = 0 ..= KERNEL_Q_MAX`).
pub const KERNEL_LEN: usize = 129;
/// Largest `q` with a non-zero vote: `exp(−q)·Q` rounds to 0 beyond `ln(2Q)` ≈ 3.47.
pub const KERNEL_Q_MAX: f32 = 3.5;
/// Exponent table length: differences to the reference of `0..=255 + Q` quanta.
pub(crate) const QTAB_LEN: usize = 256 + VOTE_QUANTA as usize;

/// Running `Z = Σq`, `S = Σ q ln q` over the interior cells in a fixed order; `H = ln Z −
/// S/Z`. With `λ > 0`, `q = exp(−λ·k/Q)` for a cell `k` quanta below the reference (table
/// lookup, `ln q = −λk/Q`); with `λ = 0`, `q` = the cell's weight. Committed and staged
/// entropy share it.
pub(super) struct EntropyAcc {
    gain: f32,
    z: f32,
    s: f32,
}

impl EntropyAcc {
    pub(super) fn new(gain: f32) -> Self {
        EntropyAcc {
            gain,
            z: 0.0,
            s: 0.0,
        }
    }

    /// A cell `below` quanta under the reference whose absolute level is `level` quanta.
    #[inline]
    pub(super) fn add(&mut self, qtab: &[f32; QTAB_LEN], below: u16, level: u32) {
        if self.gain > 0.0 {
            let k = (below as usize).min(QTAB_LEN - 1);
            let q = qtab[k];
            self.z += q;
            self.s += q * (-self.gain * k as f32 / VOTE_QUANTA as f32);
        } else if level > 0 {
            let v = level as f32 / VOTE_QUANTA as f32;
            self.z += v;
            self.s += v * ln(v);
        }
    }

    pub(super) fn entropy(&self, uniform: f32) -> f32 {
        if self.z <= 0.0 {
            uniform
        } else {
            (ln(self.z) - self.s / self.z).max(0.0)
        }
    }
}

/// [`vote_layer`] with a window, for one heading `sub` of `bin`, keeping only the 3 × 3
/// window cells centred on `(wx, wy)` (row-major, `0` outside the grid): the same votes and
/// the same kernel values, without filling or touching the rest of a layer. The
/// coarse-to-fine argmax runs 96 of these per reading; filling a 900-cell layer for each
/// cost more than the votes that reach the window. `cos_min` is `cos(cfg.max_incidence)`,
/// taken once per reading by the caller (libm's `cosf` is a software double-precision
/// routine on the M4F, and this runs 48 times per reading).
#[allow(clippy::too_many_arguments)]
pub(super) fn vote_window(
    grid: &GridSpec,
    (cfg, cos_min): (&LocalizerConfig, f32),
    rtable: &RTable,
    candidates: &[u16],
    interior: &[bool; MAX_LAYER_CELLS],
    kernel: &[u8; KERNEL_LEN],
    bin: u8,
    s: u8,
    bearing: f32,
    range: f32,
    window: (i32, i32),
) -> [u8; 9] {
    let weight = |q: f32| kernel.get((q * KERNEL_SCALE + 0.5) as usize).copied();
    window_votes(
        grid,
        (cfg, cos_min),
        rtable,
        candidates,
        interior,
        weight,
        bin,
        s,
        bearing,
        range,
        window,
    )
}

/// [`vote_window`] with the vote unquantised, `exp(−q)` in f32 (heading known, `K = 1`):
/// the window argmax at `K = 1` decides between neighbouring cells whose quantised votes
/// tie when the truth lies near their common edge ([`super::GhtLocalizer::refine_argmax`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn vote_window_exact(
    grid: &GridSpec,
    (cfg, cos_min): (&LocalizerConfig, f32),
    rtable: &RTable,
    candidates: &[u16],
    interior: &[bool; MAX_LAYER_CELLS],
    bearing: f32,
    range: f32,
    window: (i32, i32),
) -> [f32; 9] {
    let weight = |q: f32| Some(exp(-q));
    window_votes(
        grid,
        (cfg, cos_min),
        rtable,
        candidates,
        interior,
        weight,
        0,
        0,
        bearing,
        range,
        window,
    )
}

/// The window votes of [`vote_window`] with the kernel `weight(q)` (`None`: no vote); a
/// window cell keeps its best R-table point's weight.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn window_votes<T: Copy + Default + PartialOrd>(
    grid: &GridSpec,
    (cfg, cos_min): (&LocalizerConfig, f32),
    rtable: &RTable,
    candidates: &[u16],
    interior: &[bool; MAX_LAYER_CELLS],
    weight: impl Fn(f32) -> Option<T>,
    bin: u8,
    s: u8,
    bearing: f32,
    range: f32,
    (wx, wy): (i32, i32),
) -> [T; 9] {
    let mut win = [T::default(); 9];
    let nx = grid.nx as i32;
    let ny = grid.ny as i32;
    let (cw, ch) = (grid.cell[0], grid.cell[1]);
    let (inv_w, inv_h) = (1.0 / cw, 1.0 / ch);
    let (x0, y0) = (grid.origin[0], grid.origin[1]);
    let sg = 0.5 * cw.max(ch);
    let sub = cfg.effective_sub_bins();
    if s >= sub {
        return win;
    }
    let delta = if grid.rot_bins > 1 {
        grid.bin_width() / sub as f32
    } else {
        0.0
    };
    let rd = range * delta;
    let k_par = 0.5 / (sg * sg + cfg.range_sigma * cfg.range_sigma);
    let k_perp = 0.5 / (sg * sg + rd * rd / 12.0);
    let spread = cfg.spread as i32;
    let h = if grid.rot_bins > 1 {
        bin as f32 * grid.bin_width() - 0.5 * grid.bin_width() + (s as f32 + 0.5) * delta
    } else {
        grid.known_heading
    };
    let u: Vec2 = unit(h + bearing);
    let (ux, uy) = (u.x, u.y);
    let (ox, oy) = (range * ux, range * uy);
    let points = rtable.points();
    for p in candidates.iter().filter_map(|&i| points.get(i as usize)) {
        if ux * p.n[0] + uy * p.n[1] < cos_min {
            continue;
        }
        let ax = p.m[0] - ox;
        let ay = p.m[1] - oy;
        let fx = (ax - x0) * inv_w;
        let fy = (ay - y0) * inv_h;
        if !(fx >= 0.0 && fy >= 0.0 && fx < nx as f32 && fy < ny as f32) {
            continue;
        }
        let (cx, cy) = (fx as i32, fy as i32);
        if (cx - wx).abs() > spread + 1 || (cy - wy).abs() > spread + 1 {
            continue;
        }
        if !interior[(cy * nx + cx) as usize] {
            continue;
        }
        // The neighbourhood of `vote_layer`, cut to the window.
        let (ylo, yhi) = (
            (cy - spread).max(0).max(wy - 1),
            (cy + spread).min(ny - 1).min(wy + 1),
        );
        let (xlo, xhi) = (
            (cx - spread).max(0).max(wx - 1),
            (cx + spread).min(nx - 1).min(wx + 1),
        );
        for jy in ylo..=yhi {
            let dy = y0 + (jy as f32 + 0.5) * ch - ay;
            for jx in xlo..=xhi {
                let idx = (jy * nx + jx) as usize;
                if !interior[idx] {
                    continue;
                }
                let dx = x0 + (jx as f32 + 0.5) * cw - ax;
                let par = dx * ux + dy * uy;
                let perp = ux * dy - uy * dx;
                let q = par * par * k_par + perp * perp * k_perp;
                if let Some(wq) = weight(q) {
                    let w = ((jy - wy + 1) * 3 + (jx - wx + 1)) as usize;
                    if wq > win[w] {
                        win[w] = wq;
                    }
                }
            }
        }
    }
    win
}

/// The R-table entries that can vote into the window of [`vote_window`] around `(wx, wy)`
/// for a reading of `range` at any heading: a vote lands at `m − r·u`, so `m` must lie
/// within the window's reach (its cells ± `spread + 1`, as a disc) of a circle of radius
/// `r` around the window. Conservative (a centimetre of slack beyond the disc), so the
/// windowed votes over the candidates are exactly those over the whole table; returns how
/// many were written to `out`.
pub(super) fn window_candidates(
    grid: &GridSpec,
    cfg: &LocalizerConfig,
    rtable: &RTable,
    range: f32,
    (wx, wy): (i32, i32),
    out: &mut [u16],
) -> usize {
    let (cw, ch) = (grid.cell[0], grid.cell[1]);
    let reach = cfg.spread as f32 + 1.5;
    let c = (
        grid.origin[0] + (wx as f32 + 0.5) * cw,
        grid.origin[1] + (wy as f32 + 0.5) * ch,
    );
    let radius = sqrt(reach * cw * reach * cw + reach * ch * reach * ch) + 0.01 + 1e-4 * range;
    let (lo, hi) = ((range - radius).max(0.0), range + radius);
    let (lo2, hi2) = (lo * lo, hi * hi);
    let mut n = 0;
    for (i, p) in rtable.points().iter().enumerate() {
        let (dx, dy) = (p.m[0] - c.0, p.m[1] - c.1);
        let d2 = dx * dx + dy * dy;
        if d2 >= lo2 && d2 <= hi2 && n < out.len() {
            out[n] = i as u16;
            n += 1;
        }
    }
    n
}

/// Algorithms 1 and 2 for one rotation bin: fills `scratch` (one layer) with the
/// max-combined votes of measurement `(bearing, range)`; returns the number of votes.
/// `cos_min` is `cos(cfg.max_incidence)`, taken once per measurement by the caller.
#[allow(clippy::too_many_arguments)]
pub(super) fn vote_layer(
    grid: &GridSpec,
    (cfg, cos_min): (&LocalizerConfig, f32),
    rtable: &RTable,
    interior: &[bool; MAX_LAYER_CELLS],
    kernel: &[u8; KERNEL_LEN],
    scratch: &mut [u8],
    bin: u8,
    subs: (u8, u8),
    bearing: f32,
    range: f32,
    window: Option<(i32, i32)>,
) -> u32 {
    scratch.fill(0);
    let nx = grid.nx as i32;
    let ny = grid.ny as i32;
    let (cw, ch) = (grid.cell[0], grid.cell[1]);
    let (inv_w, inv_h) = (1.0 / cw, 1.0 / ch);
    let (x0, y0) = (grid.origin[0], grid.origin[1]);
    let sg = 0.5 * cw.max(ch);
    let sub = cfg.effective_sub_bins();
    let delta = if grid.rot_bins > 1 {
        grid.bin_width() / sub as f32
    } else {
        0.0
    };
    let rd = range * delta;
    let k_par = 0.5 / (sg * sg + cfg.range_sigma * cfg.range_sigma);
    let k_perp = 0.5 / (sg * sg + rd * rd / 12.0);
    let spread = cfg.spread as i32;
    let mut votes = 0u32;
    for s in subs.0..subs.1.min(sub) {
        let h = if grid.rot_bins > 1 {
            bin as f32 * grid.bin_width() - 0.5 * grid.bin_width() + (s as f32 + 0.5) * delta
        } else {
            grid.known_heading
        };
        let u: Vec2 = unit(h + bearing);
        let (ux, uy) = (u.x, u.y);
        let (ox, oy) = (range * ux, range * uy);
        for p in rtable.points() {
            // Algorithm 1: incidence precondition.
            if ux * p.n[0] + uy * p.n[1] < cos_min {
                continue;
            }
            let ax = p.m[0] - ox;
            let ay = p.m[1] - oy;
            let fx = (ax - x0) * inv_w;
            let fy = (ay - y0) * inv_h;
            // Algorithm 1: hypothesised agent inside the model (grid, then interior mask).
            if !(fx >= 0.0 && fy >= 0.0 && fx < nx as f32 && fy < ny as f32) {
                continue;
            }
            let (cx, cy) = (fx as i32, fy as i32);
            if !interior[(cy * nx + cx) as usize] {
                continue;
            }
            // A vote reaches cells within `spread` of its own: one that cannot reach the
            // 3 × 3 window around `window` is skipped (the window's values stay exact).
            if let Some((wx, wy)) = window {
                if (cx - wx).abs() > spread + 1 || (cy - wy).abs() > spread + 1 {
                    continue;
                }
            }
            votes += 1;
            // Algorithm 2: weighted vote into the neighbourhood.
            for jy in (cy - spread).max(0)..=(cy + spread).min(ny - 1) {
                let dy = y0 + (jy as f32 + 0.5) * ch - ay;
                for jx in (cx - spread).max(0)..=(cx + spread).min(nx - 1) {
                    let idx = (jy * nx + jx) as usize;
                    if !interior[idx] {
                        continue;
                    }
                    let dx = x0 + (jx as f32 + 0.5) * cw - ax;
                    let par = dx * ux + dy * uy;
                    let perp = ux * dy - uy * dx;
                    // exp(−q), quantised, from the table (nearest entry; 0 beyond the end).
                    let q = par * par * k_par + perp * perp * k_perp;
                    let k = (q * KERNEL_SCALE + 0.5) as usize;
                    if let Some(&wq) = kernel.get(k) {
                        if wq > scratch[idx] {
                            scratch[idx] = wq;
                        }
                    }
                }
            }
        }
    }
    votes
}
