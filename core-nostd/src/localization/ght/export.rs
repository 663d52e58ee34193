//! The belief map the policy reads, written straight from the accumulator: every cell's
//! best heading slot mapped through a caller's table into the int8 network's padded,
//! channel-interleaved layout, four cells at a time with a per-byte maximum the caller
//! supplies (the DSP instructions on the M4, [`max_u8x4`] elsewhere).

use super::{GhtLocalizer, TRACKED_SUB_BINS};
use crate::localization::MAX_LAYER_CELLS;

impl GhtLocalizer {
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
                // loop otherwise spills in the decision's worst case.
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
        // mask once per pixel rather than once per cell (the test per cell was 5 % of a
        // K = 10 decision).
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
