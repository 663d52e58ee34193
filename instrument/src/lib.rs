//! # activesense-sim
//!
//! The std side of activesense. Modules, lowest first (a module imports only from those
//! above it in this list, plus `activesense_core`):
//!
//! | module | what it holds |
//! |---|---|
//! | [`world`] | the simulated instrument's world ([`world::SimWorld`], placement); [`world::plans`] the seeded floor-plan generator (training and test seed ranges); [`world::planfile`] the user's own plans (JSON, GeoJSON, DXF); [`world::sensor`] the simulated EDM and topological scan |
//! | [`episode`] | the in-process episode: [`episode::EpisodeSpec`], the runner, its [`episode::Trajectory`] log, the host's seed mixing |
//! | [`answer`] | what the instrument answers: [`answer::Answer`] (the station in the plan's own coordinates, heading, precision, candidates and ambiguity; text and JSON), [`answer::coverage`] how honest its σ are |
//! | [`baselines`] | [`baselines::greedy`] the greedy benchmarks (OIGM, OIGM-cost, EEM); [`baselines::classical`] the classical grid Markov localizer |
//! | [`plot`] | every picture, from plain numbers: the budget chart and the generic line chart ([`plot`]), the evaluation's other charts ([`plot::charts`]), the trainer's learning curve ([`plot::curve`]), the plan and episode scene ([`plot::svg`]) |
//! | [`learn`] | the learned actor-critic policy: [`learn::agent`], [`learn::net`], the policy file ([`learn::file`]), int8 quantisation ([`learn::quantize`]), training ([`learn::train`]) |
//! | [`eval`] | the evaluation harness (the paper's Table 4): [`eval::record`] one episode's row and curve, [`eval::stats`] intervals and aggregation, [`eval::harness`] the parallel run, [`eval::paper`] the paper's numbers, [`eval::report`] results.md and the output files, [`eval::experiments`] the extra-measurements analysis |
//! | [`bench`](mod@bench) | [`bench::localization`] GHT vs the classical localizer; [`bench::registration`] sparse-registration accuracy |
//! | [`calibrate`] | the fit of the calibrated stop |
//! | [`inspect`] | the inspection tool: trajectory pages and ([`inspect::aggregate`]) the guided-back-propagation analysis |
//! | [`link`] | the instrument serial protocol (`docs/protocol.md`): [`link::device`] the simulated instrument, the loopback device and the QEMU launcher; [`link::qemu_cmd`] the one QEMU command line (shared with xtask); [`link::error`] the link's errors; [`link::serial`] the protocol client and its transports; [`link::remote`] the `sim`, `serial` and `mcu-bench` commands |
//! | [`geocom`] | a Leica total station over GeoCOM (`docs/GEOCOM.md`): [`geocom::wire`] framing, [`geocom::codes`] return codes, [`geocom::client`] transports and the retrying call, [`geocom::rpc`] the RPCs, [`geocom::instrument`] the core `Instrument` and the station session, [`geocom::sim`] the instrument simulator |
//! | [`cli`] | the bodies of the `activesense` commands, one module each ([`cli::plan`], [`cli::episode`], [`cli::train`], [`cli::dataset`], [`cli::eval`], [`cli::bench_registration`], [`cli::bench_localization`], [`cli::policy`]); the binary (`src/main.rs`) is the clap tree only |

pub mod answer;
pub mod baselines;
pub mod bench;
pub mod calibrate;
pub mod cli;
pub mod episode;
pub mod eval;
pub mod geocom;
pub mod inspect;
pub mod learn;
pub mod link;
pub mod plot;
pub mod world;
