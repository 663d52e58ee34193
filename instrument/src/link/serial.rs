//! Host side of the instrument serial protocol (`docs/protocol.md`): a [`Client`] that
//! speaks [`activesense_core::protocol`] over any `std::io::Read + Write`, and the transports
//! (`loopback`, `tcp:HOST:PORT`, `serial:PATH[@BAUD]`, `qemu[:ELF]`) it runs over.
//!
//! The device decides; the host only answers its action requests. [`Client::run_episode`]
//! drives one episode: it sends `StartEpisode`, then for every `Act { step, action }` asks
//! its [`Instrument`] (the simulated world, see [`crate::link::device::SimInstrument`]) for the
//! observation and sends it back, until `Done`.
//!
//! Timeouts come from the transport's read timeout; a silent device is a
//! [`LinkError::Timeout`], a closed link [`LinkError::Disconnected`], a device-side
//! rejection [`LinkError::Device`] carrying the typed [`WireError`].

use crate::link::device::{spawn_loopback, Pipe, Qemu};
use crate::link::error::{LinkError, LinkResult};
use activesense_core::device::instrument::Instrument;
use activesense_core::episode::Action;
use activesense_core::episode::{Observation, SCAN_PIXELS};
use activesense_core::protocol::*;
use activesense_core::{FloorPlan, MAX_VERTICES};
use heapless::Vec as HVec;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// One episode as seen by the host: every (action, observation) and the device's report.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeRun {
    /// The exchanged steps in order.
    pub steps: Vec<(Action, Observation)>,
    /// The device's final report.
    pub report: EpisodeReport,
}

impl EpisodeRun {
    /// The host-side [`TraceHash`] of `steps` (must equal `report.trace_hash`).
    pub fn trace_hash(&self) -> u32 {
        let mut h = TraceHash::new();
        for (a, o) in &self.steps {
            h.push(*a, o);
        }
        h.value()
    }
}

/// What the client did to get its requests through a noisy or slow line (since it was
/// created). A clean line leaves every counter at 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkCounters {
    /// Requests re-sent with the same id (the device answers a repeat with its cached
    /// reply, so nothing is done twice).
    pub resent: u32,
    /// Frames from the device that arrived corrupt (COBS, CRC, oversized) and were dropped.
    pub corrupt_replies: u32,
    /// `NO_ID` errors from the device: it received a corrupt frame (ours, or line noise).
    pub device_frame_errors: u32,
    /// Waits for a reply that ran past the reply time-out.
    pub timeouts: u32,
}

impl LinkCounters {
    /// One line for a run summary.
    pub fn summary(&self) -> String {
        format!(
            "{} frames retried ({} corrupt replies dropped, {} corrupt frames reported by the \
             device, {} reply time-outs)",
            self.resent, self.corrupt_replies, self.device_frame_errors, self.timeouts
        )
    }
}

/// How long the transport's read blocks at most: the client's clock for back-off and reply
/// time-outs ([`Client::set_reply_timeout`]) runs in steps of this.
pub const POLL: Duration = Duration::from_millis(20);
/// Reply time-out until the device has said how slow it can be (its `Hello`).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(3);
/// Most times one request is sent (the first included) before the call gives up.
pub const MAX_SENDS: u32 = 10;
/// Most reply time-outs one call sits through before it gives up.
pub const MAX_TIMEOUTS: u32 = 3;
/// First back-off before a re-send after a corrupt frame; doubles per re-send.
pub const BACKOFF: Duration = Duration::from_millis(5);
/// Longest back-off.
pub const MAX_BACKOFF: Duration = Duration::from_millis(500);

/// Protocol client over a byte stream.
///
/// **Resynchronisation.** Every frame starts after a `0x00`, so a receiver that sees
/// garbage is back in step at the next delimiter. When the device reports a corrupt frame
/// (`NO_ID` error), a reply arrives corrupt, or no reply comes within the reply time-out,
/// the client re-sends the pending request with the *same* id after a back-off (5 ms,
/// doubling, at most 500 ms; at most [`MAX_SENDS`] sends and [`MAX_TIMEOUTS`] time-outs).
/// The device answers a repeated id with its cached reply, so an episode resumes where it
/// was; [`LinkCounters`] counts what it took.
pub struct Client<T: Read + Write> {
    io: T,
    acc: FrameAccumulator,
    last_id: u16,
    counters: LinkCounters,
    reply_timeout: Duration,
    follow_device: bool,
    rx: [u8; 256],
    rx_pos: usize,
    rx_len: usize,
}

impl<T: Read + Write> Client<T> {
    /// Wraps a transport. Nothing is sent until the first call. The reply time-out is
    /// [`HANDSHAKE_TIMEOUT`] until the device's `Hello` announces its worst case.
    pub fn new(io: T) -> Self {
        Client {
            io,
            acc: FrameAccumulator::new(),
            last_id: NO_ID,
            counters: LinkCounters::default(),
            reply_timeout: HANDSHAKE_TIMEOUT,
            follow_device: true,
            rx: [0; 256],
            rx_pos: 0,
            rx_len: 0,
        }
    }

    /// The transport.
    pub fn get_mut(&mut self) -> &mut T {
        &mut self.io
    }

    /// Re-sends, corrupt frames and time-outs so far.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// The current reply time-out.
    pub fn reply_timeout(&self) -> Duration {
        self.reply_timeout
    }

    /// Sets the reply time-out. With `follow_device`, it is a floor: the next `Hello`
    /// raises it to what the device announces (its `max_reply_ms`, plus half again and
    /// 0.5 s for the line); without, it stays as given (the user's `--timeout-ms`).
    pub fn set_reply_timeout(&mut self, timeout: Duration, follow_device: bool) {
        self.reply_timeout = timeout;
        self.follow_device = follow_device;
    }

    /// Sends raw bytes (fault injection).
    pub fn send_raw(&mut self, bytes: &[u8]) -> LinkResult<()> {
        self.io.write_all(bytes)?;
        self.io.flush()?;
        Ok(())
    }

    /// Receives the next complete frame from the device, waiting at most the reply
    /// time-out. A corrupt frame is [`LinkError::BadFrame`] (the accumulator is already
    /// back in step for the next one).
    pub fn recv_frame(&mut self) -> LinkResult<(u16, Response)> {
        self.recv_until(Instant::now() + self.reply_timeout)
    }

    /// As [`Client::recv_frame`], until `deadline` ([`LinkError::Timeout`] after it; the
    /// transport's own read time-out is only the polling step).
    fn recv_until(&mut self, deadline: Instant) -> LinkResult<(u16, Response)> {
        loop {
            if self.rx_pos == self.rx_len {
                if Instant::now() >= deadline {
                    return Err(LinkError::Timeout);
                }
                let n = match self.io.read(&mut self.rx) {
                    Ok(n) => n,
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::TimedOut
                                | std::io::ErrorKind::WouldBlock
                                | std::io::ErrorKind::Interrupted
                        ) =>
                    {
                        continue
                    }
                    Err(e) => return Err(e.into()),
                };
                if n == 0 {
                    return Err(LinkError::Disconnected);
                }
                self.rx_pos = 0;
                self.rx_len = n;
            }
            let b = self.rx[self.rx_pos];
            self.rx_pos += 1;
            match self.acc.push(b) {
                Feed::Frame(f) => return decode_frame::<Response>(f).map_err(LinkError::BadFrame),
                Feed::Oversized => return Err(LinkError::BadFrame(FrameError::TooLarge)),
                Feed::Pending | Feed::Empty => {}
            }
        }
    }

    /// Encodes and sends `req` with id `id` (preceded by a resynchronising `0x00`).
    pub fn send_request(&mut self, id: u16, req: &Request) -> LinkResult<()> {
        let mut buf = [0u8; MAX_FRAME + 1];
        let n = encode_frame(id, req, &mut buf[1..])
            .map_err(|e| LinkError::Local(format!("cannot encode request: {e:?}")))?;
        self.send_raw(&buf[..n + 1])
    }

    fn next_id(&mut self) -> u16 {
        self.last_id = match self.last_id.wrapping_add(1) {
            NO_ID => 1,
            n => n,
        };
        self.last_id
    }

    /// Sends `req` and returns the matching reply (device errors as `Err`), re-sending it
    /// as the type's docs say when the line corrupts or loses frames.
    pub fn call(&mut self, req: &Request) -> LinkResult<Response> {
        let id = self.next_id();
        self.call_with_id(id, req)
    }

    fn call_with_id(&mut self, id: u16, req: &Request) -> LinkResult<Response> {
        self.send_request(id, req)?;
        let mut sends = 1u32;
        let mut timeouts = 0u32;
        let mut deadline = Instant::now() + self.reply_timeout;
        // A re-send waits for its back-off: the reply may still be on its way (the
        // corrupt frame was line noise, not our request).
        let mut resend_at: Option<Instant> = None;
        let mut last_error = LinkError::Timeout;
        loop {
            let wake = resend_at.map_or(deadline, |r| r.min(deadline));
            let event = self.recv_until(wake);
            let corrupt = match event {
                Ok((rid, resp)) if rid == id => {
                    return match resp {
                        Response::Error(e) => Err(LinkError::Device(e)),
                        r => Ok(r),
                    }
                }
                Ok((NO_ID, Response::Error(e))) => {
                    self.counters.device_frame_errors += 1;
                    last_error = LinkError::Device(e);
                    true
                }
                // A stale reply to an earlier id (a repeat answered twice), or the
                // unsolicited boot announcement: skip.
                Ok(_) => false,
                Err(LinkError::BadFrame(e)) => {
                    self.counters.corrupt_replies += 1;
                    last_error = LinkError::BadFrame(e);
                    true
                }
                Err(LinkError::Timeout) => {
                    let now = Instant::now();
                    if now >= deadline {
                        self.counters.timeouts += 1;
                        timeouts += 1;
                        if timeouts >= MAX_TIMEOUTS {
                            return Err(LinkError::Timeout);
                        }
                        last_error = LinkError::Timeout;
                        resend_at = Some(now);
                    }
                    false
                }
                Err(e) => return Err(e),
            };
            if corrupt && resend_at.is_none() {
                let backoff = BACKOFF
                    .saturating_mul(1 << (sends - 1).min(10))
                    .min(MAX_BACKOFF);
                resend_at = Some(Instant::now() + backoff);
            }
            if resend_at.is_some_and(|r| Instant::now() >= r) {
                if sends >= MAX_SENDS {
                    return Err(LinkError::GaveUp {
                        sends,
                        last: Box::new(last_error),
                    });
                }
                sends += 1;
                self.counters.resent += 1;
                resend_at = None;
                deadline = Instant::now() + self.reply_timeout;
                self.send_request(id, req)?;
            }
        }
    }

    /// Opens a session (flushing any partial frame on the device first) and checks that
    /// the device is compatible.
    pub fn hello(&mut self) -> LinkResult<DeviceInfo> {
        self.send_raw(&[0])?;
        let id = if self.last_id == NO_ID {
            1
        } else {
            self.next_id()
        };
        self.last_id = id;
        let r = self.call_with_id(
            id,
            &Request::Hello {
                protocol: PROTOCOL_VERSION,
            },
        );
        let info = match r {
            Ok(Response::Hello(info)) => info,
            Ok(other) => return Err(LinkError::Unexpected(format!("{other:?}"))),
            Err(LinkError::Device(WireError::VersionMismatch { device })) => {
                return Err(LinkError::Incompatible(format!(
                    "device speaks protocol v{device}, this host v{PROTOCOL_VERSION}"
                )))
            }
            Err(e) => return Err(e),
        };
        check_compatible(&info)?;
        if self.follow_device {
            let device = Duration::from_millis(info.max_reply_ms as u64);
            self.reply_timeout = self
                .reply_timeout
                .max(device + device / 2 + Duration::from_millis(500));
        }
        Ok(info)
    }

    /// Loads a plan, its columns and doors included (checked locally for size first).
    pub fn load_plan(&mut self, plan: &FloorPlan) -> LinkResult<PlanSummary> {
        self.load_plan_parts(plan.raw(), plan.ring_ends(), plan.openings())
    }

    /// Loads raw vertices of one ring without openings (the device validates them).
    pub fn load_raw_plan(&mut self, vertices: &[[f32; 2]]) -> LinkResult<PlanSummary> {
        self.load_plan_parts(vertices, &[], 0)
    }

    /// Loads the wire form of a plan: every ring's vertices, the ring ends and the
    /// openings mask (the device validates them).
    pub fn load_plan_parts(
        &mut self,
        vertices: &[[f32; 2]],
        rings: &[u8],
        openings: u64,
    ) -> LinkResult<PlanSummary> {
        let rings: HVec<u8, MAX_WIRE_RINGS> = HVec::from_slice(rings).map_err(|_| {
            LinkError::Local(format!(
                "plan has {} rings; the protocol carries at most {MAX_WIRE_RINGS}",
                rings.len()
            ))
        })?;
        let vertices: HVec<[f32; 2], MAX_WIRE_VERTICES> =
            HVec::from_slice(vertices).map_err(|_| {
                LinkError::Local(format!(
                    "plan has {} vertices; the protocol carries at most {MAX_WIRE_VERTICES} \
                     and the device accepts at most {MAX_VERTICES}",
                    vertices.len()
                ))
            })?;
        match self.call(&Request::LoadPlan {
            vertices,
            rings,
            openings,
        })? {
            Response::PlanLoaded(s) => Ok(s),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Runs one episode: the device decides, `instrument` answers.
    pub fn run_episode<I: Instrument>(
        &mut self,
        params: &EpisodeParams,
        instrument: &mut I,
    ) -> LinkResult<EpisodeRun>
    where
        I::Error: std::fmt::Debug,
    {
        let mut steps = Vec::new();
        let mut resp = self.call(&Request::StartEpisode(*params))?;
        loop {
            match resp {
                Response::Act { step, action } => {
                    if step as usize != steps.len() {
                        return Err(LinkError::Unexpected(format!(
                            "action request for step {step}, expected {}",
                            steps.len()
                        )));
                    }
                    let observation = instrument
                        .perform(action)
                        .map_err(|e| LinkError::Local(format!("instrument failed: {e:?}")))?;
                    steps.push((action, observation));
                    resp = self.call(&Request::Observe { step, observation })?;
                }
                Response::Done(report) => return Ok(EpisodeRun { steps, report }),
                other => return Err(LinkError::Unexpected(format!("{other:?}"))),
            }
        }
    }

    /// `Ping` round trip.
    pub fn ping(&mut self, nonce: u32) -> LinkResult<()> {
        match self.call(&Request::Ping { nonce })? {
            Response::Pong { nonce: n } if n == nonce => Ok(()),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Device status.
    pub fn status(&mut self) -> LinkResult<DeviceStatus> {
        match self.call(&Request::Status)? {
            Response::Status(s) => Ok(s),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Aborts the running episode (returns its report, if one was running).
    pub fn abort(&mut self) -> LinkResult<Option<EpisodeReport>> {
        match self.call(&Request::Abort)? {
            Response::Aborted(r) => Ok(Some(r)),
            Response::Ack => Ok(None),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Resets the device (a new `hello` is needed afterwards).
    pub fn reset(&mut self) -> LinkResult<()> {
        match self.call(&Request::Reset)? {
            Response::Ack => Ok(()),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Which policy serves `rot_bins` on the device.
    pub fn policy_info(&mut self, rot_bins: u8) -> LinkResult<PolicyInfo> {
        match self.call(&Request::PolicyInfo { rot_bins })? {
            Response::PolicyInfo(i) => Ok(i),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Uploads an int8 policy blob in [`POLICY_CHUNK`]-byte chunks and commits it; the
    /// device checks length, CRC-32, structure and K before it serves the blob. `progress`
    /// is told the bytes sent so far.
    pub fn upload_policy(
        &mut self,
        rot_bins: u8,
        blob: &[u8],
        mut progress: impl FnMut(usize),
    ) -> LinkResult<PolicyInfo> {
        let len = u32::try_from(blob.len())
            .map_err(|_| LinkError::Local("policy blob larger than 4 GiB".into()))?;
        self.expect_ack(&Request::PolicyBegin {
            rot_bins,
            len,
            crc: activesense_core::protocol::crc32(&blob[..blob.len().saturating_sub(4)]),
        })?;
        for (i, chunk) in blob.chunks(POLICY_CHUNK).enumerate() {
            let data = heapless::Vec::from_slice(chunk)
                .map_err(|_| LinkError::Local("chunk larger than POLICY_CHUNK".into()))?;
            self.expect_ack(&Request::PolicyChunk {
                offset: (i * POLICY_CHUNK) as u32,
                data,
            })?;
            progress(i * POLICY_CHUNK + chunk.len());
        }
        match self.call(&Request::PolicyCommit)? {
            Response::PolicyInfo(i) => Ok(i),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    fn expect_ack(&mut self, req: &Request) -> LinkResult<()> {
        match self.call(req)? {
            Response::Ack => Ok(()),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Stops the device.
    pub fn shutdown(&mut self) -> LinkResult<()> {
        match self.call(&Request::Shutdown)? {
            Response::Ack => Ok(()),
            other => Err(LinkError::Unexpected(format!("{other:?}"))),
        }
    }
}

/// Checks a device's `Hello` against what this host was built with.
pub fn check_compatible(info: &DeviceInfo) -> LinkResult<()> {
    let mut problems = Vec::new();
    if info.protocol != PROTOCOL_VERSION {
        problems.push(format!(
            "protocol v{} (host v{PROTOCOL_VERSION})",
            info.protocol
        ));
    }
    if info.scan_pixels as usize != SCAN_PIXELS {
        problems.push(format!(
            "{} scan pixels (host {SCAN_PIXELS})",
            info.scan_pixels
        ));
    }
    if (info.max_vertices as usize) < MAX_VERTICES {
        problems.push(format!(
            "accepts only {} vertices (host plans up to {MAX_VERTICES})",
            info.max_vertices
        ));
    }
    if (info.max_frame as usize) < MAX_FRAME {
        problems.push(format!(
            "max frame {} bytes (host {MAX_FRAME})",
            info.max_frame
        ));
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(LinkError::Incompatible(problems.join("; ")))
    }
}

/// A transport specification as given on the command line.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkSpec {
    /// The device session in a thread, over an in-memory pipe.
    Loopback,
    /// A TCP socket (`tcp:HOST:PORT`).
    Tcp(String),
    /// A serial port (`serial:PATH` or `serial:PATH@BAUD`).
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
    /// The firmware in `qemu-system-arm` (`qemu` or `qemu:ELF`).
    Qemu(PathBuf),
}

/// The firmware ELF `qemu` uses unless told otherwise.
pub const DEFAULT_ELF: &str = "target/thumbv7em-none-eabihf/firmware/activesense-firmware";
/// Default serial baud rate.
pub const DEFAULT_BAUD: u32 = 115_200;

impl std::str::FromStr for LinkSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "loopback" {
            return Ok(LinkSpec::Loopback);
        }
        if s == "qemu" {
            return Ok(LinkSpec::Qemu(PathBuf::from(DEFAULT_ELF)));
        }
        if let Some(elf) = s.strip_prefix("qemu:") {
            return Ok(LinkSpec::Qemu(PathBuf::from(elf)));
        }
        if let Some(addr) = s.strip_prefix("tcp:") {
            if !addr.contains(':') {
                return Err(format!("'{s}': expected tcp:HOST:PORT"));
            }
            return Ok(LinkSpec::Tcp(addr.to_string()));
        }
        if let Some(rest) = s.strip_prefix("serial:") {
            let (path, baud) = match rest.rsplit_once('@') {
                Some((p, b)) => (
                    p,
                    b.parse().map_err(|_| format!("'{b}' is not a baud rate"))?,
                ),
                None => (rest, DEFAULT_BAUD),
            };
            return Ok(LinkSpec::Serial {
                path: path.to_string(),
                baud,
            });
        }
        Err(format!(
            "unknown link '{s}' (expected loopback, qemu[:ELF], tcp:HOST:PORT or serial:PATH[@BAUD])"
        ))
    }
}

/// Any byte stream the client can run over.
pub trait Stream: Read + Write + Send {}
impl<T: Read + Write + Send> Stream for T {}

impl std::fmt::Display for LinkSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkSpec::Loopback => f.write_str("loopback"),
            LinkSpec::Tcp(a) => write!(f, "tcp:{a}"),
            LinkSpec::Serial { path, baud } => write!(f, "serial:{path}@{baud}"),
            LinkSpec::Qemu(elf) => write!(f, "qemu:{}", elf.display()),
        }
    }
}

/// An open link: the client plus whatever must be kept alive/stopped with it.
///
/// **Who powers the device off.** Only [`Link::shutdown`] sends `Shutdown`. [`Link::close`]
/// ends the session and leaves a device the user runs (serial port, TCP) serving, so a
/// policy uploaded into its RAM is still there for the next command; a device this process
/// started itself (the `loopback` thread, the `qemu` emulator) ends with it: the thread
/// sees its pipe close, the emulator is killed (a host-side process kill, not a protocol
/// message).
pub struct Link {
    /// The protocol client.
    pub client: Client<Box<dyn Stream>>,
    /// The emulator, for `qemu` links.
    pub qemu: Option<Qemu>,
    /// The device thread, for `loopback` links.
    pub device_thread: Option<std::thread::JoinHandle<()>>,
}

/// Opens the transport named by `spec`; `timeout` is the reply time-out until the device's
/// `Hello` announces a longer worst case ([`Client::set_reply_timeout`]).
pub fn open(spec: &LinkSpec, timeout: Duration) -> LinkResult<Link> {
    open_with_qemu_args(spec, timeout, &[])
}

/// As [`open`]; a `qemu` link gets `qemu_args` appended to the emulator's command line
/// (ignored by the other transports).
pub fn open_with_qemu_args(
    spec: &LinkSpec,
    timeout: Duration,
    qemu_args: &[String],
) -> LinkResult<Link> {
    let mut link = match spec {
        LinkSpec::Loopback => {
            let (host, device) = Pipe::pair(POLL);
            let handle = spawn_loopback(device);
            Link {
                client: Client::new(Box::new(host)),
                qemu: None,
                device_thread: Some(handle),
            }
        }
        LinkSpec::Tcp(addr) => {
            let s = std::net::TcpStream::connect(addr)
                .map_err(|e| LinkError::Local(format!("cannot connect to {addr}: {e}")))?;
            s.set_read_timeout(Some(POLL))?;
            s.set_nodelay(true)?;
            Link {
                client: Client::new(Box::new(s)),
                qemu: None,
                device_thread: None,
            }
        }
        LinkSpec::Serial { path, baud } => {
            let port = serialport::new(path, *baud)
                .timeout(POLL)
                .open()
                .map_err(|e| LinkError::Local(format!("cannot open serial port {path}: {e}")))?;
            Link {
                client: Client::new(Box::new(port)),
                qemu: None,
                device_thread: None,
            }
        }
        LinkSpec::Qemu(elf) => {
            let (qemu, stream) = Qemu::start_with_args(elf, POLL, qemu_args)?;
            Link {
                client: Client::new(Box::new(stream)),
                qemu: Some(qemu),
                device_thread: None,
            }
        }
    };
    link.client.set_reply_timeout(timeout, true);
    Ok(link)
}

impl Link {
    /// Ends the session; the device keeps serving unless this process started it (see
    /// the type's docs). Returns the emulator's semihosting output for `qemu` links.
    pub fn close(self) -> LinkResult<String> {
        self.close_with_stderr().map(|(out, _)| out)
    }

    /// As [`Link::close`], also returning the emulator's raw stderr (the firmware's defmt
    /// frames, see `cargo xtask qemu-log`); empty for other links.
    pub fn close_with_stderr(self) -> LinkResult<(String, Vec<u8>)> {
        self.finish(false)
    }

    /// Sends `Shutdown` (the device powers off: the firmware exits) and waits for the
    /// device side (thread / emulator) to stop. Returns the emulator's semihosting output
    /// for `qemu` links.
    pub fn shutdown(self) -> LinkResult<String> {
        self.shutdown_with_stderr().map(|(out, _)| out)
    }

    /// As [`Link::shutdown`], also returning the emulator's raw stderr.
    pub fn shutdown_with_stderr(self) -> LinkResult<(String, Vec<u8>)> {
        self.finish(true)
    }

    fn finish(mut self, shutdown: bool) -> LinkResult<(String, Vec<u8>)> {
        let raw = self.qemu.as_ref().map(|q| q.stderr_handle());
        let r = if shutdown {
            self.client.shutdown()
        } else {
            Ok(())
        };
        let out = if let Some(h) = self.device_thread.take() {
            drop(self.client);
            let _ = h.join();
            String::new()
        } else {
            match self.qemu.take() {
                Some(q) if r.is_ok() && shutdown => q.wait(Duration::from_secs(10))?,
                Some(q) => q.kill(),
                None => String::new(),
            }
        };
        let raw = raw
            .and_then(|r| r.lock().ok().map(|v| v.clone()))
            .unwrap_or_default();
        r.map(|_| (out, raw))
    }
}
