//! The device's protocol state machine, [`Session`]: frames in, frames out over any
//! `embedded_io` byte stream, request ids and retransmission, phases, link statistics and
//! the host-silence timeout, around one [`Controller`]. See [`crate::device`] for the
//! robustness rules.

use super::controller::{Controller, Step};
use crate::limits::SCAN_PIXELS;
use crate::protocol::*;
use crate::world::floorplan::{FloorPlan, MAX_VERTICES};
use embedded_io::{Read, Write};
use heapless::String as HString;

/// Largest encoded reply frame.
pub const MAX_REPLY: usize = 256;
/// Default silence after which a running episode is abandoned (ms).
pub const DEFAULT_TIMEOUT_MS: u32 = 10_000;

/// Static configuration of a [`Session`].
#[derive(Clone, Copy)]
pub struct SessionConfig {
    /// Version string reported in `Hello` (≤ 24 bytes; longer is cut).
    pub firmware: &'static str,
    /// Silence (ms) after which a running episode is abandoned.
    pub timeout_ms: u32,
    /// Announced in `Hello` as [`DeviceInfo::max_reply_ms`]: an upper bound on the time one
    /// request takes to answer on this device (its slowest update), so the host's reply
    /// time-out follows the device instead of a fixed guess.
    pub max_reply_ms: u32,
    /// Free-running cycle counter for per-update statistics.
    pub cycle_clock: Option<fn() -> u32>,
    /// int8 policy blobs built into the firmware (`docs/policy-blob.md`), one per K; each
    /// is validated (CRC included) when an episode asks for it.
    pub policies: &'static [&'static [u8]],
    /// The stack's high-water mark, reported in `Status` (the firmware's painted stack;
    /// `None` on the host).
    pub stack_usage: Option<fn() -> StackUsage>,
}

/// What the caller should do after [`Session::feed`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Keep serving.
    Continue,
    /// `Shutdown` was acknowledged: stop serving.
    Shutdown,
}

/// Why [`Session::serve`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ServeEnd {
    /// The host sent `Shutdown`.
    Shutdown,
    /// The link reported end of stream.
    Eof,
}

/// Something a device log should record; queued by the [`Session`] and drained with
/// [`Session::take_event`] (the oldest are dropped beyond [`MAX_EVENTS`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SessionEvent {
    /// A `Hello` opened a session.
    Opened,
    /// A plan was loaded.
    PlanLoaded {
        /// Its vertex count.
        vertices: u8,
    },
    /// An episode started.
    EpisodeStarted {
        /// Rotation bins K.
        rot_bins: u8,
        /// Action limit.
        max_actions: u16,
    },
    /// An episode ended (`Done` or `Abort`).
    EpisodeEnded(EpisodeReport),
    /// A frame or request was answered with an error.
    Rejected(WireError),
    /// The host went silent; the running episode was abandoned.
    TimedOut,
    /// `Shutdown` was acknowledged.
    Shutdown,
}

/// Capacity of the [`SessionEvent`] queue.
pub const MAX_EVENTS: usize = 4;

/// The device's protocol state machine.
pub struct Session {
    events: heapless::Deque<SessionEvent, MAX_EVENTS>,
    acc: FrameAccumulator,
    ctl: Controller,
    config: SessionConfig,
    open: bool,
    last_id: u16,
    reply: [u8; MAX_REPLY],
    reply_len: usize,
    stats: LinkStats,
    last_rx_ms: u32,
}

fn next_id(id: u16) -> u16 {
    match id.wrapping_add(1) {
        NO_ID => 1,
        n => n,
    }
}

impl Session {
    /// A closed session (power-on state).
    pub const fn new(config: SessionConfig) -> Self {
        Session {
            events: heapless::Deque::new(),
            acc: FrameAccumulator::new(),
            ctl: Controller::new(config.cycle_clock, config.policies),
            config,
            open: false,
            last_id: NO_ID,
            reply: [0; MAX_REPLY],
            reply_len: 0,
            stats: LinkStats {
                frames_ok: 0,
                frames_bad: 0,
                sequence_errors: 0,
                retransmissions: 0,
                timeouts: 0,
                episodes: 0,
            },
            last_rx_ms: 0,
        }
    }

    /// The device description sent in answer to `Hello`.
    pub fn device_info(&self) -> DeviceInfo {
        let mut firmware = HString::new();
        for c in self.config.firmware.chars() {
            if firmware.push(c).is_err() {
                break;
            }
        }
        let mut capabilities = CAP_BASELINE_AGENTS
            | CAP_GROUND_TRUTH
            | CAP_SHUTDOWN
            | CAP_LOCALIZATION
            | CAP_REGISTRATION;
        if self.config.cycle_clock.is_some() {
            capabilities |= CAP_CYCLE_COUNTS;
        }
        capabilities |= CAP_POLICY_UPLOAD;
        if self.ctl.has_policies() {
            capabilities |= CAP_LEARNT_POLICY;
        }
        DeviceInfo {
            protocol: PROTOCOL_VERSION,
            firmware,
            // Cell size depends on the loaded plan (the grid spans its extent): 0 here.
            grid: GridInfo {
                cells_x: crate::localization::MAX_NX as u16,
                cells_y: crate::localization::MAX_NY as u16,
                cell_mm: 0,
            },
            max_vertices: MAX_VERTICES as u8,
            max_actions: MAX_EPISODE_ACTIONS,
            max_rot_bins: MAX_ROT_BINS,
            scan_pixels: SCAN_PIXELS as u8,
            max_frame: MAX_FRAME as u16,
            capabilities,
            max_reply_ms: self.config.max_reply_ms,
        }
    }

    /// Sends the unsolicited boot announcement (`Hello` with id [`NO_ID`]) the firmware
    /// emits once its UART is up, so a host knows it may start talking.
    pub fn announce<W: Write>(&mut self, out: &mut W) -> Result<(), W::Error> {
        let info = self.device_info();
        self.send(NO_ID, &Response::Hello(info), out)
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        if !self.open {
            Phase::Closed
        } else if self.ctl.is_running() {
            Phase::Episode
        } else {
            Phase::Ready
        }
    }

    /// The oldest unread [`SessionEvent`].
    pub fn take_event(&mut self) -> Option<SessionEvent> {
        self.events.pop_front()
    }

    fn event(&mut self, e: SessionEvent) {
        if self.events.is_full() {
            self.events.pop_front();
        }
        let _ = self.events.push_back(e);
    }

    /// Link counters.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The controller (plan, measurements).
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    /// Checks the host-silence timeout at time `now_ms`; returns true when a running
    /// episode was abandoned (the session closes; the next `Hello` reopens it). A partial
    /// frame older than the timeout is dropped as well.
    pub fn poll(&mut self, now_ms: u32) -> bool {
        if now_ms.wrapping_sub(self.last_rx_ms) <= self.config.timeout_ms {
            return false;
        }
        self.acc.clear();
        if self.ctl.abort().is_some() {
            self.event(SessionEvent::TimedOut);
            self.stats.timeouts = self.stats.timeouts.saturating_add(1);
            self.open = false;
            return true;
        }
        false
    }

    /// Sends a reply that is not kept for retransmission (errors to frames or requests
    /// that were not taken into the sequence).
    fn send<W: Write>(&mut self, id: u16, msg: &Response, out: &mut W) -> Result<(), W::Error> {
        self.send_reply(id, msg, false, out)
    }

    /// Sends a reply; with `cache`, it is kept so a re-sent request with the same id gets
    /// it again. Every request taken into the sequence caches its reply, errors included:
    /// a host whose copy of a refusal was corrupted on the line re-sends the request and
    /// must get the same refusal, not `OutOfSequence` (protocol v6).
    fn send_reply<W: Write>(
        &mut self,
        id: u16,
        msg: &Response,
        cache: bool,
        out: &mut W,
    ) -> Result<(), W::Error> {
        let mut buf = [0u8; MAX_REPLY];
        // Every Response fits MAX_REPLY (asserted by a unit test over the largest ones);
        // a failure here would be a programming error, reported as a bare Decode error.
        let n = match encode_frame(id, msg, &mut buf) {
            Ok(n) => n,
            Err(_) => encode_frame(id, &Response::Error(WireError::Decode), &mut buf).unwrap_or(0),
        };
        if cache && id != NO_ID {
            self.reply[..n].copy_from_slice(&buf[..n]);
            self.reply_len = n;
        }
        out.write_all(&buf[..n])?;
        out.flush()
    }

    /// Feeds received bytes at time `now_ms`, writing any replies to `out`.
    pub fn feed<W: Write>(
        &mut self,
        bytes: &[u8],
        now_ms: u32,
        out: &mut W,
    ) -> Result<Control, W::Error> {
        if !bytes.is_empty() {
            self.last_rx_ms = now_ms;
        }
        for &b in bytes {
            let decoded = match self.acc.push(b) {
                Feed::Pending | Feed::Empty => continue,
                Feed::Oversized => Err((FrameError::TooLarge, NO_ID)),
                Feed::Frame(f) => decode_frame_with_id::<Request>(f),
            };
            match decoded {
                Err((e, id)) => {
                    self.event(SessionEvent::Rejected(e.to_wire()));
                    self.stats.frames_bad = self.stats.frames_bad.saturating_add(1);
                    self.send(id, &Response::Error(e.to_wire()), out)?;
                }
                Ok((id, req)) => {
                    self.stats.frames_ok = self.stats.frames_ok.saturating_add(1);
                    if self.request(id, req, out)? == Control::Shutdown {
                        return Ok(Control::Shutdown);
                    }
                }
            }
        }
        Ok(Control::Continue)
    }

    fn request<W: Write>(
        &mut self,
        id: u16,
        req: Request,
        out: &mut W,
    ) -> Result<Control, W::Error> {
        if let Request::Hello { protocol } = req {
            self.ctl.abort();
            self.acc_reset_ids(id);
            if protocol != PROTOCOL_VERSION || id == NO_ID {
                self.open = false;
                let e = if id == NO_ID {
                    WireError::OutOfSequence { expected: 1 }
                } else {
                    WireError::VersionMismatch {
                        device: PROTOCOL_VERSION,
                    }
                };
                self.event(SessionEvent::Rejected(e));
                self.send(id, &Response::Error(e), out)?;
                return Ok(Control::Continue);
            }
            self.open = true;
            self.event(SessionEvent::Opened);
            let info = self.device_info();
            self.send_reply(id, &Response::Hello(info), true, out)?;
            return Ok(Control::Continue);
        }
        if !self.open {
            self.event(SessionEvent::Rejected(WireError::NoSession));
            self.send(id, &Response::Error(WireError::NoSession), out)?;
            return Ok(Control::Continue);
        }
        if id == self.last_id && self.reply_len > 0 {
            self.stats.retransmissions = self.stats.retransmissions.saturating_add(1);
            let n = self.reply_len;
            out.write_all(&self.reply[..n])?;
            out.flush()?;
            return Ok(Control::Continue);
        }
        let expected = next_id(self.last_id);
        if id != expected {
            self.stats.sequence_errors = self.stats.sequence_errors.saturating_add(1);
            self.event(SessionEvent::Rejected(WireError::OutOfSequence {
                expected,
            }));
            self.send(
                id,
                &Response::Error(WireError::OutOfSequence { expected }),
                out,
            )?;
            return Ok(Control::Continue);
        }
        self.last_id = id;
        self.reply_len = 0;
        let started = match &req {
            Request::StartEpisode(p) => Some(SessionEvent::EpisodeStarted {
                rot_bins: p.rot_bins,
                max_actions: p.config.max_actions,
            }),
            _ => None,
        };
        let (resp, control) = self.handle(req);
        match (&resp, started) {
            (Response::Error(_), _) => {}
            (_, Some(e)) => self.event(e),
            _ => {}
        }
        match &resp {
            Response::PlanLoaded(p) => self.event(SessionEvent::PlanLoaded {
                vertices: p.vertices,
            }),
            Response::Done(r) | Response::Aborted(r) => self.event(SessionEvent::EpisodeEnded(*r)),
            Response::Error(e) => self.event(SessionEvent::Rejected(*e)),
            _ => {}
        }
        if control == Control::Shutdown {
            self.event(SessionEvent::Shutdown);
        }
        if let Response::Error(WireError::StepMismatch { .. }) = resp {
            self.stats.sequence_errors = self.stats.sequence_errors.saturating_add(1);
        }
        self.send_reply(id, &resp, true, out)?;
        Ok(control)
    }

    fn acc_reset_ids(&mut self, id: u16) {
        self.last_id = id;
        self.reply_len = 0;
    }

    fn step_response(&mut self) -> Response {
        match self.ctl.next_step() {
            Some(Step::Act { step, action }) => Response::Act { step, action },
            Some(Step::Done(rep)) => {
                self.stats.episodes = self.stats.episodes.saturating_add(1);
                Response::Done(rep)
            }
            None => Response::Error(WireError::UnexpectedRequest),
        }
    }

    fn handle(&mut self, req: Request) -> (Response, Control) {
        let r = match req {
            Request::Hello { .. } => Response::Error(WireError::UnexpectedRequest),
            Request::Ping { nonce } => Response::Pong { nonce },
            Request::LoadPlan {
                vertices,
                rings,
                openings,
            } => self.load_plan(&vertices, &rings, openings),
            Request::StartEpisode(p) => {
                if self.ctl.is_running() {
                    Response::Error(WireError::UnexpectedRequest)
                } else {
                    match self.ctl.start(&p) {
                        Ok(()) => self.step_response(),
                        Err(e) => Response::Error(e),
                    }
                }
            }
            Request::Observe { step, observation } => match self.ctl.observe(step, &observation) {
                Ok(()) => self.step_response(),
                Err(e) => Response::Error(e),
            },
            Request::Status => Response::Status(DeviceStatus {
                phase: self.phase(),
                plan_vertices: self.ctl.plan().map(|p| p.len() as u8).unwrap_or(0),
                episode_actions: self.ctl.episode_actions(),
                link: self.stats,
                cycles: self.ctl.cycles(),
                stack: self.config.stack_usage.map(|f| f()).unwrap_or_default(),
            }),
            Request::Abort => match self.ctl.abort() {
                Some(rep) => Response::Aborted(rep),
                None => Response::Ack,
            },
            Request::Reset => {
                self.ctl.reset();
                self.stats = LinkStats::default();
                self.open = false;
                Response::Ack
            }
            Request::Shutdown => {
                self.ctl.abort();
                return (Response::Ack, Control::Shutdown);
            }
            Request::PolicyBegin { rot_bins, len, crc } => {
                match self.ctl.policy_begin(rot_bins, len, crc) {
                    Ok(()) => Response::Ack,
                    Err(e) => Response::Error(e),
                }
            }
            Request::PolicyChunk { offset, data } => match self.ctl.policy_chunk(offset, &data) {
                Ok(()) => Response::Ack,
                Err(e) => Response::Error(e),
            },
            Request::PolicyCommit => match self.ctl.policy_commit() {
                Ok(info) => Response::PolicyInfo(info),
                Err(e) => Response::Error(e),
            },
            Request::PolicyInfo { rot_bins } => {
                Response::PolicyInfo(self.ctl.policy_info(rot_bins))
            }
        };
        (r, Control::Continue)
    }

    fn load_plan(&mut self, vertices: &[[f32; 2]], rings: &[u8], openings: u64) -> Response {
        if self.ctl.is_running() {
            return Response::Error(WireError::UnexpectedRequest);
        }
        // Capacities are checked by `from_parts` (TooManyVertices, TooManyRings).
        match FloorPlan::from_parts(vertices, rings, openings) {
            Ok(plan) => {
                let summary = PlanSummary {
                    vertices: plan.len() as u8,
                    perimeter: plan.perimeter(),
                    max_radius: plan.max_radius(),
                };
                self.ctl.load_plan(plan);
                Response::PlanLoaded(summary)
            }
            Err(e) => Response::Error(WireError::InvalidPlan(e)),
        }
    }

    /// Blocking serve loop over a link whose `read` blocks until at least one byte is
    /// available; `clock_ms` supplies the time for timeouts (checked after every read).
    /// Returns on `Shutdown` or end of stream.
    pub fn serve<L: Read + Write>(
        &mut self,
        link: &mut L,
        mut clock_ms: impl FnMut() -> u32,
    ) -> Result<ServeEnd, L::Error> {
        let mut buf = [0u8; 64];
        loop {
            let n = link.read(&mut buf)?;
            if n == 0 {
                return Ok(ServeEnd::Eof);
            }
            let now = clock_ms();
            self.poll(now);
            if self.feed(&buf[..n], now, link)? == Control::Shutdown {
                return Ok(ServeEnd::Shutdown);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::episode::{Action, AgentKind, EpisodeConfig, Observation, Termination};
    use crate::fixtures::rect_4x3_wire;
    use crate::world::floorplan::PlanError;
    use crate::world::geometry::Pose2;
    use heapless::Vec as HVec;
    use std::vec::Vec;

    struct Sink(Vec<u8>);
    impl embedded_io::ErrorType for Sink {
        type Error = core::convert::Infallible;
    }
    impl Write for Sink {
        fn write(&mut self, b: &[u8]) -> Result<usize, Self::Error> {
            self.0.extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    const CFG: SessionConfig = SessionConfig {
        firmware: "test",
        timeout_ms: 1000,
        max_reply_ms: 1000,
        cycle_clock: None,
        policies: &[],
        stack_usage: None,
    };

    fn frames(bytes: &[u8]) -> Vec<(u16, Response)> {
        let mut acc = FrameAccumulator::new();
        let mut v = Vec::new();
        for &b in bytes {
            if let Feed::Frame(f) = acc.push(b) {
                v.push(decode_frame::<Response>(f).unwrap());
            }
        }
        v
    }

    fn call(s: &mut Session, id: u16, req: &Request) -> Response {
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(id, req, &mut out).unwrap();
        let mut sink = Sink(Vec::new());
        s.feed(&out[..n], 0, &mut sink).unwrap();
        let mut f = frames(&sink.0);
        assert_eq!(f.len(), 1, "{f:?}");
        let (rid, r) = f.remove(0);
        assert_eq!(rid, id);
        r
    }

    fn params(max_actions: u16) -> EpisodeParams {
        EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 1,
            rot_bins: 10,
            known_heading: None,
            ground_truth: Some(Pose2::new(0.5, 0.2, 0.3)),
            initial_scan: 0,
            termination: Termination::ActionLimit,
            config: EpisodeConfig {
                steps_per_turn: 54,
                max_actions,
                ..EpisodeConfig::DEFAULT
            },
        }
    }

    #[test]
    fn full_episode_and_sequence_rules() {
        let mut s = Session::new(CFG);
        assert_eq!(
            call(&mut s, 5, &Request::Ping { nonce: 1 }),
            Response::Error(WireError::NoSession)
        );
        assert!(matches!(
            call(
                &mut s,
                5,
                &Request::Hello {
                    protocol: PROTOCOL_VERSION
                }
            ),
            Response::Hello(_)
        ));
        assert_eq!(
            call(&mut s, 9, &Request::Ping { nonce: 1 }),
            Response::Error(WireError::OutOfSequence { expected: 6 })
        );
        assert!(matches!(
            call(
                &mut s,
                6,
                &Request::LoadPlan {
                    vertices: rect_4x3_wire(),
                    rings: heapless::Vec::new(),
                    openings: 0,
                }
            ),
            Response::PlanLoaded(_)
        ));
        // Retransmission of id 6 gets the same reply again.
        assert!(matches!(
            call(
                &mut s,
                6,
                &Request::LoadPlan {
                    vertices: rect_4x3_wire(),
                    rings: heapless::Vec::new(),
                    openings: 0,
                }
            ),
            Response::PlanLoaded(_)
        ));
        let mut id = 7;
        let mut r = call(&mut s, id, &Request::StartEpisode(params(12)));
        let mut n = 0;
        while let Response::Act { step, action } = r {
            assert_eq!(step, n);
            id += 1;
            let obs = Observation {
                range: (action == Action::Measure).then_some(1.5),
                scan: 3,
            };
            if n == 2 {
                assert_eq!(
                    call(
                        &mut s,
                        id,
                        &Request::Observe {
                            step: 9,
                            observation: obs
                        }
                    ),
                    Response::Error(WireError::StepMismatch { expected: 2 })
                );
                id += 1;
            }
            r = call(
                &mut s,
                id,
                &Request::Observe {
                    step,
                    observation: obs,
                },
            );
            n += 1;
        }
        match r {
            Response::Done(rep) => {
                assert_eq!(rep.actions, 12);
                assert_eq!(rep.measurements, 2);
                assert_eq!(rep.end, EpisodeEnd::ActionLimit);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(s.controller().measurement_count(), 2);
        // The event queue keeps the latest MAX_EVENTS: start, rejected step, end.
        let events: Vec<_> = core::iter::from_fn(|| s.take_event()).collect();
        assert!(matches!(
            events.last(),
            Some(SessionEvent::EpisodeEnded(r)) if r.actions == 12
        ));
        assert!(events.contains(&SessionEvent::EpisodeStarted {
            rot_bins: 10,
            max_actions: 12
        }));
        assert!(
            events.contains(&SessionEvent::Rejected(WireError::StepMismatch {
                expected: 2
            }))
        );
        assert_eq!(s.take_event(), None);
    }

    static TICKS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
    /// A clock that advances by 7 per reading.
    fn tick7() -> u32 {
        TICKS.fetch_add(7, core::sync::atomic::Ordering::Relaxed)
    }

    #[test]
    fn cycle_statistics_split_by_update_kind() {
        let mut ctl = Controller::new(Some(tick7), &[]);
        let plan = FloorPlan::from_raw(HVec::from_slice(&rect_4x3_wire()).unwrap()).unwrap();
        ctl.load_plan(plan);
        ctl.start(&params(40)).unwrap();
        let mut k = 0;
        let rep = loop {
            match ctl.next_step().unwrap() {
                Step::Act { step, action } => {
                    // Every other measurement gets no return.
                    let range = (action == Action::Measure).then_some(1.25);
                    let range = if range.is_some() {
                        k += 1;
                        range.filter(|_| k % 2 == 1)
                    } else {
                        None
                    };
                    ctl.observe(step, &Observation { range, scan: 0 }).unwrap();
                }
                Step::Done(rep) => break rep,
            }
        };
        let c = rep.cycles;
        assert!(rep.no_returns > 0 && rep.measurements > rep.no_returns);
        assert_eq!(c.vote.updates, (rep.measurements - rep.no_returns) as u32);
        assert_eq!(c.no_return.updates, rep.no_returns as u32);
        assert_eq!(c.rotation.updates, rep.rotations as u32);
        assert_eq!(c.updates().updates, rep.actions as u32);
        // Each update reads the clock four times (observe start, decision start and end,
        // update end): 3 × 7 ticks; the decision alone spans one reading, 7 ticks. The last
        // update decides nothing (the episode ends): 2 × 7.
        assert_eq!(c.vote.max_cycles, 21);
        assert_eq!(c.updates().total_cycles, 21 * rep.actions as u64 - 7);
        assert_eq!(c.decision.updates, rep.actions as u32);
        assert_eq!(c.decision.max_cycles, 7);
        assert_eq!(c.finish, 7);
        assert_eq!(ctl.cycles(), c.updates());
    }

    /// A session that said hello and holds the square plan (request ids 1 and 2 used).
    fn session_with_rect_4x3() -> Session {
        session_with_rect_4x3_on(CFG)
    }

    /// [`session_with_rect_4x3`] with the session configuration `cfg`.
    fn session_with_rect_4x3_on(cfg: SessionConfig) -> Session {
        let mut s = Session::new(cfg);
        call(
            &mut s,
            1,
            &Request::Hello {
                protocol: PROTOCOL_VERSION,
            },
        );
        call(
            &mut s,
            2,
            &Request::LoadPlan {
                vertices: rect_4x3_wire(),
                rings: heapless::Vec::new(),
                openings: 0,
            },
        );
        s
    }

    #[test]
    fn host_only_agents_are_refused() {
        let mut s = session_with_rect_4x3();
        // The float network and the greedy benchmarks live on the host only.
        let host_only = [
            AgentKind::Learnt,
            AgentKind::Oigm,
            AgentKind::OigmCost,
            AgentKind::Eem,
        ];
        for (seq, agent) in (3..).zip(host_only) {
            let mut p = params(5);
            p.agent = agent;
            assert_eq!(
                call(&mut s, seq, &Request::StartEpisode(p)),
                Response::Error(WireError::InvalidParams(ParamError::AgentUnavailable))
            );
        }
        // The session keeps serving: a baseline episode starts.
        let r = call(&mut s, 7, &Request::StartEpisode(params(5)));
        assert!(matches!(r, Response::Act { step: 0, .. }), "{r:?}");
    }

    /// A blob serves only episodes of its instrument profile: with the paper's sensor's blob
    /// alone on board, an EDM-only `learnt-int8` episode is refused in words (typed), and
    /// the same episode on the blob's own profile starts.
    #[test]
    fn a_blob_serves_only_its_instrument() {
        use crate::episode::InstrumentProfile;
        static ONLY_SCAN: [&[u8]; 1] = [crate::policy::builtin::K10];
        let mut s = session_with_rect_4x3_on(SessionConfig {
            policies: &ONLY_SCAN,
            ..CFG
        });
        let mut p = params(5);
        p.agent = AgentKind::LearntInt8;
        p.config.instrument = InstrumentProfile::Edm;
        assert_eq!(
            call(&mut s, 3, &Request::StartEpisode(p)),
            Response::Error(WireError::InvalidParams(ParamError::AgentUnavailable))
        );
        p.config.instrument = InstrumentProfile::EdmScan;
        assert!(matches!(
            call(&mut s, 4, &Request::StartEpisode(p)),
            Response::Act { step: 0, .. }
        ));
    }

    #[test]
    fn plans_with_columns_and_doors_load_and_bad_ones_are_refused() {
        use crate::world::geometry::v2;
        let mut s = Session::new(CFG);
        call(
            &mut s,
            1,
            &Request::Hello {
                protocol: PROTOCOL_VERSION,
            },
        );
        // A 4 × 3 m room about the origin, a 0.4 m column, a door in the bottom wall.
        let plan = FloorPlan::with_columns_and_doors(
            &[v2(-2.0, -1.5), v2(2.0, -1.5), v2(2.0, 1.5), v2(-2.0, 1.5)],
            &[&[v2(0.8, 0.3), v2(1.2, 0.3), v2(1.2, 0.7), v2(0.8, 0.7)]],
            &[(v2(-1.5, -1.5), v2(-0.7, -1.5))],
            0.02,
        )
        .unwrap()
        .centered();
        let load = |vertices: &[[f32; 2]], rings: &[u8], openings: u64| Request::LoadPlan {
            vertices: HVec::from_slice(vertices).unwrap(),
            rings: HVec::from_slice(rings).unwrap(),
            openings,
        };
        match call(
            &mut s,
            2,
            &load(plan.raw(), plan.ring_ends(), plan.openings()),
        ) {
            Response::PlanLoaded(summary) => assert_eq!(summary.vertices, 10),
            other => panic!("{other:?}"),
        }
        // An opening on the column's wall, then a column ring of two vertices.
        assert_eq!(
            call(
                &mut s,
                3,
                &load(plan.raw(), plan.ring_ends(), plan.openings() | 1 << 8)
            ),
            Response::Error(WireError::InvalidPlan(PlanError::OpeningNotOnOutline(8)))
        );
        assert_eq!(
            call(&mut s, 4, &load(plan.raw(), &[6, 8, 10], plan.openings())),
            Response::Error(WireError::InvalidPlan(PlanError::RingTooSmall(1)))
        );
        assert_eq!(
            call(
                &mut s,
                5,
                &load(plan.raw(), &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10], 0)
            ),
            Response::Error(WireError::InvalidPlan(PlanError::TooManyRings))
        );
        // The session keeps serving, on the plan it loaded.
        assert_eq!(
            call(&mut s, 6, &Request::Ping { nonce: 7 }),
            Response::Pong { nonce: 7 }
        );
        let r = call(&mut s, 7, &Request::StartEpisode(params(5)));
        assert!(matches!(r, Response::Act { step: 0, .. }), "{r:?}");
    }

    #[test]
    fn bad_inputs_get_typed_errors() {
        let mut s = Session::new(CFG);
        call(
            &mut s,
            1,
            &Request::Hello {
                protocol: PROTOCOL_VERSION,
            },
        );
        let bow: HVec<_, MAX_WIRE_VERTICES> =
            HVec::from_slice(&[[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]]).unwrap();
        assert!(matches!(
            call(
                &mut s,
                2,
                &Request::LoadPlan {
                    vertices: bow,
                    rings: heapless::Vec::new(),
                    openings: 0
                }
            ),
            Response::Error(WireError::InvalidPlan(PlanError::SelfIntersection(..)))
        ));
        let mut many = HVec::<_, MAX_WIRE_VERTICES>::new();
        for i in 0..100 {
            let a = i as f32 * 0.0628;
            many.push([libm::cosf(a) * 5.0, libm::sinf(a) * 5.0])
                .unwrap();
        }
        assert_eq!(
            call(
                &mut s,
                3,
                &Request::LoadPlan {
                    vertices: many,
                    rings: heapless::Vec::new(),
                    openings: 0
                }
            ),
            Response::Error(WireError::InvalidPlan(PlanError::TooManyVertices))
        );
        assert_eq!(
            call(&mut s, 4, &Request::StartEpisode(params(5))),
            Response::Error(WireError::NoPlan)
        );
        call(
            &mut s,
            5,
            &Request::LoadPlan {
                vertices: rect_4x3_wire(),
                rings: heapless::Vec::new(),
                openings: 0,
            },
        );
        let mut p = params(5);
        p.rot_bins = 1;
        assert_eq!(
            call(&mut s, 6, &Request::StartEpisode(p)),
            Response::Error(WireError::InvalidParams(ParamError::KnownHeadingRequired))
        );
        p = params(5);
        p.ground_truth = Some(Pose2::new(9.0, 0.0, 0.0));
        assert_eq!(
            call(&mut s, 7, &Request::StartEpisode(p)),
            Response::Error(WireError::InvalidParams(ParamError::GroundTruthOutside))
        );
        let r = call(&mut s, 8, &Request::StartEpisode(params(5)));
        assert_eq!(
            r,
            Response::Act {
                step: 0,
                action: Action::Measure
            }
        );
        for (i, bad) in [f32::NAN, f32::INFINITY, -1.0].into_iter().enumerate() {
            let r = call(
                &mut s,
                9 + i as u16,
                &Request::Observe {
                    step: 0,
                    observation: Observation {
                        range: Some(bad),
                        scan: 0,
                    },
                },
            );
            assert!(
                matches!(r, Response::Error(WireError::InvalidObservation(_))),
                "{r:?}"
            );
        }
        // Still waiting at step 0; a good observation proceeds.
        let r = call(
            &mut s,
            12,
            &Request::Observe {
                step: 0,
                observation: Observation {
                    range: Some(2.0),
                    scan: 0,
                },
            },
        );
        assert_eq!(
            r,
            Response::Act {
                step: 1,
                action: Action::RotateLeft
            }
        );
    }

    #[test]
    fn stop_rule_params_are_validated_and_carried() {
        let mut s = session_with_rect_4x3();
        let mut id = 3;
        for risk in [f32::NAN, 0.0, 1.5, -0.5, f32::INFINITY] {
            let mut p = params(5);
            p.termination = Termination::Confident;
            p.config.stop_risk = risk;
            assert_eq!(
                call(&mut s, id, &Request::StartEpisode(p)),
                Response::Error(WireError::InvalidParams(ParamError::InvalidStopRisk)),
                "stop_risk {risk}"
            );
            id += 1;
        }
        for tau in [-1.0, f32::NAN, 1.5, f32::NEG_INFINITY] {
            let mut p = params(5);
            p.config.min_observability = tau;
            assert_eq!(
                call(&mut s, id, &Request::StartEpisode(p)),
                Response::Error(WireError::InvalidParams(ParamError::InvalidObservability)),
                "min_observability {tau}"
            );
            id += 1;
        }
        assert_eq!(s.phase(), Phase::Ready);
        assert!(!s.controller().is_running());
        // The device keeps serving: a valid Start runs, with the host's stop rule.
        let mut p = params(5);
        p.termination = Termination::Confident;
        p.config.stop_risk = 0.05;
        p.config.min_observability = 0.2;
        assert!(matches!(
            call(&mut s, id, &Request::StartEpisode(p)),
            Response::Act { step: 0, .. }
        ));
        let config = s.controller().runner.state().config;
        assert_eq!(config.stop_risk, 0.05);
        assert_eq!(config.min_observability, 0.2);
        // The edges of the valid ranges are accepted.
        p.config.stop_risk = 1.0;
        p.config.min_observability = 1.0;
        assert!(s.controller().check_params(&p).is_ok());
        p.config.min_observability = 0.0;
        assert!(s.controller().check_params(&p).is_ok());
    }

    #[test]
    fn garbage_and_timeouts_recover() {
        let mut s = Session::new(CFG);
        let mut sink = Sink(Vec::new());
        s.feed(&[1, 2, 3, 0], 0, &mut sink).unwrap();
        s.feed(&[0x55; MAX_FRAME + 3], 0, &mut sink).unwrap();
        s.feed(&[0], 0, &mut sink).unwrap();
        let f = frames(&sink.0);
        assert_eq!(f.len(), 2);
        assert!(f.iter().all(|(id, _)| *id == NO_ID));
        assert!(matches!(f[1].1, Response::Error(WireError::Oversized)));
        call(
            &mut s,
            1,
            &Request::Hello {
                protocol: PROTOCOL_VERSION,
            },
        );
        call(
            &mut s,
            2,
            &Request::LoadPlan {
                vertices: rect_4x3_wire(),
                rings: heapless::Vec::new(),
                openings: 0,
            },
        );
        call(&mut s, 3, &Request::StartEpisode(params(50)));
        assert_eq!(s.phase(), Phase::Episode);
        assert!(!s.poll(500));
        assert!(s.poll(5000));
        assert_eq!(s.phase(), Phase::Closed);
        assert_eq!(s.stats().timeouts, 1);
        // The next host starts over.
        assert!(matches!(
            call(
                &mut s,
                40,
                &Request::Hello {
                    protocol: PROTOCOL_VERSION
                }
            ),
            Response::Hello(_)
        ));
        assert!(matches!(
            call(&mut s, 41, &Request::StartEpisode(params(3))),
            Response::Act { .. }
        ));
        assert_eq!(
            call(&mut s, 42, &Request::Hello { protocol: 99 }),
            Response::Error(WireError::VersionMismatch {
                device: PROTOCOL_VERSION
            })
        );
    }

    /// A refusal is cached like any reply (protocol v6): the host that lost it on a noisy
    /// line re-sends the same id and gets the same error, not `OutOfSequence`, and nothing
    /// is done twice; an out-of-sequence id still gets no cached reply.
    #[test]
    fn refusals_are_retransmitted() {
        let mut s = session_with_rect_4x3();
        let mut p = params(5);
        p.rot_bins = 1;
        p.known_heading = None;
        let refused = Response::Error(WireError::InvalidParams(ParamError::KnownHeadingRequired));
        assert_eq!(call(&mut s, 3, &Request::StartEpisode(p)), refused);
        assert_eq!(call(&mut s, 3, &Request::StartEpisode(p)), refused);
        assert_eq!(s.stats().retransmissions, 1);
        // The next request proceeds in sequence; a repeat of it replays its reply only.
        let act = call(&mut s, 4, &Request::StartEpisode(params(5)));
        assert!(matches!(act, Response::Act { step: 0, .. }), "{act:?}");
        assert_eq!(call(&mut s, 4, &Request::StartEpisode(params(5))), act);
        assert_eq!(s.controller().episode_actions(), 0);
        assert_eq!(
            call(&mut s, 9, &Request::Status),
            Response::Error(WireError::OutOfSequence { expected: 5 })
        );
        assert!(matches!(
            call(&mut s, 5, &Request::Status),
            Response::Status(_)
        ));
        assert_eq!(s.phase(), Phase::Episode);
    }

    #[test]
    fn largest_replies_fit() {
        let s = Session::new(CFG);
        let max_stats = UpdateStats {
            updates: u32::MAX,
            total_cycles: u64::MAX,
            max_cycles: u32::MAX,
        };
        let rep = EpisodeReport {
            end: EpisodeEnd::Aborted,
            actions: u16::MAX,
            measurements: u16::MAX,
            rotations: u16::MAX,
            no_returns: u16::MAX,
            cost: f32::MAX,
            bearing_index: u16::MAX,
            trace_hash: u32::MAX,
            coarse: Some(Pose2::new(1.0, 2.0, 3.0)),
            refined: Some(Pose2::new(1.0, 2.0, 3.0)),
            recognised: Some(true),
            stop_risk: Some(f32::MAX),
            answer_readings: u16::MAX,
            cycles: EpisodeCycles {
                vote: max_stats,
                rotation: max_stats,
                no_return: max_stats,
                finish: u32::MAX,
                decision: max_stats,
            },
        };
        let mut info = s.device_info();
        info.firmware.clear();
        info.firmware.push_str("012345678901234567890123").unwrap();
        info.capabilities = u32::MAX;
        let st = DeviceStatus {
            phase: Phase::Episode,
            plan_vertices: 255,
            episode_actions: u16::MAX,
            link: LinkStats {
                frames_ok: u32::MAX,
                frames_bad: u32::MAX,
                sequence_errors: u32::MAX,
                retransmissions: u32::MAX,
                timeouts: u32::MAX,
                episodes: u32::MAX,
            },
            cycles: max_stats,
            stack: StackUsage {
                high_water: u32::MAX,
                size: u32::MAX,
            },
        };
        for r in [
            Response::Done(rep),
            Response::Hello(info),
            Response::Status(st),
        ] {
            let mut buf = [0u8; MAX_REPLY];
            assert!(encode_frame(u16::MAX, &r, &mut buf).is_ok(), "{r:?}");
        }
    }
}
