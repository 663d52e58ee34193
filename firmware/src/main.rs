//! activesense instrument-controller firmware (STM32F405, Cortex-M4F).
//!
//! **Boot.** Runs the core self-test (builds and validates a floor-plan, casts a ray, runs
//! a baseline agent) and prints `activesense-firmware <ver>: core initialised ...` over
//! semihosting.
//!
//! **Modes** of the emulated build (semihosting command line, i.e. QEMU
//! `-semihosting-config ...,arg=smoke` or `-append smoke`; the `board` build runs the
//! instrument instead, see [`board`]):
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
//! semihosting stdout (`hprintln!`, [`console`]), which the tests read; on hardware they
//! go to defmt. Everything else is logged with
//! `defmt` (boot, session opened, plan loaded, episode start and end with counts, rejected
//! requests, timeouts): feature `log-semihosting` (default, QEMU) writes the defmt frames
//! to semihosting stderr ([`log`]); `cargo xtask qemu-log` decodes them. Feature `log-rtt`
//! (brought by `board`, or `--no-default-features --features log-rtt`) uses `defmt-rtt`
//! on hardware.
//!
//! A panic prints `PANIC: ...` over semihosting and exits with a failure status, so a test
//! harness sees the failure instead of a hung emulator (on hardware: over defmt, then the
//! core sleeps).
//!
//! **Clocks.** stm32f4xx-hal owns the clock tree (docs/firmware.md, "Features, clocks and why QEMU keeps the HSI"). The
//! `board` build runs the HSE (8 MHz on the Olimex STM32-H405) through the PLL to 168 MHz
//! SYSCLK, 48 MHz USB clock, APB1 42 MHz, APB2 84 MHz ([`clock_plan`]). The emulated build
//! (feature `qemu`, the default) keeps the reset clocks (HSI, no PLL): QEMU 7.2's
//! netduinoplus2 does not model the RCC (its registers read 0, so the HAL's wait for
//! HSE-ready or PLL-ready would never end), and it clocks the core and SysTick at 168 MHz
//! whatever the RCC says. SysTick gives the millisecond clock (1 kHz, from the core clock:
//! 168 MHz in both builds) for the host silence timeout.
//!
//! The cycle counter of the per-update statistics is the free-running 32-bit TIM2
//! counter (prescaler 1). QEMU models the STM32 timers at 1 GHz of *virtual* time, so
//! under `-icount shift=0` (every guest instruction advances virtual time by exactly
//! 2^0 ns) one TIM2 tick is exactly one executed guest instruction: `cargo xtask
//! mcu-bench` reports these as instructions. Without `-icount` the ticks are host-paced
//! virtual nanoseconds and mean little. On the board TIM2 runs from the APB1 timer clock,
//! 84 MHz: one tick is two core cycles.
//!
//! **Structure.** An RTIC 2 app ([`serve`] for the protocol build, [`board`] for the
//! instrument build): the session (or the board's controller) is a `#[shared]` resource,
//! the USART1 receiver a `#[local]` of the task bound to USART1 (interrupt-driven receive
//! into a queue, [`usart`]), the transmitter and the queue's consumer locals of the
//! idle loop that serves; SysTick is a task that counts milliseconds. No mutable statics.
#![no_std]
#![no_main]

#[cfg(not(any(feature = "log-semihosting", feature = "log-rtt")))]
compile_error!("choose a defmt transport: feature `log-semihosting` or `log-rtt`");

#[cfg(feature = "board")]
mod board;
pub mod clock_plan;
mod console;
#[cfg(semihosting_log)]
mod log;
#[cfg(not(feature = "board"))]
mod serve;
mod stack;
mod usart;

#[cfg(all(feature = "log-rtt", not(semihosting_log)))]
use defmt_rtt as _;

use activesense_core::device::SessionEvent;
use activesense_core::episode::AgentKind;
use activesense_core::policy::BaselineAgent;
use activesense_core::world::geometry::{unit, v2};
use activesense_core::FloorPlan;
use console::say;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::Rcc;
use stm32f4xx_hal::timer::Timer;

/// The core clock QEMU's netduinoplus2 models (and SysTick counts), whatever the RCC says.
#[cfg(not(feature = "board"))]
const QEMU_CORE_HZ: u32 = 168_000_000;

/// An exclusive reference to a static that RTIC's `init` owns (its `local = [...]`
/// resources): how a big state (the session, the controller) becomes a `#[shared]`
/// resource without being built on the stack and moved.
type Owned<'a, T> = &'a mut T;

/// Milliseconds since boot, counted by the SysTick task.
static MILLIS: AtomicU32 = AtomicU32::new(0);

/// The SysTick task's work.
fn tick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

fn millis() -> u32 {
    MILLIS.load(Ordering::Relaxed)
}

/// Sets the clocks through the HAL (see the crate docs, "Clocks").
fn clocks(rcc: pac::RCC) -> Rcc {
    #[cfg(feature = "board")]
    {
        use clock_plan::*;
        use stm32f4xx_hal::prelude::*;
        rcc.freeze(
            stm32f4xx_hal::rcc::Config::hse(BOARD_HSE_HZ.Hz())
                .sysclk(SYSCLK_HZ.Hz())
                .hclk(SYSCLK_HZ.Hz())
                .pclk1(PCLK1_HZ.Hz())
                .pclk2(PCLK2_HZ.Hz())
                .require_pll48clk(),
        )
    }
    #[cfg(not(feature = "board"))]
    {
        use stm32f4xx_hal::rcc::RccExt;
        // The reset state (HSI 16 MHz, no prescalers): the HAL writes nothing.
        rcc.constrain()
    }
}

/// The frequency SysTick counts (the core clock).
fn systick_hz(_rcc: &Rcc) -> u32 {
    #[cfg(feature = "board")]
    {
        _rcc.clocks.sysclk().raw()
    }
    #[cfg(not(feature = "board"))]
    {
        QEMU_CORE_HZ
    }
}

/// SysTick: a 1 ms tick from the core clock; its interrupt on unless `quiet`.
fn start_systick(syst: &mut SYST, core_hz: u32, quiet: bool) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(core_hz / 1000 - 1);
    syst.clear_current();
    if !quiet {
        syst.enable_interrupt();
    }
    syst.enable_counter();
}

/// Starts TIM2 as a free-running 32-bit up-counter at the timer clock (prescaler 1,
/// auto-reload 0xFFFF_FFFF): the HAL enables and resets it, the PAC programs it. The
/// returned handle is TIM2's owner; [`cycles`] only reads its counter.
fn start_cycle_counter(tim2: pac::TIM2, rcc: &mut Rcc) -> pac::TIM2 {
    let tim2 = Timer::new(tim2, rcc).release();
    tim2.psc().write(|w| w.psc().set(0));
    tim2.arr().write(|w| w.arr().set(u32::MAX));
    tim2.cr1().modify(|_, w| w.cen().set_bit());
    tim2
}

/// TIM2 ticks since it started (mod 2^32): executed instructions under QEMU
/// `-icount shift=0`, two core cycles each on the board (see the crate docs).
fn cycles() -> u32 {
    // SAFETY: a read of TIM2's counter register, which has no side effects; TIM2 is owned
    // by `start_cycle_counter`'s caller and nothing writes it after start-up.
    unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
}

/// The longest one request may take on this firmware (ms), announced in `Hello`: the
/// slowest update measured by `cargo xtask mcu-bench` (1.64e9 instructions, a vote past the
/// calibrated stop's gate at K = 10: 9.8 s at 168 MHz and one instruction per cycle, and
/// about as long under QEMU's `-icount shift=0`), doubled.
#[cfg(not(feature = "board"))]
const MAX_REPLY_MS: u32 = 20_000;

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    say!("PANIC: {}", info);
    console::exit(false)
}

/// Boot: paint the stack, run the core self-test, print the boot line. `Err` after the
/// failure has been reported.
fn boot() -> Result<(), ()> {
    let range_mm = match self_test() {
        Ok(r) => r,
        Err(msg) => {
            defmt::error!("core self-test failed: {=str}", msg);
            say!("activesense-firmware: core self-test FAILED: {}", msg);
            return Err(());
        }
    };
    say!(
        "activesense-firmware {}: core initialised (self-test range {} mm)",
        env!("CARGO_PKG_VERSION"),
        range_mm
    );
    defmt::info!(
        "boot: activesense-firmware {=str}, core self-test ok (range {=u32} mm)",
        env!("CARGO_PKG_VERSION"),
        range_mm
    );
    Ok(())
}

/// The `dsp-selftest` mode: compare the int8 kernels on the device, report, exit.
#[cfg_attr(feature = "board", allow(dead_code))]
fn dsp_selftest() -> ! {
    use activesense_core::policy::{builtin::POLICIES, int8::selftest};
    match selftest::run(0x5eed, &POLICIES, Some(cycles)) {
        Ok(r) => {
            say!(
                "dsp-selftest: ok, {} comparisons equal; one K = 10 network pass: dsp {} / portable {} / reference {} instructions",
                r.cases,
                r.fast_ticks,
                r.portable_ticks,
                r.reference_ticks
            );
            say!("dsp-selftest: dsp pass by layer (conv1, conv2, fc_belief, fc_side, fc_joint, actor, critic): {:?}", r.layer_ticks);
            console::exit(true)
        }
        Err(m) => {
            say!("dsp-selftest: FAILED: {:?}", m);
            console::exit(false)
        }
    }
}

/// Logs the session's queued events with defmt.
#[cfg_attr(feature = "board", allow(dead_code))]
fn log_event(e: SessionEvent) {
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

/// The 4 m x 3 m room of the self-test (and of the board's stand-alone episodes).
fn room() -> Result<FloorPlan, &'static str> {
    FloorPlan::new(&[v2(0.0, 0.0), v2(4.0, 0.0), v2(4.0, 3.0), v2(0.0, 3.0)])
        .map_err(|_| "plan rejected")
}

/// Builds the room, casts one ray from (1, 1) along +x (expect 3 m) and runs the
/// heuristic-1 agent for one period.
fn self_test() -> Result<u32, &'static str> {
    let plan = room()?;
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
