//! # activesense-sim
//!
//! The std side of activesense: the seeded floor-plan generator ([`plans`]), the simulated
//! instrument and its sensors ([`world`], [`sensor`]), the episode runner with its
//! trajectory log ([`episode`]) and SVG rendering ([`svg`]); the classical grid Markov
//! localizer ([`classical`]) and its side-by-side benchmark against the GHT localizer
//! ([`bench_localization`]). The `activesense` binary
//! (`src/main.rs`) is the command-line front end.

pub mod bench_localization;
pub mod bench_registration;
pub mod classical;
pub mod episode;
pub mod eval;
pub mod plans;
pub mod plot;
pub mod sensor;
pub mod svg;
pub mod world;
