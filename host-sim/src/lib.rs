//! # activesense-sim
//!
//! The std side of activesense: the seeded floor-plan generator ([`plans`]), the simulated
//! instrument and its sensors ([`world`], [`sensor`]), the episode runner with its
//! trajectory log ([`episode`]), the evaluation harness ([`eval`], [`plot`]) and SVG
//! rendering ([`svg`]); the classical grid Markov localizer ([`classical`]) and the
//! localization / registration benchmarks ([`bench_localization`], [`bench_registration`]);
//! the learned actor-critic policy network and its policy file format ([`learn`]); the
//! inspection tool: trajectory pages and the guided-back-propagation analysis ([`inspect`]).
//! [`link`], [`device`] and [`remote`] talk the instrument serial protocol
//! (`docs/protocol.md`) to the firmware (QEMU, serial, TCP) or to the core session in a
//! thread. [`planfile`] reads the user's own floor plans (JSON, GeoJSON, DXF). [`calibrate`] fits the calibrated stop. The `activesense` binary (`src/main.rs`) is the command-line front end.

pub mod bench_localization;
pub mod bench_registration;
pub mod calibrate;
pub mod classical;
pub mod cli;
pub mod device;
pub mod episode;
pub mod eval;
pub mod greedy;
pub mod inspect;
pub mod learn;
pub mod link;
pub mod planfile;
pub mod plans;
pub mod plot;
pub mod remote;
pub mod sensor;
pub mod svg;
pub mod world;
