//! The device end of the link as seen from the host: the simulated instrument that answers
//! the device's action requests ([`SimInstrument`]), the in-memory [`Pipe`] and the
//! `loopback` device thread (the core [`Session`] on the host), a std serve loop for any
//! `Read + Write` ([`serve_std`], used by loopback and the pty test). The real firmware
//! under QEMU is [`crate::link::qemu`]; the protocol client is [`crate::link::serial`].

use crate::episode::EpisodeSpec;
use crate::world::SimWorld;
use activesense_core::agents::Action;
use activesense_core::episode::Observation;
use activesense_core::instrument::{Instrument, Turn};
use activesense_core::session::{Control, ServeEnd, Session, SessionConfig, DEFAULT_TIMEOUT_MS};
use activesense_core::wire::EpisodeParams;
use activesense_core::FloorPlan;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::io::{self, Read, Write};
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
    let params = EpisodeParams {
        agent: spec.agent,
        seed: spec.agent_seed(),
        steps_per_turn: spec.config.steps_per_turn,
        max_actions: spec.config.max_actions,
        rot_bins: spec.rot_bins,
        known_heading: (spec.rot_bins == 1).then_some(truth.theta),
        ground_truth: Some(truth),
        initial_scan,
        termination: spec.termination,
        stop_risk: spec.config.stop_risk,
        min_observability: spec.config.min_observability,
    };
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
    cycle_clock: None,
    policies: &activesense_core::builtin::POLICIES,
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
