//! The int8 policies the instrument carries in flash: the committed learnt policies for
//! K = 1 and K = 10 (`policies/k{K}/policy.q8`, made by `activesense policy quantize` from
//! the float policies next to them). The firmware serves them; the host's emulated device
//! and the host's `learnt-int8` agent use the same bytes, so both sides run one network.
//! A `static` that nobody references costs no flash.

/// `policies/k1/policy.q8`.
pub static K1: &[u8] = include_bytes!("../../../policies/k1/policy.q8");
/// `policies/k10/policy.q8`.
pub static K10: &[u8] = include_bytes!("../../../policies/k10/policy.q8");
/// Both, for [`crate::device::SessionConfig::policies`].
pub static POLICIES: [&[u8]; 2] = [K1, K10];
