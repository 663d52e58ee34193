//! In-process loopback: the host client and the core device session (in a thread) over an
//! in-memory pipe.

use activesense_core::device::{Session, SessionConfig};
use activesense_core::protocol::Phase;
use activesense_instrument::link::device::{serve_std, Pipe, HOST_DEVICE};
use activesense_instrument::link::serial::{self, Client, LinkSpec};
use activesense_tests::{
    check_episodes, check_episodes_with, confident_stop, fault_suite, host_actions, host_episode,
    spec,
};
use std::time::Duration;

#[test]
fn loopback_episodes_are_bit_identical_to_in_process_runs() {
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    l.client.hello().unwrap();
    assert!(check_episodes(&mut l.client, 10, 1) > 0);
    assert!(check_episodes(&mut l.client, 10, 10) > 0);
    l.close().unwrap();
}

/// The confident stop with a non-default stop rule (protocol v4 carries `stop_risk` and
/// `min_observability`): the device takes the host's actions and stops at the host's step.
#[test]
fn loopback_confident_stop_rule_matches_host() {
    const STOP_RISK: f32 = 0.05;
    const MIN_OBSERVABILITY: f32 = 0.2;
    const EPISODES: u32 = 4;
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    l.client.hello().unwrap();
    let mut rule_matters = 0;
    for rot_bins in [1, 10] {
        let adjust = confident_stop(STOP_RISK, MIN_OBSERVABILITY);
        assert!(check_episodes_with(&mut l.client, EPISODES, rot_bins, &adjust) > 0);
        // The threshold changes where the host stops in some of these episodes, so the
        // agreement above shows that the device was told it (and did not run τ = 0).
        for i in 0..EPISODES {
            let mut told = spec(i, rot_bins);
            adjust(&mut told);
            let mut plain = told.clone();
            plain.config.min_observability = 0.0;
            rule_matters += usize::from(host_actions(&told) != host_actions(&plain));
        }
    }
    assert!(
        rule_matters > 0,
        "τ = {MIN_OBSERVABILITY} changed no episode"
    );
    l.close().unwrap();
}

/// By the doors of a plan: readings through them are explained on the device as on the
/// host, and it takes the host's actions and stops where the host stops.
#[test]
fn loopback_episodes_by_a_door_match_host() {
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    l.client.hello().unwrap();
    assert!(check_episodes_with(&mut l.client, 3, 10, activesense_tests::edm_only_by_a_door) > 0);
    l.close().unwrap();
    // Some of those readings did go through a door.
    let through: usize = (0..3)
        .map(|i| {
            let mut s = spec(i, 10);
            activesense_tests::edm_only_by_a_door(&mut s);
            activesense_tests::host_episode(&s)
                .steps
                .iter()
                .filter(|st| {
                    st.range_kind == Some(activesense_instrument::world::sensor::RangeKind::Behind)
                })
                .count()
        })
        .sum();
    assert!(
        through >= 3,
        "{through} readings through a door in 3 episodes"
    );
}

/// On a building site (readings off furniture, columns, people, a wall off its line) the
/// device still takes the host's actions and stops where the host stops.
#[test]
fn loopback_cluttered_site_episodes_match_host() {
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    l.client.hello().unwrap();
    for rot_bins in [1, 10] {
        assert!(
            check_episodes_with(
                &mut l.client,
                4,
                rot_bins,
                activesense_tests::edm_only_on_site
            ) > 0
        );
    }
    l.close().unwrap();
    // The site is there: some of those readings hit clutter.
    let cluttered = (0..4)
        .filter(|&i| {
            let mut s = spec(i, 10);
            s.agent = activesense_core::episode::AgentKind::Heuristic1;
            activesense_tests::edm_only_on_site(&mut s);
            activesense_instrument::episode::run_episode(&s)
                .steps
                .iter()
                .any(|st| {
                    st.range_kind == Some(activesense_instrument::world::sensor::RangeKind::Clutter)
                })
        })
        .count();
    assert!(cluttered > 0, "no reading hit the site's clutter");
}

/// A confident episode that never gets sure enough to stop (P = 1e-6) answers with its
/// lowest-risk moment; protocol v5 reports its risk and readings, and the device's answer
/// equals the host's (checked in [`check_episodes_with`]).
#[test]
fn loopback_unstopped_confident_episodes_answer_alike() {
    const EPISODES: u32 = 6;
    let adjust = confident_stop(1e-6, 0.0);
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    l.client.hello().unwrap();
    assert!(check_episodes_with(&mut l.client, EPISODES, 10, &adjust) > 0);
    l.close().unwrap();
    // The earlier answer is exercised: some episode answers before its last reading.
    let earlier = (0..EPISODES)
        .filter(|&i| {
            let mut s = spec(i, 10);
            adjust(&mut s);
            let t = host_episode(&s);
            let returned = t.steps.iter().filter(|st| st.range.is_some()).count();
            (t.outcome.answer_readings as usize) < returned
        })
        .count();
    assert!(earlier > 0, "no episode answered before its last reading");
}

#[test]
fn loopback_policy_upload() {
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    activesense_tests::policy_upload_suite(&mut l.client);
    l.close().unwrap();
}

#[test]
fn loopback_fault_suite() {
    let mut l = serial::open(&LinkSpec::Loopback, Duration::from_secs(30)).unwrap();
    fault_suite(&mut l.client);
    check_episodes(&mut l.client, 2, 10);
    l.close().unwrap();
}

/// The same device session serves host after host: one that vanishes mid-episode (link
/// closed), one that goes silent (timeout), then a good one.
#[test]
fn device_survives_hosts_that_disappear() {
    let mut session = Box::new(Session::new(SessionConfig {
        timeout_ms: 200,
        ..HOST_DEVICE
    }));
    // Host 1 starts an episode and drops the link.
    let (host, mut dev) = Pipe::pair(Duration::from_secs(30));
    let t = std::thread::spawn(move || {
        let mut c = Client::new(host);
        c.hello().unwrap();
        let (plan, params, _) = activesense_instrument::link::device::sim_episode(&spec(0, 10));
        c.load_plan(&plan).unwrap();
        c.call(&activesense_core::protocol::Request::StartEpisode(params))
            .unwrap();
    });
    serve_std(&mut session, &mut dev).unwrap();
    t.join().unwrap();
    assert_eq!(session.phase(), Phase::Episode);

    // Host 2 starts an episode and goes silent without closing: the timeout abandons it.
    let (host, mut dev) = Pipe::pair(Duration::from_secs(30));
    let t = std::thread::spawn(move || {
        let mut c = Client::new(host);
        c.hello().unwrap();
        let (plan, params, _) = activesense_instrument::link::device::sim_episode(&spec(1, 1));
        c.load_plan(&plan).unwrap();
        c.call(&activesense_core::protocol::Request::StartEpisode(params))
            .unwrap();
        std::thread::sleep(Duration::from_millis(600));
    });
    serve_std(&mut session, &mut dev).unwrap();
    t.join().unwrap();
    assert_eq!(session.phase(), activesense_core::protocol::Phase::Closed);
    assert_eq!(session.stats().timeouts, 1);

    // Host 3 is served normally.
    let (host, mut dev) = Pipe::pair(Duration::from_secs(30));
    let t = std::thread::spawn(move || {
        let mut c = Client::new(host);
        c.hello().unwrap();
        check_episodes(&mut c, 2, 10);
        c.shutdown().unwrap();
    });
    serve_std(&mut session, &mut dev).unwrap();
    t.join().unwrap();
    assert_eq!(session.stats().episodes, 2);
}
