//! Register-level USART1 driver for the STM32F405 (also what QEMU's netduinoplus2 models
//! as `stm32f2xx-usart` on `serial0`), implementing `embedded_io` Read/ReadReady/Write.
//!
//! Pins: PA9 = TX, PA10 = RX, alternate function 7. Polled, no interrupts, no DMA. The
//! receive side is drained quickly by the main loop; QEMU holds further input back until
//! DR has been read (RXNE clear), so nothing is lost under emulation. On hardware at
//! 115200 Bd a byte arrives every 87 µs, far slower than the per-byte session work.

use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};

const RCC: usize = 0x4002_3800;
const RCC_AHB1ENR: usize = RCC + 0x30;
const RCC_APB2ENR: usize = RCC + 0x44;
const GPIOA: usize = 0x4002_0000;
const GPIO_MODER: usize = 0x00;
const GPIO_AFRH: usize = 0x24;
const USART1: usize = 0x4001_1000;
const SR: usize = 0x00;
const DR: usize = 0x04;
const BRR: usize = 0x08;
const CR1: usize = 0x0C;
const SR_RXNE: u32 = 1 << 5;
const SR_TC: u32 = 1 << 6;
const SR_TXE: u32 = 1 << 7;
const SR_ORE: u32 = 1 << 3;
const CR1_UE: u32 = 1 << 13;
const CR1_TE: u32 = 1 << 3;
const CR1_RE: u32 = 1 << 2;

const CR1_RXNEIE: u32 = 1 << 5;

/// USART1 global interrupt number.
pub const IRQN: i16 = 37;

/// USART1's interrupt line for the NVIC.
#[derive(Clone, Copy)]
pub struct Usart1Irq;

// SAFETY: 37 is USART1's position in the STM32F405 vector table.
unsafe impl cortex_m::interrupt::InterruptNumber for Usart1Irq {
    fn number(self) -> u16 {
        IRQN as u16
    }
}

/// Lets RXNE raise the USART1 interrupt (to wake from `wfi`).
pub fn enable_rx_interrupt() {
    wr(USART1 + CR1, rd(USART1 + CR1) | CR1_RXNEIE);
}

fn rd(addr: usize) -> u32 {
    // SAFETY: `addr` is one of the fixed, aligned STM32F405 peripheral registers above.
    unsafe { read_volatile(addr as *const u32) }
}

fn wr(addr: usize, v: u32) {
    // SAFETY: as in `rd`.
    unsafe { write_volatile(addr as *mut u32, v) }
}

/// USART1, 8N1, polled.
pub struct Usart1 {
    _private: (),
}

impl Usart1 {
    /// Enables clocks, routes PA9/PA10 to AF7, sets the baud rate from `pclk2` and
    /// enables transmitter and receiver.
    pub fn init(baud: u32, pclk2: u32) -> Self {
        wr(RCC_AHB1ENR, rd(RCC_AHB1ENR) | 1); // GPIOAEN
        wr(RCC_APB2ENR, rd(RCC_APB2ENR) | (1 << 4)); // USART1EN
        let moder = rd(GPIOA + GPIO_MODER) & !(0b1111 << 18);
        wr(GPIOA + GPIO_MODER, moder | (0b1010 << 18)); // PA9, PA10: alternate function
        let afrh = rd(GPIOA + GPIO_AFRH) & !(0xFF << 4);
        wr(GPIOA + GPIO_AFRH, afrh | (0x77 << 4)); // AF7 on PA9, PA10
                                                   // Oversampling by 16: BRR = pclk / baud, mantissa.fraction in 12.4 fixed point.
        wr(USART1 + BRR, (pclk2 + baud / 2) / baud.max(1));
        wr(USART1 + CR1, CR1_UE | CR1_TE | CR1_RE);
        Usart1 { _private: () }
    }

    fn rx_ready(&self) -> bool {
        rd(USART1 + SR) & (SR_RXNE | SR_ORE) != 0
    }
}

impl embedded_io::ErrorType for Usart1 {
    type Error = Infallible;
}

impl embedded_io::ReadReady for Usart1 {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.rx_ready())
    }
}

impl embedded_io::Read for Usart1 {
    /// Blocks until one byte is available, then takes what is ready (up to `buf.len()`).
    /// An overrun (lost byte) surfaces as a CRC/framing error one protocol level up.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        if buf.is_empty() {
            return Ok(0);
        }
        while !self.rx_ready() {}
        let mut n = 0;
        while n < buf.len() && self.rx_ready() {
            // Reading SR then DR clears RXNE and ORE.
            buf[n] = rd(USART1 + DR) as u8;
            n += 1;
        }
        Ok(n)
    }
}

impl embedded_io::Write for Usart1 {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &b in buf {
            while rd(USART1 + SR) & SR_TXE == 0 {}
            wr(USART1 + DR, b as u32);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        while rd(USART1 + SR) & SR_TC == 0 {}
        Ok(())
    }
}
