//! The Leica instrument behind the core's [`Instrument`] trait, and the session that runs
//! the core's [`EpisodeRunner`] against any instrument (the GeoCOM one, or the simulated
//! world in-process for the bit-identity reference).
//!
//! Frames: the core's encoder bearing `b` turns counter-clockwise; a Leica's horizontal
//! angle Hz turns clockwise. The session starts at the instrument's current Hz, `hz0`, as
//! bearing 0, and positions the telescope to `Hz = hz0 − b` (mod 2π) for every rotation
//! step, the telescope level (V = π/2) unless a vertical angle is given. A measurement is
//! TMC_DoMeasure(TMC_DEF_DIST) + TMC_GetSimpleMea; the horizontal range is the slope
//! distance × sin V. No distance (GRC_TMC_DIST_ERROR, GRC_TMC_ANGLE_OK, no signal) is a
//! no-return, exactly as the simulator's.

use crate::agents::Policies;
use crate::baselines::greedy::EemAgent;
use crate::geocom::client::{Client, GeoComError};
use crate::geocom::codes::ReturnCode;
use crate::geocom::rpc;
use crate::world::sensor::SensorModel;
use crate::world::SimWorld;
use activesense_core::device::instrument::{Instrument, Turn};
use activesense_core::episode::{Action, AgentKind, Observation, Termination};
use activesense_core::episode::{EpisodeConfig, EpisodeParams, EpisodeState};
use activesense_core::pipeline::runner::{Booked, EpisodeRunner};
use activesense_core::pipeline::{PipelineResult, Stop};
use activesense_core::policy::{BaselineAgent, Policy};
use activesense_core::FloorPlan;
use serde::Serialize;
use std::convert::Infallible;
use std::f64::consts::{FRAC_PI_2, TAU};

/// What the instrument says about itself.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InstrumentInfo {
    /// CSV_GetInstrumentName.
    pub name: String,
    /// CSV_GetInstrumentNo.
    pub serial: i64,
    /// COM_GetSWVersion (release.version.subversion).
    pub geocom_version: String,
    /// Hz at the start (the session's bearing 0, rad).
    pub hz0: f64,
}

/// A motorised Leica total station over GeoCOM.
pub struct GeoComInstrument {
    client: Client,
    state: EpisodeState,
    hz0: f64,
    v: f64,
    /// The return code of the last measurement (a warning is kept for the live view).
    pub last_rc: ReturnCode,
}

impl GeoComInstrument {
    /// Pings the instrument, reads who it is, sets reflectorless single measurements and
    /// levels the telescope at the current Hz (bearing 0). `vertical`: zenith angle to
    /// measure at (rad; default π/2, level).
    pub fn connect(
        mut client: Client,
        config: EpisodeConfig,
        vertical: Option<f64>,
    ) -> Result<(Self, InstrumentInfo), Box<(Client, GeoComError)>> {
        let r = Self::hello(&mut client, vertical);
        match r {
            Ok((info, v)) => Ok((
                GeoComInstrument {
                    client,
                    state: EpisodeState::new(config),
                    hz0: info.hz0,
                    v,
                    last_rc: ReturnCode::OK,
                },
                info,
            )),
            Err(e) => Err(Box::new((client, e))),
        }
    }

    /// The opening RPCs of [`GeoComInstrument::connect`].
    fn hello(
        client: &mut Client,
        vertical: Option<f64>,
    ) -> Result<(InstrumentInfo, f64), GeoComError> {
        rpc::null_proc(client)?;
        let name = rpc::instrument_name(client)?;
        let serial = rpc::serial_no(client)?;
        let (a, b, c) = rpc::sw_version(client)?;
        rpc::set_reflectorless(client)?;
        rpc::set_edm_mode(client, rpc::EDM_SINGLE_STANDARD)?;
        let (hz0, _) = rpc::get_angle(client)?;
        let v = vertical.unwrap_or(FRAC_PI_2);
        let fast = client.config().timeout;
        client.set_timeout(client.config().slow_timeout.max(fast));
        rpc::make_positioning(client, hz0, v)?;
        client.set_timeout(fast);
        Ok((
            InstrumentInfo {
                name,
                serial,
                geocom_version: format!("{a}.{b}.{c}"),
                hz0,
            },
            v,
        ))
    }

    /// The Hz that encoder bearing `b` (rad, counter-clockwise) stands at.
    pub fn hz_of(&self, bearing: f32) -> f64 {
        (self.hz0 - bearing as f64).rem_euclid(TAU)
    }

    /// The client (for the closing RPCs).
    pub fn client(&mut self) -> &mut Client {
        &mut self.client
    }

    /// Gives the client back.
    pub fn into_client(self) -> Client {
        self.client
    }

    fn slow<T>(
        &mut self,
        f: impl FnOnce(&mut Client) -> Result<T, GeoComError>,
    ) -> Result<T, GeoComError> {
        let fast = self.client.config().timeout;
        self.client
            .set_timeout(self.client.config().slow_timeout.max(fast));
        let r = f(&mut self.client);
        self.client.set_timeout(fast);
        r
    }
}

impl Instrument for GeoComInstrument {
    type Error = GeoComError;

    fn rotate(&mut self, turn: Turn) -> Result<(), GeoComError> {
        let action = match turn {
            Turn::Left => Action::RotateLeft,
            Turn::Right => Action::RotateRight,
        };
        let mut next = self.state;
        next.apply(action);
        let (hz, v) = (self.hz_of(next.bearing()), self.v);
        self.slow(|c| rpc::make_positioning(c, hz, v))?;
        self.state = next;
        Ok(())
    }

    fn measure(&mut self) -> Result<Option<f32>, GeoComError> {
        let m = self.slow(|c| {
            rpc::do_measure(c, rpc::tmc_prog::DEF_DIST)?;
            rpc::get_simple_mea(c, 5000)
        })?;
        self.state.apply(Action::Measure);
        self.last_rc = m.rc;
        // Level telescope: sin(π/2) is exactly 1 in f64, so the range is the simulator's
        // f32 bit for bit.
        Ok(m.slope.map(|d| (d * m.v.sin()) as f32))
    }

    /// A Leica has no topological scan camera: the scan is empty (as `NoScan` on our
    /// hardware).
    fn scan(&mut self) -> Result<u32, GeoComError> {
        Ok(0)
    }
}

/// The simulated world without its camera: the in-process reference a GeoCOM session
/// through the simulator must reproduce bit for bit (same world stream, scan 0).
pub struct NoCameraSim(pub SimWorld);

impl NoCameraSim {
    /// The world for `(plan, sensor, config, world_seed)`, with its initial scan taken as
    /// [`crate::episode::start_episode`] and the GeoCOM simulator take it (it only draws
    /// from the stream when the scan is noisy).
    pub fn new(plan: FloorPlan, sensor: SensorModel, config: EpisodeConfig, seed: u64) -> Self {
        let mut w = SimWorld::new(plan, sensor, config, seed);
        let _ = w.scan();
        NoCameraSim(w)
    }
}

impl Instrument for NoCameraSim {
    type Error = Infallible;
    fn rotate(&mut self, turn: Turn) -> Result<(), Infallible> {
        self.0.act(match turn {
            Turn::Left => Action::RotateLeft,
            Turn::Right => Action::RotateRight,
        });
        Ok(())
    }
    fn measure(&mut self) -> Result<Option<f32>, Infallible> {
        Ok(self.0.act(Action::Measure).0.range)
    }
    fn scan(&mut self) -> Result<u32, Infallible> {
        Ok(0)
    }
}

/// What the station session runs: the room, the agent and its seed, the episode settings.
#[derive(Clone, Debug)]
pub struct SessionSetup {
    /// The centred room (model frame).
    pub plan: FloorPlan,
    /// The acting agent.
    pub agent: AgentKind,
    /// Its seed (and the registration's).
    pub agent_seed: u64,
    /// Rotation step, action limit, stop risk.
    pub config: EpisodeConfig,
    /// Sensor model the EEM benchmark plans with.
    pub sensor: SensorModel,
}

impl SessionSetup {
    /// The core's parameters: heading unknown (K = 10), no ground truth, the calibrated
    /// stop, no scan.
    pub fn params(&self) -> EpisodeParams {
        EpisodeParams {
            agent: self.agent,
            seed: self.agent_seed,
            rot_bins: ROT_BINS,
            known_heading: None,
            ground_truth: None,
            initial_scan: 0,
            termination: Termination::Confident,
            config: self.config,
        }
    }
}

/// Rotation bins of a station session: a surveyor's instrument does not know its heading.
pub const ROT_BINS: u8 = 10;

/// One step of the live view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SessionStep {
    /// 0-based step.
    pub step: u16,
    /// The action.
    pub action: Action,
    /// Encoder bearing index after it.
    pub bearing_index: u16,
    /// Encoder bearing after it (rad).
    pub bearing: f32,
    /// The range (measurements with a return).
    pub range: Option<f32>,
    /// True for a measurement without a usable return.
    pub no_return: bool,
    /// Belief entropy after it (nats).
    pub entropy: f32,
    /// The calibrated stop's current P(wrong), once it has one.
    pub risk: Option<f32>,
}

/// The session's result.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionOutcome {
    /// Coarse estimate, refined registration, stop risk, readings used.
    pub result: PipelineResult,
    /// Every step.
    pub steps: Vec<SessionStep>,
    /// Why it stopped (`None`: the action limit).
    pub stop: Option<Stop>,
    /// Final counts and cost.
    pub state: EpisodeState,
}

/// Why a session did not finish.
#[derive(Debug)]
pub enum SessionError<E> {
    /// The instrument failed.
    Instrument(E),
    /// The core refused the plan or an answer.
    Rejected(String),
}

/// Runs the core [`EpisodeRunner`] with `policy` against `inst` to the calibrated stop or
/// the action limit, then registers. `on_step` sees every step (the live view).
pub fn run_session<I: Instrument>(
    setup: &SessionSetup,
    policy: &mut dyn Policy,
    inst: &mut I,
    on_step: &mut dyn FnMut(&SessionStep),
) -> Result<SessionOutcome, SessionError<I::Error>> {
    let mut runner = Box::new(EpisodeRunner::new_empty());
    runner.start(&setup.plan, &setup.params()).map_err(|e| {
        SessionError::Rejected(format!("the plan does not fit the pipeline: {e:?}"))
    })?;
    let mut steps = Vec::new();
    while let Some(action) = runner.decide(policy) {
        let obs: Observation = inst.perform(action).map_err(SessionError::Instrument)?;
        let booked = runner
            .observe(action, &obs)
            .map_err(|e| SessionError::Rejected(format!("instrument answer refused: {e:?}")))?;
        let state = runner.state();
        let pipe = runner.pipeline();
        let step = SessionStep {
            step: state.actions - 1,
            action,
            bearing_index: state.bearing_index,
            bearing: state.bearing(),
            range: obs.range,
            no_return: booked == Booked::NoReturn,
            entropy: pipe.localizer().entropy(),
            risk: pipe.stop_risk_estimate(),
        };
        on_step(&step);
        steps.push(step);
    }
    Ok(SessionOutcome {
        result: runner.finish(&setup.plan),
        steps,
        stop: runner.stop(),
        state: *runner.state(),
    })
}

/// Runs `f` with the policy `agent` names: a baseline, EEM, or the committed learnt
/// policy for K = 10 (float or int8) in `policies`. The oracle benchmarks need the ground
/// truth, which an instrument on site does not have.
pub fn with_policy<R>(
    setup: &SessionSetup,
    policies: &Policies,
    f: impl FnOnce(&mut dyn Policy) -> R,
) -> anyhow::Result<R> {
    Ok(match setup.agent {
        AgentKind::Learnt => {
            let p = policies
                .for_rot_bins(ROT_BINS)
                .ok_or_else(|| anyhow::anyhow!("no learnt policy loaded for K = {ROT_BINS}"))?;
            f(&mut p.agent())
        }
        AgentKind::LearntInt8 => {
            let p = policies
                .int8_for(ROT_BINS)
                .ok_or_else(|| anyhow::anyhow!("no int8 policy loaded for K = {ROT_BINS}"))?;
            p.with_agent(|a| f(a))
        }
        AgentKind::Oigm | AgentKind::OigmCost => anyhow::bail!(
            "agent {} needs the ground truth, which an instrument on site does not have",
            setup.agent.name()
        ),
        AgentKind::Eem => f(&mut EemAgent::new(
            setup.plan.clone(),
            setup.sensor,
            setup.config,
        )),
        other => f(&mut BaselineAgent::new(other, setup.agent_seed)),
    })
}

/// The in-process reference: the same session against the simulated world (no camera)
/// that the GeoCOM simulator plays with `world_seed`.
pub fn reference_session(
    setup: &SessionSetup,
    policies: &Policies,
    world_seed: u64,
) -> anyhow::Result<SessionOutcome> {
    let mut world = NoCameraSim::new(setup.plan.clone(), setup.sensor, setup.config, world_seed);
    with_policy(setup, policies, |p| {
        run_session(setup, p, &mut world, &mut |_| {})
    })?
    .map_err(|e| match e {
        SessionError::Instrument(i) => match i {},
        SessionError::Rejected(r) => anyhow::anyhow!(r),
    })
}
