//! The component benchmarks behind `activesense bench-localization` ([`localization`]: the GHT
//! localizer against the classical grid localizer) and `activesense bench-registration`
//! ([`registration`]: sparse-registration accuracy from coarse poses).

pub mod localization;
pub mod registration;
