//! The int8 policies the instrument carries in flash: the committed learnt policies for
//! K = 1 and K = 10 of each instrument profile (`policies/k{K}/policy.q8` for the paper's
//! sensor, `policies/edm/k{K}/policy.q8` for the EDM-only instrument; made by `activesense
//! policy quantize` from the float policies next to them). The firmware serves them; the
//! host's emulated device and the host's `learnt-int8` agent use the same bytes, so both
//! sides run one network. A `static` that nobody references costs no flash.

use crate::episode::InstrumentProfile;

/// `policies/k1/policy.q8`.
pub static K1: &[u8] = include_bytes!("../../../policies/k1/policy.q8");
/// `policies/k10/policy.q8`.
pub static K10: &[u8] = include_bytes!("../../../policies/k10/policy.q8");
/// `policies/edm/k1/policy.q8`.
pub static EDM_K1: &[u8] = include_bytes!("../../../policies/edm/k1/policy.q8");
/// `policies/edm/k10/policy.q8`.
pub static EDM_K10: &[u8] = include_bytes!("../../../policies/edm/k10/policy.q8");
/// All four, for [`crate::device::SessionConfig::policies`].
pub static POLICIES: [&[u8]; 4] = [K1, K10, EDM_K1, EDM_K10];

/// The built-in blobs of `instrument`, with their K.
pub fn blobs_for(instrument: InstrumentProfile) -> [(u8, &'static [u8]); 2] {
    match instrument {
        InstrumentProfile::EdmScan => [(1, K1), (10, K10)],
        InstrumentProfile::Edm => [(1, EDM_K1), (10, EDM_K10)],
    }
}
