//! # activesense-sim
//!
//! The std side of activesense: the seeded floor-plan generator ([`plans`]), the simulated
//! instrument and its sensors ([`world`], [`sensor`]), the episode runner with its
//! trajectory log ([`episode`]) and SVG rendering ([`svg`]). The `activesense` binary
//! (`src/main.rs`) is the command-line front end.

pub mod episode;
pub mod plans;
pub mod sensor;
pub mod svg;
pub mod world;
