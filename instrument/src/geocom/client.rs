//! The GeoCOM client: one request, one reply, every reply checked (prefix, transaction id,
//! optional CRC, `RC_COM`), with the recovery explicit in [`ClientConfig`]:
//!
//! * each request is preceded by a lone LF, which the manual recommends to clear the
//!   instrument's receive buffer after line noise;
//! * a reply that does not come within `timeout` is a time-out: the client resynchronises
//!   and repeats the request, up to `retries` times;
//! * a garbled or truncated line, a CRC mismatch, or a `RC_COM` that a repeat can cure
//!   ([`CodeClass::Retry`]): resynchronise (drop everything pending, wait for the line to
//!   fall quiet) and repeat with a new transaction id, so that a late reply to the old
//!   request is recognised by its id and dropped;
//! * a busy instrument (`GRC_TMC_BUSY`, `GRC_SYSBUSY`): wait `busy_wait` and repeat, up to
//!   `busy_retries` times;
//! * a dropped connection: reconnect once (TCP re-dials, a serial port is reopened) and
//!   repeat.
//!
//! Every recovery is recorded as an [`Event`] (the live view prints them); when a request
//! cannot be completed the error names the fault and the RPC ([`GeoComError`]).

use crate::geocom::codes::rpc_numbers::rpc_name;
use crate::geocom::codes::{CodeClass, ReturnCode};
use crate::geocom::wire::{self, Param, Reply, MAX_LINE};
use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// A byte link to an instrument that can be re-established.
pub trait Transport: Read + Write + Send {
    /// Sets the read time-out (reads return `TimedOut`/`WouldBlock` after it).
    fn set_read_timeout(&mut self, t: Duration) -> io::Result<()>;
    /// Re-establishes the link after it dropped.
    fn reconnect(&mut self) -> io::Result<()>;
    /// `tcp:HOST:PORT`, `serial:/dev/ttyUSB0:19200`.
    fn describe(&self) -> String;
}

/// GeoCOM over TCP (Bluetooth/Wi-Fi bridges, the instrument simulator).
pub struct TcpTransport {
    addr: String,
    stream: TcpStream,
}

impl TcpTransport {
    /// Connects to `addr` (`HOST:PORT`).
    pub fn connect(addr: &str) -> io::Result<Self> {
        let stream = TcpStream::connect(addr)?;
        stream.set_nodelay(true)?;
        Ok(TcpTransport {
            addr: addr.to_owned(),
            stream,
        })
    }
}

impl Read for TcpTransport {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.stream.read(buf)
    }
}
impl Write for TcpTransport {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.stream.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.stream.flush()
    }
}
impl Transport for TcpTransport {
    fn set_read_timeout(&mut self, t: Duration) -> io::Result<()> {
        self.stream
            .set_read_timeout(Some(t.max(Duration::from_millis(1))))
    }
    fn reconnect(&mut self) -> io::Result<()> {
        let t = self.stream.read_timeout()?;
        self.stream = TcpStream::connect(&self.addr)?;
        self.stream.set_nodelay(true)?;
        self.stream.set_read_timeout(t)
    }
    fn describe(&self) -> String {
        format!("tcp:{}", self.addr)
    }
}

/// GeoCOM over a serial port (RS-232 cable, Bluetooth SPP, the simulator's pty).
pub struct SerialTransport {
    path: String,
    baud: u32,
    port: Box<dyn serialport::SerialPort>,
}

/// The Leica default baud rate.
pub const DEFAULT_BAUD: u32 = 19200;

impl SerialTransport {
    /// Opens `path` at `baud`, 8N1 (the GeoCOM default).
    pub fn open(path: &str, baud: u32) -> io::Result<Self> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(500))
            .open()
            .map_err(io::Error::other)?;
        Ok(SerialTransport {
            path: path.to_owned(),
            baud,
            port,
        })
    }
}

impl Read for SerialTransport {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.port.read(buf)
    }
}
impl Write for SerialTransport {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.port.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.port.flush()
    }
}
impl Transport for SerialTransport {
    fn set_read_timeout(&mut self, t: Duration) -> io::Result<()> {
        self.port.set_timeout(t).map_err(io::Error::other)
    }
    fn reconnect(&mut self) -> io::Result<()> {
        let t = self.port.timeout();
        self.port = serialport::new(&self.path, self.baud)
            .timeout(t)
            .open()
            .map_err(io::Error::other)?;
        Ok(())
    }
    fn describe(&self) -> String {
        format!("serial:{}:{}", self.path, self.baud)
    }
}

/// Time-outs and retries (all explicit; the defaults suit a TPS1200 at 19200 baud).
#[derive(Clone, Copy, Debug)]
pub struct ClientConfig {
    /// How long to wait for a reply line (positioning and measuring are slower: the
    /// session sets a longer time-out around them).
    pub timeout: Duration,
    /// Reply time-out around AUT_MakePositioning and the EDM measurement.
    pub slow_timeout: Duration,
    /// Repeats after a time-out, a garbled line, a CRC mismatch or a dropped link.
    pub retries: u32,
    /// Repeats while the instrument answers busy.
    pub busy_retries: u32,
    /// Wait before repeating a busy request.
    pub busy_wait: Duration,
    /// Add (and require on replies) the CRC-16 header field.
    pub crc: bool,
    /// Send a lone LF before every request.
    pub leading_lf: bool,
}

impl Default for ClientConfig {
    fn default() -> Self {
        ClientConfig {
            timeout: Duration::from_secs(5),
            slow_timeout: Duration::from_secs(30),
            retries: 3,
            busy_retries: 10,
            busy_wait: Duration::from_millis(200),
            crc: false,
            leading_lf: true,
        }
    }
}

/// What went wrong with one RPC.
#[derive(Clone, Debug, PartialEq)]
pub enum Fault {
    /// The RPC answered with this return code (`RC`).
    Code(ReturnCode),
    /// The communication layer answered with this code (`RC_COM`).
    Com(ReturnCode),
    /// No reply within the time-out, after every repeat.
    Timeout {
        /// Time-out per attempt (ms).
        ms: u64,
        /// Attempts made.
        attempts: u32,
    },
    /// Replies that were not GeoCOM (garbled or truncated), after every repeat.
    Garbled(String),
    /// Replies whose CRC did not match, after every repeat.
    Crc,
    /// Busy after every repeat.
    Busy(ReturnCode),
    /// The link dropped and could not be re-established.
    Dropped(String),
    /// A reply that is GeoCOM but not what this RPC returns (missing or bad values).
    BadReply(String),
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fault::Code(c) => write!(f, "{c}"),
            Fault::Com(c) => write!(f, "communication error {c}"),
            Fault::Timeout { ms, attempts } => write!(
                f,
                "time-out: no reply within {ms} ms in {attempts} attempts (check cable, baud rate and that GeoCOM is on)"
            ),
            Fault::Garbled(l) => write!(f, "garbled reply {l:?} after every repeat (check baud rate and line noise)"),
            Fault::Crc => write!(f, "CRC mismatch on every repeat (line noise?)"),
            Fault::Busy(c) => write!(f, "instrument stayed busy ({c})"),
            Fault::Dropped(e) => write!(f, "connection dropped and could not be re-established ({e})"),
            Fault::BadReply(e) => write!(f, "unexpected reply: {e}"),
        }
    }
}

/// A failed RPC: the fault and the RPC it happened in.
#[derive(Clone, Debug, PartialEq)]
pub struct GeoComError {
    /// The RPC number.
    pub rpc: u16,
    /// What happened.
    pub fault: Fault,
}

impl std::fmt::Display for GeoComError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} (RPC {}): {}",
            rpc_name(self.rpc),
            self.rpc,
            self.fault
        )
    }
}

impl std::error::Error for GeoComError {}

/// A recovered fault (the session went on).
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// The RPC it happened in.
    pub rpc: u16,
    /// What happened and what the client did.
    pub what: String,
}

impl std::fmt::Display for Event {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} (RPC {}): {}",
            rpc_name(self.rpc),
            self.rpc,
            self.what
        )
    }
}

enum Attempt {
    Reply(Reply),
    Timeout,
    Garbled(String),
    Crc,
    Dropped(String),
}

/// The GeoCOM client over a [`Transport`].
pub struct Client {
    io: Box<dyn Transport>,
    config: ClientConfig,
    pending: Vec<u8>,
    trid: u16,
    events: Vec<Event>,
}

impl Client {
    /// A client on `io`.
    pub fn new(io: Box<dyn Transport>, config: ClientConfig) -> Self {
        Client {
            io,
            config,
            pending: Vec::new(),
            trid: 0,
            events: Vec::new(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Changes the reply time-out (positioning a motor takes longer than a ping).
    pub fn set_timeout(&mut self, t: Duration) {
        self.config.timeout = t;
    }

    /// The link, described.
    pub fn describe(&self) -> String {
        self.io.describe()
    }

    /// Recovered faults since the last call of this.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    fn event(&mut self, rpc: u16, what: String) {
        self.events.push(Event { rpc, what });
    }

    fn next_trid(&mut self) -> u16 {
        // 1..=7 like GeoComPy's counter would work; the manual allows any 16-bit value.
        self.trid = self.trid.wrapping_add(1).max(1);
        self.trid
    }

    /// Drops everything pending and waits until the line has been quiet for a moment.
    fn resync(&mut self) {
        self.pending.clear();
        let quiet = Duration::from_millis(50);
        let _ = self.io.set_read_timeout(quiet);
        let deadline = Instant::now() + Duration::from_millis(500);
        let mut buf = [0u8; 256];
        while Instant::now() < deadline {
            match self.io.read(&mut buf) {
                Ok(n) if n > 0 => continue,
                _ => break,
            }
        }
    }

    /// Reads one line (without CR/LF) before `deadline`.
    fn read_line(&mut self, deadline: Instant) -> Result<String, Attempt> {
        loop {
            if let Some(i) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=i).collect();
                let text = String::from_utf8_lossy(&line);
                let t = text.trim_end_matches(['\r', '\n']).to_owned();
                if t.is_empty() {
                    continue;
                }
                return Ok(t);
            }
            if self.pending.len() > MAX_LINE {
                let junk = String::from_utf8_lossy(&self.pending[..40]).into_owned();
                self.pending.clear();
                return Err(Attempt::Garbled(junk));
            }
            let now = Instant::now();
            if now >= deadline {
                if !self.pending.is_empty() {
                    // A line that never ended: truncated.
                    let junk = String::from_utf8_lossy(&self.pending).into_owned();
                    self.pending.clear();
                    return Err(Attempt::Garbled(junk));
                }
                return Err(Attempt::Timeout);
            }
            let _ = self.io.set_read_timeout(deadline - now);
            let mut buf = [0u8; 256];
            match self.io.read(&mut buf) {
                Ok(0) => return Err(Attempt::Dropped("end of stream".into())),
                Ok(n) => self.pending.extend_from_slice(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(Attempt::Dropped(e.to_string())),
            }
        }
    }

    fn attempt(&mut self, rpc: u16, params: &[Param]) -> Result<Attempt, GeoComError> {
        let trid = self.next_trid();
        let line = wire::emit_request(rpc, Some(trid), self.config.crc, params).map_err(|e| {
            GeoComError {
                rpc,
                fault: Fault::BadReply(format!("cannot encode request: {e}")),
            }
        })?;
        let mut bytes = Vec::with_capacity(line.len() + 3);
        if self.config.leading_lf {
            bytes.push(b'\n');
        }
        bytes.extend_from_slice(line.as_bytes());
        bytes.extend_from_slice(b"\r\n");
        if let Err(e) = self.io.write_all(&bytes).and_then(|_| self.io.flush()) {
            return Ok(Attempt::Dropped(e.to_string()));
        }
        let deadline = Instant::now() + self.config.timeout;
        loop {
            let line = match self.read_line(deadline) {
                Ok(l) => l,
                Err(a) => return Ok(a),
            };
            let reply = match wire::parse_reply(&line) {
                Ok(r) => r,
                Err(_) => return Ok(Attempt::Garbled(line)),
            };
            if reply.header.trid.is_some_and(|t| t != trid) {
                // A late reply to an earlier, repeated request: not ours.
                self.event(
                    rpc,
                    format!(
                        "dropped a stale reply (transaction {:?})",
                        reply.header.trid
                    ),
                );
                continue;
            }
            if self.config.crc && !reply.header.crc_ok {
                return Ok(Attempt::Crc);
            }
            return Ok(Attempt::Reply(reply));
        }
    }

    /// Sends `rpc` with `params` and returns the checked reply (`RC_COM` = 0). The RPC's
    /// own return code is left to the caller ([`crate::geocom::rpc`]), except busy, which
    /// is waited out here.
    pub fn call(&mut self, rpc: u16, params: &[Param]) -> Result<Reply, GeoComError> {
        let mut retries = 0;
        let mut busy = 0;
        let mut reconnected = false;
        loop {
            let fault = match self.attempt(rpc, params)? {
                Attempt::Reply(r) => {
                    let com = ReturnCode(r.header.first);
                    let rc = ReturnCode(r.rc);
                    if com != ReturnCode::OK {
                        if com.class() == CodeClass::Retry {
                            Fault::Com(com)
                        } else {
                            return Err(GeoComError {
                                rpc,
                                fault: Fault::Com(com),
                            });
                        }
                    } else if rc.class() == CodeClass::Busy {
                        if busy >= self.config.busy_retries {
                            return Err(GeoComError {
                                rpc,
                                fault: Fault::Busy(rc),
                            });
                        }
                        busy += 1;
                        self.event(rpc, format!("{}: waiting and repeating", rc.name()));
                        std::thread::sleep(self.config.busy_wait);
                        continue;
                    } else {
                        return Ok(r);
                    }
                }
                Attempt::Timeout => Fault::Timeout {
                    ms: self.config.timeout.as_millis() as u64,
                    attempts: retries + 1,
                },
                Attempt::Garbled(l) => Fault::Garbled(l.chars().take(60).collect()),
                Attempt::Crc => Fault::Crc,
                Attempt::Dropped(e) => {
                    if reconnected {
                        return Err(GeoComError {
                            rpc,
                            fault: Fault::Dropped(e),
                        });
                    }
                    reconnected = true;
                    std::thread::sleep(Duration::from_millis(100));
                    match self.io.reconnect() {
                        Ok(()) => {
                            self.pending.clear();
                            self.event(
                                rpc,
                                format!("connection dropped ({e}): reconnected, repeating"),
                            );
                            continue;
                        }
                        Err(e2) => {
                            return Err(GeoComError {
                                rpc,
                                fault: Fault::Dropped(format!("{e}; reconnect: {e2}")),
                            })
                        }
                    }
                }
            };
            if retries >= self.config.retries {
                return Err(GeoComError { rpc, fault });
            }
            retries += 1;
            let what = match &fault {
                Fault::Timeout { .. } => "time-out".to_owned(),
                Fault::Garbled(l) => format!("garbled reply {l:?}"),
                Fault::Crc => "CRC mismatch".to_owned(),
                Fault::Com(c) => c.name().to_owned(),
                f => f.to_string(),
            };
            self.event(
                rpc,
                format!(
                    "{what}: resynchronised, repeating ({retries}/{})",
                    self.config.retries
                ),
            );
            self.resync();
        }
    }
}
