//! activesense-sim
