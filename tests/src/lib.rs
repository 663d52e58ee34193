//! Helpers shared by the workspace integration tests in `tests/tests/`.
//!
//! The link tests (`loopback.rs`, `pty.rs`, `qemu_hil.rs`) run the same checks over three
//! transports: [`check_episodes`] (the device's actions and report are bit-identical to the
//! in-process run and to the lead's episode runner) and [`fault_suite`] (every documented
//! error, after which the device serves the next request/session).

use activesense_core::episode::Observation;
use activesense_core::episode::Termination;
use activesense_core::episode::{Action, AgentKind};
use activesense_core::protocol::*;
use activesense_core::world::floorplan::PlanError;
use activesense_instrument::agents::{run_agent_episode, Policies};
use activesense_instrument::episode::{EndReason, EpisodeSpec, Trajectory};
use activesense_instrument::learn::agent::Int8Policy;
use activesense_instrument::link::device::sim_episode;
use activesense_instrument::link::error::LinkError;
use activesense_instrument::link::runner::{reference_run, same_run};
use activesense_instrument::link::serial::Client;
use activesense_instrument::world::plans::TEST_SEEDS;
use std::io::{Read, Write};
use std::path::PathBuf;

/// The episode spec used by the link tests: baselines and the int8 learnt policy the
/// device carries, in turn.
pub fn spec(i: u32, rot_bins: u8) -> EpisodeSpec {
    let agents = [
        AgentKind::Heuristic1,
        AgentKind::LearntInt8,
        AgentKind::Blind2,
        AgentKind::Blind0,
    ];
    EpisodeSpec {
        episode_seed: 7 + i as u64,
        rot_bins,
        ..EpisodeSpec::new(TEST_SEEDS.start + i, agents[i as usize % agents.len()])
    }
}

/// Runs `n` episodes with `rot_bins` over `client` and checks each against the
/// in-process run ([`reference_run`]) and the lead's [`run_episode`]. Returns the number
/// of steps exchanged.
pub fn check_episodes<T: Read + Write>(client: &mut Client<T>, n: u32, rot_bins: u8) -> usize {
    check_episodes_with(client, n, rot_bins, |_| {})
}

/// An `adjust` for [`check_episodes_with`]: the confident stop with the given stop rule
/// (`stop_risk`, `min_observability`), which the host sends in `EpisodeParams` (protocol v4).
pub fn confident_stop(stop_risk: f32, min_observability: f32) -> impl Fn(&mut EpisodeSpec) {
    move |s| {
        s.termination = Termination::Confident;
        s.config.stop_risk = stop_risk;
        s.config.min_observability = min_observability;
    }
}

/// An `adjust` for [`check_episodes_with`]: the EDM-only instrument (no scan; its own int8
/// policies and stop tables, which the host names in `EpisodeParams`, protocol v9) with the
/// calibrated stop at the default risk.
pub fn edm_only(s: &mut EpisodeSpec) {
    s.config.instrument = activesense_core::episode::InstrumentProfile::Edm;
    s.termination = Termination::Confident;
}

/// An `adjust` for [`check_episodes_with`]: [`edm_only`] in a room that is not its plan (a
/// building site: furniture, a column, obstacles, a wall off its line, people in the beam).
/// The device only hears readings, so it must decide as the host does on them too.
pub fn edm_only_on_site(s: &mut EpisodeSpec) {
    edm_only(s);
    s.sensor.site = activesense_instrument::world::site::SiteLevel::Site;
}

/// An `adjust` for [`check_episodes_with`]: [`edm_only`] in the fixtures' room with a
/// column and two doors (`cli/tests/fixtures/plans/features/column-door.geojson`): its
/// readings through a door are explained and pair with no wall (`registration::beyond_door`)
/// on the device as on the host. (Episode seed 7, the first of [`spec`]'s, stands 0.4 m
/// from the west door and reads through it ten times.)
pub fn edm_only_by_a_door(s: &mut EpisodeSpec) {
    use activesense_instrument::world::planfile::{load_rooms, LoadOptions};
    edm_only(s);
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../cli/tests/fixtures/plans/features/column-door.geojson");
    let room = load_rooms(&file, &LoadOptions::default())
        .expect("the column-and-door fixture loads")
        .remove(0)
        .plan;
    s.plan_seed = room.seed();
    s.user_plan = Some(room);
}

/// The host's own episode for `s` (baseline, or the int8 policy built into the firmware).
pub fn host_episode(s: &EpisodeSpec) -> Trajectory {
    let mut policies = Policies::default();
    policies
        .load_int8_for(s.config.instrument, &[], &[s.rot_bins])
        .expect("built-in int8 policies");
    run_agent_episode(s, &policies).expect("host episode")
}

/// The actions of [`host_episode`].
pub fn host_actions(s: &EpisodeSpec) -> Vec<Action> {
    host_episode(s).steps.iter().map(|st| st.action).collect()
}

/// As [`check_episodes`], with `adjust` applied to each episode's [`spec`] (termination,
/// stop rule): the device must take the host's actions and stop at the host's step.
pub fn check_episodes_with<T: Read + Write>(
    client: &mut Client<T>,
    n: u32,
    rot_bins: u8,
    adjust: impl Fn(&mut EpisodeSpec),
) -> usize {
    let mut steps = 0;
    for i in 0..n {
        let mut s = spec(i, rot_bins);
        adjust(&mut s);
        let (plan, params, mut inst) = sim_episode(&s);
        client.load_plan(&plan).expect("load plan");
        let run = client.run_episode(&params, &mut inst).expect("episode");
        let (p2, prm2, mut inst2) = sim_episode(&s);
        let local = reference_run(&p2, &prm2, &mut inst2).expect("reference");
        assert!(
            same_run(&run, &local),
            "episode {i} K={rot_bins} differs from in-process"
        );
        assert_eq!(run.trace_hash(), run.report.trace_hash);
        // The host's own run: the baseline, or the int8 policy built into the firmware.
        let mut policies = Policies::default();
        policies
            .load_int8_for(s.config.instrument, &[], &[rot_bins])
            .expect("built-in int8 policies");
        let traj = run_agent_episode(&s, &policies).expect("host episode");
        let lead: Vec<(Action, Option<u32>, u32)> = traj
            .steps
            .iter()
            .map(|st| (st.action, st.range.map(f32::to_bits), st.scan))
            .collect();
        let ours: Vec<(Action, Option<u32>, u32)> = run
            .steps
            .iter()
            .map(|(a, o)| (*a, o.range.map(f32::to_bits), o.scan))
            .collect();
        assert_eq!(
            ours, lead,
            "episode {i} differs from the host episode runner"
        );
        assert_eq!(run.report.actions, traj.summary.actions);
        assert_eq!(run.report.measurements, traj.summary.measurements);
        assert_eq!(run.report.cost.to_bits(), traj.summary.cost.to_bits());
        let host_end = match traj.end {
            EndReason::CoarseSuccess | EndReason::Confident => EpisodeEnd::Localized,
            EndReason::ActionLimit => EpisodeEnd::ActionLimit,
        };
        assert_eq!(
            run.report.end, host_end,
            "episode {i} K={rot_bins}: end reason"
        );
        // The results, not only the actions: coarse and refined AgentPoses bit for bit.
        let bits = |p: Option<activesense_core::Pose2>| {
            p.map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()])
        };
        assert_eq!(
            bits(run.report.coarse),
            bits(traj.outcome.coarse),
            "episode {i}: coarse pose"
        );
        assert_eq!(
            bits(run.report.refined),
            bits(traj.outcome.refined.map(|r| r.pose)),
            "episode {i}: refined pose"
        );
        assert_eq!(
            run.report.recognised,
            Some(traj.outcome.recognised),
            "episode {i}: recognised"
        );
        assert_eq!(
            (
                run.report.stop_risk.map(f32::to_bits),
                run.report.answer_readings
            ),
            (
                traj.outcome.stop_risk.map(f32::to_bits),
                traj.outcome.answer_readings
            ),
            "episode {i}: stop risk and the readings the answer is based on"
        );
        assert!(
            run.report.coarse.is_some(),
            "episode {i}: the device localized nothing"
        );
        steps += run.steps.len();
    }
    steps
}

fn raw_frame<M: serde::Serialize>(id: u16, m: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_frame(id, m, &mut buf).expect("encode");
    buf[..n].to_vec()
}

fn expect_error<T: Read + Write>(c: &mut Client<T>, want_id: u16, want: WireError) {
    let (id, r) = c.recv_frame().expect("reply");
    assert_eq!((id, r), (want_id, Response::Error(want)));
}

fn device_err<T>(r: Result<T, LinkError>) -> WireError {
    match r {
        Err(LinkError::Device(e)) => e,
        Err(e) => panic!("expected a device error, got {e}"),
        Ok(_) => panic!("expected a device error, got success"),
    }
}

/// Every fault of `docs/protocol.md` ("Errors"), each followed by proof that the device
/// still serves. Leaves the client in an open session.
pub fn fault_suite<T: Read + Write>(c: &mut Client<T>) {
    c.hello().expect("hello");
    // 1. Random garbage (no delimiter inside), then a delimiter: one Framing/CRC error.
    let mut rng = 0x1234_5678u32;
    let garbage: Vec<u8> = (0..300)
        .map(|_| {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            (rng as u8).max(1)
        })
        .collect();
    c.send_raw(&garbage).unwrap();
    c.send_raw(&[0]).unwrap();
    let (id, r) = c.recv_frame().unwrap();
    assert_eq!(id, NO_ID);
    assert!(
        matches!(r, Response::Error(WireError::Framing | WireError::Crc)),
        "{r:?}"
    );
    c.ping(1).expect("ping after garbage");

    // 2. Truncated frame followed by a delimiter.
    let f = raw_frame(999, &Request::Ping { nonce: 5 });
    c.send_raw(&f[..f.len() / 2]).unwrap();
    c.send_raw(&[0]).unwrap();
    let (id, r) = c.recv_frame().unwrap();
    assert_eq!(id, NO_ID);
    assert!(
        matches!(r, Response::Error(WireError::Framing | WireError::Crc)),
        "{r:?}"
    );
    c.ping(2).expect("ping after truncation");

    // 3. Corrupted frame (one payload bit flipped): CRC error.
    let mut f = raw_frame(999, &Request::Ping { nonce: 6 });
    let k = f.len() / 2;
    f[k] ^= if f[k] == 0x10 { 0x20 } else { 0x10 };
    c.send_raw(&f).unwrap();
    let (id, r) = c.recv_frame().unwrap();
    assert_eq!(id, NO_ID);
    // A flipped COBS code byte shows up as a framing error, any other bit as a CRC error.
    assert!(
        matches!(r, Response::Error(WireError::Framing | WireError::Crc)),
        "{r:?}"
    );
    c.ping(3).expect("ping after corruption");

    // 4. Oversized frame: Oversized, resync on the next delimiter.
    c.send_raw(&vec![0x42u8; MAX_FRAME + 50]).unwrap();
    c.send_raw(&[0]).unwrap();
    expect_error(c, NO_ID, WireError::Oversized);
    c.ping(4).expect("ping after oversized frame");

    // 5. Plans: too many vertices (typed), self-intersecting, NaN coordinate.
    let circle: Vec<[f32; 2]> = (0..100)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 100.0;
            [5.0 * a.cos(), 5.0 * a.sin()]
        })
        .collect();
    assert_eq!(
        device_err(c.load_raw_plan(&circle)),
        WireError::InvalidPlan(PlanError::TooManyVertices)
    );
    let bow = [[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]];
    assert!(matches!(
        device_err(c.load_raw_plan(&bow)),
        WireError::InvalidPlan(PlanError::SelfIntersection(..))
    ));
    let nan = [[0.0, 0.0], [2.0, 0.0], [f32::NAN, 2.0]];
    assert_eq!(
        device_err(c.load_raw_plan(&nan)),
        WireError::InvalidPlan(PlanError::NonFiniteCoordinate(2))
    );
    // A plan beyond the wire capacity is refused locally, before sending.
    let huge: Vec<[f32; 2]> = (0..200).map(|i| [i as f32, 0.0]).collect();
    assert!(matches!(c.load_raw_plan(&huge), Err(LinkError::Local(_))));

    // 6. Episode: bad params, NaN/inf/negative ranges, wrong step; then a clean finish.
    let s = spec(0, 10);
    let (plan, params, _) = sim_episode(&s);
    c.load_plan(&plan).expect("plan");
    let mut p = params;
    p.rot_bins = 1;
    p.known_heading = None;
    assert_eq!(
        device_err(c.call(&Request::StartEpisode(p))),
        WireError::InvalidParams(ParamError::KnownHeadingRequired)
    );
    // The stop rule (v4): stop_risk outside (0, 1] and min_observability outside [0, 1]
    // (NaN included) are refused with typed errors; the device keeps serving.
    for risk in [f32::NAN, 0.0, 1.5] {
        let mut p = params;
        p.termination = Termination::Confident;
        p.config.stop_risk = risk;
        assert_eq!(
            device_err(c.call(&Request::StartEpisode(p))),
            WireError::InvalidParams(ParamError::InvalidStopRisk),
            "stop_risk {risk}"
        );
    }
    for tau in [-1.0, f32::NAN] {
        let mut p = params;
        p.config.min_observability = tau;
        assert_eq!(
            device_err(c.call(&Request::StartEpisode(p))),
            WireError::InvalidParams(ParamError::InvalidObservability),
            "min_observability {tau}"
        );
    }
    let mut p = params;
    p.config.max_actions = 20;
    p.agent = AgentKind::Heuristic0; // step 0 is a measurement
    assert_eq!(
        c.call(&Request::StartEpisode(p)).unwrap(),
        Response::Act {
            step: 0,
            action: Action::Measure
        }
    );
    for (r, e) in [
        (f32::NAN, ObservationError::NonFiniteRange),
        (f32::INFINITY, ObservationError::NonFiniteRange),
        (f32::NEG_INFINITY, ObservationError::NonFiniteRange),
        (-0.5, ObservationError::NegativeRange),
    ] {
        let obs = Observation {
            range: Some(r),
            scan: 0,
        };
        assert_eq!(
            device_err(c.call(&Request::Observe {
                step: 0,
                observation: obs
            })),
            WireError::InvalidObservation(e)
        );
    }
    let ok = Observation {
        range: Some(2.5),
        scan: 1,
    };
    assert_eq!(
        device_err(c.call(&Request::Observe {
            step: 5,
            observation: ok
        })),
        WireError::StepMismatch { expected: 0 }
    );
    assert_eq!(
        c.call(&Request::Observe {
            step: 0,
            observation: ok
        })
        .unwrap(),
        Response::Act {
            step: 1,
            action: Action::RotateLeft
        }
    );
    // Out-of-sequence request id.
    c.send_raw(&raw_frame(4000, &Request::Status)).unwrap();
    let (id, r) = c.recv_frame().unwrap();
    assert_eq!(id, 4000);
    assert!(
        matches!(r, Response::Error(WireError::OutOfSequence { .. })),
        "{r:?}"
    );
    // 7. The host disappears mid-episode; a new host says Hello and runs a full episode.
    {
        let mut fresh = Client::new(c.get_mut());
        fresh.hello().expect("new session after abandoned episode");
        let st = fresh.status().unwrap();
        assert_eq!(st.phase, Phase::Ready);
        check_episodes(&mut fresh, 1, 1);
    }
    // The old client object continues with its own id counter: re-open.
    c.hello().expect("hello again");
    let st = c.status().unwrap();
    assert!(st.link.frames_bad >= 4, "{st:?}");
    assert!(st.link.sequence_errors >= 2, "{st:?}");
    assert_eq!(c.abort().unwrap(), None);
}

/// The firmware ELF for the QEMU test: `ACTIVESENSE_FIRMWARE_ELF` if set, else built here
/// with `cargo build -p activesense-firmware --target thumbv7em-none-eabihf --profile
/// firmware` (a no-op when up to date; `.ci/run` may build it first).
pub fn firmware_elf() -> PathBuf {
    if let Ok(p) = std::env::var("ACTIVESENSE_FIRMWARE_ELF") {
        return PathBuf::from(p);
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = std::process::Command::new(cargo)
        .current_dir(&root)
        .args([
            "build",
            "-p",
            "activesense-firmware",
            "--target",
            "thumbv7em-none-eabihf",
            "--profile",
            "firmware",
        ])
        .status()
        .expect("run cargo to build the firmware");
    assert!(status.success(), "building the firmware failed");
    root.join(activesense_instrument::link::serial::DEFAULT_ELF)
}

/// The `activesense` CLI binary, built here with `cargo build -p activesense --bin
/// activesense` (a no-op when up to date): the tests that need a *second process* (the
/// device must keep serving between commands) run it.
pub fn activesense_bin() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = std::process::Command::new(cargo)
        .current_dir(&root)
        .args(["build", "-p", "activesense", "--bin", "activesense"])
        .status()
        .expect("run cargo to build the CLI");
    assert!(status.success(), "building the CLI failed");
    let target = std::env::var("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("target"));
    target.join("debug").join("activesense")
}

/// Runs one learnt-int8 episode on the device and checks its actions against the host
/// playing `blob` (bit-identical).
fn learnt_episode_matches<T: Read + Write>(client: &mut Client<T>, seed_index: u32, blob: &[u8]) {
    let mut s = spec(seed_index, 1);
    s.agent = AgentKind::LearntInt8;
    let (plan, params, mut inst) = sim_episode(&s);
    client.load_plan(&plan).expect("load plan");
    let run = client
        .run_episode(&params, &mut inst)
        .expect("learnt-int8 episode");
    let mut policies = Policies::default();
    policies.set_int8(Int8Policy::new(blob.to_vec(), "test blob".into()).expect("blob"));
    let traj = run_agent_episode(&s, &policies).expect("host episode");
    let host: Vec<Action> = traj.steps.iter().map(|st| st.action).collect();
    let device: Vec<Action> = run.steps.iter().map(|(a, _)| *a).collect();
    assert_eq!(
        device, host,
        "device and host disagree on the int8 policy's actions"
    );
}

/// A K = 1 int8 blob different from the built-in one: a random network, quantised.
pub fn other_k1_blob() -> Vec<u8> {
    let net = activesense_lab::learn::quantize::random_net(1, 77);
    activesense_lab::learn::quantize::quantize_calibrated(
        &net,
        activesense_core::episode::InstrumentProfile::EdmScan,
        3,
        5,
    )
    .0
}

/// The policy upload: a good blob replaces the built-in K = 1 policy and serves (episodes
/// bit-identical to the host playing it); a corrupt, mis-announced or wrong-K blob is
/// refused and the uploaded policy keeps serving; an episode cancels a staged upload;
/// `Reset` brings the built-in policy back.
pub fn policy_upload_suite<T: Read + Write>(client: &mut Client<T>) {
    use activesense_core::policy::builtin;
    use activesense_core::policy::int8::stored_crc;
    client.hello().expect("hello");
    let before = client.policy_info(1).expect("info");
    assert_eq!(before.source, PolicySource::BuiltIn);
    assert_eq!(Some(before.crc), stored_crc(builtin::K1));
    learnt_episode_matches(client, 1, builtin::K1);

    let good = other_k1_blob();
    assert_ne!(stored_crc(&good), stored_crc(builtin::K1));
    let info = client.upload_policy(1, &good, |_| {}).expect("upload");
    assert_eq!(info.source, PolicySource::Uploaded);
    assert_eq!(
        (info.len as usize, Some(info.crc)),
        (good.len(), stored_crc(&good))
    );
    learnt_episode_matches(client, 1, &good);

    // Structurally broken but with a matching CRC: refused by the blob parser.
    let mut broken = good.clone();
    broken[0] ^= 0xff;
    match client.upload_policy(1, &broken, |_| {}) {
        Err(LinkError::Device(WireError::Policy(PolicyError::Invalid(_)))) => {}
        other => panic!("broken blob: {other:?}"),
    }
    // Bytes that do not match the announced CRC.
    client
        .call(&Request::PolicyBegin {
            rot_bins: 1,
            len: good.len() as u32,
            crc: stored_crc(&good).unwrap() ^ 1,
        })
        .expect("begin");
    for (i, c) in good.chunks(POLICY_CHUNK).enumerate() {
        client
            .call(&Request::PolicyChunk {
                offset: (i * POLICY_CHUNK) as u32,
                data: heapless::Vec::from_slice(c).unwrap(),
            })
            .expect("chunk");
    }
    match client.call(&Request::PolicyCommit) {
        Err(LinkError::Device(WireError::Policy(PolicyError::Checksum))) => {}
        other => panic!("bad crc: {other:?}"),
    }
    // The K = 10 blob announced as K = 1.
    match client.upload_policy(1, builtin::K10, |_| {}) {
        Err(LinkError::Device(WireError::Policy(PolicyError::WrongRotBins { found: 10 }))) => {}
        other => panic!("wrong K: {other:?}"),
    }
    // Too large for the slot.
    match client.call(&Request::PolicyBegin {
        rot_bins: 1,
        len: 1 << 20,
        crc: 0,
    }) {
        Err(LinkError::Device(WireError::Policy(PolicyError::TooLarge { .. }))) => {}
        other => panic!("too large: {other:?}"),
    }
    // A chunk out of order.
    client
        .call(&Request::PolicyBegin {
            rot_bins: 1,
            len: good.len() as u32,
            crc: stored_crc(&good).unwrap(),
        })
        .expect("begin");
    match client.call(&Request::PolicyChunk {
        offset: 7,
        data: heapless::Vec::new(),
    }) {
        Err(LinkError::Device(WireError::Policy(PolicyError::ChunkOffset { expected: 0 }))) => {}
        other => panic!("offset: {other:?}"),
    }
    // Every refusal left the uploaded policy in service.
    let after = client.policy_info(1).expect("info");
    assert_eq!(
        (after.source, Some(after.crc)),
        (PolicySource::Uploaded, stored_crc(&good))
    );
    // An episode takes the staging memory back: the half-done upload is gone.
    learnt_episode_matches(client, 2, &good);
    match client.call(&Request::PolicyCommit) {
        Err(LinkError::Device(WireError::Policy(PolicyError::NoUpload))) => {}
        other => panic!("commit after an episode: {other:?}"),
    }
    // K = 10 still runs its built-in policy.
    assert_eq!(
        client.policy_info(10).expect("info").source,
        PolicySource::BuiltIn
    );
    client.reset().expect("reset");
    client.hello().expect("hello");
    assert_eq!(
        Some(client.policy_info(1).expect("info").crc),
        stored_crc(builtin::K1)
    );
}
