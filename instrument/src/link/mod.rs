//! The host side of the instrument serial protocol (`docs/protocol.md`), lowest first:
//! [`device`] is the simulated instrument the host plays (the world's sensors) and the core
//! session served in a thread or over any byte stream, and the firmware under QEMU, whose
//! command line is built in [`qemu_cmd`] (one place, shared with `cargo xtask`); [`error`] is
//! the link's error type; [`serial`] is the protocol client and the
//! transports (loopback, TCP, serial port, QEMU); [`runner`] runs one episode on a device
//! (restarts from its seeds after a lost link, `--verify`, the session's end); [`remote`]
//! holds the commands that drive an instrument (`sim`, `serial`), [`mcu_bench`] the
//! firmware's instruction counts (`mcu-bench`); `policy upload/info` are in
//! [`crate::cli::policy`].

pub mod device;
pub mod error;
pub mod mcu_bench;
pub mod qemu_cmd;
pub mod remote;
pub mod runner;
pub mod serial;
