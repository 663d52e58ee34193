//! The policy seam (paper §3.1, Fig. 2): what a sampling policy sees and how it answers.
//!
//! Every agent — the seven Table-3 baselines, the learnt actor-critic on the host, and its
//! int8 form on the instrument — implements [`Policy`]: it receives a [`PolicyInput`] built
//! by this module from the episode's own state and returns the next [`Action`]. The state
//! representation of Fig. 2 is extracted here, once, and nowhere else, so the trainer, the
//! host evaluation and the firmware feed a network bit-identical inputs:
//!
//! - **belief map** ([`PolicyInput::write_belief`]): the GHT belief as the localizer holds
//!   it, `K × 30 × 30` (`[bin][y][x]`), each cell's probability divided by the largest one,
//!   so values lie in `[0, 1]` whatever the belief's sharpness (and quantise to int8
//!   without a per-state scale). Cells outside the room are 0; before the first vote the
//!   interior is uniformly 1, which shows the network the room's shape.
//! - **side features** ([`PolicyInput::write_side`], [`SIDE_FEATURES`] values): the last
//!   [`SCAN_HISTORY`] topological scans (20 pixels each, most recent first), the last
//!   [`ACTION_HISTORY`] actions one-hot (most recent first; zeros before the episode's
//!   start), the beam's reference direction `(cos, sin)` of `bearing + heading offset`
//!   (the model-frame beam direction when the heading is known, K = 1; relative to rotation
//!   bin 0 otherwise), the step index over [`STEP_SCALE`] and the returned ranges over
//!   [`MEASUREMENT_SCALE`].
//!
//! The features are `f32` computed with plain arithmetic and `libm`, so the host and the
//! Cortex-M4F compute the same bits.

pub mod baselines;
pub mod builtin;
pub mod int8;

pub use baselines::BaselineAgent;

use crate::episode::Action;
use crate::episode::SCAN_PIXELS;
use crate::localization::{GhtLocalizer, MAX_NX, MAX_NY};
use crate::world::math::{cos, sin};

/// Side of the belief map the policy sees (cells per axis).
pub const BELIEF_SIDE: usize = MAX_NX;
/// Cells in one belief plane.
pub const BELIEF_PLANE: usize = BELIEF_SIDE * BELIEF_SIDE;
/// Topological scans the policy remembers.
pub const SCAN_HISTORY: usize = 4;
/// Actions the policy remembers (≥ 6, so heuristic-1's period fits in the window).
pub const ACTION_HISTORY: usize = 8;
/// Length of the side-feature vector.
pub const SIDE_FEATURES: usize = SCAN_HISTORY * SCAN_PIXELS + ACTION_HISTORY * 3 + 4;
/// The step index is divided by this (the evaluation's action limit).
pub const STEP_SCALE: f32 = 100.0;
/// The number of returned ranges is divided by this.
pub const MEASUREMENT_SCALE: f32 = 10.0;

const _: () = assert!(MAX_NX == MAX_NY, "the policy's belief map is square");

/// The recent scans and actions of an episode (fixed size, most recent first).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct History {
    scans: [u32; SCAN_HISTORY],
    scans_seen: u8,
    actions: [Option<Action>; ACTION_HISTORY],
}

impl History {
    /// An empty history.
    pub const fn new() -> Self {
        History {
            scans: [0; SCAN_HISTORY],
            scans_seen: 0,
            actions: [None; ACTION_HISTORY],
        }
    }

    /// Starts an episode with the scan seen before the first action.
    pub fn start(&mut self, initial_scan: u32) {
        *self = Self::new();
        self.push_scan(initial_scan);
    }

    fn push_scan(&mut self, scan: u32) {
        self.scans.copy_within(0..SCAN_HISTORY - 1, 1);
        self.scans[0] = scan;
        self.scans_seen = self.scans_seen.saturating_add(1);
    }

    /// Books one action and the scan seen after it.
    pub fn push(&mut self, action: Action, scan: u32) {
        self.actions.copy_within(0..ACTION_HISTORY - 1, 1);
        self.actions[0] = Some(action);
        self.push_scan(scan);
    }

    /// Scan `i` steps back (0 = latest); `None` beyond what was seen.
    pub fn scan(&self, i: usize) -> Option<u32> {
        (i < SCAN_HISTORY && i < self.scans_seen as usize).then(|| self.scans[i])
    }

    /// Action `i` steps back (0 = latest).
    pub fn action(&self, i: usize) -> Option<Action> {
        self.actions.get(i).copied().flatten()
    }
}

impl Default for History {
    fn default() -> Self {
        Self::new()
    }
}

/// Everything a policy may look at before choosing an action. Built by
/// [`crate::pipeline::runner::EpisodeRunner::input`]; a policy never sees the ground truth.
#[derive(Clone, Copy)]
pub struct PolicyInput<'a> {
    /// The GHT localizer holding the belief.
    pub localizer: &'a GhtLocalizer,
    /// Recent scans and actions.
    pub history: &'a History,
    /// Actions taken so far (the index of the action being chosen).
    pub step: u16,
    /// Ranges voted so far.
    pub measurements: u16,
    /// Encoder bearing (rad, scene frame).
    pub bearing: f32,
    /// Model-frame heading of encoder bearing 0 when known (K = 1), else 0.
    pub heading_offset: f32,
}

impl PolicyInput<'_> {
    /// Belief planes `K` (the localizer's rotation bins).
    pub fn belief_planes(&self) -> usize {
        self.localizer.grid().rot_bins as usize
    }

    /// Values [`PolicyInput::write_belief`] writes: `K × BELIEF_PLANE`.
    pub fn belief_len(&self) -> usize {
        self.belief_planes() * BELIEF_PLANE
    }

    /// Writes the belief map, `[bin][y][x]` over a `BELIEF_SIDE²` plane (a smaller grid is
    /// zero-padded), as probability over the largest probability. Returns the values
    /// written (`belief_len()`), or 0 when `out` is too short or the localizer not ready.
    pub fn write_belief(&self, out: &mut [f32]) -> usize {
        self.fill_belief(out, 0.0, |v| v)
    }

    /// The belief map of [`PolicyInput::write_belief`], each value quantised on the way
    /// with [`crate::policy::int8::quantize_value`] (`scale`, `zero_point`): exactly the
    /// quantisation of the float map, without a `K × 900` float buffer (36 KB at K = 10,
    /// too much for the instrument). Returns the values written, or 0 as `write_belief`.
    pub fn write_belief_q(&self, out: &mut [i8], scale: f32, zero_point: i32) -> usize {
        let p = crate::policy::int8::QuantParams { scale, zero_point };
        let q = |v| crate::policy::int8::quantize_value(v, p);
        self.fill_belief(out, q(0.0), q)
    }

    /// The value of every belief level (`table[level]`) and of a cell outside the room,
    /// each `map(probability / peak)`.
    fn level_table<T: Copy + PartialEq>(&self, map: impl Fn(f32) -> T) -> ([T; 256], T) {
        let loc = self.localizer;
        // A cell's probability is a function of its level (0..=255) alone, and increases
        // with it: the peak is the top level's (the localizer keeps it), and each cell's value is one of 256, each
        // computed by exactly the arithmetic `prob(i) * scale` would do. On the Cortex-M4 this
        // took the K = 10 map from millions of instructions to one table look-up per cell.
        let top = loc.max_level();
        let peak = loc.prob_of_level(top).max(0.0);
        let scale = if peak > 0.0 { 1.0 / peak } else { 0.0 };
        let outside = map(loc.prob_of_level(None) * scale);
        let mut table = [outside; 256];
        let Some(top) = top else {
            return (table, outside);
        };
        let value = |m: u8| map(loc.prob_of_level(Some(m)) * scale);
        // Every step of `value` (a table read, a division, products, the caller's rounding)
        // is monotone, so the values do not decrease with the level: from the top down, once
        // a level gives level 0's value, every level below gives it too. Far below the peak
        // that is most levels (they round to the zero point), and each one is two divisions
        // and a software `roundf` on the M4 (in the decision's worst case, every level).
        let bottom = value(0);
        let mut m = top;
        while m > 0 {
            let v = value(m);
            if v == bottom {
                break;
            }
            table[m as usize] = v;
            m -= 1;
        }
        table[..=m as usize].fill(bottom);
        (table, outside)
    }

    /// The quantised belief map of [`PolicyInput::write_belief_q`] in the int8 network's
    /// convolution layout (`crate::policy::int8::fast`): cell `(bin, y, x)` at
    /// `out[((y + 1)·side + x + 1)·K + bin]`, the `K` planes of a pixel adjacent, one row and
    /// column of padding before the map. Writes only the map's cells (the caller fills the
    /// rest with the zero point, the quantised 0). Returns `belief_len()`, or 0 when the
    /// localizer is not ready or `out` is shorter than `side² · K` or `side ≤ BELIEF_SIDE`.
    pub fn write_belief_q_hwc(
        &self,
        out: &mut [i8],
        scale: f32,
        zero_point: i32,
        side: usize,
    ) -> usize {
        let loc = self.localizer;
        let k = self.belief_planes();
        if !loc.is_ready() || side <= BELIEF_SIDE || out.len() < side * side * k {
            return 0;
        }
        let p = crate::policy::int8::QuantParams { scale, zero_point };
        let (table, outside) = self.level_table(|v| crate::policy::int8::quantize_value(v, p));
        loc.write_levels_interleaved_with(
            out,
            side,
            BELIEF_SIDE,
            &table,
            outside,
            <crate::policy::int8::Fast as crate::policy::int8::dot::Dot>::max_u8x4,
        );
        self.belief_len()
    }

    /// The one belief extraction both writers share: `map(probability / peak)` per cell,
    /// `blank` outside the grid.
    fn fill_belief<T: Copy + PartialEq>(
        &self,
        out: &mut [T],
        blank: T,
        map: impl Fn(f32) -> T,
    ) -> usize {
        let loc = self.localizer;
        let n = self.belief_len();
        if !loc.is_ready() || out.len() < n {
            return 0;
        }
        let g = loc.grid();
        let (nx, ny) = (g.nx as usize, g.ny as usize);
        let (table, outside) = self.level_table(map);
        if nx == BELIEF_SIDE && ny == BELIEF_SIDE {
            // The grid is the map: flat cell index = output index.
            loc.for_each_level(|i, lv| {
                if let Some(o) = out.get_mut(i) {
                    *o = lv.map_or(outside, |m| table[m as usize]);
                }
            });
            return n;
        }
        out[..n].iter_mut().for_each(|v| *v = blank);
        // Cells come in grid order, [bin][y][x]: walk the output position along.
        let (mut x, mut y, mut base) = (0usize, 0usize, 0usize);
        loc.for_each_level(|_, lv| {
            if y < BELIEF_SIDE && x < BELIEF_SIDE {
                out[base + y * BELIEF_SIDE + x] = match lv {
                    Some(m) => table[m as usize],
                    None => outside,
                };
            }
            x += 1;
            if x == nx {
                x = 0;
                y += 1;
                if y == ny {
                    y = 0;
                    base += BELIEF_PLANE;
                }
            }
        });
        n
    }

    /// Writes the [`SIDE_FEATURES`] side features (layout in the module doc).
    pub fn write_side(&self, out: &mut [f32; SIDE_FEATURES]) {
        let mut k = 0;
        for s in 0..SCAN_HISTORY {
            let scan = self.history.scan(s);
            for p in 0..SCAN_PIXELS {
                out[k] = match scan {
                    Some(m) if m & (1 << p) != 0 => 1.0,
                    _ => 0.0,
                };
                k += 1;
            }
        }
        for a in 0..ACTION_HISTORY {
            let act = self.history.action(a);
            for (j, want) in [Action::RotateLeft, Action::RotateRight, Action::Measure]
                .into_iter()
                .enumerate()
            {
                out[k + j] = if act == Some(want) { 1.0 } else { 0.0 };
            }
            k += 3;
        }
        let beam = self.bearing + self.heading_offset;
        out[k] = cos(beam);
        out[k + 1] = sin(beam);
        out[k + 2] = self.step as f32 / STEP_SCALE;
        out[k + 3] = self.measurements as f32 / MEASUREMENT_SCALE;
    }
}

/// A sampling policy: chooses the next action from what the instrument knows.
pub trait Policy {
    /// The next action. Called once per action of the episode, in order.
    fn act(&mut self, input: &PolicyInput<'_>) -> Action;
}

/// The Table-3 baselines ignore the state by definition.
impl Policy for BaselineAgent {
    fn act(&mut self, _input: &PolicyInput<'_>) -> Action {
        self.next_action()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localization::LocalizerConfig;
    use crate::world::geometry::unit;

    #[test]
    fn belief_map_is_probability_over_peak_bit_for_bit() {
        // The table-driven extraction equals the plain definition prob(i) · (1 / peak) at
        // every cell, before and after votes, with the heading known and unknown.
        let plan = crate::fixtures::l_room_8x6();
        let truth = crate::Pose2::new(-1.0, -0.5, 0.3);
        for cfg in [
            LocalizerConfig::known_heading(0.3),
            LocalizerConfig {
                rot_bins: 10,
                ..LocalizerConfig::DEFAULT
            },
        ] {
            let mut loc = GhtLocalizer::new_empty();
            loc.reset(&plan, &cfg).unwrap();
            let history = History::new();
            for k in 0..6 {
                let input = PolicyInput {
                    localizer: &loc,
                    history: &history,
                    step: k,
                    measurements: k,
                    bearing: 0.0,
                    heading_offset: 0.0,
                };
                let mut fast = [0.0f32; 10 * BELIEF_PLANE];
                let n = input.write_belief(&mut fast);
                assert_eq!(n, cfg.rot_bins as usize * BELIEF_PLANE);
                let g = loc.grid();
                let peak = (0..g.len()).map(|i| loc.prob(i)).fold(0.0f32, f32::max);
                let scale = if peak > 0.0 { 1.0 / peak } else { 0.0 };
                for i in 0..g.len() {
                    let c = g.cell_at(i);
                    let o =
                        c.bin as usize * BELIEF_PLANE + c.iy as usize * BELIEF_SIDE + c.ix as usize;
                    assert_eq!(
                        fast[o].to_bits(),
                        (loc.prob(i) * scale).to_bits(),
                        "cell {i}"
                    );
                }
                // The int8 network's padded, channel-interleaved map holds the same
                // quantised values as the planar one, the zero point around them.
                let (scale_q, zp) = (1.0 / 255.0, -128);
                let mut planar = [0i8; 10 * BELIEF_PLANE];
                assert_eq!(input.write_belief_q(&mut planar, scale_q, zp), n);
                // Each quantised cell is exactly the quantised probability (the level table
                // stops evaluating levels once they give level 0's value).
                let q = crate::policy::int8::QuantParams {
                    scale: scale_q,
                    zero_point: zp,
                };
                for i in 0..g.len() {
                    let c = g.cell_at(i);
                    let o =
                        c.bin as usize * BELIEF_PLANE + c.iy as usize * BELIEF_SIDE + c.ix as usize;
                    let want = crate::policy::int8::quantize_value(loc.prob(i) * scale, q);
                    assert_eq!(planar[o], want, "int8 cell {i}");
                }
                let (side, kb) = (BELIEF_SIDE + 1, cfg.rot_bins as usize);
                let mut hwc = [zp as i8; 31 * 31 * 10];
                assert_eq!(input.write_belief_q_hwc(&mut hwc, scale_q, zp, side), n);
                for (i, &v) in hwc[..side * side * kb].iter().enumerate() {
                    let (y, x, b) = (i / kb / side, i / kb % side, i % kb);
                    let want = if x == 0 || y == 0 {
                        zp as i8
                    } else {
                        planar[b * BELIEF_PLANE + (y - 1) * BELIEF_SIDE + x - 1]
                    };
                    assert_eq!(v, want, "bin {b} y {y} x {x}");
                }
                let bearing = k as f32 * 0.9;
                let hit = plan
                    .ray_cast(truth.translation(), unit(truth.theta + bearing))
                    .unwrap();
                loc.update(bearing, hit.range).unwrap();
            }
        }
    }

    #[test]
    fn history_keeps_the_most_recent_first() {
        let mut h = History::new();
        h.start(0b1);
        assert_eq!(h.scan(0), Some(1));
        assert_eq!(h.scan(1), None);
        assert_eq!(h.action(0), None);
        h.push(Action::Measure, 0b10);
        h.push(Action::RotateLeft, 0b100);
        assert_eq!(h.scan(0), Some(4));
        assert_eq!(h.scan(2), Some(1));
        assert_eq!(h.action(0), Some(Action::RotateLeft));
        assert_eq!(h.action(1), Some(Action::Measure));
        for _ in 0..20 {
            h.push(Action::RotateRight, 7);
        }
        assert_eq!(h.action(ACTION_HISTORY - 1), Some(Action::RotateRight));
        assert_eq!(h.scan(SCAN_HISTORY), None);
    }
}
