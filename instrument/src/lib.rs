//! # activesense-instrument
//!
//! The instrument side of activesense: everything a user runs to set up a station against a
//! floor plan, and nothing of the lab (training, evaluation, calibration, benchmarks live in
//! `activesense-lab`, which depends on this crate and never the other way round). Modules,
//! lowest first (a module imports only from those above it in this list, plus
//! `activesense_core`):
//!
//! | module | what it holds |
//! |---|---|
//! | [`world`] | the simulated instrument's world ([`world::SimWorld`], placement); [`world::plans`] the seeded floor-plan generator (training and test seed ranges); [`world::planfile`] the user's own plans (JSON, GeoJSON, DXF); [`world::sensor`] the simulated EDM and topological scan |
//! | [`episode`] | the in-process episode: [`episode::EpisodeSpec`], the runner, its [`episode::Trajectory`] log, the host's seed mixing |
//! | [`answer`] | what the instrument answers: [`answer::Answer`] (the station in the plan's own coordinates, heading, precision, candidates and ambiguity; text and JSON) |
//! | [`baselines`] | [`baselines::greedy`] the greedy agents (OIGM, OIGM-cost, EEM) that play behind the same agent dispatch as the others |
//! | [`plot`] | [`plot::svg`] the plan and episode drawing |
//! | [`learn`] | the learnt policy as the instrument plays it: [`learn::net`] the network, [`learn::file`] the policy file, [`learn::agent`] the float and int8 agents behind the core's `Policy` seam |
//! | [`agents`] | which agent plays: the one dispatch from an agent's name to its episode, and the policies a run loaded |
//! | [`link`] | the instrument serial protocol (`docs/protocol.md`): [`link::device`] the simulated instrument, the loopback device and the QEMU launcher; [`link::qemu_cmd`] the one QEMU command line (shared with xtask); [`link::error`] the link's errors; [`link::serial`] the protocol client and its transports; [`link::runner`] one episode on a device |
//! | [`geocom`] | a Leica total station over GeoCOM (`docs/GEOCOM.md`): [`geocom::wire`] framing, [`geocom::codes`] return codes, [`geocom::client`] transports and the retrying call, [`geocom::rpc`] the RPCs, [`geocom::instrument`] the core `Instrument` and the station session, [`geocom::sim`] the instrument simulator |

pub mod agents;
pub mod answer;
pub mod baselines;
pub mod episode;
pub mod geocom;
pub mod learn;
pub mod link;
pub mod plot;
pub mod world;

#[cfg(test)]
mod fixtures;
