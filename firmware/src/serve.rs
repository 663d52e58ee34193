//! The protocol build (not `board`): serve the serial protocol on USART1 until the host
//! sends `Shutdown` (see the crate docs for the run modes).

#[rtic::app(device = stm32f4xx_hal::pac)]
mod app {
    use crate::console::{self, say};
    use crate::usart::{self, HostTx, RxQueue, RX_QUEUE};
    use crate::Owned;
    use activesense_core::device::{Control, Session, SessionConfig, DEFAULT_TIMEOUT_MS};
    use cortex_m::peripheral::SYST;
    use heapless::spsc::{Consumer, Producer};
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::serial::{config::Config as SerialConfig, Rx, RxListen, SerialExt};
    use stm32f4xx_hal::{gpio::GpioExt, pac};

    const CONFIG: SessionConfig = SessionConfig {
        firmware: concat!("activesense-fw ", env!("CARGO_PKG_VERSION")),
        timeout_ms: DEFAULT_TIMEOUT_MS,
        max_reply_ms: crate::MAX_REPLY_MS,
        cycle_clock: Some(crate::cycles),
        policies: &activesense_core::policy::builtin::POLICIES,
        stack_usage: Some(crate::stack::usage),
    };

    #[shared]
    struct Shared {
        /// The whole protocol state (frame buffers, plan, measurement log): a static of
        /// `init` (not on the stack), shared by reference.
        session: Owned<'static, Session>,
    }

    #[local]
    struct Local {
        rx: Rx<pac::USART1>,
        rx_in: Producer<'static, u8, RX_QUEUE>,
        rx_out: Consumer<'static, u8, RX_QUEUE>,
        tx: HostTx,
        syst: SYST,
        bench: bool,
        _tim2: pac::TIM2,
    }

    #[init(local = [
        session: Session = Session::new(CONFIG),
        queue: RxQueue = RxQueue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        crate::stack::paint();
        if crate::boot().is_err() {
            console::exit(false);
        }
        if console::cmdline_has(b"smoke") {
            defmt::info!("smoke mode: exit");
            console::exit(true);
        }
        let dp = cx.device;
        let mut rcc = crate::clocks(dp.RCC);
        let tim2 = crate::start_cycle_counter(dp.TIM2, &mut rcc);
        if console::cmdline_has(b"dsp-selftest") {
            crate::dsp_selftest();
        }
        let bench = console::cmdline_has(b"bench");
        if bench {
            defmt::info!("bench mode: SysTick interrupt only while idle");
        }
        let mut syst = cx.core.SYST;
        crate::start_systick(&mut syst, crate::systick_hz(&rcc), bench);

        let gpioa = dp.GPIOA.split(&mut rcc);
        let serial = dp
            .USART1
            .serial::<u8>(
                (gpioa.pa9, gpioa.pa10),
                SerialConfig::default().baudrate(crate::clock_plan::HOST_BAUD.bps()),
                &mut rcc,
            )
            .unwrap_or_else(|_| panic!("USART1 configuration"));
        let (tx, mut rx) = serial.split();
        rx.listen();
        let (rx_in, rx_out) = cx.local.queue.split();
        (
            Shared {
                session: cx.local.session,
            },
            Local {
                rx,
                rx_in,
                rx_out,
                tx: HostTx(tx),
                syst,
                bench,
                _tim2: tim2,
            },
        )
    }

    /// Interrupt-driven receive into the queue.
    #[task(binds = USART1, local = [rx, rx_in], priority = 1)]
    fn usart1(cx: usart1::Context) {
        usart::on_rx_interrupt(cx.local.rx, cx.local.rx_in);
    }

    /// The millisecond clock.
    #[task(binds = SysTick, priority = 2)]
    fn systick(_: systick::Context) {
        crate::tick();
    }

    #[idle(shared = [session], local = [rx_out, tx, syst, bench])]
    fn idle(mut cx: idle::Context) -> ! {
        let idle::LocalResources {
            rx_out,
            tx,
            syst,
            bench,
            ..
        } = cx.local;
        let Ok(()) = cx.shared.session.lock(|s| s.announce(tx));
        say!(
            "activesense-firmware: serving protocol v{} on USART1",
            activesense_core::protocol::PROTOCOL_VERSION
        );
        defmt::info!(
            "serving protocol v{=u16} on USART1",
            activesense_core::protocol::PROTOCOL_VERSION
        );
        let mut buf = [0u8; 64];
        loop {
            let n = usart::take(rx_out, &mut buf);
            if n > 0 {
                let control = cx.shared.session.lock(|s| {
                    let c = s.feed(&buf[..n], crate::millis(), tx);
                    while let Some(e) = s.take_event() {
                        crate::log_event(e);
                    }
                    c
                });
                match control {
                    Ok(Control::Continue) => {}
                    Ok(Control::Shutdown) => {
                        say!("activesense-firmware: shutdown");
                        console::exit(true);
                    }
                    Err(e) => match e {},
                }
            } else if cx.shared.session.lock(|s| {
                let abandoned = s.poll(crate::millis());
                while let Some(e) = s.take_event() {
                    crate::log_event(e);
                }
                abandoned
            }) {
                say!("activesense-firmware: host silent, episode abandoned");
            } else {
                // Sleep until a byte arrives (USART1) or the next SysTick. Under QEMU this
                // also frees the emulator's I/O thread, which a polling loop would starve.
                // In bench mode the tick runs only here, never inside a timed update.
                if *bench {
                    syst.enable_interrupt();
                }
                cortex_m::interrupt::free(|_| {
                    // With interrupts masked, a byte arriving after this check still
                    // ends the `wfi` (it pends the interrupt).
                    if !rx_out.ready() {
                        cortex_m::asm::wfi();
                    }
                });
                if *bench {
                    // A tick that pended meanwhile has already run.
                    syst.disable_interrupt();
                }
            }
        }
    }
}
