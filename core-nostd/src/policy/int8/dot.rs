//! The two inner products the int8 network spends its time in, behind one trait so the
//! layer code (`super::fast`) is written once: [`Portable`] (plain Rust, every target, the
//! reference) and, on the Cortex-M4, `Dsp` (`super::dsp`, SMLAD / SXTB16 / SXTAB16 in
//! `asm!`). Both compute the same integers exactly: a sum of products of small integers in
//! an `i32` that cannot overflow for any valid blob (`docs/policy-blob.md`), so the order of
//! the additions does not matter and host and device agree bit for bit.
//!
//! Data shapes (see `super::fast` for where they come from):
//! - [`Dot::conv4`]: one 3 × 3 window: three runs of `seg` int8 activations (`seg` a
//!   multiple of 4) at `x[0..]`, `x[row..]`, `x[2·row..]`; `w` holds 4 output channels'
//!   weights *pre-widened* to int16 pairs in SMLAD order, the three runs one after the
//!   other: for every 4 activations `v[4j..4j+4]` of the runs and every channel `r`,
//!   `w[8j + 2r] = (w₀, w₂)` and `w[8j + 2r + 1] = (w₁, w₃)` (low half first).
//!   `acc[r] += Σ v·w`.
//! - [`Dot::fc2`]: `x` is int8 (a multiple of 4 long), `off` is minus the input zero point,
//!   `w0`/`w1` two int8 weight rows as long as `x`: `Σ (x + off)·w` for both rows.

/// The inner products of the int8 kernels (see the module doc for the data shapes).
pub trait Dot {
    /// `acc[r] += Σ v·w_r` over the window's three runs, 4 channels of pre-widened weights.
    fn conv4(x: &[i8], row: usize, seg: usize, w: &[u32], acc: &mut [i32; 4]);
    /// `[Σ (x + off)·w0, Σ (x + off)·w1]` over int8 `x`, `w0`, `w1`.
    fn fc2(x: &[i8], off: i32, w0: &[u8], w1: &[u8]) -> [i32; 2];
    /// Each byte the larger of `a`'s and `b`'s: the belief map's maximum over a cell's
    /// heading slots, four cells at a time
    /// ([`crate::localization::GhtLocalizer::write_levels_interleaved_with`]).
    fn max_u8x4(a: u32, b: u32) -> u32 {
        crate::localization::ght::max_u8x4(a, b)
    }
}

/// Plain Rust: the reference for `Dsp`, and what every target but the M4 runs.
pub struct Portable;

/// The low and high signed halves of a pre-widened weight pair.
fn halves(p: u32) -> (i32, i32) {
    (p as u16 as i16 as i32, (p >> 16) as u16 as i16 as i32)
}

impl Dot for Portable {
    fn conv4(x: &[i8], row: usize, seg: usize, w: &[u32], acc: &mut [i32; 4]) {
        let runs = (0..3).filter_map(|k| x.get(k * row..k * row + seg));
        for (xs, ws) in runs.flat_map(|r| r.chunks_exact(4)).zip(w.chunks_exact(8)) {
            let (x0, x1, x2, x3) = (xs[0] as i32, xs[1] as i32, xs[2] as i32, xs[3] as i32);
            for (a, p) in acc.iter_mut().zip(ws.chunks_exact(2)) {
                let (w0, w2) = halves(p[0]);
                let (w1, w3) = halves(p[1]);
                *a = a.wrapping_add(x0 * w0 + x1 * w1 + x2 * w2 + x3 * w3);
            }
        }
    }

    fn fc2(x: &[i8], off: i32, w0: &[u8], w1: &[u8]) -> [i32; 2] {
        let mut acc = [0i32; 2];
        for ((&xv, &a), &b) in x.iter().zip(w0).zip(w1) {
            let v = xv as i32 + off;
            acc[0] = acc[0].wrapping_add(v * (a as i8 as i32));
            acc[1] = acc[1].wrapping_add(v * (b as i8 as i32));
        }
        acc
    }
}
