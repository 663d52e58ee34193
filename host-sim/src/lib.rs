//! # activesense-sim
//!
//! The std side of activesense: the seeded floor-plan generator ([`plans`]), the simulated
//! instrument and its sensors ([`world`], [`sensor`]), the episode runner with its
//! trajectory log ([`episode`]) and SVG rendering ([`svg`]). The `activesense` binary
//! (`src/main.rs`) is the command-line front end. [`link`], [`device`] and [`remote`] talk
//! the instrument serial protocol (`docs/protocol.md`) to the firmware (QEMU, serial, TCP)
//! or to the core session in a thread.

pub mod device;
pub mod episode;
pub mod link;
pub mod plans;
pub mod remote;
pub mod sensor;
pub mod svg;
pub mod world;
