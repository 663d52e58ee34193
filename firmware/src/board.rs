//! The board build (feature `board`): the Olimex STM32-H405 (STM32F405RGT6, 8 MHz
//! crystal) runs the instrument stand-alone — the core's `HardwareInstrument` on real
//! pins, the episode's decisions on the chip — and reports each episode over the host
//! link. Pin map and bring-up: docs/firmware.md.
//!
//! * USART1 (PA9 TX, PA10 RX), 115200 8N1: the host link. A received `R` starts one
//!   episode; its report comes back as one text line (`episode <n>: ...`), and every step
//!   is logged with defmt over RTT.
//! * USART2 (PA2 TX, PA3 RX): the B605B laser distance module
//!   ([`activesense_core::device::laser`]), read with a timeout ([`EdmPort`]).
//! * PB0 = STEP, PB1 = DIR of a step/dir stepper driver (A4988 / DRV8825 class) turning
//!   the bearing; TIM5 times the pulses.
//!
//! The plan is the self-test's 4 m x 3 m room, the agent heuristic-1 at K = 10 with the
//! calibrated stop. The board runs one controller and does not serve the simulation
//! protocol: one controller (~86 KB) fits the 128 KB SRAM, a protocol session beside it
//! does not. The protocol build (`serve`) is what QEMU and the host simulator talk to.

use crate::clock_plan::{Pll, BOARD_PLL, HOST_BRR, PCLK1_HZ, PCLK2_HZ, SYSCLK_HZ, USB_HZ};
use embedded_hal_nb::serial::Read as _;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::Rcc;
use stm32f4xx_hal::serial::{Error as SerialError, Rx, Tx};

/// How long the module may take to answer one measurement (ms). Slow mode and weak
/// reflections take seconds.
pub const EDM_TIMEOUT_MS: u32 = 5_000;
/// Stepper pulses per motor turn: a 200-step motor at 1/16 microstepping.
pub const MOTOR_PULSES_PER_TURN: u32 = 200 * 16;
/// Step pulse high and low time (µs).
pub const STEP_PULSE_US: u32 = 200;
/// Settling time after a rotation step (ms).
pub const SETTLE_MS: u32 = 50;

/// USART2 to the laser module, as the `embedded_io` port the B605B driver wants: blocking
/// writes, and reads that give up after [`EDM_TIMEOUT_MS`] (returning `Ok(0)`, "silent").
pub struct EdmPort {
    pub tx: Tx<pac::USART2>,
    pub rx: Rx<pac::USART2>,
}

impl embedded_io::ErrorType for EdmPort {
    type Error = SerialError;
}

impl embedded_io::Read for EdmPort {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, SerialError> {
        let Some(first) = buf.first_mut() else {
            return Ok(0);
        };
        let start = crate::millis();
        loop {
            match self.rx.read() {
                Ok(b) => {
                    *first = b;
                    return Ok(1);
                }
                Err(nb::Error::WouldBlock) => {
                    if crate::millis().wrapping_sub(start) >= EDM_TIMEOUT_MS {
                        return Ok(0);
                    }
                }
                Err(nb::Error::Other(e)) => return Err(e),
            }
        }
    }
}

impl embedded_io::Write for EdmPort {
    fn write(&mut self, buf: &[u8]) -> Result<usize, SerialError> {
        for &b in buf {
            loop {
                match embedded_hal_nb::serial::Write::write(&mut self.tx, b) {
                    Ok(()) => break,
                    Err(nb::Error::WouldBlock) => {}
                    Err(nb::Error::Other(e)) => return Err(e),
                }
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), SerialError> {
        nb::block!(embedded_hal_nb::serial::Write::flush(&mut self.tx))
    }
}

/// Compares what the HAL programmed with the clock plan the host tests check
/// ([`crate::clock_plan`]); logs the result.
pub fn check_clocks(rcc: &Rcc) -> bool {
    let r = rcc.pllcfgr().read();
    let pll = Pll {
        m: r.pllm().bits() as u32,
        n: r.plln().bits() as u32,
        p: (r.pllp().bits() as u32 + 1) * 2,
        q: r.pllq().bits() as u32,
    };
    // SAFETY: a side-effect-free read of USART1's baud register, after the HAL set it.
    let brr = unsafe { (*pac::USART1::ptr()).brr().read().bits() } as u32;
    let c = &rcc.clocks;
    let ok = pll == BOARD_PLL
        && c.sysclk().raw() == SYSCLK_HZ
        && c.pll48clk().map(|f| f.raw()) == Some(USB_HZ)
        && c.pclk1().raw() == PCLK1_HZ
        && c.pclk2().raw() == PCLK2_HZ
        && brr == HOST_BRR;
    if ok {
        defmt::info!(
            "clocks: PLL M {=u32} N {=u32} P {=u32} Q {=u32}, SYSCLK {=u32} Hz, USART1 BRR {=u32:#x}",
            pll.m,
            pll.n,
            pll.p,
            pll.q,
            c.sysclk().raw(),
            brr
        );
    } else {
        defmt::error!(
            "clocks differ from the plan: PLL M {=u32} N {=u32} P {=u32} Q {=u32}, SYSCLK {=u32} Hz, USART1 BRR {=u32:#x}",
            pll.m,
            pll.n,
            pll.p,
            pll.q,
            c.sysclk().raw(),
            brr
        );
    }
    ok
}

#[rtic::app(device = stm32f4xx_hal::pac)]
mod app {
    use super::*;
    use crate::console::{self, say};
    use crate::usart::{self, HostTx, RxQueue, RX_QUEUE};
    use crate::Owned;
    use activesense_core::device::instrument::{
        run_local, HardwareInstrument, LocalError, NoScan, StepperConfig,
    };
    use activesense_core::device::laser::B605b;
    use activesense_core::device::Controller;
    use activesense_core::episode::{AgentKind, EpisodeConfig, EpisodeParams, Termination};
    use activesense_core::policy::builtin::POLICIES;
    use core::fmt::Write as _;
    use heapless::spsc::{Consumer, Producer};
    use stm32f4xx_hal::gpio::{GpioExt, Output, PB0, PB1};
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::serial::{config::Config as SerialConfig, RxListen, SerialExt};
    use stm32f4xx_hal::timer::Delay;

    type Instrument = HardwareInstrument<
        PB0<Output>,
        PB1<Output>,
        Delay<pac::TIM5, 1_000_000>,
        B605b<EdmPort>,
        NoScan,
    >;

    #[shared]
    struct Shared {
        /// The episode controller (localizer, policy, registration): a static of `init`.
        controller: Owned<'static, Controller>,
    }

    #[local]
    struct Local {
        rx: Rx<pac::USART1>,
        rx_in: Producer<'static, u8, RX_QUEUE>,
        rx_out: Consumer<'static, u8, RX_QUEUE>,
        tx: HostTx,
        instrument: Instrument,
        _tim2: pac::TIM2,
    }

    #[init(local = [
        controller: Controller = Controller::new(Some(crate::cycles), &POLICIES),
        queue: RxQueue = RxQueue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        crate::stack::paint();
        if crate::boot().is_err() {
            console::exit(false);
        }
        let dp = cx.device;
        let mut rcc = crate::clocks(dp.RCC);
        let tim2 = crate::start_cycle_counter(dp.TIM2, &mut rcc);
        let mut syst = cx.core.SYST;
        crate::start_systick(&mut syst, crate::systick_hz(&rcc), false);

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let host = dp
            .USART1
            .serial::<u8>(
                (gpioa.pa9, gpioa.pa10),
                SerialConfig::default().baudrate(crate::clock_plan::HOST_BAUD.bps()),
                &mut rcc,
            )
            .unwrap_or_else(|_| panic!("USART1 configuration"));
        let edm = dp
            .USART2
            .serial::<u8>(
                (gpioa.pa2, gpioa.pa3),
                SerialConfig::default().baudrate(crate::clock_plan::EDM_BAUD.bps()),
                &mut rcc,
            )
            .unwrap_or_else(|_| panic!("USART2 configuration"));
        check_clocks(&rcc);
        let (tx, mut rx) = host.split();
        rx.listen();
        let (edm_tx, edm_rx) = edm.split();
        let steps_per_turn = EpisodeConfig::default().steps_per_turn.max(1) as u32;
        let stepper = StepperConfig {
            // Rounded: 3200 / 54 = 59.3 (docs/firmware.md, "The stepper").
            pulses_per_step: (MOTOR_PULSES_PER_TURN + steps_per_turn / 2) / steps_per_turn,
            pulse_us: STEP_PULSE_US,
            settle_ms: SETTLE_MS,
        };
        let instrument = HardwareInstrument::new(
            gpiob.pb0.into_push_pull_output(),
            gpiob.pb1.into_push_pull_output(),
            dp.TIM5.delay_us(&mut rcc),
            B605b::new(EdmPort {
                tx: edm_tx,
                rx: edm_rx,
            }),
            NoScan,
            stepper,
        );
        let (rx_in, rx_out) = cx.local.queue.split();
        (
            Shared {
                controller: cx.local.controller,
            },
            Local {
                rx,
                rx_in,
                rx_out,
                tx: HostTx(tx),
                instrument,
                _tim2: tim2,
            },
        )
    }

    /// Interrupt-driven receive into the queue.
    #[task(binds = USART1, local = [rx, rx_in], priority = 1)]
    fn usart1(cx: usart1::Context) {
        usart::on_rx_interrupt(cx.local.rx, cx.local.rx_in);
    }

    /// The millisecond clock (also the EDM read timeout's).
    #[task(binds = SysTick, priority = 2)]
    fn systick(_: systick::Context) {
        crate::tick();
    }

    #[idle(shared = [controller], local = [rx_out, tx, instrument])]
    fn idle(mut cx: idle::Context) -> ! {
        let idle::LocalResources {
            rx_out,
            tx,
            instrument,
            ..
        } = cx.local;
        let Ok(plan) = crate::room() else {
            say!("activesense-firmware: the room plan is rejected");
            console::exit(false)
        };
        let _ = writeln!(
            tx,
            "activesense-firmware {} (Olimex STM32-H405): send R to run an episode\r",
            env!("CARGO_PKG_VERSION")
        );
        say!("activesense-firmware: instrument ready, waiting for R on USART1");
        let mut episode: u32 = 0;
        let mut buf = [0u8; 16];
        loop {
            let n = usart::take(rx_out, &mut buf);
            if buf[..n].contains(&b'R') {
                episode += 1;
                let params = EpisodeParams {
                    agent: AgentKind::Heuristic1,
                    seed: episode as u64,
                    rot_bins: 10,
                    known_heading: None,
                    ground_truth: None,
                    initial_scan: 0,
                    termination: Termination::Confident,
                    config: EpisodeConfig::default(),
                };
                defmt::info!("episode {=u32}: start", episode);
                let result = cx.shared.controller.lock(|ctl| {
                    run_local(ctl, &plan, &params, instrument, |action, obs| {
                        defmt::info!(
                            "step: {} -> range {}",
                            defmt::Debug2Format(&action),
                            defmt::Debug2Format(&obs.range)
                        )
                    })
                });
                let stack = crate::stack::usage();
                defmt::info!(
                    "stack: high-water mark {=u32} of {=u32} bytes",
                    stack.high_water,
                    stack.size
                );
                match result {
                    Ok(r) => {
                        let _ = writeln!(
                            tx,
                            "episode {}: {:?} after {} actions ({} measurements, {} no-return, {} rotations), refined {:?}, trace {:08x}; stack {} of {} bytes\r",
                            episode,
                            r.end,
                            r.actions,
                            r.measurements,
                            r.no_returns,
                            r.rotations,
                            r.refined,
                            r.trace_hash,
                            stack.high_water,
                            stack.size
                        );
                        defmt::info!(
                            "episode {=u32}: {} after {=u16} actions",
                            episode,
                            defmt::Debug2Format(&r.end),
                            r.actions
                        );
                    }
                    Err(e) => {
                        let what = match e {
                            LocalError::Rejected(_) => "rejected",
                            LocalError::Instrument(_) => "instrument failed",
                        };
                        let _ = writeln!(tx, "episode {}: {}: {:?}\r", episode, what, e);
                        defmt::warn!("episode {=u32}: {=str}", episode, what);
                    }
                }
            } else if n == 0 {
                cortex_m::interrupt::free(|_| {
                    if !rx_out.ready() {
                        cortex_m::asm::wfi();
                    }
                });
            }
        }
    }
}
