//! Agents beyond the core's blind and heuristic ones that the instrument side can play: the
//! greedy information-gain benchmarks ([`greedy`]: OIGM and OIGM-cost, which need the ground
//! truth and so run only in simulation, and EEM, which does not).

pub mod greedy;
