//! Tests of the one episode parameter type: its protocol-v5 wire bytes (a test vector
//! encoded by the old `wire::EpisodeParams`), its validity check and its seed derivation.

use super::*;
use crate::episode::InstrumentProfile;

fn params(
    termination: Termination,
    known_heading: Option<f32>,
    gt: Option<Pose2>,
) -> EpisodeParams {
    EpisodeParams {
        agent: AgentKind::Heuristic1,
        seed: 0x0123_4567_89AB_CDEF,
        rot_bins: 10,
        known_heading,
        ground_truth: gt,
        initial_scan: 0b1_0110,
        termination,
        config: EpisodeConfig {
            steps_per_turn: 54,
            max_actions: 100,
            costs: ActionCosts::default(),
            min_observability: 0.125,
            stop_risk: 0.05,
            instrument: InstrumentProfile::EdmScan,
        },
    }
}

fn full() -> EpisodeParams {
    params(
        Termination::Confident,
        Some(0.25),
        Some(Pose2::new(0.5, -0.25, 1.0)),
    )
}

/// Encoded by the protocol-v5 `wire::EpisodeParams` (derived serde, before the one
/// parameter type): the same values must give the same bytes followed by the instrument
/// profile (protocol v9; 0 = the paper's sensor, 1 = EDM only), and decode back.
#[test]
fn wire_bytes_are_protocol_v5_then_the_instrument() {
    const V5_FULL: [u8; 41] = [
        4, 239, 155, 175, 205, 248, 172, 209, 145, 1, 54, 100, 10, 1, 0, 0, 128, 62, 1, 0, 0, 0,
        63, 0, 0, 128, 190, 0, 0, 128, 63, 22, 1, 205, 204, 76, 61, 0, 0, 0, 62,
    ];
    const V5_BARE: [u8; 25] = [
        4, 239, 155, 175, 205, 248, 172, 209, 145, 1, 54, 100, 10, 0, 0, 22, 0, 205, 204, 76, 61,
        0, 0, 0, 62,
    ];
    for (p, want) in [
        (full(), &V5_FULL[..]),
        (params(Termination::Oracle, None, None), &V5_BARE[..]),
    ] {
        for (instrument, code) in [(InstrumentProfile::EdmScan, 0), (InstrumentProfile::Edm, 1)] {
            let mut p = p;
            p.config.instrument = instrument;
            let want = [want, &[code]].concat();
            let mut raw = [0u8; 64];
            let got = postcard::to_slice(&p, &mut raw).unwrap();
            assert_eq!(got, &want[..]);
            let back: EpisodeParams = postcard::from_bytes(&want).unwrap();
            assert_eq!(back, p);
            assert_eq!(back.config.costs, ActionCosts::default());
        }
        // A protocol-v8 message (no profile) does not decode.
        assert!(postcard::from_bytes::<EpisodeParams>(want).is_err());
    }
    // A truncated message (a v3 StartEpisode without the stop rule) does not decode.
    assert!(postcard::from_bytes::<EpisodeParams>(&V5_FULL[..V5_FULL.len() - 8]).is_err());
}

#[test]
fn stop_rule_validation() {
    assert_eq!(full().check_stop_rule(), Ok(()));
    assert_eq!(full().check(), Ok(()));
    for risk in [f32::NAN, 0.0, -0.01, 1.5, f32::INFINITY, f32::NEG_INFINITY] {
        let mut p = full();
        p.config.stop_risk = risk;
        assert_eq!(
            p.check_stop_rule(),
            Err(ParamError::InvalidStopRisk),
            "{risk}"
        );
    }
    for tau in [-1.0, f32::NAN, 1.01, f32::INFINITY, -0.0001] {
        let mut p = full();
        p.config.min_observability = tau;
        assert_eq!(
            p.check_stop_rule(),
            Err(ParamError::InvalidObservability),
            "{tau}"
        );
    }
    for (risk, tau) in [(1.0, 0.0), (f32::MIN_POSITIVE, 1.0), (0.01, 0.5)] {
        let mut p = full();
        p.config.stop_risk = risk;
        p.config.min_observability = tau;
        assert_eq!(p.check_stop_rule(), Ok(()), "{risk} {tau}");
    }
}

#[test]
fn check_covers_limits_and_poses() {
    let mut p = full();
    p.config.steps_per_turn = 0;
    assert_eq!(p.check(), Err(ParamError::StepsPerTurn));
    p = full();
    p.config.max_actions = MAX_EPISODE_ACTIONS + 1;
    assert_eq!(p.check(), Err(ParamError::MaxActions));
    p = full();
    p.rot_bins = 0;
    assert_eq!(p.check(), Err(ParamError::RotBins));
    p = full();
    p.rot_bins = 1;
    p.known_heading = None;
    assert_eq!(p.check(), Err(ParamError::KnownHeadingRequired));
    p.known_heading = Some(f32::NAN);
    assert_eq!(p.check(), Err(ParamError::NonFinite));
    p = full();
    p.ground_truth = Some(Pose2::new(f32::INFINITY, 0.0, 0.0));
    assert_eq!(p.check(), Err(ParamError::NonFinite));
}

#[test]
fn registration_seed_is_tagged_splitmix() {
    // The value protocol v5's `pipeline::registration_seed` gave.
    let mut z: u64 = 7 ^ 0x7265_6769_7374_6572;
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    assert_eq!(registration_seed(7), z);
    let mut p = full();
    p.seed = 7;
    assert_eq!(p.registration_seed(), z);
}
