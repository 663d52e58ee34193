//! The int8 network's inner products on the Cortex-M4's DSP instructions (`SMLAD`: two
//! 16 × 16 multiplies and both products added to an accumulator in one instruction;
//! `SXTB16` / `SXTAB16`: two int8 lanes of a word sign-extended to int16, plus an offset),
//! as CMSIS-NN's int8 kernels use them. Compiled only for `target_arch = "arm"`; every
//! other target runs [`Portable`](super::dot::Portable), which computes the same integers
//! and is what the firmware's `dsp-selftest` mode ([`super::selftest`], run under QEMU by
//! `tests/tests/qemu_hil.rs`) compares this module against on the emulated M4.
//!
//! **What it buys** (guest instructions under `qemu-system-arm -icount shift=0`): one K = 10
//! network pass 398 969 with these kernels, 919 642 with the portable ones on the same
//! layout, 1 122 934 with the reference kernels (`-append dsp-selftest`); a whole K = 10
//! policy decision, input quantisation included, 659 814 mean / 699 584 max against
//! 1 404 878 / 1 438 482 before (`cargo xtask mcu-bench --episodes 20 --agent learnt-int8`).
//! The inner loop is 17 instructions per 16 multiply-accumulates (conv) and 15 per 8 (fully
//! connected).
//!
//! **The core's first `unsafe`** (the other is `world::math::fpu`, the FPU's square
//! root). Stable Rust has no DSP intrinsics (`__smlad` is unstable) and LLVM's
//! parallel-DSP pass does not fuse int8 loops (it pairs 16-bit loads only: a stand-alone
//! `i16` dot product did get SMLAD, but the int8 reference kernel compiled to one `SMLABB`
//! or `MLA` per product, no SMLAD in the whole firmware), so these loops are
//! `core::arch::asm!`, which is `unsafe`. The crate is `#![deny(unsafe_code)]` with an
//! `#[allow(unsafe_code)]` on this module and on `world::math::fpu`; the safe
//! wrappers below check every length before an `asm!` block reads memory (a mismatch falls
//! back to the portable kernel, never reads out of bounds), and the blocks only read
//! (`readonly`, no stack, no writes). `docs/ARCHITECTURE.md` ("unsafe") records this.
//!
//! Alignment: the weight pairs are `&[u32]` (word aligned, as `LDRD` needs); activations
//! and flash weights are read with `LDR`, which the Cortex-M4 allows unaligned.

use super::dot::{Dot, Portable};
use core::arch::asm;

/// The DSP backend of [`Dot`].
pub struct Dsp;

impl Dot for Dsp {
    fn conv4(x: &[i8], row: usize, seg: usize, w: &[u32], acc: &mut [i32; 4]) {
        let words = seg / 4;
        if seg % 4 != 0
            || words == 0
            || words > 63
            || row < seg
            || row - seg >= 1 << 24
            || x.len() < 2 * row + seg
            || w.len() < 3 * 8 * words
        {
            return Portable::conv4(x, row, seg, w, acc);
        }
        // One register for the loop constants and the run counter (12 registers are all
        // there is): bits 0–5 the words per run, bits 6–7 the run (1, 2, 3; 4 carries out of
        // them and ends the loop), bits 8– the bytes from one run's end to the next's start.
        let packed = ((row - seg) << 8 | 1 << 6 | words) as u32;
        let [mut a0, mut a1, mut a2, mut a3] = *acc;
        // SAFETY: three runs of `words ≥ 1` iterations each read `seg = 4·words` bytes of
        // `x` at offsets 0, `row` and `2·row` (checked: `x.len() ≥ 2·row + seg`) and
        // `32·words` bytes of `w` each, `96·words` in all (checked: `w.len() ≥ 24·words`
        // words, word aligned as a `&[u32]`, which LDRD needs). It writes only registers.
        unsafe {
            asm!(
                "and {n}, {k}, #63",
                "2:",
                "ldr {x}, [{px}], #4",
                "sxtb16 {xb}, {x}, ror #8",
                "sxtb16 {x}, {x}",
                "ldrd {w0}, {w1}, [{pw}], #8",
                "smlad {a0}, {x}, {w0}, {a0}",
                "smlad {a0}, {xb}, {w1}, {a0}",
                "ldrd {w0}, {w1}, [{pw}], #8",
                "smlad {a1}, {x}, {w0}, {a1}",
                "smlad {a1}, {xb}, {w1}, {a1}",
                "ldrd {w0}, {w1}, [{pw}], #8",
                "smlad {a2}, {x}, {w0}, {a2}",
                "smlad {a2}, {xb}, {w1}, {a2}",
                "ldrd {w0}, {w1}, [{pw}], #8",
                "smlad {a3}, {x}, {w0}, {a3}",
                "smlad {a3}, {xb}, {w1}, {a3}",
                "subs {n}, {n}, #1",
                "bne 2b",
                // Next run: x forward to its start, the word count again, the run counter up.
                "add {px}, {px}, {k}, lsr #8",
                "and {n}, {k}, #63",
                "add {k}, {k}, #64",
                "tst {k}, #192",
                "bne 2b",
                px = inout(reg) x.as_ptr() => _,
                pw = inout(reg) w.as_ptr() => _,
                k = inout(reg) packed => _,
                n = out(reg) _,
                x = out(reg) _,
                xb = out(reg) _,
                w0 = out(reg) _,
                w1 = out(reg) _,
                a0 = inout(reg) a0,
                a1 = inout(reg) a1,
                a2 = inout(reg) a2,
                a3 = inout(reg) a3,
                options(pure, readonly, nostack),
            );
        }
        *acc = [a0, a1, a2, a3];
    }

    #[inline]
    fn max_u8x4(a: u32, b: u32) -> u32 {
        let m: u32;
        // SAFETY: registers only: USUB8 sets the APSR.GE bit of each byte lane where
        // `a ≥ b`, SEL takes that lane from `a`, the others from `b`.
        unsafe {
            asm!(
                "usub8 {t}, {a}, {b}",
                "sel {m}, {a}, {b}",
                a = in(reg) a,
                b = in(reg) b,
                t = out(reg) _,
                m = out(reg) m,
                options(pure, nomem, nostack),
            );
        }
        m
    }

    fn fc2(x: &[i8], off: i32, w0: &[u8], w1: &[u8]) -> [i32; 2] {
        let n = x.len() / 4;
        if x.len() % 4 != 0 || w0.len() != x.len() || w1.len() != x.len() || n == 0 {
            return Portable::fc2(x, off, w0, w1);
        }
        // Both halfwords of `offp` hold `off` (|off| ≤ 128: a valid zero point), which
        // SXTAB16 adds to each sign-extended lane: x + off stays inside int16.
        let offp = (off as u32 & 0xFFFF) | ((off as u32) << 16);
        let (mut a0, mut a1) = (0i32, 0i32);
        // SAFETY: the loop runs `n ≥ 1` times, reading `4n` bytes from each of `x`, `w0`
        // and `w1` (checked: all three are `4n` long; LDR may be unaligned on the M4). It
        // writes only registers.
        unsafe {
            asm!(
                "2:",
                "ldr {x}, [{px}], #4",
                "sxtab16 {xb}, {off}, {x}, ror #8",
                "sxtab16 {x}, {off}, {x}",
                "ldr {w}, [{p0}], #4",
                "sxtb16 {wb}, {w}, ror #8",
                "sxtb16 {w}, {w}",
                "smlad {a0}, {x}, {w}, {a0}",
                "smlad {a0}, {xb}, {wb}, {a0}",
                "ldr {w}, [{p1}], #4",
                "sxtb16 {wb}, {w}, ror #8",
                "sxtb16 {w}, {w}",
                "smlad {a1}, {x}, {w}, {a1}",
                "smlad {a1}, {xb}, {wb}, {a1}",
                "subs {n}, {n}, #1",
                "bne 2b",
                px = inout(reg) x.as_ptr() => _,
                p0 = inout(reg) w0.as_ptr() => _,
                p1 = inout(reg) w1.as_ptr() => _,
                n = inout(reg) n => _,
                off = in(reg) offp,
                x = out(reg) _,
                xb = out(reg) _,
                w = out(reg) _,
                wb = out(reg) _,
                a0 = inout(reg) a0,
                a1 = inout(reg) a1,
                options(pure, readonly, nostack),
            );
        }
        [a0, a1]
    }
}
