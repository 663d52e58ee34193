//! A GeoCOM instrument simulator: a server that answers the RPCs of
//! [`crate::geocom::rpc`] as the manual specifies, playing the simulated world (the
//! host's ray casting and EDM noise / outlier model, [`crate::world::sensor`], from the
//! same random stream as the in-process episode), with a motor that takes time to turn,
//! and faults injected on request ([`FaultSpec`]). `activesense geocom-sim` serves it on
//! TCP or a pseudo-terminal; the tests drive it in a thread.
//!
//! Angles: the simulated instrument's raw Hz at the world's encoder bearing `b` is
//! `hz_start − b` (clockwise), plus the orientation TMC_SetOrientation set. A positioning
//! onto the episode's encoder grid (within 1e-7 rad) turns the world's encoder step by
//! step (each step one `SimWorld::act`, as in-process), so a session driven through the
//! simulator meets the same noise as the in-process episode; a positioning between grid
//! steps measures along that exact direction ([`SimWorld::measure_along`]).

use crate::geocom::codes::ReturnCode;
use crate::geocom::rpc::{self, *};
use crate::geocom::wire::{self, Param};
use crate::world::sensor::SensorModel;
use crate::world::SimWorld;
use activesense_core::episode::{Action, EpisodeConfig};
use activesense_core::FloorPlan;
use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::io::{self, Read, Write};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A fault class the simulator injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKind {
    /// The measurement finds no distance (GRC_TMC_ANGLE_OK).
    NoDistance,
    /// No EDM signal (GRC_TMC_SIGNAL_ERROR).
    NoSignal,
    /// Accuracy not guaranteed (GRC_TMC_ACCURACY_GUARANTEE, values valid).
    Accuracy,
    /// GRC_TMC_BUSY, nothing done.
    Busy,
    /// No reply at all (the request is lost).
    Timeout,
    /// The reply is garbled (done, then corrupted).
    Garbled,
    /// The reply stops half-way and the line falls silent.
    Truncated,
    /// The reply's CRC field is wrong.
    Crc,
    /// The connection drops before the request is done.
    Drop,
    /// The motor fails (GRC_AUT_MOTOR_ERROR to a positioning).
    Motor,
}

impl FaultKind {
    const NAMES: &'static [(&'static str, FaultKind)] = &[
        ("no-distance", FaultKind::NoDistance),
        ("no-signal", FaultKind::NoSignal),
        ("accuracy", FaultKind::Accuracy),
        ("busy", FaultKind::Busy),
        ("timeout", FaultKind::Timeout),
        ("garbled", FaultKind::Garbled),
        ("truncated", FaultKind::Truncated),
        ("crc", FaultKind::Crc),
        ("drop", FaultKind::Drop),
        ("motor", FaultKind::Motor),
    ];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        Self::NAMES
            .iter()
            .find(|n| n.1 == self)
            .map_or("?", |n| n.0)
    }
}

/// One injected fault: `kind` on the `nth` (1-based) request of `rpc`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FaultSpec {
    /// What.
    pub kind: FaultKind,
    /// Which RPC's requests are counted.
    pub rpc: u16,
    /// Which of them.
    pub nth: u32,
}

impl std::str::FromStr for FaultSpec {
    type Err = String;
    /// `KIND@RPC:N`, e.g. `busy@2108:3` (the third TMC_GetSimpleMea answers busy).
    fn from_str(s: &str) -> Result<Self, String> {
        let usage = || {
            let kinds: Vec<_> = FaultKind::NAMES.iter().map(|n| n.0).collect();
            format!(
                "fault '{s}': expected KIND@RPC:N, e.g. busy@2108:3 (KIND: {})",
                kinds.join(", ")
            )
        };
        let (kind, rest) = s.split_once('@').ok_or_else(usage)?;
        let (rpc, nth) = rest.split_once(':').ok_or_else(usage)?;
        let kind = FaultKind::NAMES
            .iter()
            .find(|n| n.0 == kind)
            .ok_or_else(usage)?
            .1;
        Ok(FaultSpec {
            kind,
            rpc: rpc.parse().map_err(|_| usage())?,
            nth: nth.parse().ok().filter(|n| *n > 0).ok_or_else(usage)?,
        })
    }
}

/// The simulator's settings.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// The room (model frame, centred).
    pub plan: FloorPlan,
    /// EDM model.
    pub sensor: SensorModel,
    /// The episode's encoder grid (rotation step).
    pub config: EpisodeConfig,
    /// The world stream's seed (placement and noise).
    pub world_seed: u64,
    /// Motor speed (rad/s; 0 = instant).
    pub motor_speed: f64,
    /// Time one EDM measurement takes.
    pub edm_time: Duration,
    /// Faults to inject.
    pub faults: Vec<FaultSpec>,
}

/// What an observer (a test, the CLI) can see of the simulated instrument.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimState {
    /// Every request's RPC, in order.
    pub log: Vec<u16>,
    /// True while the EDM has a measurement program running / a distance held.
    pub edm_on: bool,
    /// True while the motor turns.
    pub moving: bool,
    /// Station E0, N0, H0, Hi (TMC_SetStation).
    pub station: [f64; 4],
    /// Orientation offset added to raw Hz (TMC_SetOrientation).
    pub orientation: f64,
    /// Faults fired, `kind@rpc:n`.
    pub fired: Vec<String>,
    /// The world's truth (model frame): x, y, heading.
    pub truth: [f32; 3],
    /// Raw Hz at encoder bearing 0.
    pub hz_start: f64,
}

enum Out {
    Line(String),
    Partial(String),
    Silent,
    Drop,
}

/// The simulated instrument.
pub struct GeoComSim {
    cfg: SimConfig,
    world: SimWorld,
    index: u16,
    free: Option<f64>,
    v: f64,
    last: Option<Option<f64>>,
    counts: HashMap<u16, u32>,
    state: Arc<Mutex<SimState>>,
}

fn wrap_pi(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r >= PI {
        r - TAU
    } else {
        r
    }
}

impl GeoComSim {
    /// Places the instrument in the room (the world seed fixes where and which way).
    pub fn new(cfg: SimConfig) -> Self {
        let mut world = SimWorld::new(cfg.plan.clone(), cfg.sensor, cfg.config, cfg.world_seed);
        // The initial scan the in-process episode takes (it draws only when scans are
        // noisy): keeps the streams aligned.
        let _ = world.scan();
        let t = world.truth();
        // Where the circle reads 0 is arbitrary on a real instrument: derive it.
        let hz_start = (cfg.world_seed % 6283) as f64 / 1000.0;
        let state = SimState {
            truth: [t.x, t.y, t.theta],
            hz_start,
            ..Default::default()
        };
        GeoComSim {
            cfg,
            world,
            index: 0,
            free: None,
            v: FRAC_PI_2,
            last: None,
            counts: HashMap::new(),
            state: Arc::new(Mutex::new(state)),
        }
    }

    /// The observable state (shared; the simulator updates it as it serves).
    pub fn state(&self) -> Arc<Mutex<SimState>> {
        self.state.clone()
    }

    fn with_state<R>(&self, f: impl FnOnce(&mut SimState) -> R) -> R {
        let mut g = self.state.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut g)
    }

    fn step(&self) -> f64 {
        TAU / self.cfg.config.steps_per_turn.max(1) as f64
    }

    fn grid_bearing(&self, index: u16) -> f32 {
        let mut s = activesense_core::episode::EpisodeState::new(self.cfg.config);
        s.bearing_index = index;
        s.bearing()
    }

    /// The encoder bearing the telescope stands at (rad, counter-clockwise).
    fn bearing(&self) -> f64 {
        self.free
            .unwrap_or_else(|| self.grid_bearing(self.index) as f64)
    }

    /// Hz as the instrument reports it (oriented).
    fn hz(&self) -> f64 {
        let (start, orient) = self.with_state(|s| (s.hz_start, s.orientation));
        (start - self.bearing() + orient).rem_euclid(TAU)
    }

    fn position(&mut self, hz: f64, v: f64) {
        let (start, orient) = self.with_state(|s| (s.hz_start, s.orientation));
        let target = wrap_pi(start - (hz - orient));
        let turn = wrap_pi(target - self.bearing()).abs();
        self.with_state(|s| s.moving = true);
        if self.cfg.motor_speed > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(turn / self.cfg.motor_speed));
        }
        let n = self.cfg.config.steps_per_turn.max(1) as i64;
        let k = (target / self.step()).round() as i64;
        let k = k.rem_euclid(n) as u16;
        if wrap_pi(target - self.grid_bearing(k) as f64).abs() < 1e-7 {
            // Onto the encoder grid: one world step per encoder step, the shorter way.
            let diff = (k as i64 - self.index as i64).rem_euclid(n);
            let (action, count) = if diff <= n / 2 {
                (Action::RotateLeft, diff)
            } else {
                (Action::RotateRight, n - diff)
            };
            for _ in 0..count {
                self.world.act(action);
            }
            self.index = k;
            self.free = None;
        } else {
            self.free = Some(target);
        }
        self.v = v;
        self.with_state(|s| s.moving = false);
    }

    fn measure(&mut self) {
        if !self.cfg.edm_time.is_zero() {
            std::thread::sleep(self.cfg.edm_time);
        }
        let horizontal = match self.free {
            None => self.world.act(Action::Measure).0.range,
            Some(b) => {
                let a = self.world.truth().theta + b as f32;
                self.world.measure_along(a).0
            }
        };
        let s = self.v.sin();
        // A level telescope (sin V = 1) returns the world's range exactly.
        self.last = Some(
            horizontal
                .filter(|_| s.abs() > 0.1)
                .map(|h| h as f64 / s.abs()),
        );
        self.with_state(|st| st.edm_on = true);
    }

    /// (rc, values) of a measurement reply.
    fn mea_reply(&self, extra: Option<i64>) -> (u16, Vec<Param>) {
        let (hz, v) = (self.hz(), self.v);
        let mut vals = vec![Param::Real(hz), Param::Real(v)];
        let rc = match self.last {
            Some(Some(d)) => {
                vals.push(Param::Real(d));
                0
            }
            Some(None) => {
                vals.push(Param::Real(0.0));
                ReturnCode::TMC_DIST_ERROR.0
            }
            None => {
                vals.push(Param::Real(0.0));
                ReturnCode::TMC_ANGLE_OK.0
            }
        };
        if let Some(m) = extra {
            vals.push(Param::Int(m));
        }
        (rc, vals)
    }

    /// Executes one request: (RC, values).
    fn execute(&mut self, rpc: u16, p: &[String]) -> (u16, Vec<Param>) {
        let real = |i: usize| p.get(i).and_then(|s| wire::real(s));
        let int = |i: usize| p.get(i).and_then(|s| wire::int(s));
        let iv = ReturnCode::IVPARAM.0;
        match rpc {
            COM_NULLPROC => (0, vec![]),
            COM_GET_DOUBLE_PRECISION => (0, vec![Param::Int(15)]),
            COM_GET_SW_VERSION => (0, vec![Param::Int(1), Param::Int(50), Param::Int(0)]),
            CSV_GET_SW_VERSION => (0, vec![Param::Int(0), Param::Int(1), Param::Int(0)]),
            CSV_GET_INSTRUMENT_NO => (0, vec![Param::Int(4_242_424)]),
            CSV_GET_INSTRUMENT_NAME => (0, vec![Param::Str("activesense geocom-sim".into())]),
            BAP_SET_TARGET_TYPE => match int(0) {
                Some(0 | 1) => (0, vec![]),
                _ => (iv, vec![]),
            },
            BAP_GET_TARGET_TYPE => (0, vec![Param::Int(1)]),
            TMC_SET_EDM_MODE => match int(0) {
                Some(0..=13) => (0, vec![]),
                _ => (iv, vec![]),
            },
            EDM_LASERPOINTER | MOT_STOP_CONTROLLER => (0, vec![]),
            TMC_GET_ANGLE5 => (0, vec![Param::Real(self.hz()), Param::Real(self.v)]),
            AUT_MAKE_POSITIONING => match (real(0), real(1)) {
                (Some(hz), Some(v)) if v > 0.0 && v < TAU => {
                    self.position(hz, v);
                    (0, vec![])
                }
                _ => (iv, vec![]),
            },
            TMC_DO_MEASURE => match int(0) {
                Some(rpc::tmc_prog::DEF_DIST) => {
                    self.measure();
                    (0, vec![])
                }
                Some(rpc::tmc_prog::STOP | rpc::tmc_prog::CLEAR) => {
                    self.last = None;
                    self.with_state(|s| s.edm_on = false);
                    (0, vec![])
                }
                Some(_) => (0, vec![]),
                None => (iv, vec![]),
            },
            TMC_GET_SIMPLE_MEA => self.mea_reply(None),
            BAP_MEAS_DISTANCE_ANGLE => {
                self.measure();
                self.mea_reply(Some(int(0).unwrap_or(rpc::BAP_DEF_DIST)))
            }
            TMC_GET_STATION => {
                let s = self.with_state(|s| s.station);
                (0, s.iter().map(|&x| Param::Real(x)).collect())
            }
            TMC_SET_STATION => match (real(0), real(1), real(2), real(3)) {
                (Some(e), Some(n), Some(h), Some(hi)) => {
                    self.with_state(|s| s.station = [e, n, h, hi]);
                    (0, vec![])
                }
                _ => (iv, vec![]),
            },
            TMC_SET_ORIENTATION => match real(0) {
                Some(hz) => {
                    // The current direction reads `hz` from now on.
                    let raw = (self.hz() - self.with_state(|s| s.orientation)).rem_euclid(TAU);
                    self.last = None;
                    self.with_state(|s| {
                        s.orientation = (hz - raw).rem_euclid(TAU);
                        s.edm_on = false;
                    });
                    (0, vec![])
                }
                None => (iv, vec![]),
            },
            _ => (u16::MAX, vec![]),
        }
    }

    fn fault_for(&mut self, rpc: u16) -> Option<FaultKind> {
        let n = self.counts.entry(rpc).or_insert(0);
        *n += 1;
        let n = *n;
        let f = self
            .cfg
            .faults
            .iter()
            .find(|f| f.rpc == rpc && f.nth == n)
            .map(|f| f.kind)?;
        self.with_state(|s| s.fired.push(format!("{}@{rpc}:{n}", f.name())));
        Some(f)
    }

    fn handle(&mut self, line: &str) -> Out {
        let req = match wire::parse_request(line) {
            Ok(r) => r,
            // The manual's reply to an undecodable request.
            Err(_) => {
                return Out::Line(wire::emit_reply(
                    ReturnCode::COM_CANT_DECODE_REQ.0,
                    0,
                    false,
                    0,
                    "",
                ))
            }
        };
        let rpc = req.header.first;
        let trid = req.header.trid.unwrap_or(0);
        let crc = req.header.crc.is_some();
        self.with_state(|s| s.log.push(rpc));
        if crc && !req.header.crc_ok {
            return Out::Line(wire::emit_reply(
                ReturnCode::COM_SRVR_RX_CHECKSUM_ERROR.0,
                trid,
                crc,
                0,
                "",
            ));
        }
        let fault = self.fault_for(rpc);
        match fault {
            Some(FaultKind::Timeout) => return Out::Silent,
            Some(FaultKind::Drop) => return Out::Drop,
            Some(FaultKind::Busy) => {
                return Out::Line(wire::emit_reply(0, trid, crc, ReturnCode::TMC_BUSY.0, ""))
            }
            Some(FaultKind::Motor) if rpc == AUT_MAKE_POSITIONING => {
                return Out::Line(wire::emit_reply(
                    0,
                    trid,
                    crc,
                    ReturnCode::AUT_MOTOR_ERROR.0,
                    "",
                ))
            }
            _ => {}
        }
        let (mut rc, mut vals) = self.execute(rpc, &req.params);
        if rc == u16::MAX {
            return Out::Line(wire::emit_reply(
                ReturnCode::COM_PROC_UNAVAIL.0,
                trid,
                crc,
                0,
                "",
            ));
        }
        let mea = matches!(rpc, TMC_GET_SIMPLE_MEA | BAP_MEAS_DISTANCE_ANGLE);
        match fault {
            Some(FaultKind::NoDistance) if mea => {
                rc = ReturnCode::TMC_ANGLE_OK.0;
                vals.truncate(2);
                vals.push(Param::Real(0.0));
            }
            Some(FaultKind::NoSignal) if mea => {
                rc = ReturnCode::TMC_SIGNAL_ERROR.0;
                vals.truncate(2);
                vals.push(Param::Real(0.0));
            }
            Some(FaultKind::Accuracy) if mea && rc == 0 => {
                rc = ReturnCode::TMC_ACCURACY_GUARANTEE.0
            }
            _ => {}
        }
        let values = wire::format_values(&vals).unwrap_or_default();
        let line = wire::emit_reply(0, trid, crc, rc, &values);
        match fault {
            Some(FaultKind::Garbled) => {
                Out::Line(line.replacen(':', "#\u{7f}", 1).replace('%', "?"))
            }
            Some(FaultKind::Truncated) => Out::Partial(line[..line.len() / 2].to_owned()),
            Some(FaultKind::Crc) => {
                // A reply CRC that cannot match (the line's own plus one).
                let good = wire::crc16(wire::emit_reply(0, trid, false, rc, &values).as_bytes());
                let head = format!("%R1P,0,{trid},{}:", good.wrapping_add(1));
                let tail = line.split_once(':').map_or("", |x| x.1);
                Out::Line(format!("{head}{tail}"))
            }
            _ => Out::Line(line),
        }
    }

    /// Serves one connection until it closes (`Ok(true)`) or a drop fault ends it
    /// (`Ok(false)`).
    pub fn serve<S: Read + Write>(&mut self, io: &mut S) -> io::Result<bool> {
        let mut pending: Vec<u8> = Vec::new();
        let mut buf = [0u8; 512];
        loop {
            while let Some(i) = pending.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = pending.drain(..=i).collect();
                let text = String::from_utf8_lossy(&raw);
                let line = text.trim_end_matches(['\r', '\n']);
                if line.is_empty() {
                    // The client's buffer-clearing LF.
                    continue;
                }
                match self.handle(line) {
                    Out::Line(l) => {
                        io.write_all(l.as_bytes())?;
                        io.write_all(b"\r\n")?;
                        io.flush()?;
                    }
                    Out::Partial(l) => {
                        io.write_all(l.as_bytes())?;
                        io.flush()?;
                    }
                    Out::Silent => {}
                    Out::Drop => return Ok(false),
                }
            }
            if pending.len() > wire::MAX_LINE {
                pending.clear();
            }
            match io.read(&mut buf) {
                Ok(0) => return Ok(true),
                Ok(n) => pending.extend_from_slice(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) => {}
                Err(e) if e.kind() == io::ErrorKind::BrokenPipe => return Ok(true),
                Err(e) => return Err(e),
            }
        }
    }
}

/// Serves TCP connections one after another (a dropped one is followed by the next
/// accept, the instrument's state kept) until the listener fails.
pub fn serve_tcp(listener: std::net::TcpListener, mut sim: GeoComSim) -> io::Result<()> {
    loop {
        let (mut conn, _) = listener.accept()?;
        conn.set_nodelay(true)?;
        // A served connection that errors (reset by the peer) is just over.
        let _ = sim.serve(&mut conn);
    }
}

/// Starts the simulator on a fresh pseudo-terminal in a thread; returns the path a client
/// opens (the slave side) and the simulator's state. On a pty a drop fault leaves the
/// line silent (nothing to hang up).
#[cfg(unix)]
pub fn serve_pty(sim: GeoComSim) -> io::Result<(String, Arc<Mutex<SimState>>)> {
    use serialport::SerialPort;
    let (mut master, slave) = serialport::TTYPort::pair().map_err(io::Error::other)?;
    master
        .set_timeout(Duration::from_millis(20))
        .map_err(io::Error::other)?;
    let name = slave
        .name()
        .ok_or_else(|| io::Error::other("pty without a name"))?;
    let state = sim.state();
    std::thread::spawn(move || {
        let mut sim = sim;
        // Keep the slave open: a master whose slave closed reports a hang-up.
        let _slave = slave;
        loop {
            match sim.serve(&mut master) {
                Ok(false) => continue,
                Ok(true) => std::thread::sleep(Duration::from_millis(20)),
                Err(_) => std::thread::sleep(Duration::from_millis(20)),
            }
        }
    });
    Ok((name, state))
}
