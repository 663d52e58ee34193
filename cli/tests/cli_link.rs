//! The link from the user's side: `activesense serial run` over a pseudo-terminal whose
//! line carries injected noise, against the core device session (in this test), and the
//! shutdown rule (only `--shutdown` / `serial shutdown` power the instrument off).
//!
//! The noise relay sits between the pty the CLI opens and a TCP socket the device session
//! serves, paced like a 115200-baud UART: every 50 ms, in each direction, a burst of 1..=63 random bytes (0x00 included)
//! is spliced into the next chunk of traffic at a random offset (or sent alone when the
//! line is idle), so bursts land inside frames. The CLI must resynchronise, re-send and
//! finish every episode, verified bit-identical to the in-process run.
//!
//! The CI run is short (`NOISE_EPISODES` episodes, K = 1 and K = 10); the target
//! (40 episodes, K = 10) runs with `ACTIVESENSE_NOISE_EPISODES=40 ACTIVESENSE_NOISE_ROT_BINS=10
//! cargo test -p activesense --test cli_link -- --nocapture noisy`.
#![cfg(unix)]

mod common;

use activesense_core::device::{ServeEnd, Session};
use activesense_instrument::link::device::{serve_std, HOST_DEVICE};
use common::{activesense, s};
use serialport::{SerialPort, TTYPort};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Episodes of the CI run (per K).
const NOISE_EPISODES: u32 = 3;
/// Period of the noise bursts, per direction.
const BURST_PERIOD: Duration = Duration::from_millis(50);
/// Bursts are 1..BURST_MAX bytes long.
const BURST_MAX: usize = 64;
/// The relay paces each direction like a 115200-baud UART (10 bits a byte), so the noise
/// meets frames as often as on a real line (a pty alone moves bytes at memory speed).
const BYTE_TIME: Duration = Duration::from_nanos(86_806);

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/plans")
        .join(name)
}

/// xorshift64: the noise is reproducible from its seed.
struct Noise(u64);
impl Noise {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn burst(&mut self) -> Vec<u8> {
        let n = 1 + (self.next() as usize % (BURST_MAX - 1));
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// Counts of what the relay injected.
#[derive(Default)]
struct Injected {
    bursts: AtomicU64,
    bytes: AtomicU64,
}

/// Copies `from` to `to`, splicing a noise burst into the traffic every [`BURST_PERIOD`],
/// until `stop`. `from` must have a short read time-out.
fn relay(
    mut from: impl Read,
    mut to: impl Write,
    seed: u64,
    stop: Arc<AtomicBool>,
    injected: Arc<Injected>,
) {
    let mut noise = Noise(seed);
    let mut buf = [0u8; 512];
    let mut next_burst = Instant::now() + BURST_PERIOD;
    // The first frame in each direction always gets a burst, so even a run shorter than a
    // few periods meets noise inside its frames.
    let mut first_frame = true;
    while !stop.load(Ordering::Relaxed) {
        let chunk: Vec<u8> = match from.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => buf[..n].to_vec(),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                ) =>
            {
                Vec::new()
            }
            Err(_) => return,
        };
        let mut out = chunk;
        if Instant::now() >= next_burst || (first_frame && !out.is_empty()) {
            first_frame &= out.is_empty();
            let b = noise.burst();
            injected.bursts.fetch_add(1, Ordering::Relaxed);
            injected.bytes.fetch_add(b.len() as u64, Ordering::Relaxed);
            let at = if out.is_empty() {
                0
            } else {
                noise.next() as usize % out.len()
            };
            out.splice(at..at, b);
            next_burst = next_burst.max(Instant::now()) + BURST_PERIOD;
        }
        if !out.is_empty() {
            if to.write_all(&out).is_err() || to.flush().is_err() {
                return;
            }
            std::thread::sleep(BYTE_TIME * out.len() as u32);
        }
    }
}

/// The CLI's stdout after `serial run` over the noisy pty against the core session.
fn noisy_serial_run(episodes: u32, rot_bins: u8) -> (String, u64, u64) {
    let (master, slave) = TTYPort::pair().expect("pty pair");
    let port = slave.name().expect("pty name");
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let device = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let mut session = Box::new(Session::new(HOST_DEVICE));
        let end = serve_std(&mut session, &mut s);
        (end.ok(), session.stats())
    });
    let dev = TcpStream::connect(addr).unwrap();
    dev.set_read_timeout(Some(Duration::from_millis(10)))
        .unwrap();
    let mut m_rx = master;
    m_rx.set_timeout(Duration::from_millis(10)).unwrap();
    let m_tx = m_rx.try_clone_native().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let injected = Arc::new(Injected::default());
    let to_device = {
        let (d, stop, inj) = (dev.try_clone().unwrap(), stop.clone(), injected.clone());
        std::thread::spawn(move || relay(m_rx, d, 0x9E37_79B9_7F4A_7C15, stop, inj))
    };
    let to_host = {
        let (stop, inj) = (stop.clone(), injected.clone());
        std::thread::spawn(move || relay(dev, m_tx, 0xD1B5_4A32_D192_ED03, stop, inj))
    };
    let t0 = Instant::now();
    let out = activesense(&[
        "serial",
        "run",
        "--port",
        &port,
        "--plan",
        s(&fixture("l-room.json")),
        "--episodes",
        &episodes.to_string(),
        "--rot-bins",
        &rot_bins.to_string(),
        "--verify",
    ]);
    let secs = t0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    let _ = to_device.join();
    let _ = to_host.join();
    drop(slave);
    let (end, stats) = device.join().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{stdout}{stderr}");
    // The CLI ended its session without powering the device off.
    assert_ne!(end, Some(ServeEnd::Shutdown), "{stdout}");
    let bursts = injected.bursts.load(Ordering::Relaxed);
    let bytes = injected.bytes.load(Ordering::Relaxed);
    println!(
        "noisy serial run: {episodes} episodes, K = {rot_bins}, {secs:.1} s, {bursts} bursts \
         ({bytes} bytes) injected; device saw {} frames ok, {} bad, {} retransmissions\n\
         {stdout}{stderr}",
        stats.frames_ok, stats.frames_bad, stats.retransmissions
    );
    (stdout, bursts, stats.frames_bad as u64)
}

fn resent(stdout: &str) -> u64 {
    let line = stdout
        .lines()
        .find(|l| l.starts_with("link (host): "))
        .unwrap_or_else(|| panic!("no link summary: {stdout}"));
    line["link (host): ".len()..]
        .split(' ')
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"))
}

/// `serial run --verify` completes every episode over a line with injected noise, and
/// says how many frames it re-sent.
#[test]
fn serial_run_survives_line_noise() {
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<u32>().ok());
    let episodes = env("ACTIVESENSE_NOISE_EPISODES").unwrap_or(NOISE_EPISODES);
    let ks: Vec<u8> = match env("ACTIVESENSE_NOISE_ROT_BINS").map(|k| k as u8) {
        Some(k) => vec![k],
        None => vec![1, 10],
    };
    for k in ks {
        let (stdout, bursts, bad) = noisy_serial_run(episodes, k);
        assert!(
            stdout.contains(&format!(
                "every episode verified bit-identical to the in-process run ({episodes} episodes)"
            )),
            "{stdout}"
        );
        for i in 0..episodes {
            assert!(
                stdout.contains(&format!("episode {i}: ")),
                "episode {i}: {stdout}"
            );
        }
        // The noise reached the frames: the device saw corrupt frames and the host re-sent.
        // The bursts are paced by time, so a fast run sees fewer: a K = 10 run of three
        // episodes takes about 0.3 s, 10-odd bursts at 50 ms in both directions. (A denser
        // period hits most long replies and exhausts the retries: 25 ms does.)
        assert!(bursts >= 5 && bad > 0, "{bursts} bursts, {bad} bad frames");
        assert!(resent(&stdout) > 0, "{stdout}");
    }
}

/// Only `serial shutdown` powers the instrument off; `serial run` leaves it serving, so a
/// second command finds it (the same session object serves both).
#[test]
fn only_serial_shutdown_powers_off() {
    let (master, slave) = TTYPort::pair().expect("pty pair");
    let port = slave.name().expect("pty name");
    let device = std::thread::spawn(move || {
        let mut m = master;
        m.set_timeout(Duration::from_millis(20)).unwrap();
        let mut session = Box::new(Session::new(HOST_DEVICE));
        let end = serve_std(&mut session, &mut m);
        (end.ok(), session.stats().episodes)
    });
    let plan = fixture("l-room.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "serial",
            "run",
            "--port",
            &port,
            "--plan",
            s(&plan),
            "--episodes",
            "1",
        ];
        args.extend_from_slice(extra);
        let out = activesense(&args);
        assert!(
            out.status.success(),
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(&[]);
    run(&[]);
    let out = activesense(&["serial", "shutdown", "--port", &port]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (end, episodes) = device.join().unwrap();
    drop(slave);
    assert_eq!(end, Some(ServeEnd::Shutdown));
    assert_eq!(episodes, 2);
}
