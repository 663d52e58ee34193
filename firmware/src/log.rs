//! defmt global logger over semihosting **stderr** (feature `log-semihosting`, the
//! default; QEMU). The plain-text console lines (`hprintln!`: boot, shutdown, panic) stay
//! on semihosting stdout, so the binary defmt stream and the text never mix: QEMU with
//! `-semihosting-config target=native` writes the guest's stderr (`:tt` opened for append)
//! to its own stderr, where `cargo xtask qemu-log` reads and decodes it.
//!
//! Frames are encoded by [`defmt::Encoder`] (rzCOBS) into a small buffer that is written
//! with one semihosting call per frame (or per 128 bytes).
//!
//! On hardware (`--features board`, or `--no-default-features --features log-rtt`) the
//! `defmt-rtt` crate provides the logger.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_semihosting::hio::{self, HostStream};

#[defmt::global_logger]
struct Logger;

struct Out {
    stream: Option<HostStream>,
    buf: [u8; 128],
    len: usize,
}

struct State {
    encoder: defmt::Encoder,
    restore: critical_section::RestoreState,
    out: Out,
}

struct Shared(UnsafeCell<State>);

// SAFETY: `State` is only touched between `acquire` and `release`, i.e. inside a
// critical section on this single core, guarded against re-entry by `TAKEN`.
unsafe impl Sync for Shared {}

static TAKEN: AtomicBool = AtomicBool::new(false);
static STATE: Shared = Shared(UnsafeCell::new(State {
    encoder: defmt::Encoder::new(),
    restore: critical_section::RestoreState::invalid(),
    out: Out {
        stream: None,
        buf: [0; 128],
        len: 0,
    },
}));

impl Out {
    fn flush(&mut self) {
        if self.stream.is_none() {
            self.stream = hio::hstderr().ok();
        }
        if let Some(s) = self.stream.as_mut() {
            let _ = s.write_all(&self.buf[..self.len]);
        }
        self.len = 0;
    }

    fn put(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if self.len == self.buf.len() {
                self.flush();
            }
            self.buf[self.len] = b;
            self.len += 1;
        }
    }
}

/// The logger state.
///
/// # Safety
/// The caller holds the logger (between `acquire` and `release`).
#[allow(clippy::mut_from_ref)]
unsafe fn state<'a>() -> &'a mut State {
    // SAFETY: exclusive by the caller's contract.
    unsafe { &mut *STATE.0.get() }
}

// SAFETY: frames are only written between acquire and release, inside one critical
// section; re-entry panics (the panic handler prints with hprintln, not defmt).
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        // SAFETY: paired with the `release` in `Logger::release`.
        let restore = unsafe { critical_section::acquire() };
        if TAKEN.swap(true, Ordering::Relaxed) {
            panic!("defmt logger taken reentrantly");
        }
        // SAFETY: inside the critical section, TAKEN held.
        let State {
            encoder,
            restore: r,
            out,
        } = unsafe { state() };
        *r = restore;
        encoder.start_frame(|b| out.put(b));
    }

    unsafe fn flush() {}

    unsafe fn release() {
        // SAFETY: called after a successful acquire (defmt's contract).
        let State {
            encoder,
            restore,
            out,
        } = unsafe { state() };
        encoder.end_frame(|b| out.put(b));
        out.flush();
        let restore = *restore;
        TAKEN.store(false, Ordering::Relaxed);
        // SAFETY: the section acquired in `acquire`.
        unsafe { critical_section::release(restore) };
    }

    unsafe fn write(bytes: &[u8]) {
        // SAFETY: between acquire and release.
        let State { encoder, out, .. } = unsafe { state() };
        encoder.write(bytes, |b| out.put(b));
    }
}
