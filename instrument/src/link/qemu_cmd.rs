//! The QEMU command line for the firmware's board, in one place: `qemu-system-arm` emulating
//! the netduinoplus2 (STM32F405, Cortex-M4) with semihosting on, no monitor, no graphics, and
//! USART1 (`serial0`) wherever the caller points it. `link::device::Qemu` (the `qemu` link)
//! and `cargo xtask` (the smoke boot) both build their emulator from [`qemu_command`].
//!
//! Why this file is shared by path and not by a dependency: xtask must build and run before
//! anything else does (`cargo xtask setup` installs the toolchain pieces), so it depends only
//! on the small no_std core, never on this std crate with its clap, rayon, serial-port and DXF
//! dependencies; and the core is no_std (no `std::process`) and owned by the firmware side.
//! So this file imports nothing but `std`, and xtask compiles the same file as its own module
//! (`#[path = "../../instrument/src/link/qemu_cmd.rs"] mod qemu_cmd;`). Keep it std-only.

use std::path::Path;
use std::process::Command;

/// Where the emulated USART1 (`serial0`) goes.
#[derive(Clone, Copy, Debug)]
pub enum QemuSerial {
    /// Connect to a TCP listener on 127.0.0.1 at this port (the host link).
    Tcp(u16),
    /// Listen on 127.0.0.1 at this port, boot without waiting for a client, and take a
    /// new client after one leaves: an instrument the user started, which serves command
    /// after command (`--link tcp:127.0.0.1:PORT`).
    TcpServer(u16),
    /// Nowhere (the smoke boot, which never serves the link).
    Null,
}

/// `program` (normally `qemu-system-arm`) on the netduinoplus2 board running `elf`, with
/// semihosting and USART1 on `serial`. Callers append their own arguments (`-append smoke`,
/// `-icount shift=0`) and set up stdio.
pub fn qemu_command(program: &str, elf: &Path, serial: QemuSerial) -> Command {
    let serial = match serial {
        QemuSerial::Tcp(port) => format!("tcp:127.0.0.1:{port},nodelay=on"),
        QemuSerial::TcpServer(port) => {
            format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on")
        }
        QemuSerial::Null => "null".to_string(),
    };
    let mut c = Command::new(program);
    c.args([
        "-cpu",
        "cortex-m4",
        "-machine",
        "netduinoplus2",
        "-nographic",
        "-monitor",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-serial",
        &serial,
        "-kernel",
    ])
    .arg(elf);
    c
}
