//! The plain-text console and the way out. In the emulated build (`cfg(emulated)`, see
//! `build.rs`) both go through semihosting: lines on QEMU's stdout (which the tests read),
//! the exit status to QEMU. On hardware there is no semihosting host (a semihosting call
//! without a debugger stops the core), so the lines go to defmt (RTT) and "exit" parks
//! the core.

/// Prints one console line (`format_args!` syntax).
#[cfg(emulated)]
macro_rules! say {
    ($($t:tt)*) => { cortex_m_semihosting::hprintln!($($t)*) };
}

/// Prints one console line (`format_args!` syntax).
#[cfg(not(emulated))]
macro_rules! say {
    ($($t:tt)*) => { defmt::println!("{}", defmt::Display2Format(&format_args!($($t)*))) };
}

pub(crate) use say;

/// Ends the program: exit status `ok` under QEMU; on hardware the core sleeps.
pub fn exit(ok: bool) -> ! {
    #[cfg(emulated)]
    cortex_m_semihosting::debug::exit(if ok {
        cortex_m_semihosting::debug::EXIT_SUCCESS
    } else {
        cortex_m_semihosting::debug::EXIT_FAILURE
    });
    let _ = ok;
    loop {
        cortex_m::asm::wfi();
    }
}

/// True when the semihosting command line contains the word `word` (always false on
/// hardware).
#[cfg_attr(feature = "board", allow(dead_code))]
pub fn cmdline_has(word: &[u8]) -> bool {
    #[cfg(emulated)]
    {
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
    #[cfg(not(emulated))]
    {
        let _ = word;
        false
    }
}
