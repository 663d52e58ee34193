//! The firmware under QEMU: [`Qemu`] starts `qemu-system-arm` on the firmware ELF with
//! USART1 (`serial0`) on a TCP listener of this process, waits for the firmware's boot
//! announcement, and collects the emulator's console and defmt output. The emulator's
//! command line itself is built in [`crate::link::qemu_cmd`], which `cargo xtask` shares.

use crate::link::error::{LinkError, LinkResult};
use crate::link::qemu_cmd::{qemu_command, QemuSerial};
use activesense_core::wire::{decode_frame, Feed, FrameAccumulator, Response, NO_ID};
use std::io::{self, Read};
use std::path::Path;
use std::process::{Child, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

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
