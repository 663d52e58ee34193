//! Reliability under load: many consecutive episodes in **one** QEMU session of
//! the real firmware, cycling through both K (1, 10), both agents (heuristic-1, the int8
//! learnt policy) and both stops (oracle, confident), each checked bit-identical to the
//! host's in-process run and the host's own agent (`check_episodes_with`); the link's
//! timeouts turn a hang into a failure. `ACTIVESENSE_SOAK_EPISODES` sets the count (default
//! 8, one of each combination, which CI runs); `cargo xtask soak --episodes N` runs it long.
//!
//! Watched every 8 episodes, from the device's own `Status` and the host's link counters:
//! the device's completed-episode count must follow the host's one for one, its bad frames,
//! sequence errors, re-sent replies and abandoned episodes must stay 0, as must the host's
//! re-sent requests, dropped replies and reply time-outs on this clean line. The device's
//! largest update (cycles since power-on) is reported, not asserted: it depends on the
//! plans, and without `-icount` QEMU's timers follow the host's wall time, so it is not an
//! instruction count (`cargo xtask mcu-bench` counts instructions). Not watched: the stack's high-water mark, which the firmware does not measure.

use activesense_core::episode::AgentKind;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::link::serial::{self, LinkSpec};
use activesense_instrument::world::plans::TEST_SEEDS;
use activesense_tests::{check_episodes_with, confident_stop, firmware_elf};
use std::time::{Duration, Instant};

#[test]
fn qemu_soak_episodes_bit_identical() {
    let n: u32 = std::env::var("ACTIVESENSE_SOAK_EPISODES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8);
    let elf = firmware_elf();
    let mut l = serial::open(&LinkSpec::Qemu(elf), Duration::from_secs(10)).expect("start qemu");
    let info = l.client.hello().expect("hello");
    let before = l.client.status().expect("status");
    let started = Instant::now();
    let mut steps = 0usize;
    for j in 0..n {
        // Combination j mod 8: K, agent, stop; plan and episode seeds advance with j.
        let k = if j % 2 == 0 { 1 } else { 10 };
        let agent = if (j / 2) % 2 == 0 {
            AgentKind::Heuristic1
        } else {
            AgentKind::LearntInt8
        };
        let confident = (j / 4) % 2 == 1;
        let stop = confident_stop(0.05, 0.2);
        steps += check_episodes_with(&mut l.client, 1, k, |s| {
            *s = EpisodeSpec {
                episode_seed: 7 + j as u64,
                rot_bins: k,
                ..EpisodeSpec::new(TEST_SEEDS.start + j, agent)
            };
            if confident {
                stop(s);
            }
        });
        if (j + 1) % 8 == 0 || j + 1 == n {
            let st = l.client.status().expect("status during the soak");
            let link = st.link;
            let host = l.client.counters();
            println!(
                "soak: {} episodes bit-identical, {steps} steps, {:.1} s; device: {} episodes, \
                 {} frames ok, {} bad, {} sequence errors, {} replies re-sent, {} abandoned, \
                 largest update {} cycles over {} updates; host: {}",
                j + 1,
                started.elapsed().as_secs_f64(),
                link.episodes - before.link.episodes,
                link.frames_ok - before.link.frames_ok,
                link.frames_bad,
                link.sequence_errors,
                link.retransmissions,
                link.timeouts,
                st.cycles.max_cycles,
                st.cycles.updates,
                host.summary()
            );
            assert_eq!(
                link.episodes - before.link.episodes,
                j + 1,
                "device episode count"
            );
            assert_eq!(
                (
                    link.frames_bad,
                    link.sequence_errors,
                    link.retransmissions,
                    link.timeouts
                ),
                (
                    before.link.frames_bad,
                    before.link.sequence_errors,
                    before.link.retransmissions,
                    before.link.timeouts
                ),
                "device link counters grew on a clean line"
            );
            assert_eq!(
                host,
                Default::default(),
                "host link counters on a clean line"
            );
        }
    }
    // The session still answers and reports the same firmware after the load.
    let again = l.client.hello().expect("hello after the soak");
    assert_eq!(again.firmware, info.firmware);
    let out = l
        .shutdown()
        .expect("firmware shuts down with exit status 0");
    assert!(out.contains("activesense-firmware: shutdown"), "{out}");
    assert!(!out.contains("PANIC"), "{out}");
}
