//! QEMU hardware-in-the-loop: the real firmware ELF in `qemu-system-arm -M netduinoplus2`,
//! USART1 on a local TCP socket. The ELF is built by [`firmware_elf`] (cargo, thumb target,
//! `firmware` profile) unless `ACTIVESENSE_FIRMWARE_ELF` names one.

use activesense_instrument::link::serial::{self, LinkSpec};
use activesense_tests::{
    check_episodes, check_episodes_with, confident_stop, fault_suite, firmware_elf,
};
use std::time::Duration;

/// Stack the HIL episodes must leave untouched: the deepest path of a longer or rarer
/// episode than these, and an exception frame on top.
const STACK_MARGIN: u32 = 1024;

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
    // The EDM-only instrument: its own built-in blobs and stop tables on the device, the
    // same actions and stop as on the host.
    assert!(check_episodes_with(&mut l.client, 4, 1, activesense_tests::edm_only) > 0);
    assert!(check_episodes_with(&mut l.client, 4, 10, activesense_tests::edm_only) > 0);
    // ... and on a cluttered site, where readings hit what the plan does not draw.
    assert!(check_episodes_with(&mut l.client, 3, 10, activesense_tests::edm_only_on_site) > 0);
    // ... and by the doors of a plan, where readings go through them.
    assert!(check_episodes_with(&mut l.client, 2, 10, activesense_tests::edm_only_by_a_door) > 0);
    fault_suite(&mut l.client);
    check_episodes(&mut l.client, 1, 10);
    // A policy uploaded into the firmware's RAM slot serves bit-identically; bad uploads
    // are refused with the uploaded policy still serving.
    activesense_tests::policy_upload_suite(&mut l.client);
    // The firmware's painted stack: how deep these episodes, faults and uploads went.
    let stack = l.client.status().expect("status").stack;
    eprintln!("device stack: {stack:?}");
    assert!(
        stack.size > 30_000 && stack.high_water > 10_000,
        "{stack:?}"
    );
    assert!(
        stack.high_water + STACK_MARGIN <= stack.size,
        "less than {STACK_MARGIN} bytes of stack left: {stack:?}"
    );
    let out = l
        .shutdown()
        .expect("firmware shuts down with exit status 0");
    assert!(out.contains("core initialised"), "{out}");
    assert!(out.contains("activesense-firmware: shutdown"), "{out}");
}

/// An instrument the user started keeps serving between commands: `policy upload` in one
/// process, then `policy info` in a second process shows the uploaded policy (in the
/// firmware's RAM), and only `--shutdown` powers it off (exit status 0).
#[test]
fn qemu_policy_upload_then_info_in_a_second_process() {
    use activesense_instrument::link::device::qemu_binary;
    use activesense_instrument::link::qemu_cmd::{qemu_command, QemuSerial};
    use std::process::{Command, Stdio};
    let elf = firmware_elf();
    let cli = activesense_tests::activesense_bin();
    let dir = std::env::temp_dir().join(format!("activesense-hil-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let blob_path = dir.join("other-k1.q8");
    let blob = activesense_tests::other_k1_blob();
    std::fs::write(&blob_path, &blob).unwrap();
    let crc = activesense_core::policy::int8::stored_crc(&blob).unwrap();
    // A free port for QEMU to listen on (USART1 as a TCP server, as a user would run it).
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut qemu = qemu_command(&qemu_binary(), &elf, QemuSerial::TcpServer(port))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start qemu");
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(std::time::Instant::now() < deadline, "qemu did not listen");
        std::thread::sleep(Duration::from_millis(50));
    }
    let link = format!("tcp:127.0.0.1:{port}");
    let run = |args: &[&str]| {
        let out = Command::new(&cli)
            .args(args)
            .output()
            .expect("run activesense");
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "activesense {args:?}: {text}");
        text
    };
    let up = run(&[
        "policy",
        "upload",
        "--link",
        &link,
        "--int8",
        blob_path.to_str().unwrap(),
    ]);
    let uploaded = format!("K =  1: Uploaded ({} bytes, crc {crc:08x})", blob.len());
    assert!(up.contains(&uploaded), "{up}");
    // A second process: the device kept serving, with the uploaded policy in its RAM.
    let info = run(&["policy", "info", "--link", &link]);
    assert!(info.contains(&uploaded), "{info}");
    assert!(info.contains("K = 10: BuiltIn"), "{info}");
    assert!(
        qemu.try_wait().unwrap().is_none(),
        "the firmware exited without --shutdown"
    );
    // Only --shutdown powers it off.
    run(&["policy", "info", "--link", &link, "--shutdown"]);
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let status = loop {
        if let Some(s) = qemu.try_wait().unwrap() {
            break s;
        }
        if std::time::Instant::now() > deadline {
            let _ = qemu.kill();
            panic!("the firmware did not stop after --shutdown");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut console = String::new();
    std::io::Read::read_to_string(&mut qemu.stdout.take().unwrap(), &mut console).unwrap();
    assert!(status.success(), "{status}: {console}");
    assert!(
        console.contains("activesense-firmware: shutdown"),
        "{console}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `mcu-bench`: under `-icount shift=0` the firmware's TIM2 counts executed instructions,
/// so two runs give identical counts, every update is booked under its kind, and the
/// work is ordered as it must be (rotation < K = 1 vote < K = 10 vote).
#[test]
fn qemu_instruction_counts_reproducible() {
    use activesense::commands::mcu_bench::{mcu_bench, McuBenchArgs};
    use activesense_instrument::world::plans::TEST_SEEDS;
    let args = McuBenchArgs {
        elf: firmware_elf(),
        episodes: 2,
        first_seed: TEST_SEEDS.start,
        agent: activesense_core::episode::AgentKind::Heuristic1,
        options: Default::default(),
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
        // The end of episode registers (a whole refinement): more than a rotation's
        // bookkeeping. (Not necessarily more than a vote: a K = 10 vote covers ten heading
        // slots and the coarse-to-fine argmax, and since the ICP takes its heading's sine
        // and cosine once per iteration heuristic-1's largest K = 10 vote, 9.8 M on these
        // two episodes, outweighs its largest end of episode, 9.1 M.)
        assert!(
            r.finish.count == 2 && r.finish.max > r.rotation.max,
            "{r:?}"
        );
        assert!(r.rotation.max < r.vote.mean() as u64, "{r:?}");
    }
    assert!(k10.vote.mean() > 5.0 * k1.vote.mean(), "{k1:?} {k10:?}");
}

/// The int8 network's DSP `asm!` kernels run only on the M4: the firmware's `dsp-selftest`
/// mode compares them there with the portable and the reference kernels (random tensors,
/// random layers, the built-in K = 1 and K = 10 policies) and exits 1 on any difference.
#[test]
fn qemu_dsp_kernels_equal_the_reference() {
    use activesense_instrument::link::qemu_cmd::{qemu_command, QemuSerial};
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
