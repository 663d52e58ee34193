//! QEMU hardware-in-the-loop: the real firmware ELF in `qemu-system-arm -M netduinoplus2`,
//! USART1 on a local TCP socket. The ELF is built by [`firmware_elf`] (cargo, thumb target,
//! `firmware` profile) unless `ACTIVESENSE_FIRMWARE_ELF` names one.

use activesense_sim::link::serial::{self, LinkSpec};
use activesense_tests::{
    check_episodes, check_episodes_with, confident_stop, fault_suite, firmware_elf,
};
use std::time::Duration;

#[test]
fn qemu_firmware_episodes_bit_identical_and_faults() {
    let elf = firmware_elf();
    let mut l = serial::open(&LinkSpec::Qemu(elf), Duration::from_secs(10)).expect("start qemu");
    let info = l.client.hello().expect("hello");
    assert!(info.firmware.starts_with("activesense-fw"), "{info:?}");
    // 20 episodes: 10 with the heading known (K = 1), 10 with K = 10.
    assert!(check_episodes(&mut l.client, 10, 1) > 0);
    assert!(check_episodes(&mut l.client, 10, 10) > 0);
    // The confident stop with the host's stop rule (protocol v4): stop_risk 0.05 and an
    // observability threshold, the same actions and stop step on the firmware as on the host.
    assert!(check_episodes_with(&mut l.client, 2, 10, confident_stop(0.05, 0.2)) > 0);
    fault_suite(&mut l.client);
    check_episodes(&mut l.client, 1, 10);
    // A policy uploaded into the firmware's RAM slot serves bit-identically; bad uploads
    // are refused with the uploaded policy still serving.
    activesense_tests::policy_upload_suite(&mut l.client);
    let out = l.close().expect("firmware shuts down with exit status 0");
    assert!(out.contains("core initialised"), "{out}");
    assert!(out.contains("activesense-firmware: shutdown"), "{out}");
}

/// `mcu-bench`: under `-icount shift=0` the firmware's TIM2 counts executed instructions,
/// so two runs give identical counts, every update is booked under its kind, and the
/// work is ordered as it must be (rotation < K = 1 vote < K = 10 vote).
#[test]
fn qemu_instruction_counts_reproducible() {
    use activesense_sim::link::remote::{mcu_bench, McuBenchArgs};
    use activesense_sim::world::plans::TEST_SEEDS;
    let args = McuBenchArgs {
        elf: firmware_elf(),
        episodes: 2,
        first_seed: TEST_SEEDS.start,
        agent: activesense_core::episode::AgentKind::Heuristic1,
        episode_seed: 0,
        termination: activesense_core::episode::Termination::Oracle,
        timeout_ms: 20_000,
    };
    let a = mcu_bench(&args).expect("first run");
    let b = mcu_bench(&args).expect("second run");
    assert_eq!(
        format!("{a:?}"),
        format!("{b:?}"),
        "counts must be reproducible"
    );
    let (k1, k10) = (&a[0], &a[1]);
    assert_eq!((k1.rot_bins, k10.rot_bins), (1, 10));
    for r in [k1, k10] {
        assert!(r.vote.count > 0 && r.rotation.count > 0, "{r:?}");
        assert!(r.finish.count == 2 && r.finish.max > r.vote.max, "{r:?}");
        assert!(r.rotation.max < r.vote.mean() as u64, "{r:?}");
    }
    assert!(k10.vote.mean() > 5.0 * k1.vote.mean(), "{k1:?} {k10:?}");
}

/// The int8 network's DSP `asm!` kernels run only on the M4: the firmware's `dsp-selftest`
/// mode compares them there with the portable and the reference kernels (random tensors,
/// random layers, the built-in K = 1 and K = 10 policies) and exits 1 on any difference.
#[test]
fn qemu_dsp_kernels_equal_the_reference() {
    use activesense_sim::link::qemu_cmd::{qemu_command, QemuSerial};
    use std::process::Stdio;
    use std::time::Instant;
    let elf = firmware_elf();
    let mut cmd = qemu_command("qemu-system-arm", &elf, QemuSerial::Null);
    cmd.args(["-icount", "shift=0", "-append", "dsp-selftest"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let mut child = cmd.spawn().expect("start qemu-system-arm");
    let started = Instant::now();
    while child.try_wait().expect("wait for qemu").is_none() {
        if started.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("dsp-selftest did not finish within 120 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().expect("qemu output");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("dsp-selftest: ok"), "{stdout}");
    println!("{stdout}");
}
