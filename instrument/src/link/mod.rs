//! The host side of the instrument serial protocol (`docs/protocol.md`), lowest first:
//! [`device`] is the simulated instrument the host plays (the world's sensors) and the core
//! session served in a thread or over any byte stream, and the firmware under QEMU, whose
//! command line is built in [`qemu_cmd`] (one place, shared with `cargo xtask`); [`error`] is
//! the link's error type; [`serial`] is the protocol client and the
//! transports (loopback, TCP, serial port, QEMU); [`runner`] runs one episode on a device
//! (restarts from its seeds after a lost link, `--verify`, the session's end). The commands
//! that drive an instrument (`sim`, `serial`, `mcu-bench`, `policy upload/info`) are the
//! `activesense` binary's.

pub mod device;
pub mod error;
pub mod qemu_cmd;
pub mod runner;
pub mod serial;
