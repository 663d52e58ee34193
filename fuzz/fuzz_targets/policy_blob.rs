//! Fuzz target: the int8 policy blob parser (`QuantizedPolicy::parse`) and, for whatever it
//! accepts, one decision on a fixed episode state. Neither may panic on any bytes. Half the
//! inputs are raw bytes; the other half are edits of the firmware's K = 1 blob (the input as
//! `(offset, xor)` byte pairs) with the length field and CRC repaired, so the fuzzer reaches the
//! tensor table and the kernels instead of stopping at the checksum.
#![no_main]

use activesense_core::episode::{AgentKind, EpisodeConfig, EpisodeParams, Termination};
use activesense_core::pipeline::runner::EpisodeRunner;
use activesense_core::policy::int8::{QuantizedPolicy, Scratch};
use activesense_core::world::geometry::v2;
use activesense_core::FloorPlan;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let bytes: Vec<u8> = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let mut b = activesense_core::policy::builtin::K1.to_vec();
        for e in rest.chunks_exact(3) {
            let at = u16::from_le_bytes([e[0], e[1]]) as usize % b.len();
            b[at] ^= e[2];
        }
        let n = b.len();
        b[20..24].copy_from_slice(&(n as u32).to_le_bytes());
        let crc = activesense_core::checksum::crc32(&b[..n - 4]);
        b[n - 4..].copy_from_slice(&crc.to_le_bytes());
        b
    };
    let Ok(policy) = QuantizedPolicy::parse(&bytes) else {
        return;
    };
    let plan = FloorPlan::new(&[v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)])
        .expect("square")
        .centered();
    let mut runner = Box::new(EpisodeRunner::new_empty());
    let params = EpisodeParams {
        agent: AgentKind::Blind0,
        seed: 1,
        rot_bins: policy.rot_bins().clamp(1, 10),
        known_heading: Some(0.0),
        ground_truth: None,
        initial_scan: 0b101,
        termination: Termination::ActionLimit,
        config: EpisodeConfig::default(),
    };
    if runner.start(&plan, &params).is_err() {
        return;
    }
    let mut scratch = Box::new(Scratch::new());
    let _ = policy.decide(&runner.input(), &mut scratch);
});
