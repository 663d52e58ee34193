//! USART1, the host link (PA9 = TX, PA10 = RX, AF7; QEMU's `serial0`), on stm32f4xx-hal's
//! serial driver. 8N1 at [`BAUD`](crate::clock_plan::HOST_BAUD).
//!
//! **Receive** is interrupt-driven: the RTIC task bound to USART1 (`main.rs`) moves every
//! received byte into a single-producer single-consumer queue ([`RxQueue`]) that the
//! serving loop drains. When the queue is full the task masks its interrupt and leaves the
//! byte in the data register; the serving loop unmasks it after taking bytes out
//! ([`resume_rx`]). Under QEMU this is flow control (QEMU holds further input back until DR
//! has been read), so nothing is lost under emulation however slowly the loop drains; on
//! hardware the queue holds 2.2 ms of input at 115200 Bd, far more than the per-byte
//! session work needs. A receive error (overrun, framing, noise) drops the byte; the
//! protocol's CRC turns that into one rejected frame.
//!
//! **Transmit** is blocking, byte by byte ([`HostTx`]).

use core::convert::Infallible;
use embedded_hal_nb::serial::Read as _;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4xx_hal::pac::{self, Interrupt, NVIC};
use stm32f4xx_hal::serial::{Rx, Tx};

/// Bytes the receive queue holds (one less than its size).
pub const RX_QUEUE: usize = 256;
/// The receive queue between the USART1 task and the serving loop.
pub type RxQueue = Queue<u8, RX_QUEUE>;

/// The USART1 interrupt's work: drain the receiver into `queue` (see the module docs).
pub fn on_rx_interrupt(rx: &mut Rx<pac::USART1>, queue: &mut Producer<'static, u8, RX_QUEUE>) {
    loop {
        if !queue.ready() {
            // Full: leave the byte in DR and stop the (level-triggered) interrupt until the
            // serving loop has made room.
            NVIC::mask(Interrupt::USART1);
            return;
        }
        match rx.read() {
            Ok(b) => {
                let _ = queue.enqueue(b); // cannot fail: `ready` above
            }
            Err(nb::Error::WouldBlock) => return,
            // The HAL has cleared the error by reading DR; the byte is lost.
            Err(nb::Error::Other(_)) => {}
        }
    }
}

/// Takes up to `buf.len()` received bytes; lets the receive interrupt run again.
pub fn take(queue: &mut Consumer<'static, u8, RX_QUEUE>, buf: &mut [u8]) -> usize {
    let mut n = 0;
    while n < buf.len() {
        match queue.dequeue() {
            Some(b) => {
                buf[n] = b;
                n += 1;
            }
            None => break,
        }
    }
    if n > 0 {
        resume_rx();
    }
    n
}

/// Unmasks USART1 after [`on_rx_interrupt`] masked it for a full queue.
fn resume_rx() {
    // SAFETY: RTIC set USART1's priority at start-up and binds its handler; unmasking only
    // re-enables that same handler, which touches nothing but its own local resources.
    unsafe { NVIC::unmask(Interrupt::USART1) };
}

/// USART1's transmitter as a blocking `embedded_io` writer (it cannot fail: the HAL's
/// transmit only ever reports "not yet").
pub struct HostTx(pub Tx<pac::USART1>);

impl embedded_io::ErrorType for HostTx {
    type Error = Infallible;
}

impl embedded_io::Write for HostTx {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &b in buf {
            while let Err(nb::Error::WouldBlock) =
                embedded_hal_nb::serial::Write::write(&mut self.0, b)
            {}
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        while let Err(nb::Error::WouldBlock) = embedded_hal_nb::serial::Write::flush(&mut self.0) {}
        Ok(())
    }
}

impl core::fmt::Write for HostTx {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let Ok(()) = embedded_io::Write::write_all(self, s.as_bytes());
        Ok(())
    }
}
