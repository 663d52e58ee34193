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
use std::time::Duration;

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

/// Protocol client over a byte stream.
pub struct Client<T: Read + Write> {
    io: T,
    acc: FrameAccumulator,
    last_id: u16,
    /// Re-sends of a request after a `NO_ID` error (the device saw a corrupt frame).
    pub retries: u32,
    rx: [u8; 256],
    rx_pos: usize,
    rx_len: usize,
}

impl<T: Read + Write> Client<T> {
    /// Wraps a transport. Nothing is sent until the first call.
    pub fn new(io: T) -> Self {
        Client {
            io,
            acc: FrameAccumulator::new(),
            last_id: NO_ID,
            retries: 0,
            rx: [0; 256],
            rx_pos: 0,
            rx_len: 0,
        }
    }

    /// The transport.
    pub fn get_mut(&mut self) -> &mut T {
        &mut self.io
    }

    /// Sends raw bytes (fault injection).
    pub fn send_raw(&mut self, bytes: &[u8]) -> LinkResult<()> {
        self.io.write_all(bytes)?;
        self.io.flush()?;
        Ok(())
    }

    /// Receives the next complete frame from the device.
    pub fn recv_frame(&mut self) -> LinkResult<(u16, Response)> {
        loop {
            if self.rx_pos == self.rx_len {
                let n = self.io.read(&mut self.rx)?;
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

    /// Sends `req` and returns the matching reply (device errors as `Err`). A `NO_ID`
    /// error means the device saw a corrupt frame: the request is re-sent with the same
    /// id up to 3 times.
    pub fn call(&mut self, req: &Request) -> LinkResult<Response> {
        let id = self.next_id();
        self.call_with_id(id, req)
    }

    fn call_with_id(&mut self, id: u16, req: &Request) -> LinkResult<Response> {
        let mut attempts = 0;
        self.send_request(id, req)?;
        loop {
            let (rid, resp) = self.recv_frame()?;
            if rid == id {
                return match resp {
                    Response::Error(e) => Err(LinkError::Device(e)),
                    r => Ok(r),
                };
            }
            if let (NO_ID, Response::Error(e)) = (rid, &resp) {
                if attempts >= 3 {
                    return Err(LinkError::Device(*e));
                }
                attempts += 1;
                self.retries += 1;
                self.send_request(id, req)?;
            }
            // Stale reply to an earlier id, or an unsolicited boot announcement: skip.
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
        Ok(info)
    }

    /// Loads a plan (checked locally for size first).
    pub fn load_plan(&mut self, plan: &FloorPlan) -> LinkResult<PlanSummary> {
        self.load_raw_plan(plan.raw())
    }

    /// Loads raw vertices (the device validates them).
    pub fn load_raw_plan(&mut self, vertices: &[[f32; 2]]) -> LinkResult<PlanSummary> {
        let vertices: HVec<[f32; 2], MAX_WIRE_VERTICES> =
            HVec::from_slice(vertices).map_err(|_| {
                LinkError::Local(format!(
                    "plan has {} vertices; the protocol carries at most {MAX_WIRE_VERTICES} \
                     and the device accepts at most {MAX_VERTICES}",
                    vertices.len()
                ))
            })?;
        match self.call(&Request::LoadPlan { vertices })? {
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

/// An open link: the client plus whatever must be kept alive/stopped with it.
pub struct Link {
    /// The protocol client.
    pub client: Client<Box<dyn Stream>>,
    /// The emulator, for `qemu` links.
    pub qemu: Option<Qemu>,
    /// The device thread, for `loopback` links.
    pub device_thread: Option<std::thread::JoinHandle<()>>,
}

/// Opens the transport named by `spec` with reply timeout `timeout`.
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
    match spec {
        LinkSpec::Loopback => {
            let (host, device) = Pipe::pair(timeout);
            let handle = spawn_loopback(device);
            Ok(Link {
                client: Client::new(Box::new(host)),
                qemu: None,
                device_thread: Some(handle),
            })
        }
        LinkSpec::Tcp(addr) => {
            let s = std::net::TcpStream::connect(addr)
                .map_err(|e| LinkError::Local(format!("cannot connect to {addr}: {e}")))?;
            s.set_read_timeout(Some(timeout))?;
            s.set_nodelay(true)?;
            Ok(Link {
                client: Client::new(Box::new(s)),
                qemu: None,
                device_thread: None,
            })
        }
        LinkSpec::Serial { path, baud } => {
            let port = serialport::new(path, *baud)
                .timeout(timeout)
                .open()
                .map_err(|e| LinkError::Local(format!("cannot open serial port {path}: {e}")))?;
            Ok(Link {
                client: Client::new(Box::new(port)),
                qemu: None,
                device_thread: None,
            })
        }
        LinkSpec::Qemu(elf) => {
            let (qemu, stream) = Qemu::start_with_args(elf, timeout, qemu_args)?;
            Ok(Link {
                client: Client::new(Box::new(stream)),
                qemu: Some(qemu),
                device_thread: None,
            })
        }
    }
}

impl Link {
    /// Sends `Shutdown` and waits for the device side (thread / emulator) to stop.
    /// Returns the emulator's semihosting output for `qemu` links.
    pub fn close(self) -> LinkResult<String> {
        self.close_with_stderr().map(|(out, _)| out)
    }

    /// As [`Link::close`], also returning the emulator's raw stderr (the firmware's defmt
    /// frames, see `cargo xtask qemu-log`); empty for other links.
    pub fn close_with_stderr(self) -> LinkResult<(String, Vec<u8>)> {
        let raw = self.qemu.as_ref().map(|q| q.stderr_handle());
        let out = self.close_inner()?;
        let raw = raw
            .and_then(|r| r.lock().ok().map(|v| v.clone()))
            .unwrap_or_default();
        Ok((out, raw))
    }

    fn close_inner(mut self) -> LinkResult<String> {
        let r = self.client.shutdown();
        if let Some(h) = self.device_thread.take() {
            drop(self.client);
            let _ = h.join();
            return r.map(|_| String::new());
        }
        let out = match self.qemu.take() {
            Some(q) => q.wait(Duration::from_secs(10))?,
            None => String::new(),
        };
        r.map(|_| out)
    }
}
