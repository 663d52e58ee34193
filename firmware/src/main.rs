//! activesense instrument-controller firmware (STM32F405, Cortex-M4F).
//!
//! **Boot.** Runs the core self-test (builds and validates a floor-plan, casts a ray, runs
//! a baseline agent) and prints `activesense-firmware <ver>: core initialised ...` over
//! semihosting.
//!
//! **Modes** (semihosting command line, i.e. QEMU `-semihosting-config ...,arg=smoke` or
//! `-append smoke`):
//! * `smoke`: exit with status 0 right after the boot line (`cargo xtask qemu-smoke`).
//! * `dsp-selftest`: run [`activesense_core::policy::int8::selftest`] (the int8 network's
//!   DSP `asm!` kernels against the portable and the reference kernels, on random tensors
//!   and the built-in policies), print `dsp-selftest: ok ...` with the instructions of one
//!   K = 10 network pass per backend (meaningful under `-icount shift=0`), and exit 0; a
//!   difference prints `dsp-selftest: FAILED ...` and exits 1 (`tests/tests/qemu_hil.rs`).
//! * `bench`: serve the protocol as by default, but with the SysTick interrupt enabled
//!   only while the core sleeps waiting for the host, so no tick handler runs inside a
//!   timed update (`cargo xtask mcu-bench`). The millisecond clock then counts idle time
//!   only. (The tick must stay on while idle: QEMU with `-icount` and no timer armed can
//!   miss the USART wake-up.)
//! * default: serve the serial protocol (`docs/protocol.md`,
//!   [`activesense_core::device`]) on USART1 (QEMU `serial0`) until the host sends
//!   `Shutdown`; then print `activesense-firmware: shutdown` and exit with status 0.
//!   The firmware owns the decisions; in simulation the host answers its action requests.
//!
//! **Logging.** Readable status lines (boot, serving, shutdown, panic) are plain text on
//! semihosting stdout (`hprintln!`), which the tests read. Everything else is logged with
//! `defmt` (boot, session opened, plan loaded, episode start and end with counts, rejected
//! requests, timeouts): feature `log-semihosting` (default, QEMU) writes the defmt frames
//! to semihosting stderr ([`log`]); `cargo xtask qemu-log` decodes them. Feature `log-rtt`
//! (`--no-default-features --features log-rtt`) uses `defmt-rtt` on hardware.
//!
//! A panic prints `PANIC: ...` over semihosting and exits with a failure status, so a test
//! harness sees the failure instead of a hung emulator.
//!
//! **Clocks.** SysTick runs from the core clock, assumed to be 168 MHz (QEMU's
//! netduinoplus2 models SYSCLK at 168 MHz; real hardware needs the PLL set up first,
//! which this firmware does not do yet). It provides the millisecond clock for the host
//! silence timeout.
//!
//! The cycle counter of the per-update statistics is the free-running 32-bit TIM2
//! counter (prescaler 1). On hardware after reset (HSI 16 MHz, APB1 undivided) TIM2
//! counts core clock cycles. QEMU models the STM32 timers at 1 GHz of *virtual* time, so
//! under `-icount shift=0` (every guest instruction advances virtual time by exactly
//! 2^0 ns) one TIM2 tick is exactly one executed guest instruction: `cargo xtask
//! mcu-bench` reports these as instructions. Without `-icount` the ticks are host-paced
//! virtual nanoseconds and mean little.
#![no_std]
#![no_main]

#[cfg(all(feature = "log-semihosting", feature = "log-rtt"))]
compile_error!("choose one defmt transport: feature `log-semihosting` or `log-rtt`");
#[cfg(not(any(feature = "log-semihosting", feature = "log-rtt")))]
compile_error!("choose a defmt transport: feature `log-semihosting` or `log-rtt`");

#[cfg(feature = "log-semihosting")]
mod log;
mod stack;
mod usart;

#[cfg(feature = "log-rtt")]
use defmt_rtt as _;

use activesense_core::device::{Control, Session, SessionConfig, SessionEvent, DEFAULT_TIMEOUT_MS};
use activesense_core::episode::AgentKind;
use activesense_core::policy::BaselineAgent;
use activesense_core::world::geometry::{unit, v2};
use activesense_core::FloorPlan;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hprintln};
use embedded_io::{Read, ReadReady};

/// Core clock (Hz) SysTick counts.
const CORE_HZ: u32 = 168_000_000;
/// SysTick reload for a 1 ms tick.
const TICK_RELOAD: u32 = CORE_HZ / 1000 - 1;

static MILLIS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

fn millis() -> u32 {
    MILLIS.load(Ordering::Relaxed)
}

const RCC_APB1ENR: usize = 0x4002_3840;
const TIM2_CR1: usize = 0x4000_0000;
const TIM2_CNT: usize = 0x4000_0024;

/// Starts TIM2 as a free-running up-counter (reset values: prescaler 1, ARR 0xFFFF_FFFF).
fn start_cycle_counter() {
    // SAFETY: fixed, aligned STM32F405 registers; RCC_APB1ENR bit 0 = TIM2EN,
    // TIM2_CR1 bit 0 = CEN. Nothing else uses TIM2.
    unsafe {
        let en = core::ptr::read_volatile(RCC_APB1ENR as *const u32);
        core::ptr::write_volatile(RCC_APB1ENR as *mut u32, en | 1);
        core::ptr::write_volatile(TIM2_CR1 as *mut u32, 1);
    }
}

/// TIM2 ticks since it started (mod 2^32): core cycles on hardware, executed instructions
/// under QEMU `-icount shift=0` (see the crate docs).
fn cycles() -> u32 {
    // SAFETY: read-only access to the TIM2 counter register.
    unsafe { core::ptr::read_volatile(TIM2_CNT as *const u32) }
}

/// USART1's interrupt (IRQ 37) only wakes the core from `wfi`. The line stays high until
/// DR is read, so the handler masks it in the NVIC; the main loop reads the data and
/// unmasks it again before the next `wfi`.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == usart::IRQN {
        cortex_m::peripheral::NVIC::mask(usart::Usart1Irq);
    }
}

/// The longest one request may take on this firmware (ms), announced in `Hello`: the
/// slowest update measured by `cargo xtask mcu-bench` (1.64e9 instructions, a vote past the
/// calibrated stop's gate at K = 10: 9.8 s at 168 MHz and one instruction per cycle, and
/// about as long under QEMU's `-icount shift=0`), doubled.
const MAX_REPLY_MS: u32 = 20_000;

const CONFIG: SessionConfig = SessionConfig {
    firmware: concat!("activesense-fw ", env!("CARGO_PKG_VERSION")),
    timeout_ms: DEFAULT_TIMEOUT_MS,
    max_reply_ms: MAX_REPLY_MS,
    cycle_clock: Some(cycles),
    policies: &activesense_core::policy::builtin::POLICIES,
    stack_usage: Some(stack::usage),
};

/// The whole protocol state (frame buffers, plan, measurement log) lives here, not on
/// the stack.
static mut SESSION: Session = Session::new(CONFIG);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("PANIC: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

/// True when the semihosting command line contains the word `word`.
fn cmdline_has(word: &[u8]) -> bool {
    let mut buf = [0u8; 128];
    let mut block = [buf.as_mut_ptr() as usize, buf.len() - 1];
    // SAFETY: SYS_GET_CMDLINE writes at most block[1] bytes into `buf` and updates
    // block[1] with the length; both outlive the call.
    let rc = unsafe {
        cortex_m_semihosting::syscall1(
            cortex_m_semihosting::nr::GET_CMDLINE,
            block.as_mut_ptr() as usize,
        )
    };
    if rc != 0 {
        return false;
    }
    let len = block[1].min(buf.len());
    buf[..len]
        .split(|&c| c == b' ' || c == 0)
        .any(|w| w == word)
}

#[entry]
fn main() -> ! {
    stack::paint();
    let cp = cortex_m::Peripherals::take().unwrap();
    let range_mm = match self_test() {
        Ok(r) => r,
        Err(msg) => {
            defmt::error!("core self-test failed: {=str}", msg);
            hprintln!("activesense-firmware: core self-test FAILED: {}", msg);
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        }
    };
    hprintln!(
        "activesense-firmware {}: core initialised (self-test range {} mm)",
        env!("CARGO_PKG_VERSION"),
        range_mm
    );
    defmt::info!(
        "boot: activesense-firmware {=str}, core self-test ok (range {=u32} mm)",
        env!("CARGO_PKG_VERSION"),
        range_mm
    );
    if cmdline_has(b"smoke") {
        defmt::info!("smoke mode: exit");
        debug::exit(debug::EXIT_SUCCESS);
    }
    if cmdline_has(b"dsp-selftest") {
        dsp_selftest();
    }
    let bench = cmdline_has(b"bench");
    if bench {
        defmt::info!("bench mode: SysTick interrupt only while idle");
    }

    start_cycle_counter();
    let mut syst = cp.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(TICK_RELOAD);
    syst.clear_current();
    if !bench {
        syst.enable_interrupt();
    }
    syst.enable_counter();

    let mut uart = usart::Usart1::init(115_200, CORE_HZ / 2);
    usart::enable_rx_interrupt();
    // SAFETY: the only reference to SESSION, taken once before the serve loop.
    let session: &mut Session = unsafe { &mut *core::ptr::addr_of_mut!(SESSION) };
    let Ok(()) = session.announce(&mut uart);
    hprintln!(
        "activesense-firmware: serving protocol v{} on USART1",
        activesense_core::protocol::PROTOCOL_VERSION
    );
    defmt::info!(
        "serving protocol v{=u16} on USART1",
        activesense_core::protocol::PROTOCOL_VERSION
    );
    let mut buf = [0u8; 64];
    loop {
        if uart.read_ready().unwrap_or(false) {
            let n = uart.read(&mut buf).unwrap_or(0);
            let control = session.feed(&buf[..n], millis(), &mut uart);
            log_events(session);
            match control {
                Ok(Control::Continue) => {}
                Ok(Control::Shutdown) => {
                    hprintln!("activesense-firmware: shutdown");
                    debug::exit(debug::EXIT_SUCCESS);
                }
                Err(e) => match e {},
            }
        } else if session.poll(millis()) {
            log_events(session);
            hprintln!("activesense-firmware: host silent, episode abandoned");
        } else {
            // Sleep until a byte arrives (USART1 IRQ) or the next SysTick. Under QEMU this
            // also frees the emulator's I/O thread, which a polling loop would starve.
            cortex_m::peripheral::NVIC::unpend(usart::Usart1Irq);
            // SAFETY: as at start-up; DefaultHandler only masks the line again.
            unsafe { cortex_m::peripheral::NVIC::unmask(usart::Usart1Irq) };
            if bench {
                syst.enable_interrupt();
            }
            if !uart.read_ready().unwrap_or(false) {
                cortex_m::asm::wfi();
            }
            if bench {
                // A tick that pended meanwhile has already run (interrupts are enabled).
                syst.disable_interrupt();
            }
        }
    }
}

/// The `dsp-selftest` mode: compare the int8 kernels on the device, report, exit.
fn dsp_selftest() -> ! {
    use activesense_core::policy::{builtin::POLICIES, int8::selftest};
    start_cycle_counter();
    match selftest::run(0x5eed, &POLICIES, Some(cycles)) {
        Ok(r) => {
            hprintln!(
                "dsp-selftest: ok, {} comparisons equal; one K = 10 network pass: dsp {} / portable {} / reference {} instructions",
                r.cases,
                r.fast_ticks,
                r.portable_ticks,
                r.reference_ticks
            );
            hprintln!("dsp-selftest: dsp pass by layer (conv1, conv2, fc_belief, fc_side, fc_joint, actor, critic): {:?}", r.layer_ticks);
            debug::exit(debug::EXIT_SUCCESS);
        }
        Err(m) => {
            hprintln!("dsp-selftest: FAILED: {:?}", m);
            debug::exit(debug::EXIT_FAILURE);
        }
    }
    #[allow(clippy::empty_loop)]
    loop {}
}

/// Logs the session's queued events with defmt.
fn log_events(session: &mut Session) {
    while let Some(e) = session.take_event() {
        match e {
            SessionEvent::Opened => defmt::info!("session opened"),
            SessionEvent::PlanLoaded { vertices } => {
                defmt::info!("plan loaded: {=u8} vertices", vertices)
            }
            SessionEvent::EpisodeStarted {
                rot_bins,
                max_actions,
            } => defmt::info!(
                "episode start: K = {=u8}, max {=u16} actions",
                rot_bins,
                max_actions
            ),
            SessionEvent::EpisodeEnded(r) => defmt::info!(
                "episode end: {} after {=u16} actions ({=u16} measurements, {=u16} no-return, \
                 {=u16} rotations), recognised {}, {=u32} votes, finish {=u32} cycles",
                defmt::Debug2Format(&r.end),
                r.actions,
                r.measurements,
                r.no_returns,
                r.rotations,
                defmt::Debug2Format(&r.recognised),
                r.cycles.vote.updates,
                r.cycles.finish
            ),
            SessionEvent::Rejected(err) => {
                defmt::warn!("request rejected: {}", defmt::Debug2Format(&err))
            }
            SessionEvent::TimedOut => defmt::warn!("host silent: episode abandoned"),
            SessionEvent::Shutdown => defmt::info!("shutdown requested"),
        }
    }
}

/// Builds a 4 m x 3 m room, casts one ray from (1, 1) along +x (expect 3 m) and runs the
/// heuristic-1 agent for one period.
fn self_test() -> Result<u32, &'static str> {
    let plan = FloorPlan::new(&[v2(0.0, 0.0), v2(4.0, 0.0), v2(4.0, 3.0), v2(0.0, 3.0)])
        .map_err(|_| "plan rejected")?;
    let hit = plan.ray_cast(v2(1.0, 1.0), unit(0.0)).ok_or("no ray hit")?;
    if libm::fabsf(hit.range - 3.0) > 1e-4 {
        return Err("wrong range");
    }
    let mut agent = BaselineAgent::new(AgentKind::Heuristic1, 0);
    let measures = (0..6)
        .filter(|_| agent.next_action() == activesense_core::episode::Action::Measure)
        .count();
    if measures != 1 {
        return Err("agent period");
    }
    Ok((hit.range * 1000.0) as u32)
}
