//! `activesense station` (set up a Leica total station in the plan's frame over GeoCOM)
//! and `activesense geocom-sim` (the GeoCOM instrument simulator to try it against).
//! `docs/GEOCOM.md` describes the protocol, the RPCs and the fault handling.

use super::options::{parse_agent, EpisodeOption, EpisodeOptions, SensorArgs};
use activesense_core::episode::{Action, AgentKind, Termination};
use activesense_core::pipeline::Stop;
use activesense_core::registration::Measurement;
use activesense_instrument::agents::Policies;
use activesense_instrument::answer::{Answer, AnswerInput, HeadingHint};
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::geocom::client::{
    Client, ClientConfig, SerialTransport, TcpTransport, Transport, DEFAULT_BAUD,
};
use activesense_instrument::geocom::instrument::{
    run_session, with_policy, GeoComInstrument, InstrumentInfo, SessionError, SessionOutcome,
    SessionSetup, SessionStep, ROT_BINS,
};
use activesense_instrument::geocom::rpc;
use activesense_instrument::geocom::sim::{FaultSpec, GeoComSim, SimConfig};
use activesense_instrument::world::planfile::{self, PlanFrame, PlanReadArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;
use std::f64::consts::{FRAC_PI_2, TAU};
use std::path::PathBuf;
use std::time::Duration;

/// Where the instrument is: `geocom:serial:PATH[:BAUD]` or `geocom:tcp:HOST:PORT`.
#[derive(Clone, Debug, PartialEq)]
pub enum GeoComLink {
    /// A serial port and its baud rate.
    Serial(String, u32),
    /// A TCP address `HOST:PORT`.
    Tcp(String),
}

impl std::str::FromStr for GeoComLink {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let usage =
            || format!("link '{s}': expected geocom:serial:PATH[:BAUD] or geocom:tcp:HOST:PORT");
        let rest = s.strip_prefix("geocom:").ok_or_else(usage)?;
        if let Some(addr) = rest.strip_prefix("tcp:") {
            if addr
                .rsplit_once(':')
                .is_none_or(|(_, p)| p.parse::<u16>().is_err())
            {
                return Err(usage());
            }
            return Ok(GeoComLink::Tcp(addr.to_owned()));
        }
        let path = rest.strip_prefix("serial:").ok_or_else(usage)?;
        match path.rsplit_once(':') {
            Some((p, b)) if !p.is_empty() && b.parse::<u32>().is_ok() => Ok(GeoComLink::Serial(
                p.to_owned(),
                b.parse().map_err(|_| usage())?,
            )),
            _ if !path.is_empty() => Ok(GeoComLink::Serial(path.to_owned(), DEFAULT_BAUD)),
            _ => Err(usage()),
        }
    }
}

impl GeoComLink {
    /// Opens the transport.
    pub fn open(&self) -> Result<Box<dyn Transport>> {
        Ok(match self {
            GeoComLink::Tcp(a) => Box::new(TcpTransport::connect(a).with_context(|| {
                format!("cannot connect to tcp:{a} (is the instrument or geocom-sim listening?)")
            })?),
            GeoComLink::Serial(p, b) => {
                Box::new(SerialTransport::open(p, *b).with_context(|| {
                    format!("cannot open serial port {p} (check the cable and permissions)")
                })?)
            }
        })
    }
}

/// `activesense station`.
#[derive(Args, Debug)]
#[command(mut_arg("termination", |a| a.default_value("confident")))]
#[command(mut_arg("instrument", |a| a.default_value("edm")))]
pub struct StationArgs {
    // clap's help text: the brackets are an optional part, not a rustdoc link.
    #[allow(rustdoc::broken_intra_doc_links)]
    /// The instrument: geocom:serial:/dev/ttyUSB0[:BAUD] (default 19200 baud) or
    /// geocom:tcp:HOST:PORT (Bluetooth/Wi-Fi bridge, `activesense geocom-sim`).
    #[arg(long)]
    pub link: GeoComLink,
    /// The floor plan (JSON, GeoJSON or DXF; docs/PLANS.md).
    #[arg(long)]
    pub plan: PathBuf,
    #[command(flatten)]
    pub read: PlanReadArgs,
    /// Agent: a baseline (blind-0..2, heuristic-0..3), eem, learnt (the committed float
    /// policy for K = 10) or learnt-int8.
    #[arg(long, value_parser = parse_agent, default_value = "heuristic-1")]
    pub agent: AgentKind,
    /// Policy file for the learnt agent (default: policies/k10/policy.policy).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// int8 blob for learnt-int8 (default: the firmware's for K = 10).
    #[arg(long)]
    pub int8: Option<PathBuf>,
    /// How the station plays its episode: heading unknown (--rot-bins 10) and the
    /// calibrated stop (--termination confident), both the defaults here; --stop-risk is the
    /// risk of a wrong answer you accept (docs/EVALUATION.md, 'Calibrated stop').
    #[command(flatten)]
    pub episode: EpisodeOptions,
    /// Zenith angle to measure at, degrees (default 90: telescope level).
    #[arg(long)]
    pub vertical_deg: Option<f64>,
    /// Write the station coordinates and orientation to the instrument (TMC_SetStation,
    /// TMC_SetOrientation). Without it nothing on the instrument changes.
    #[arg(long)]
    pub set_station: bool,
    /// In a symmetric room: which of the equally good candidates to write (0-based, as
    /// printed). Without it an ambiguous answer is not written.
    #[arg(long)]
    pub tie_break: Option<u8>,
    /// Add the CRC-16 header field to requests and require it on replies.
    #[arg(long)]
    pub crc: bool,
    /// Reply time-out for quick RPCs (ms).
    #[arg(long, default_value_t = 3000)]
    pub timeout_ms: u64,
    /// Reply time-out around positioning and measuring (ms).
    #[arg(long, default_value_t = 30000)]
    pub move_timeout_ms: u64,
    /// Repeats after a time-out, garbled line, CRC mismatch or dropped link.
    #[arg(long, default_value_t = 3)]
    pub retries: u32,
    /// Write the answer and the session log as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Do not print every reading.
    #[arg(long)]
    pub quiet: bool,
    /// An approximate heading, DEG±TOL (degrees counter-clockwise from the plan's +x axis, the
    /// direction of encoder bearing 0): narrows a symmetric room's candidates in the answer.
    #[arg(long, value_parser = activesense_instrument::answer::parse_heading_hint, allow_hyphen_values = true)]
    pub heading_hint: Option<HeadingHint>,
}

/// The station session's outcome in the model frame (the plan centred by the loader): what
/// the bit-identity tests compare. What the surveyor reads is the [`Answer`] built from it
/// ([`StationReport::answer`]): plan coordinates, precision, candidates.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StationReport {
    /// The room.
    pub plan: String,
    /// Who answered.
    pub instrument: Option<InstrumentInfo>,
    /// Station position (model frame, m) and the model direction of encoder bearing 0
    /// (rad, counter-clockwise from +x).
    pub pose: Option<[f32; 3]>,
    /// Encoder bearing the telescope stands at after the session (rad).
    pub final_bearing: f32,
    /// Calibrated P(wrong) of the answer.
    pub risk: Option<f32>,
    /// True when the calibrated stop fired (not the action limit).
    pub stopped: bool,
    /// Rotational symmetry order of the room (> 1: as many equally good candidates).
    pub symmetry_order: u8,
    /// Readings the answer rests on.
    pub answer_readings: u16,
    /// Every (bearing, range) reading with a return.
    pub readings: Vec<[f32; 2]>,
    /// Actions taken.
    pub actions: u16,
}

impl StationReport {
    /// Builds the report from a session.
    pub fn new(plan: &str, instrument: Option<InstrumentInfo>, o: &SessionOutcome) -> Self {
        let pose = o.result.refined.map(|r| r.pose).or(o.result.coarse);
        StationReport {
            plan: plan.to_owned(),
            instrument,
            pose: pose.map(|p| [p.x, p.y, p.theta]),
            final_bearing: o.state.bearing(),
            risk: o.result.stop_risk,
            stopped: o.stop == Some(Stop::Confident),
            symmetry_order: o.result.symmetry_order,
            answer_readings: o.result.answer_readings,
            readings: o
                .steps
                .iter()
                .filter(|s| !s.no_return)
                .filter_map(|s| s.range.map(|r| [s.bearing, r]))
                .collect(),
            actions: o.state.actions,
        }
    }

    /// The symmetric candidates (k = 0 the answer itself): the pose turned by 2πk/order
    /// about the model origin.
    pub fn candidates(&self) -> Vec<[f64; 3]> {
        let Some([x, y, t]) = self.pose else {
            return vec![];
        };
        let n = self.symmetry_order.max(1);
        (0..n)
            .map(|k| {
                let a = TAU * k as f64 / n as f64;
                let (s, c) = a.sin_cos();
                let (x, y) = (x as f64, y as f64);
                [c * x - s * y, s * x + c * y, (t as f64 + a).rem_euclid(TAU)]
            })
            .collect()
    }

    /// Prints the session's counts (the pose itself is printed by the [`Answer`], in the
    /// plan's coordinates).
    pub fn print(&self) {
        println!(
            "{} readings ({} in the answer), {} actions, risk {}, {}",
            self.readings.len(),
            self.answer_readings,
            self.actions,
            self.risk.map_or("-".into(), |r| format!("{r:.3}")),
            if self.stopped {
                "calibrated stop"
            } else {
                "action limit"
            }
        );
        if self.symmetry_order > 1 {
            println!(
                "the room is symmetric (order {}): the candidates above are equally good; --set-station needs --tie-break K",
                self.symmetry_order
            );
        }
    }

    /// Writes the station to the instrument: E, N = the candidate in the plan's own
    /// coordinates ([`PlanFrame::to_plan`], f64), in metres (the instrument's unit: a
    /// millimetre plan's coordinates are divided by 1000), keeping its heights;
    /// orientation = the azimuth (clockwise from +y) of the telescope's current direction.
    /// Refuses an ambiguous or unconfident answer.
    pub fn write_to_instrument(
        &self,
        client: &mut Client,
        frame: &PlanFrame,
        tie_break: Option<u8>,
        answer: &Answer,
        max_risk: f32,
    ) -> Result<[f64; 4]> {
        let (risk, mismatch) = (answer.risk, answer.mismatch.as_deref());
        let cands = self.candidates();
        if cands.is_empty() {
            bail!("no answer: nothing written to the instrument");
        }
        if let Some(m) = mismatch {
            bail!("{m}; nothing written: check the room against the plan (furniture, doors, walls off their lines), or measure from another set-up");
        }
        let k = match (self.symmetry_order > 1, tie_break) {
            (false, _) => 0,
            (true, Some(k)) if (k as usize) < cands.len() => k as usize,
            (true, Some(k)) => bail!("--tie-break {k}: the room has {} candidates (0..{})", cands.len(), cands.len() - 1),
            (true, None) => bail!(
                "the room is symmetric (order {}): the answer is ambiguous, nothing written; choose a candidate with --tie-break K",
                self.symmetry_order
            ),
        };
        if !self.stopped && risk.is_none_or(|r| r > f64::from(max_risk)) {
            bail!(
                "the answer is not confident enough to write: {}, above the {} you accept (--stop-risk); nothing written",
                match risk {
                    Some(r) => format!("the risk that it is wrong is {:.1} %", 100.0 * r),
                    None => match &answer.wall_reliance {
                        Some(w) => format!("the stop does not answer while {w}"),
                        None => "the stop has no estimate of the risk that it is wrong".to_string(),
                    },
                },
                format_args!("{:.1} %", 100.0 * max_risk)
            );
        }
        let [x, y, t] = cands[k];
        let az = (FRAC_PI_2 - (t + self.final_bearing as f64)).rem_euclid(TAU);
        let e = |e: activesense_instrument::geocom::client::GeoComError| {
            anyhow::anyhow!("writing the station failed: {e}")
        };
        rpc::do_measure(client, rpc::tmc_prog::CLEAR).map_err(e)?;
        let old = rpc::get_station(client).map_err(e)?;
        let [e_plan, n_plan] = frame.to_plan([x, y]);
        let station = [e_plan * frame.scale, n_plan * frame.scale, old[2], old[3]];
        rpc::set_station(client, station).map_err(e)?;
        rpc::set_orientation(client, az).map_err(e)?;
        println!(
            "written: TMC_SetStation E {:.4} N {:.4} (heights kept), TMC_SetOrientation Hz {:.6} rad",
            station[0], station[1], az
        );
        Ok(station)
    }
}

impl StationReport {
    /// The surveyor's answer: the plan's own coordinates (`frame`), precision, candidates
    /// (a symmetric room's twins), the stated risk.
    pub fn answer(
        &self,
        setup: &SessionSetup,
        frame: &PlanFrame,
        o: &SessionOutcome,
        hint: Option<HeadingHint>,
    ) -> Answer {
        let readings: Vec<Measurement> = o
            .steps
            .iter()
            .filter(|s| s.action == Action::Measure && !s.no_return)
            .filter_map(|s| s.range.map(|r| Measurement::new(s.bearing, r)))
            .take(o.result.answer_readings as usize)
            .collect();
        Answer::new(&AnswerInput {
            label: self.plan.clone(),
            plan: &setup.plan,
            frame,
            pose: o.result.refined.map(|r| r.pose).or(o.result.coarse),
            refined: o.result.refined.is_some(),
            readings: &readings,
            heading_known: false,
            symmetry_order: o.result.symmetry_order,
            stop_risk: o.result.stop_risk,
            stop_tables: Some((setup.agent, setup.config.instrument, ROT_BINS)),
            truth: None,
            hint,
            range_sigma: setup.sensor.sigma,
        })
    }
}

fn live(s: &SessionStep) {
    let what = match (s.action, s.range, s.no_return) {
        (Action::Measure, Some(r), false) => format!("range {r:.4} m"),
        (Action::Measure, _, _) => "no return".to_owned(),
        (a, _, _) => format!("{a:?}"),
    };
    println!(
        "step {:3}  bearing {:7.2}°  {:<18} entropy {:.3}  risk {}",
        s.step,
        s.bearing.to_degrees(),
        what,
        s.entropy,
        s.risk.map_or("-".into(), |r| format!("{r:.3}"))
    );
}

/// The session setup and policies for `a` in `room`.
pub fn setup_of(a: &StationArgs) -> Result<(String, SessionSetup, Policies)> {
    let loaded = planfile::load_plan(&a.plan, &a.read.options())?;
    let named = loaded.plan;
    if a.episode.one_rot_bins(ROT_BINS)? != ROT_BINS {
        bail!("a station does not know its heading: it localizes with --rot-bins {ROT_BINS}");
    }
    a.episode
        .require_termination("station", &[Termination::Confident])?;
    if !a.episode.site.is_plan() {
        bail!("`station` does not take --site: the room is whatever the instrument stands in; give --site to `geocom-sim` to simulate a furnished one");
    }
    let mut spec = EpisodeSpec::new(named.seed(), a.agent);
    spec.episode_seed = a.episode.episode_seed;
    let config = a.episode.config();
    let mut policies = Policies::default();
    match a.agent {
        AgentKind::Learnt => {
            policies = Policies::load_for(config.instrument, a.policy.as_slice(), &[ROT_BINS])?
        }
        AgentKind::LearntInt8 => {
            policies.load_int8_for(config.instrument, a.int8.as_slice(), &[ROT_BINS])?
        }
        _ => {}
    }
    let setup = SessionSetup {
        plan: named.plan.clone(),
        agent: a.agent,
        agent_seed: spec.agent_seed(),
        config,
        sensor: Default::default(),
    };
    Ok((named.name, setup, policies))
}

/// Runs `activesense station`; returns the report (the tests call this).
pub fn station(a: &StationArgs) -> Result<StationReport> {
    let (name, setup, policies) = setup_of(a)?;
    let frame = planfile::load_plan(&a.plan, &a.read.options())?.plan.frame;
    let config = ClientConfig {
        timeout: Duration::from_millis(a.timeout_ms),
        slow_timeout: Duration::from_millis(a.move_timeout_ms),
        retries: a.retries,
        crc: a.crc,
        ..Default::default()
    };
    let client = Client::new(a.link.open()?, config);
    let (mut inst, info) = match GeoComInstrument::connect(
        client,
        setup.config,
        a.vertical_deg.map(f64::to_radians),
    ) {
        Ok(x) => x,
        Err(failed) => {
            let (mut c, e) = *failed;
            let still = rpc::safe_state(&mut c);
            bail!("{e}; {}", still_note(&still));
        }
    };
    println!(
        "instrument: {} (serial {}, GeoCOM {}) on {}",
        info.name,
        info.serial,
        info.geocom_version,
        inst.client().describe()
    );
    let quiet = a.quiet;
    let outcome = with_policy(&setup, &policies, |p| {
        run_session(&setup, p, &mut inst, &mut |s| {
            if !quiet {
                live(s)
            }
        })
    })?;
    for ev in inst.client().take_events() {
        println!("recovered: {ev}");
    }
    let outcome = match outcome {
        Ok(o) => o,
        Err(e) => {
            let msg = match e {
                SessionError::Instrument(e) => e.to_string(),
                SessionError::Rejected(r) => r,
            };
            let still = rpc::safe_state(inst.client());
            bail!("{msg}; {}", still_note(&still));
        }
    };
    let report = StationReport::new(&name, Some(info), &outcome);
    let answer = report.answer(&setup, &frame, &outcome, a.heading_hint);
    println!("{}", answer.to_text());
    report.print();
    let written = if a.set_station {
        Some(report.write_to_instrument(
            inst.client(),
            &frame,
            a.tie_break,
            &answer,
            a.episode.stop_risk,
        ))
    } else {
        None
    };
    let still = rpc::safe_state(inst.client());
    if !still.is_empty() {
        eprintln!("warning: {}", still_note(&still));
    }
    if let Some(p) = &a.json {
        super::write_file(
            p,
            &serde_json::to_string_pretty(&serde_json::json!({
                "answer": &answer,
                "session": &report,
                "steps": &outcome.steps,
            }))?,
        )?;
    }
    if let Some(Err(e)) = written {
        return Err(e);
    }
    Ok(report)
}

fn still_note(errs: &[activesense_instrument::geocom::client::GeoComError]) -> String {
    if errs.is_empty() {
        "instrument left still, EDM off".to_owned()
    } else {
        let e: Vec<String> = errs.iter().map(|e| e.to_string()).collect();
        format!(
            "could not confirm the instrument is still and the EDM off ({})",
            e.join("; ")
        )
    }
}

/// `activesense station`.
pub fn run(a: StationArgs) -> Result<()> {
    station(&a).map(drop)
}

/// `activesense geocom-sim`.
#[derive(Args)]
#[command(mut_arg("instrument", |a| a.default_value("edm")))]
pub struct GeocomSimArgs {
    /// The room to play (JSON, GeoJSON or DXF).
    #[arg(long)]
    pub plan: PathBuf,
    #[command(flatten)]
    pub read: PlanReadArgs,
    /// Listen on tcp:HOST:PORT (port 0: any free one, printed).
    #[arg(long, conflicts_with = "pty", required_unless_present = "pty")]
    pub listen: Option<String>,
    /// Serve on a new pseudo-terminal (its path is printed; use geocom:serial:PATH).
    #[arg(long)]
    pub pty: bool,
    /// The episode seed (with the room's name: where the instrument stands, the noise) and
    /// the encoder grid the station command uses (--steps-per-turn); the station decides
    /// the rest.
    #[command(flatten)]
    pub episode: EpisodeOptions,
    /// Motor speed, degrees per second (0: instant).
    #[arg(long, default_value_t = 90.0)]
    pub motor_deg_per_s: f64,
    /// Time of one EDM measurement (ms).
    #[arg(long, default_value_t = 300)]
    pub edm_ms: u64,
    /// Inject a fault: KIND@RPC:N (the N-th request of RPC), repeatable; KIND one of
    /// no-distance, no-signal, accuracy, busy, timeout, garbled, truncated, crc, drop, motor.
    #[arg(long = "fault")]
    pub faults: Vec<FaultSpec>,
    #[command(flatten)]
    pub(crate) sensor: SensorArgs,
}

/// The simulator for `a` (the tests build it the same way).
pub fn sim_of(a: &GeocomSimArgs) -> Result<(String, GeoComSim)> {
    let named = planfile::load_plan(&a.plan, &a.read.options())?.plan;
    a.episode.refuse(
        "geocom-sim",
        &[
            EpisodeOption::RotBins,
            EpisodeOption::MaxActions,
            EpisodeOption::StopRisk,
            EpisodeOption::MinObservability,
            EpisodeOption::Termination,
        ],
        "the simulator plays the room; `station` decides where to measure and when to stop",
    )?;
    let mut spec = EpisodeSpec::new(named.seed(), AgentKind::Heuristic1);
    spec.episode_seed = a.episode.episode_seed;
    let cfg = SimConfig {
        plan: named.plan.clone(),
        sensor: a.episode.sensor(a.sensor.model()?),
        config: a.episode.config(),
        world_seed: spec.world_seed(),
        motor_speed: a.motor_deg_per_s.max(0.0).to_radians(),
        edm_time: Duration::from_millis(a.edm_ms),
        faults: a.faults.clone(),
    };
    Ok((named.name, GeoComSim::new(cfg)))
}

/// Runs `activesense geocom-sim` until killed.
pub fn run_sim(a: GeocomSimArgs) -> Result<()> {
    let (name, sim) = sim_of(&a)?;
    if a.pty {
        #[cfg(unix)]
        {
            let (path, _) = activesense_instrument::geocom::sim::serve_pty(sim)?;
            println!(
                "geocom-sim: room {name} on pty {path} (connect with --link geocom:serial:{path})"
            );
            loop {
                std::thread::sleep(Duration::from_secs(3600));
            }
        }
        #[cfg(not(unix))]
        bail!("--pty needs a Unix system");
    }
    let listen = a.listen.as_deref().unwrap_or_default();
    let addr = listen
        .strip_prefix("tcp:")
        .with_context(|| format!("--listen {listen}: expected tcp:HOST:PORT"))?;
    let listener =
        std::net::TcpListener::bind(addr).with_context(|| format!("cannot listen on {addr}"))?;
    let local = listener.local_addr()?;
    println!("geocom-sim: room {name} on tcp:{local} (connect with --link geocom:tcp:{local})");
    activesense_instrument::geocom::sim::serve_tcp(listener, sim)?;
    Ok(())
}
