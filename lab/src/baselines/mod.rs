//! The baselines the learnt agent is measured against, beyond the core's blind and heuristic
//! agents: the greedy information-gain benchmarks ([`greedy`]: OIGM, OIGM-cost, EEM) and the
//! classical grid Markov localizer ([`classical`]) the GHT localizer is benchmarked against.

pub mod classical;
pub mod greedy;
