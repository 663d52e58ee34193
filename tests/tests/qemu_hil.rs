//! QEMU hardware-in-the-loop: the real firmware ELF in `qemu-system-arm -M netduinoplus2`,
//! USART1 on a local TCP socket. The ELF is built by [`firmware_elf`] (cargo, thumb target,
//! `firmware` profile) unless `ACTIVESENSE_FIRMWARE_ELF` names one.

use activesense_sim::link::{self, LinkSpec};
use activesense_tests::{check_episodes, fault_suite, firmware_elf};
use std::time::Duration;

#[test]
fn qemu_firmware_episodes_bit_identical_and_faults() {
    let elf = firmware_elf();
    let mut l = link::open(&LinkSpec::Qemu(elf), Duration::from_secs(10)).expect("start qemu");
    let info = l.client.hello().expect("hello");
    assert!(info.firmware.starts_with("activesense-fw"), "{info:?}");
    // 20 episodes: 10 with the heading known (K = 1), 10 with K = 10.
    assert!(check_episodes(&mut l.client, 10, 1) > 0);
    assert!(check_episodes(&mut l.client, 10, 10) > 0);
    fault_suite(&mut l.client);
    check_episodes(&mut l.client, 1, 10);
    let out = l.close().expect("firmware shuts down with exit status 0");
    assert!(out.contains("core initialised"), "{out}");
    assert!(out.contains("activesense-firmware: shutdown"), "{out}");
}
