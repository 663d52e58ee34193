//! Driver for a real laser-distance module: the **B605B** TTL laser ranging module (sold
//! as a "laser distance meter module / LDM", 2.0–3.3 V, UART at 3.3 V logic), whose
//! serial protocol is one ASCII byte per command.
//!
//! From the module's *Quick Start* ("Module Type: B605B"), the commands this driver uses or
//! names ([`cmd`]):
//!
//! > All commands are single ASCII character code in upper case.
//! > 1. 'O'(0x4F): Turn ON laser beam, and return ",OK!";
//! > 2. 'C'(0x43): Turn OFF laser beam, and return ", OK!";
//! > 3. 'S'(0x53): Module status read, module returns Temperature & Battery Voltage,
//! >    e.g.: "18.0'C, 2.7V";
//! > 4. 'D'(0x44): Auto mode Distance read, […] Module returns distant result and reflect
//! >    Signal Quality(SQ) after the successful measurement, returned string e.g.:
//! >    "12.345m, 0079", smaller SQ value stands for more reliable distance result. If the
//! >    distance is no more than 10.000 m, the tens digit will be replace by a space
//! >    character(HEX:0x20), then the string will be like: " 2.345m, 0079" […]
//! >    Module returns error code if measure failed, e.g.: ":Er08!" for reporting weak
//! >    reflect level error […];
//! > 5. 'M'(0x4D): Slow mode distance read for higher accuracy, returns same as 'D' command.
//! > 6. 'F'(0x46): Fast mode distance read for lower accuracy, but higher speed, returns
//! >    same as 'D' command.
//!
//! and from the same family's operation sequence: "Controller sends out the operation
//! command (single byte ASCII); Echo command from module to indicate command has been
//! received and now in progress; Command result from module." The reply therefore is the
//! echoed command byte, then the result; the parser ([`ReplyParser`]) skips the echo and
//! any CR/LF, and knows a result is complete from its own shape (four SQ digits after
//! `m,`, or the `!` of an error), so it does not depend on a line terminator.
//!
//! **Use with [`HardwareInstrument`](super::instrument::HardwareInstrument).** That
//! instrument speaks a generic line protocol to its EDM (`M\r\n` → `D <mm>\r\n` or
//! `E <code>\r\n`, code [`EDM_NO_RETURN`] = no return). [`B605b`] implements
//! `embedded_io::{Read, Write}` on that side and translates: a written `M` line makes it
//! send `D` to the module and turns the module's answer into the reply line. The module's
//! weak-reflection error `Er08` (no target, out of range) becomes a no-return; any other
//! module error code `Er<nn>` becomes `E <nn>` (a hardware fault upstream); a garbled reply
//! becomes `E 254`; a silent module (the port's `read` returns `Ok(0)`, e.g. on the
//! firmware's read timeout) ends the reply (upstream: `EdmEof`). Nothing here panics on
//! what the module sends.

use super::instrument::EDM_NO_RETURN;

/// The module's single-byte commands (quoted in the module docs above).
pub mod cmd {
    /// 'O' (0x4F): turn the laser beam on; replies ",OK!".
    pub const LASER_ON: u8 = b'O';
    /// 'C' (0x43): turn the laser beam off; replies ", OK!".
    pub const LASER_OFF: u8 = b'C';
    /// 'S' (0x53): status (temperature and battery voltage), e.g. "18.0'C, 2.7V".
    pub const STATUS: u8 = b'S';
    /// 'D' (0x44): auto-mode distance read, e.g. "12.345m, 0079" or ":Er08!".
    pub const MEASURE_AUTO: u8 = b'D';
    /// 'M' (0x4D): slow-mode (more accurate) distance read; replies as 'D'.
    pub const MEASURE_SLOW: u8 = b'M';
    /// 'F' (0x46): fast-mode (less accurate) distance read; replies as 'D'.
    pub const MEASURE_FAST: u8 = b'F';
}

/// The module's error code for a weak reflection (no target / out of range).
pub const ERR_WEAK_REFLECTION: u8 = 8;
/// The reply code [`B605b`] gives upstream for a reply it could not parse.
pub const REPLY_GARBLED: u16 = 254;
/// Longest result the parser accepts ("12.345m, 0079" is 13 bytes).
pub const MAX_REPLY: usize = 24;

/// One parsed distance reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    /// A distance (millimetres) and its signal quality (smaller = more reliable).
    Distance {
        /// Distance (mm).
        mm: u32,
        /// Signal quality SQ.
        quality: u16,
    },
    /// The module's error code (`:Er<nn>!`).
    Error(u8),
}

/// Error of [`B605b::measure`].
#[derive(Debug, PartialEq, Eq)]
pub enum LaserError<E> {
    /// The port failed.
    Port(E),
    /// The module went silent before the reply was complete.
    Silent,
    /// The reply did not parse, or outgrew [`MAX_REPLY`].
    Garbled,
}

/// Streaming parser of one distance reply ('D', 'M', 'F').
#[derive(Clone, Debug)]
pub struct ReplyParser {
    buf: [u8; MAX_REPLY],
    len: usize,
}

impl Default for ReplyParser {
    fn default() -> Self {
        Self::new()
    }
}

impl ReplyParser {
    /// An empty parser.
    pub const fn new() -> Self {
        ReplyParser {
            buf: [0; MAX_REPLY],
            len: 0,
        }
    }

    /// Feeds one byte; returns the result once the reply is complete (the parser is then
    /// empty again). `Some(Err(()))`: the reply is garbled.
    pub fn push(&mut self, b: u8) -> Option<Result<Reading, ()>> {
        // CR/LF and the echoed command byte before the result carry nothing.
        if b == b'\r' || b == b'\n' || (self.len == 0 && b.is_ascii_alphabetic()) {
            return None;
        }
        if self.len == self.buf.len() {
            self.len = 0;
            return Some(Err(()));
        }
        self.buf[self.len] = b;
        self.len += 1;
        let reply = &self.buf[..self.len];
        let done = if reply[0] == b':' {
            b == b'!'
        } else {
            // Complete once four signal-quality digits follow the "m,".
            match reply.iter().position(|&c| c == b'm') {
                Some(m) => {
                    let sq = &reply[m + 1..];
                    sq.iter().filter(|c| c.is_ascii_digit()).count() == 4
                        || sq.iter().any(|c| !matches!(c, b',' | b' ' | b'0'..=b'9'))
                }
                None => false,
            }
        };
        if !done {
            return None;
        }
        let result = parse(reply).ok_or(());
        self.len = 0;
        Some(result)
    }
}

/// Parses a complete result (echo and CR/LF already removed).
fn parse(reply: &[u8]) -> Option<Reading> {
    if let Some(code) = reply.strip_prefix(b":Er") {
        let code = code.strip_suffix(b"!")?;
        if code.is_empty() || code.len() > 2 || !code.iter().all(u8::is_ascii_digit) {
            return None;
        }
        return Some(Reading::Error(digits(code) as u8));
    }
    let m = reply.iter().position(|&c| c == b'm')?;
    let (number, rest) = (&reply[..m], &reply[m + 1..]);
    let rest = rest.strip_prefix(b",")?;
    let sq = trim_spaces(rest);
    if sq.len() != 4 || !sq.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let number = trim_spaces(number);
    let dot = number.iter().position(|&c| c == b'.')?;
    let (whole, frac) = (&number[..dot], &number[dot + 1..]);
    if whole.is_empty()
        || whole.len() > 4
        || frac.is_empty()
        || frac.len() > 3
        || !whole.iter().chain(frac).all(u8::is_ascii_digit)
    {
        return None;
    }
    let scale = [100, 10, 1][frac.len() - 1];
    Some(Reading::Distance {
        mm: digits(whole) * 1000 + digits(frac) * scale,
        quality: digits(sq) as u16,
    })
}

fn digits(d: &[u8]) -> u32 {
    d.iter().fold(0, |v, &c| v * 10 + (c - b'0') as u32)
}

fn trim_spaces(mut s: &[u8]) -> &[u8] {
    while let [b' ', rest @ ..] = s {
        s = rest;
    }
    while let [rest @ .., b' '] = s {
        s = rest;
    }
    s
}

/// The B605B on a byte port (`embedded_io`; a `read` returning `Ok(0)` means the module
/// stayed silent, e.g. the firmware's read timed out). Also the EDM side of
/// [`HardwareInstrument`](super::instrument::HardwareInstrument), see the module docs.
pub struct B605b<U> {
    port: U,
    /// Distance command sent for an `M` line from upstream.
    command: u8,
    /// Upstream line being written.
    line: [u8; 8],
    line_len: usize,
    /// The line outgrew `line` (it is not a request).
    overlong: bool,
    /// A complete `M` line waits for its measurement.
    requested: bool,
    /// Reply line for upstream and how much of it was read.
    reply: [u8; 12],
    reply_len: usize,
    reply_pos: usize,
}

impl<U: embedded_io::Read + embedded_io::Write> B605b<U> {
    /// The module on `port`, measuring in auto mode ('D').
    pub fn new(port: U) -> Self {
        B605b {
            port,
            command: cmd::MEASURE_AUTO,
            line: [0; 8],
            line_len: 0,
            overlong: false,
            requested: false,
            reply: [0; 12],
            reply_len: 0,
            reply_pos: 0,
        }
    }

    /// Measures with `command` ([`cmd::MEASURE_SLOW`] or [`cmd::MEASURE_FAST`]) instead of
    /// auto mode.
    pub fn with_command(mut self, command: u8) -> Self {
        self.command = command;
        self
    }

    /// Gives the port back.
    pub fn release(self) -> U {
        self.port
    }

    /// Sends `command` (one of the distance reads) and parses the module's reply.
    pub fn measure(&mut self, command: u8) -> Result<Reading, LaserError<U::Error>> {
        self.port.write_all(&[command]).map_err(LaserError::Port)?;
        self.port.flush().map_err(LaserError::Port)?;
        let mut parser = ReplyParser::new();
        // Echo, CR/LF and the result: bounded, so a babbling module cannot hold us here.
        for _ in 0..4 * MAX_REPLY {
            let mut b = [0u8; 1];
            if self.port.read(&mut b).map_err(LaserError::Port)? == 0 {
                return Err(LaserError::Silent);
            }
            if let Some(r) = parser.push(b[0]) {
                return r.map_err(|()| LaserError::Garbled);
            }
        }
        Err(LaserError::Garbled)
    }

    /// Runs the requested measurement and stores the upstream reply line.
    fn answer(&mut self) -> Result<(), U::Error> {
        let (tag, value) = match self.measure(self.command) {
            Ok(Reading::Distance { mm, .. }) => (b'D', mm),
            Ok(Reading::Error(ERR_WEAK_REFLECTION)) => (b'E', EDM_NO_RETURN as u32),
            Ok(Reading::Error(code)) => (b'E', code as u32),
            Err(LaserError::Garbled) => (b'E', REPLY_GARBLED as u32),
            Err(LaserError::Silent) => return Ok(()), // nothing to read: EOF upstream
            Err(LaserError::Port(e)) => return Err(e),
        };
        let mut digits = [0u8; 10];
        let mut n = 0;
        let mut v = value;
        loop {
            digits[n] = b'0' + (v % 10) as u8;
            n += 1;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        self.reply[0] = tag;
        self.reply[1] = b' ';
        let mut len = 2;
        for &d in digits[..n].iter().rev() {
            if len + 2 < self.reply.len() {
                self.reply[len] = d;
                len += 1;
            }
        }
        self.reply[len] = b'\r';
        self.reply[len + 1] = b'\n';
        self.reply_len = len + 2;
        self.reply_pos = 0;
        Ok(())
    }
}

impl<U: embedded_io::ErrorType> embedded_io::ErrorType for B605b<U> {
    type Error = U::Error;
}

impl<U: embedded_io::Read + embedded_io::Write> embedded_io::Write for B605b<U> {
    /// Takes the upstream request line; `M` requests one measurement. Other lines are
    /// ignored (their reply is EOF), an over-long line is dropped.
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            match b {
                b'\r' => {}
                b'\n' => {
                    self.requested = !self.overlong && &self.line[..self.line_len] == b"M";
                    self.line_len = 0;
                    self.overlong = false;
                    self.reply_len = 0;
                    self.reply_pos = 0;
                }
                _ if self.line_len < self.line.len() => {
                    self.line[self.line_len] = b;
                    self.line_len += 1;
                }
                _ => self.overlong = true,
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl<U: embedded_io::Read + embedded_io::Write> embedded_io::Read for B605b<U> {
    /// The reply line to the last `M` request (measured on the first read); `Ok(0)` when
    /// there is none or the module stayed silent.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if self.requested {
            self.requested = false;
            self.answer()?;
        }
        let rest = &self.reply[self.reply_pos..self.reply_len];
        let n = rest.len().min(buf.len());
        buf[..n].copy_from_slice(&rest[..n]);
        self.reply_pos += n;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::device::instrument::{
        HardwareInstrument, HwError, Instrument, NoScan, StepperConfig,
    };
    use embedded_hal_mock::eh1::delay::CheckedDelay;
    use embedded_hal_mock::eh1::digital::Mock as Pin;
    use std::vec::Vec;

    /// A scripted module: records what is sent, plays back `rx`, then stays silent.
    struct Module {
        tx: Vec<u8>,
        rx: Vec<u8>,
    }

    impl embedded_io::ErrorType for Module {
        type Error = embedded_io::ErrorKind;
    }
    impl embedded_io::Read for Module {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            if self.rx.is_empty() || buf.is_empty() {
                return Ok(0);
            }
            buf[0] = self.rx.remove(0);
            Ok(1)
        }
    }
    impl embedded_io::Write for Module {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.tx.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    fn module(rx: &[u8]) -> B605b<Module> {
        B605b::new(Module {
            tx: Vec::new(),
            rx: rx.to_vec(),
        })
    }

    fn parse_all(bytes: &[u8]) -> Vec<Result<Reading, ()>> {
        let mut p = ReplyParser::new();
        bytes.iter().filter_map(|&b| p.push(b)).collect()
    }

    #[test]
    fn parses_the_manuals_examples() {
        let d = |mm, quality| Ok(Reading::Distance { mm, quality });
        assert_eq!(parse_all(b"D12.345m, 0079"), [d(12_345, 79)]);
        assert_eq!(parse_all(b"D 2.345m, 0079\r\n"), [d(2_345, 79)]);
        assert_eq!(parse_all(b"M\r\n 0.051m,1234"), [d(51, 1234)]);
        assert_eq!(parse_all(b"D:Er08!"), [Ok(Reading::Error(8))]);
        assert_eq!(parse_all(b"F:Er15!\r\n"), [Ok(Reading::Error(15))]);
        // Two replies back to back.
        assert_eq!(
            parse_all(b"D 1.000m, 0001\r\nD:Er08!"),
            [d(1_000, 1), Ok(Reading::Error(8))]
        );
    }

    #[test]
    fn rejects_garbled_replies() {
        for bad in [
            &b"D12.3x5m, 0079"[..],
            b"D12345m, 0079",
            b"D.5m, 0079",
            b"D1.2345m, 0079",
            b"D:Erxx!",
            b"D:Er!",
            b"D1.000m; 0001",
        ] {
            assert_eq!(parse_all(bad), [Err(())], "{:?}", core::str::from_utf8(bad));
        }
        // A reply that never ends is cut at the buffer's size.
        let r = parse_all(&[b'7'; 3 * MAX_REPLY]);
        assert!(!r.is_empty() && r.iter().all(|x| x.is_err()));
    }

    #[test]
    fn measure_sends_the_command_and_reads_the_reply() {
        let mut m = module(b"D 3.250m, 0042\r\n");
        assert_eq!(
            m.measure(cmd::MEASURE_AUTO),
            Ok(Reading::Distance {
                mm: 3_250,
                quality: 42
            })
        );
        assert_eq!(m.release().tx, b"D");
        let mut m = module(b"M 3.2");
        assert_eq!(m.measure(cmd::MEASURE_SLOW), Err(LaserError::Silent));
        assert_eq!(m.release().tx, b"M");
    }

    const CFG: StepperConfig = StepperConfig {
        pulses_per_step: 1,
        pulse_us: 5,
        settle_ms: 20,
    };

    type Measured =
        Result<Option<f32>, HwError<embedded_hal_mock::eh1::MockError, embedded_io::ErrorKind>>;

    /// The whole chain: `HardwareInstrument` (mock pins and delay) → B605B driver →
    /// scripted module.
    fn instrument_measure(rx: &[u8]) -> (Measured, Vec<u8>) {
        let mut hw = HardwareInstrument::new(
            Pin::new(&[]),
            Pin::new(&[]),
            CheckedDelay::new(&[]),
            module(rx),
            NoScan,
            CFG,
        );
        let r = hw.measure();
        let (mut s, mut d, mut dl, edm, _) = hw.release();
        s.done();
        d.done();
        dl.done();
        (r, edm.release().tx)
    }

    #[test]
    fn hardware_instrument_measures_through_the_module() {
        assert_eq!(
            instrument_measure(b"D 3.250m, 0042\r\n"),
            (Ok(Some(3.25)), b"D".to_vec())
        );
        assert_eq!(
            instrument_measure(b"D12.345m, 0079"),
            (Ok(Some(12.345)), b"D".to_vec())
        );
        // Weak reflection: a no-return.
        assert_eq!(instrument_measure(b"D:Er08!"), (Ok(None), b"D".to_vec()));
        // Any other module error, a garbled reply: a hardware fault; silence: EOF.
        assert_eq!(instrument_measure(b"D:Er03!").0, Err(HwError::EdmProtocol));
        assert_eq!(
            instrument_measure(b"D3.2.5m, 0042").0,
            Err(HwError::EdmProtocol)
        );
        assert_eq!(instrument_measure(b"D 3.2").0, Err(HwError::EdmEof));
    }

    #[test]
    fn slow_mode_sends_m_and_other_lines_get_nothing() {
        let mut m = module(b"M 1.500m, 0010").with_command(cmd::MEASURE_SLOW);
        use embedded_io::{Read, Write};
        m.write_all(b"X\r\n").unwrap();
        let mut buf = [0u8; 16];
        assert_eq!(m.read(&mut buf), Ok(0));
        m.write_all(b"M\r\n").unwrap();
        let n = m.read(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"D 1500\r\n");
        assert_eq!(m.release().tx, b"M");
    }
}
