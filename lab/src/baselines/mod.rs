//! The classical grid Markov localizer ([`classical`]) the GHT localizer is benchmarked
//! against (paper Table 1). The greedy benchmark agents are in
//! `activesense_instrument::baselines`, behind the one agent dispatch.

pub mod classical;
