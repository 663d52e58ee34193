//! The board's clock tree and baud divisors, as plain `const fn`s: what the `board` build
//! asks of stm32f4xx-hal (HSE → PLL → 168 MHz SYSCLK, 48 MHz USB clock, APB1 42 MHz,
//! APB2 84 MHz) and what the HAL computes for it, written out so it can be checked on the
//! host against RM0090 (the STM32F405 reference manual) without the chip:
//!
//! * `xtask`'s unit tests (`cargo test -p xtask`, run by `cargo xtask ci`) include this
//!   file and check [`pll`] and [`brr_over16`] against RM0090's formulas and values;
//! * the firmware asserts the board's plan at compile time (below) and, on the board at
//!   boot, compares the PLLCFGR fields the HAL wrote with [`BOARD_PLL`] (defmt log).
//!
//! RM0090 §6.3.2 (RCC_PLLCFGR): f(VCO in) = f(PLL in) / M, 1–2 MHz (2 MHz recommended to
//! limit jitter), 2 ≤ M ≤ 63; f(VCO out) = f(VCO in) × N, 100–432 MHz, 50 ≤ N ≤ 432;
//! SYSCLK = f(VCO out) / P, P ∈ {2, 4, 6, 8}, ≤ 168 MHz; USB OTG FS / SDIO / RNG clock =
//! f(VCO out) / Q, 2 ≤ Q ≤ 15, must be 48 MHz for USB.
//!
//! RM0090 §30.3.4 (USART baud rate): baud = f(PCLK) / (8 × (2 − OVER8) × USARTDIV), with
//! USARTDIV in 12.4 fixed point in USART_BRR (mantissa bits 15:4, fraction bits 3:0) when
//! oversampling by 16 (OVER8 = 0).

/// The Olimex STM32-H405's crystal (Q1): 8 MHz.
pub const BOARD_HSE_HZ: u32 = 8_000_000;
/// SYSCLK = HCLK: the STM32F405's maximum.
pub const SYSCLK_HZ: u32 = 168_000_000;
/// The USB OTG FS / SDIO / RNG clock (PLL48CK).
pub const USB_HZ: u32 = 48_000_000;
/// APB1 (USART2, TIM2, TIM5): its maximum, HCLK / 4.
pub const PCLK1_HZ: u32 = 42_000_000;
/// APB2 (USART1): its maximum, HCLK / 2.
pub const PCLK2_HZ: u32 = 84_000_000;
/// The host link's baud rate (USART1, docs/protocol.md).
pub const HOST_BAUD: u32 = 115_200;
/// The EDM module's baud rate (USART2, 8N1). An assumption: set it to what your module's
/// label or datasheet says (docs/firmware.md, "The EDM module").
pub const EDM_BAUD: u32 = 19_200;

/// The main PLL's dividers (P as the divisor 2/4/6/8, not its register encoding).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pll {
    /// Input divider M.
    pub m: u32,
    /// VCO multiplier N.
    pub n: u32,
    /// SYSCLK divider P.
    pub p: u32,
    /// 48 MHz-domain divider Q.
    pub q: u32,
}

impl Pll {
    /// VCO input (Hz) from the PLL source `src_hz`.
    pub const fn vco_in(self, src_hz: u32) -> u32 {
        src_hz / self.m
    }
    /// VCO output (Hz).
    pub const fn vco_out(self, src_hz: u32) -> u32 {
        self.vco_in(src_hz) * self.n
    }
    /// SYSCLK (Hz).
    pub const fn sysclk(self, src_hz: u32) -> u32 {
        self.vco_out(src_hz) / self.p
    }
    /// PLL48CK (Hz).
    pub const fn usb(self, src_hz: u32) -> u32 {
        self.vco_out(src_hz) / self.q
    }
}

/// The dividers stm32f4xx-hal 0.23 programs for `src_hz` → `sysclk_hz` with the 48 MHz
/// clock required (`Config::hse(..).sysclk(..).require_pll48clk()`; its
/// `MainPll::fast_setup`): the smallest M whose VCO input divides 48 MHz best, P the
/// largest even divisor keeping the VCO ≤ 432 MHz, then Q (4..=9) and N matching 48 MHz
/// first and SYSCLK second.
pub const fn pll(src_hz: u32, sysclk_hz: u32) -> Pll {
    let m_min = src_hz.div_ceil(2_000_000);
    let m_max = src_hz / 1_000_000;
    let p = {
        let d = (432_000_000 / sysclk_hz) & !1;
        if d < 8 {
            d
        } else {
            8
        }
    };
    let mut m = m_min;
    let mut best_m = m_min;
    let mut best_err = u32::MAX;
    while m <= m_max {
        let vin = src_hz / m;
        let err = USB_HZ - vin * (USB_HZ / vin);
        if err < best_err {
            best_err = err;
            best_m = m;
        }
        m += 1;
    }
    let vin = src_hz / best_m;
    let mut q = 4;
    let mut best_q = 4;
    let mut best = (u32::MAX, u32::MAX);
    while q <= 9 {
        let n = USB_HZ * q / vin;
        let usb_err = USB_HZ - vin * n / q;
        let sys_err = sysclk_hz.abs_diff(vin * n / p);
        if usb_err < best.0 || (usb_err == best.0 && sys_err < best.1) {
            best = (usb_err, sys_err);
            best_q = q;
        }
        q += 1;
    }
    let n = USB_HZ * best_q / vin;
    Pll {
        m: best_m,
        n,
        p,
        q: (vin * n).div_ceil(USB_HZ),
    }
}

/// USART_BRR for `baud` from `pclk_hz`, oversampling by 16: USARTDIV × 16 rounded to the
/// nearest integer (what stm32f4xx-hal writes, `calculate_brr`).
pub const fn brr_over16(pclk_hz: u32, baud: u32) -> u32 {
    (pclk_hz + baud / 2) / baud
}

/// The baud rate a BRR value really gives (oversampling by 16).
pub const fn baud_of(pclk_hz: u32, brr: u32) -> u32 {
    pclk_hz / brr
}

/// The board's PLL.
pub const BOARD_PLL: Pll = pll(BOARD_HSE_HZ, SYSCLK_HZ);
/// USART1's divisor on the board.
pub const HOST_BRR: u32 = brr_over16(PCLK2_HZ, HOST_BAUD);
/// USART2's divisor on the board.
pub const EDM_BRR: u32 = brr_over16(PCLK1_HZ, EDM_BAUD);

// The board's plan meets RM0090 exactly, or the firmware does not build.
const _: () = {
    let p = BOARD_PLL;
    assert!(p.sysclk(BOARD_HSE_HZ) == SYSCLK_HZ);
    assert!(p.usb(BOARD_HSE_HZ) == USB_HZ);
    assert!(p.vco_in(BOARD_HSE_HZ) >= 1_000_000 && p.vco_in(BOARD_HSE_HZ) <= 2_000_000);
    assert!(p.vco_out(BOARD_HSE_HZ) >= 100_000_000 && p.vco_out(BOARD_HSE_HZ) <= 432_000_000);
    assert!(p.m >= 2 && p.m <= 63 && p.n >= 50 && p.n <= 432 && p.q >= 2 && p.q <= 15);
    assert!(HOST_BRR >> 4 != 0 && HOST_BRR <= 0xFFFF && EDM_BRR <= 0xFFFF);
};
