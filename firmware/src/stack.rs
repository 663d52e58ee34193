//! The stack's high-water mark: how deep the main stack has ever been, so a change that
//! adds stack (a buffer in a hot frame, a deeper call chain) is seen before it overflows
//! into the statics. The statics (mostly the session: the GHT localizer, the policy's
//! activations and upload slot) leave about 40 KiB of the 128 KiB SRAM for the stack, and
//! an overflow does not fault on the M4 without an MPU guard: it corrupts the statics.
//!
//! At boot, before anything deep runs, the free RAM between the end of the statics
//! (`__sheap`, cortex-m-rt's first free byte) and the current stack pointer (less a
//! margin for `main`'s own frame) is painted with a pattern; the high-water mark is the
//! lowest word no longer holding it. Read-only afterwards, and an estimate in one
//! direction only: a frame that reserved stack but never wrote it is not seen (stores
//! happen before loads in practice; a large zeroed buffer is written). Reported with the
//! device's counters (`Status`, `docs/protocol.md`).

use activesense_core::protocol::StackUsage;

/// What free stack words hold until something writes them.
const PAINT: u32 = 0x57AC_57AC;
/// Left unpainted below the stack pointer at boot: `main`'s frame while it paints.
const MARGIN: usize = 256;

extern "C" {
    // cortex-m-rt's linker script: the first byte after the statics, and the top of RAM
    // (the initial stack pointer).
    static __sheap: u32;
    static _stack_start: u32;
}

fn bounds() -> (usize, usize) {
    // Only the symbols' addresses are taken, never their contents.
    (
        core::ptr::addr_of!(__sheap) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

/// Paints the free stack. Call once, first thing in `main`.
pub fn paint() {
    let (bottom, _) = bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = (bottom + 3) & !3;
    while p + MARGIN < sp {
        // SAFETY: between the end of the statics and below the live stack (with a margin
        // for this frame): memory nothing else owns yet.
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// The deepest the stack has been since [`paint`], and the stack's size (from the top of
/// RAM down to the statics).
pub fn usage() -> StackUsage {
    let (bottom, top) = bounds();
    let mut p = (bottom + 3) & !3;
    // SAFETY: reads of the painted region, which only the stack ever writes.
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    StackUsage {
        high_water: (top - p) as u32,
        size: (top - bottom) as u32,
    }
}
