//! # activesense-lab
//!
//! The lab side of activesense: how the committed policies, stop tables and result tables
//! are made and measured. It depends on `activesense-instrument` (the episode, the agents,
//! the world) and adds nothing the instrument needs. Modules, lowest first (a module imports
//! only from those above it in this list, plus the instrument and core crates):
//!
//! | module | what it holds |
//! |---|---|
//! | [`baselines`] | [`baselines::classical`] the classical grid Markov localizer (paper Table 1) |
//! | [`coverage`] | how honest the answer's σ are and how often answers are ambiguous (`answer-coverage`) |
//! | [`plot`] | the lab's charts from plain numbers: the budget chart and the generic line chart ([`plot`]), the evaluation's other charts ([`plot::charts`]), the trainer's learning curve ([`plot::curve`]) |
//! | [`learn`] | [`learn::train`] the trainer, [`learn::hyper`] its hyper-parameters, [`learn::quantize`] int8 quantisation |
//! | [`eval`] | the evaluation harness (the paper's Table 4): [`eval::record`] one episode's row and curve, [`eval::stats`] intervals and aggregation, [`eval::harness`] the parallel run, [`eval::paper`] the paper's numbers, [`eval::report`] results.md and the output files, [`eval::experiments`] the extra-measurements analysis, [`eval::frontier`] the risk–cost frontier |
//! | [`bench`](mod@bench) | [`bench::localization`] GHT vs the classical localizer; [`bench::registration`] sparse-registration accuracy |
//! | [`calibrate`] | the fit of the calibrated stop |
//! | [`inspect`] | the inspection tool: trajectory pages and ([`inspect::aggregate`]) the guided-back-propagation analysis |

pub mod baselines;
pub mod bench;
pub mod calibrate;
pub mod coverage;
pub mod eval;
pub mod inspect;
pub mod learn;
pub mod plot;
