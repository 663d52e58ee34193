//! The device end of the link as seen from the host: the simulated instrument that answers
//! the device's action requests ([`SimInstrument`]), the in-memory [`Pipe`] and the
//! `loopback` device thread (the core [`Session`] on the host), a std serve loop for any
//! `Read + Write` ([`serve_std`], used by loopback and the pty test), and the QEMU launcher
//! ([`Qemu`]) that runs the real firmware ELF with USART1 on a local TCP socket (its command
//! line comes from [`crate::link::qemu_cmd`]). The protocol client is [`crate::link::serial`].

use crate::episode::EpisodeSpec;
use crate::link::error::{LinkError, LinkResult};
use crate::link::qemu_cmd::{qemu_command, QemuSerial};
use crate::world::SimWorld;
use activesense_core::device::instrument::{Instrument, Turn};
use activesense_core::device::{Control, ServeEnd, Session, SessionConfig, DEFAULT_TIMEOUT_MS};
use activesense_core::episode::Action;
use activesense_core::episode::Observation;
use activesense_core::protocol::{
    decode_frame, EpisodeParams, Feed, FrameAccumulator, Response, NO_ID,
};
use activesense_core::FloorPlan;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::io::{self, Read, Write};
use std::path::Path;
use std::process::{Child, Stdio};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// The simulated instrument (the lead's [`SimWorld`]) behind the core [`Instrument`] trait.
pub struct SimInstrument {
    world: SimWorld,
    last: Option<Observation>,
}

impl SimInstrument {
    /// Wraps a world.
    pub fn new(world: SimWorld) -> Self {
        SimInstrument { world, last: None }
    }

    /// The world.
    pub fn world(&self) -> &SimWorld {
        &self.world
    }
}

impl Instrument for SimInstrument {
    type Error = Infallible;

    fn rotate(&mut self, turn: Turn) -> Result<(), Infallible> {
        let a = match turn {
            Turn::Left => Action::RotateLeft,
            Turn::Right => Action::RotateRight,
        };
        self.last = Some(self.world.act(a).0);
        Ok(())
    }

    fn measure(&mut self) -> Result<Option<f32>, Infallible> {
        let o = self.world.act(Action::Measure).0;
        self.last = Some(o);
        Ok(o.range)
    }

    fn scan(&mut self) -> Result<u32, Infallible> {
        Ok(match self.last.take() {
            Some(o) => o.scan,
            None => self.world.scan(),
        })
    }

    /// One `SimWorld::act` per action, exactly as the lead's episode runner does, so the
    /// world's random stream (noise, outliers, scan errors) is consumed identically.
    fn perform(&mut self, action: Action) -> Result<Observation, Infallible> {
        Ok(self.world.act(action).0)
    }
}

/// Builds everything one simulated episode needs: the model, the parameters the host
/// sends in `StartEpisode` (ground truth and, for K = 1, the known heading included) and
/// the instrument. Seeds come from `spec` exactly as in [`crate::episode::run_episode`]
/// (the initial scan is taken first, as there).
pub fn sim_episode(spec: &EpisodeSpec) -> (FloorPlan, EpisodeParams, SimInstrument) {
    let plan = spec.plan();
    let mut world = SimWorld::new(plan.clone(), spec.sensor, spec.config, spec.world_seed());
    let initial_scan = world.scan();
    let truth = world.truth();
    let params = spec.params(truth, initial_scan);
    (plan, params, SimInstrument::new(world))
}

// ---------------------------------------------------------------------------------------
// In-memory pipe

#[derive(Default)]
struct Chan {
    state: Mutex<(VecDeque<u8>, bool)>,
    cv: Condvar,
}

/// One end of an in-memory duplex byte pipe with a read timeout. Dropping an end closes
/// both directions: the peer reads EOF and its writes fail with `BrokenPipe`.
pub struct Pipe {
    rx: Arc<Chan>,
    tx: Arc<Chan>,
    timeout: Duration,
}

impl Pipe {
    /// A connected pair: (host end with `timeout`, device end with a 20 ms poll timeout).
    pub fn pair(timeout: Duration) -> (Pipe, Pipe) {
        let a = Arc::new(Chan::default());
        let b = Arc::new(Chan::default());
        (
            Pipe {
                rx: a.clone(),
                tx: b.clone(),
                timeout,
            },
            Pipe {
                rx: b,
                tx: a,
                timeout: Duration::from_millis(20),
            },
        )
    }
}

impl Drop for Pipe {
    fn drop(&mut self) {
        for c in [&self.rx, &self.tx] {
            if let Ok(mut s) = c.state.lock() {
                s.1 = true;
            }
            c.cv.notify_all();
        }
    }
}

impl Read for Pipe {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let deadline = Instant::now() + self.timeout;
        let mut s = self
            .rx
            .state
            .lock()
            .map_err(|_| io::Error::other("poisoned"))?;
        loop {
            if !s.0.is_empty() {
                let n = buf.len().min(s.0.len());
                for (d, b) in buf.iter_mut().zip(s.0.drain(..n)) {
                    *d = b;
                }
                return Ok(n);
            }
            if s.1 {
                return Ok(0);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(io::ErrorKind::TimedOut.into());
            }
            s = self
                .rx
                .cv
                .wait_timeout(s, deadline - now)
                .map_err(|_| io::Error::other("poisoned"))?
                .0;
        }
    }
}

impl Write for Pipe {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut s = self
            .tx
            .state
            .lock()
            .map_err(|_| io::Error::other("poisoned"))?;
        if s.1 {
            return Err(io::ErrorKind::BrokenPipe.into());
        }
        s.0.extend(buf);
        self.tx.cv.notify_all();
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// Device session on the host

/// `embedded_io::Write` over a `std::io::Write`.
pub struct EioWrite<'a, W: Write>(pub &'a mut W);

impl<W: Write> embedded_io::ErrorType for EioWrite<'_, W> {
    type Error = io::Error;
}

impl<W: Write> embedded_io::Write for EioWrite<'_, W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.0.flush()
    }
}

/// Session configuration of the host-emulated device.
pub const HOST_DEVICE: SessionConfig = SessionConfig {
    firmware: concat!("host-session ", env!("CARGO_PKG_VERSION")),
    timeout_ms: DEFAULT_TIMEOUT_MS,
    // Native code (the core at opt-level 3 in every profile) answers in well under a
    // second; the bound leaves room for a debug build on a loaded CI machine.
    max_reply_ms: 5_000,
    cycle_clock: None,
    policies: &activesense_core::policy::builtin::POLICIES,
    stack_usage: None,
};

/// Serves the protocol from `session` over a std stream whose reads time out (the
/// timeouts drive [`Session::poll`]), exactly like the firmware's main loop. Returns on
/// `Shutdown`, end of stream or an I/O error.
pub fn serve_std<T: Read + Write>(session: &mut Session, io: &mut T) -> io::Result<ServeEnd> {
    let start = Instant::now();
    let now = || start.elapsed().as_millis() as u32;
    let mut buf = [0u8; 256];
    loop {
        match io.read(&mut buf) {
            Ok(0) => return Ok(ServeEnd::Eof),
            Ok(n) => {
                if session.feed(&buf[..n], now(), &mut EioWrite(io))? == Control::Shutdown {
                    return Ok(ServeEnd::Shutdown);
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                ) =>
            {
                session.poll(now());
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
}

/// Runs the core session in a thread on the device end of a pipe.
pub fn spawn_loopback(mut device: Pipe) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut session = Box::new(Session::new(HOST_DEVICE));
        let _ = serve_std(&mut session, &mut device);
    })
}

// ---------------------------------------------------------------------------------------
// QEMU

/// A running `qemu-system-arm -M netduinoplus2` with the firmware; USART1 (`serial0`) is
/// connected to a TCP listener of this process. The emulator is killed on drop.
pub struct Qemu {
    child: Option<Child>,
    output: Arc<Mutex<String>>,
    stderr: Arc<Mutex<Vec<u8>>>,
}

/// The emulator binary (`ACTIVESENSE_QEMU` overrides).
pub fn qemu_binary() -> String {
    std::env::var("ACTIVESENSE_QEMU").unwrap_or_else(|_| "qemu-system-arm".into())
}

impl Qemu {
    /// Starts the emulator on `elf` and waits (up to 10 s) for it to connect USART1.
    /// Returns the emulator and the connected stream (read timeout `timeout`).
    pub fn start(elf: &Path, timeout: Duration) -> LinkResult<(Qemu, std::net::TcpStream)> {
        Self::start_with_args(elf, timeout, &[])
    }

    /// As [`Qemu::start`], with `extra` appended to the emulator's command line (e.g.
    /// `-icount shift=0` for instruction counting, `-append bench` for the firmware).
    pub fn start_with_args(
        elf: &Path,
        timeout: Duration,
        extra: &[String],
    ) -> LinkResult<(Qemu, std::net::TcpStream)> {
        if !elf.is_file() {
            return Err(LinkError::Local(format!(
                "firmware ELF not found at {} (build it with `cargo build -p activesense-firmware \
                 --target thumbv7em-none-eabihf --profile firmware`)",
                elf.display()
            )));
        }
        let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
        let port = listener.local_addr()?.port();
        let mut child = qemu_command(&qemu_binary(), elf, QemuSerial::Tcp(port))
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| LinkError::Local(format!("cannot start {}: {e}", qemu_binary())))?;
        let output = Arc::new(Mutex::new(String::new()));
        let stderr = Arc::new(Mutex::new(Vec::new()));
        for (is_stderr, pipe) in [false, true].into_iter().zip([
            child
                .stdout
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
            child
                .stderr
                .take()
                .map(|p| Box::new(p) as Box<dyn Read + Send>),
        ]) {
            let Some(pipe) = pipe else { continue };
            let out = output.clone();
            let raw = stderr.clone();
            std::thread::spawn(move || {
                let mut pipe = pipe;
                let mut buf = [0u8; 512];
                while let Ok(n) = pipe.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    if is_stderr {
                        if let Ok(mut r) = raw.lock() {
                            r.extend_from_slice(&buf[..n]);
                        }
                    } else if let Ok(mut o) = out.lock() {
                        o.push_str(&String::from_utf8_lossy(&buf[..n]));
                    }
                }
            });
        }
        let mut qemu = Qemu {
            child: Some(child),
            output,
            stderr,
        };
        listener.set_nonblocking(true)?;
        let deadline = Instant::now() + Duration::from_secs(10);
        let stream = loop {
            match listener.accept() {
                Ok((s, _)) => break s,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if let Some(c) = qemu.child.as_mut() {
                        if let Ok(Some(status)) = c.try_wait() {
                            return Err(LinkError::Local(format!(
                                "qemu exited ({status}) before connecting: {}",
                                qemu.diagnostics()
                            )));
                        }
                    }
                    if Instant::now() > deadline {
                        return Err(LinkError::Local(format!(
                            "qemu did not connect its serial port within 10 s: {}",
                            qemu.diagnostics()
                        )));
                    }
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(e.into()),
            }
        };
        stream.set_nonblocking(false)?;
        stream.set_nodelay(true)?;
        // The firmware announces itself with an unsolicited Hello frame once USART1 is
        // enabled (QEMU drops input that arrives before): wait for it.
        stream.set_read_timeout(Some(Duration::from_millis(100)))?;
        let mut acc = FrameAccumulator::new();
        let mut byte = [0u8; 1];
        let announced = loop {
            match (&stream).read(&mut byte) {
                Ok(0) => break Err("serial link closed".to_string()),
                Ok(_) => match acc.push(byte[0]) {
                    Feed::Frame(f) => match decode_frame::<Response>(f) {
                        Ok((NO_ID, Response::Hello(_))) => break Ok(()),
                        other => break Err(format!("unexpected boot frame {other:?}")),
                    },
                    _ => continue,
                },
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    if Instant::now() > deadline {
                        break Err("no boot announcement within 10 s".into());
                    }
                }
                Err(e) => break Err(e.to_string()),
            }
        };
        if let Err(e) = announced {
            return Err(LinkError::Local(format!(
                "firmware did not start: {e}: {}",
                qemu.diagnostics()
            )));
        }
        stream.set_read_timeout(Some(timeout))?;
        Ok((qemu, stream))
    }

    /// The emulator's stderr bytes so far, unaltered: the firmware's defmt frames
    /// (semihosting stderr) and any QEMU diagnostics.
    pub fn stderr_bytes(&self) -> Vec<u8> {
        self.stderr.lock().map(|o| o.clone()).unwrap_or_default()
    }

    /// A handle on the raw stderr buffer that outlives [`Qemu::wait`].
    pub fn stderr_handle(&self) -> Arc<Mutex<Vec<u8>>> {
        self.stderr.clone()
    }

    /// Semihosting console output (the emulator's stdout) so far.
    pub fn output(&self) -> String {
        self.output.lock().map(|o| o.clone()).unwrap_or_default()
    }

    /// Console output plus the emulator's stderr (lossy text: QEMU diagnostics, and the
    /// firmware's binary defmt frames) for error messages.
    pub fn diagnostics(&self) -> String {
        format!(
            "{}{}",
            self.output(),
            String::from_utf8_lossy(&self.stderr_bytes())
        )
    }

    /// Stops the emulator (kills the process: the device this host started ends with the
    /// host's command) and returns its console output so far.
    pub fn kill(mut self) -> String {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
            // Let the reader threads drain the pipes.
            std::thread::sleep(Duration::from_millis(50));
        }
        self.output()
    }

    /// Waits for the emulator to exit; returns its output, or an error when it exits
    /// non-zero or does not exit within `timeout` (then it is killed).
    pub fn wait(mut self, timeout: Duration) -> LinkResult<String> {
        let deadline = Instant::now() + timeout;
        let mut child = match self.child.take() {
            Some(c) => c,
            None => return Ok(self.output()),
        };
        loop {
            if let Some(status) = child.try_wait()? {
                // Let the reader threads drain the pipes.
                std::thread::sleep(Duration::from_millis(50));
                return if status.success() {
                    Ok(self.output())
                } else {
                    Err(LinkError::Local(format!(
                        "qemu exited with {status}: {}",
                        self.diagnostics()
                    )))
                };
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                return Err(LinkError::Local(format!(
                    "qemu did not exit within {timeout:?}; killed: {}",
                    self.diagnostics()
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
