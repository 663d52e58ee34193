//! # activesense-sim
//!
//! The std side of activesense. Modules, lowest first (a module imports only from those
//! above it in this list, plus `activesense_core`):
//!
//! | module | what it holds |
//! |---|---|
//! | [`world`] | the seeded floor-plan generator ([`world::plans`]), the user's own plans ([`world::planfile`]: JSON, GeoJSON, DXF), the simulated sensors ([`world::sensor`]) and the simulated instrument's world ([`world::SimWorld`]) |
//! | [`episode`] | the in-process episode: [`episode::EpisodeSpec`], the runner and its [`episode::Trajectory`] log |
//! | [`baselines`] | the greedy benchmarks ([`baselines::greedy`]: OIGM, EEM) and the classical grid Markov localizer ([`baselines::classical`]) |
//! | [`plot`] | every picture: the plan/trajectory scene ([`plot::svg`]), the evaluation charts and the trainer's learning curve, all from plain data |
//! | [`learn`] | the learned actor-critic policy: network, policy file, int8 quantisation, training |
//! | [`eval`] | the evaluation harness (the paper's Table 4): episodes, statistics, the markdown report, the extra-measurements experiment |
//! | [`bench`] | the localization and registration benchmarks |
//! | [`calibrate`] | the fit of the calibrated stop |
//! | [`inspect`] | the inspection tool: trajectory pages and the guided-back-propagation analysis |
//! | [`link`] | the instrument serial protocol (`docs/protocol.md`) to the firmware (QEMU, serial, TCP) or to the core session in a thread, and the commands that drive it |
//! | [`cli`] | the bodies of the `activesense` commands; the binary (`src/main.rs`) is the clap tree only |

pub mod baselines;
pub mod bench;
pub mod calibrate;
pub mod cli;
pub mod episode;
pub mod eval;
pub mod inspect;
pub mod learn;
pub mod link;
pub mod plot;
pub mod world;
