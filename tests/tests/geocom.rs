//! GeoCOM end to end: `activesense station` through the GeoCOM simulator over TCP and a
//! pty gives the in-process episode's answer bit for bit, on every room of the plan
//! fixtures and on generated plans; every injected fault class ends in a recovery or a
//! one-line message naming the fault and the RPC, with the instrument left still.

use activesense::commands::options::EpisodeOptions;
use activesense::commands::station::{station, GeoComLink, StationArgs, StationReport};
use activesense_core::episode::{AgentKind, EpisodeConfig};
use activesense_instrument::agents::Policies;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::geocom::instrument::reference_session;
use activesense_instrument::geocom::sim::{serve_tcp, FaultSpec, GeoComSim, SimConfig, SimState};
use activesense_instrument::world::planfile::{self, LoadOptions, PlanReadArgs};
use activesense_instrument::world::plans;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../cli/tests/fixtures/plans")
}

fn args(link: GeoComLink, plan: &Path, room: Option<String>, agent: AgentKind) -> StationArgs {
    StationArgs {
        link,
        plan: plan.to_path_buf(),
        read: PlanReadArgs {
            units: None,
            layer: None,
            room,
        },
        agent,
        policy: None,
        int8: None,
        episode: EpisodeOptions {
            max_actions: 60,
            episode_seed: 3,
            termination: activesense_core::episode::Termination::Confident,
            ..Default::default()
        },
        vertical_deg: None,
        set_station: false,
        tie_break: None,
        crc: false,
        timeout_ms: 2000,
        move_timeout_ms: 2000,
        retries: 3,
        json: None,
        quiet: true,
        heading_hint: None,
    }
}

/// The simulator for the room `a` names, as `activesense geocom-sim` builds it.
fn sim_config(a: &StationArgs, faults: Vec<FaultSpec>) -> SimConfig {
    let named = planfile::load_plan(&a.plan, &a.read.options())
        .unwrap()
        .plan;
    let mut spec = EpisodeSpec::new(named.seed(), a.agent);
    spec.episode_seed = a.episode.episode_seed;
    SimConfig {
        plan: named.plan,
        sensor: Default::default(),
        config: EpisodeConfig {
            steps_per_turn: a.episode.steps_per_turn,
            ..Default::default()
        },
        world_seed: spec.world_seed(),
        motor_speed: 0.0,
        edm_time: Duration::ZERO,
        faults,
    }
}

fn start_tcp(cfg: SimConfig) -> (GeoComLink, Arc<Mutex<SimState>>) {
    let sim = GeoComSim::new(cfg);
    let state = sim.state();
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || serve_tcp(l, sim));
    (GeoComLink::Tcp(addr.to_string()), state)
}

/// The in-process episode's report for the session `a` describes.
fn reference(a: &StationArgs) -> StationReport {
    let (name, setup, policies) = activesense::commands::station::setup_of(a).unwrap();
    let cfg = sim_config(a, vec![]);
    let o = reference_session(&setup, &policies, cfg.world_seed).unwrap();
    StationReport::new(&name, None, &o)
}

fn through_sim(
    mut a: StationArgs,
    faults: Vec<FaultSpec>,
) -> (anyhow::Result<StationReport>, SimState) {
    let (link, state) = start_tcp(sim_config(&a, faults));
    a.link = link;
    let r = station(&a).map(|mut r| {
        r.instrument = None;
        r
    });
    let s = state.lock().unwrap().clone();
    (r, s)
}

fn every_fixture_room() -> Vec<(PathBuf, Option<String>)> {
    let mut out = Vec::new();
    // The fixture rooms, and those with columns and doors one folder down.
    let mut files: Vec<_> = std::fs::read_dir(fixtures())
        .unwrap()
        .map(|e| e.unwrap().path())
        .flat_map(|p| {
            if p.is_dir() {
                std::fs::read_dir(&p)
                    .unwrap()
                    .map(|e| e.unwrap().path())
                    .collect()
            } else {
                vec![p]
            }
        })
        .collect();
    files.sort();
    for f in files {
        let rooms = planfile::load_rooms(&f, &LoadOptions::default()).unwrap();
        if rooms.len() == 1 {
            out.push((f, None));
        } else {
            for i in 0..rooms.len() {
                out.push((f.clone(), Some(i.to_string())));
            }
        }
    }
    out
}

fn generated_plan_files(dir: &Path, n: usize) -> Vec<PathBuf> {
    plans::TEST_SEEDS
        .take(n)
        .map(|seed| {
            let plan = plans::generate(seed);
            let v: Vec<[f32; 2]> = plan.vertices().map(|p| [p.x, p.y]).collect();
            let p = dir.join(format!("generated-{seed}.json"));
            std::fs::write(&p, serde_json::json!({ "vertices": v }).to_string()).unwrap();
            p
        })
        .collect()
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("activesense-geocom-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn dummy() -> GeoComLink {
    GeoComLink::Tcp("127.0.0.1:1".into())
}

#[test]
fn tcp_answers_are_bit_identical_on_every_fixture_room_and_generated_plans() {
    let dir = tmpdir("gen");
    let mut rooms = every_fixture_room();
    rooms.extend(generated_plan_files(&dir, 3).into_iter().map(|p| (p, None)));
    assert!(rooms.len() >= 6, "{rooms:?}");
    for (file, room) in rooms {
        let a = args(dummy(), &file, room.clone(), AgentKind::Heuristic1);
        let want = reference(&a);
        let (got, state) = through_sim(a, vec![]);
        let got = got.unwrap_or_else(|e| panic!("{} {room:?}: {e}", file.display()));
        assert_eq!(got, want, "{} {room:?}", file.display());
        assert!(!got.readings.is_empty());
        // The session leaves the EDM off and the motor still.
        assert!(!state.edm_on && !state.moving);
        assert_eq!(
            state.station, [0.0; 4],
            "nothing written without --set-station"
        );
    }
}

#[test]
fn learnt_float_and_int8_policies_are_bit_identical_through_the_simulator() {
    let file = fixtures().join("l-room.json");
    for agent in [AgentKind::Learnt, AgentKind::LearntInt8] {
        let a = args(dummy(), &file, None, agent);
        let want = reference(&a);
        let (got, _) = through_sim(a, vec![]);
        assert_eq!(got.unwrap(), want, "{agent:?}");
    }
    // Policies for K = 10 are the committed ones.
    assert!(Policies::load(&[], &[10]).is_ok());
}

#[cfg(unix)]
#[test]
fn pty_answers_are_bit_identical() {
    let dir = tmpdir("pty");
    let mut rooms = vec![
        (fixtures().join("l-room.dxf"), None),
        (fixtures().join("offices.geojson"), Some("1".to_owned())),
    ];
    rooms.push((generated_plan_files(&dir, 1).remove(0), None));
    for (file, room) in rooms {
        let mut a = args(dummy(), &file, room, AgentKind::Heuristic1);
        let want = reference(&a);
        let sim = GeoComSim::new(sim_config(&a, vec![]));
        let (path, _state) = activesense_instrument::geocom::sim::serve_pty(sim).unwrap();
        a.link = format!("geocom:serial:{path}:115200").parse().unwrap();
        let mut got = station(&a).unwrap();
        got.instrument = None;
        assert_eq!(got, want, "{}", file.display());
    }
}

fn spec(s: &str) -> FaultSpec {
    s.parse().unwrap()
}

/// Faults the session recovers from without changing the answer by a bit.
#[test]
fn recovered_faults_keep_the_answer_bit_identical() {
    let file = fixtures().join("l-room.json");
    let base = args(dummy(), &file, None, AgentKind::Heuristic1);
    let want = reference(&base);
    for (faults, crc) in [
        ("busy@2108:2", false),
        ("busy@9027:1", false),
        ("timeout@9027:2", false),
        ("timeout@2108:3", false),
        ("garbled@2108:2", false),
        ("garbled@9027:4", false),
        ("truncated@9027:3", false),
        ("truncated@2108:1", false),
        ("crc@2108:2", true),
        ("crc@9027:2", true),
        ("drop@2008:2", false),
        ("drop@9027:3", false),
        ("accuracy@2108:1", false),
    ] {
        let mut a = args(dummy(), &file, None, AgentKind::Heuristic1);
        a.crc = crc;
        a.timeout_ms = 300;
        a.move_timeout_ms = 300;
        let (got, state) = through_sim(a, vec![spec(faults)]);
        let got = got.unwrap_or_else(|e| panic!("{faults}: {e}"));
        assert_eq!(got, want, "{faults}");
        assert_eq!(state.fired.len(), 1, "{faults}: {:?}", state.fired);
        assert!(!state.edm_on && !state.moving, "{faults}");
    }
}

/// Failed measurements are no-returns: the session goes on, one reading fewer.
#[test]
fn no_distance_and_no_signal_are_no_returns() {
    let file = fixtures().join("l-room.json");
    let want = reference(&args(dummy(), &file, None, AgentKind::Heuristic1));
    for f in ["no-distance@2108:1", "no-signal@2108:2"] {
        let (got, state) = through_sim(
            args(dummy(), &file, None, AgentKind::Heuristic1),
            vec![spec(f)],
        );
        let got = got.unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(state.fired.len(), 1, "{f}");
        // The first readings match the reference except the one lost.
        assert_ne!(got.readings, want.readings, "{f}");
        assert!(!state.edm_on, "{f}");
    }
}

/// Faults that end the session: one line naming the fault and the RPC, the instrument
/// left still with the EDM off.
#[test]
fn fatal_faults_end_with_the_instrument_still() {
    let file = fixtures().join("l-room.json");
    let cases: &[(&[&str], &str, &str)] = &[
        (
            &["motor@9027:3"],
            "AUT_MakePositioning (RPC 9027)",
            "GRC_AUT_MOTOR_ERROR",
        ),
        (
            &[
                "timeout@9027:2",
                "timeout@9027:3",
                "timeout@9027:4",
                "timeout@9027:5",
            ],
            "AUT_MakePositioning (RPC 9027)",
            "time-out",
        ),
        (
            &[
                "busy@2108:1",
                "busy@2108:2",
                "busy@2108:3",
                "busy@2108:4",
                "busy@2108:5",
                "busy@2108:6",
                "busy@2108:7",
                "busy@2108:8",
                "busy@2108:9",
                "busy@2108:10",
                "busy@2108:11",
            ],
            "TMC_GetSimpleMea (RPC 2108)",
            "busy",
        ),
        (
            &[
                "garbled@2008:1",
                "garbled@2008:2",
                "garbled@2008:3",
                "garbled@2008:4",
            ],
            "TMC_DoMeasure (RPC 2008)",
            "garbled",
        ),
    ];
    for (faults, rpc, what) in cases {
        let mut a = args(dummy(), &file, None, AgentKind::Heuristic1);
        a.timeout_ms = 200;
        a.move_timeout_ms = 200;
        let (got, state) = through_sim(a, faults.iter().map(|f| spec(f)).collect());
        let msg = got.expect_err("session must fail").to_string();
        assert!(!msg.contains('\n'), "{msg}");
        assert!(msg.contains(rpc) && msg.contains(what), "{msg}");
        assert!(msg.contains("left still, EDM off"), "{msg}");
        assert!(!state.edm_on && !state.moving, "{faults:?}");
        assert_eq!(
            state.log[state.log.len() - 3..],
            [2008, 1004, 6002],
            "{faults:?}: {:?}",
            &state.log
        );
    }
}

#[test]
fn set_station_writes_the_pose_and_orientation() {
    let file = fixtures().join("l-room.json");
    let mut a = args(dummy(), &file, None, AgentKind::Heuristic1);
    a.set_station = true;
    a.episode.max_actions = 100;
    a.episode.stop_risk = 0.05;
    let (got, state) = through_sim(a, vec![]);
    let got = got.unwrap();
    assert_eq!(got.symmetry_order, 1);
    let [x, y, _] = got.pose.unwrap();
    // Written in the plan's own coordinates (metres), not the centred model frame.
    let frame = activesense_instrument::world::planfile::load_plan(&file, &Default::default())
        .unwrap()
        .plan
        .frame;
    let [e, n] = frame.to_plan([x as f64, y as f64]);
    assert_eq!(state.station[0], e * frame.scale);
    assert_eq!(state.station[1], n * frame.scale);
    assert_ne!(
        frame.bbox_centre,
        [0.0, 0.0],
        "the fixture must be off-centre for this test to tell the frames apart"
    );
    // Against the simulator's truth: position within 5 cm, orientation within 0.5°.
    let [tx, ty, th] = state.truth;
    assert!(
        ((x - tx).powi(2) + (y - ty).powi(2)).sqrt() < 0.05,
        "{x} {y} vs {tx} {ty}"
    );
    let want = (std::f64::consts::FRAC_PI_2 - th as f64 - state.hz_start)
        .rem_euclid(std::f64::consts::TAU);
    let d = (state.orientation - want + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    assert!(
        d.abs() < 0.5f64.to_radians(),
        "orientation {} vs {want}",
        state.orientation
    );
}

/// A room that does not match its plan (here: a building site where four readings in ten
/// stray) is not written to the instrument: the refusal says so in words, with the count of
/// readings that are not on the plan, and nothing reaches the instrument's station.
#[test]
fn a_room_unlike_its_plan_is_not_written() {
    let file = fixtures().join("l-room.json");
    let mut a = args(dummy(), &file, None, AgentKind::Heuristic1);
    a.set_station = true;
    let mut cfg = sim_config(&a, vec![]);
    cfg.sensor.site = activesense_instrument::world::site::SiteLevel::Site;
    cfg.sensor.outlier_prob = 0.4;
    let (link, state) = start_tcp(cfg);
    a.link = link;
    let msg = station(&a).expect_err("must refuse").to_string();
    assert!(
        msg.starts_with("the room does not match its plan: ")
            && msg.contains("readings are not on the plan"),
        "{msg}"
    );
    assert!(msg.contains("nothing written"), "{msg}");
    let state = state.lock().unwrap().clone();
    assert_eq!(state.station, [0.0; 4]);
    // `station` is played in the room it stands in: it takes no --site.
    let mut b = args(dummy(), &file, None, AgentKind::Heuristic1);
    b.episode.site = activesense_instrument::world::site::SiteLevel::Furnished;
    let msg = station(&b).expect_err("--site refused").to_string();
    assert!(msg.contains("does not take --site"), "{msg}");
}

#[test]
fn an_ambiguous_answer_is_not_written_without_a_tie_break() {
    let dir = tmpdir("sym");
    let p = dir.join("rectangle.json");
    std::fs::write(&p, r#"{"vertices": [[0,0],[8,0],[8,5],[0,5]]}"#).unwrap();
    let mut a = args(dummy(), &p, None, AgentKind::Heuristic1);
    a.set_station = true;
    a.episode.max_actions = 100;
    let (got, state) = through_sim(a, vec![]);
    let msg = got.expect_err("must refuse").to_string();
    assert!(msg.contains("ambiguous"), "{msg}");
    assert_eq!(state.station, [0.0; 4]);
    assert!(!state.log.contains(&2010) && !state.log.contains(&2113));
}

/// Issue 24: a millimetre DXF in national-grid coordinates (E ≈ 2.6e6 m) gives the same
/// answer, relative to the room, as the same room centred in metres — to < 1 mm — and the
/// station written to the instrument is the national-grid one, in metres.
#[test]
fn national_grid_dxf_gives_the_centred_rooms_answer() {
    let dir = tmpdir("grid");
    let room: [[f64; 2]; 6] = [
        [0.0, 0.0],
        [6.0, 0.0],
        [6.0, 3.0],
        [2.5, 3.0],
        [2.5, 5.0],
        [0.0, 5.0],
    ];
    let (e0, n0) = (2_600_123.0, 1_200_456.0);
    // The same file name in two folders: the name seeds where the instrument stands.
    let write_dxf = |sub: &str, insunits: u8, pts: Vec<[f64; 2]>| {
        let mut dxf = format!(
            "0\nSECTION\n2\nHEADER\n9\n$INSUNITS\n70\n{insunits}\n0\nENDSEC\n0\nSECTION\n2\nENTITIES\n0\nLWPOLYLINE\n5\n20\n8\nWALLS\n100\nAcDbPolyline\n90\n6\n70\n1\n"
        );
        for p in pts {
            dxf += &format!("10\n{}\n20\n{}\n", p[0], p[1]);
        }
        dxf += "0\nENDSEC\n0\nEOF\n";
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        let path = dir.join(sub).join("room.dxf");
        std::fs::write(&path, dxf).unwrap();
        path
    };
    // Millimetres on the national grid ($INSUNITS 4), and metres centred on the bounding
    // box ($INSUNITS 6).
    let dxf_path = write_dxf(
        "grid",
        4,
        room.iter()
            .map(|p| [(p[0] + e0) * 1000.0, (p[1] + n0) * 1000.0])
            .collect(),
    );
    let centred_path = write_dxf(
        "centred",
        6,
        room.iter().map(|p| [p[0] - 3.0, p[1] - 2.5]).collect(),
    );
    let answer_of = |plan: &Path, tag: &str| {
        let mut a = args(dummy(), plan, None, AgentKind::Heuristic1);
        a.set_station = true;
        a.episode.max_actions = 300;
        a.episode.stop_risk = 0.1;
        let out = dir.join(format!("{tag}.json"));
        a.json = Some(out.clone());
        let (got, state) = through_sim(a, vec![]);
        got.unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap();
        (v["answer"].clone(), state.station)
    };
    let (grid, grid_station) = answer_of(&dxf_path, "grid");
    let (cent, cent_station) = answer_of(&centred_path, "centred");
    assert_eq!(grid["unit"], "mm");
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    // Relative to the room's bounding-box centre, in metres.
    let de = (f(&grid["easting"]) / 1000.0 - (e0 + 3.0)) - f(&cent["easting"]);
    let dn = (f(&grid["northing"]) / 1000.0 - (n0 + 2.5)) - f(&cent["northing"]);
    assert!(de.hypot(dn) < 1e-3, "answers differ by {de}, {dn} m");
    assert!((f(&grid["heading_deg"]) - f(&cent["heading_deg"])).abs() < 1e-6);
    // Written to the instrument in metres, national grid.
    assert!(
        (grid_station[0] - (e0 + 3.0) - cent_station[0]).abs() < 1e-3,
        "{grid_station:?} vs {cent_station:?}"
    );
    assert!((grid_station[1] - (n0 + 2.5) - cent_station[1]).abs() < 1e-3);
    assert!(grid_station[0] > 2.6e6 && grid_station[1] > 1.2e6);
}
