//! The instrument's sensors and actuators behind one trait, and the embedded-hal 1.0
//! hardware implementation.
//!
//! The firmware owns the decisions (which action next, localization, registration); an
//! [`Instrument`] only *answers*: it turns the bearing motor one rotation step, takes one
//! EDM range measurement, and reports the topological scan at the current bearing.
//!
//! Implementations:
//! * [`HardwareInstrument`] (here): a stepper motor on step/dir pins ([`OutputPin`] +
//!   [`DelayNs`]) turns the bearing; the EDM sits on its own UART ([`embedded_io`]).
//!   Host-tested against `embedded-hal-mock` (see the tests below).
//! * The *remote* instrument: in simulation the host plays the sensors over the serial link.
//!   On the device this is the [`crate::device`] state machine itself (its `Act` replies
//!   are the action requests); on the host, the simulated world implements this trait and
//!   answers them (`activesense_sim::link`).
//!
//! [`run_local`] runs a whole episode against any `Instrument` in-process (the firmware's
//! stand-alone mode on real hardware, and the reference run the link tests compare to).

use crate::device::{Controller, Step};
use crate::episode::Action;
use crate::episode::{Observation, SCAN_PIXELS};
use crate::protocol::{EpisodeParams, EpisodeReport, WireError};
use crate::FloorPlan;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;

/// Rotation direction of one bearing step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Turn {
    /// Counter-clockwise (+1 encoder step).
    Left,
    /// Clockwise (−1 encoder step).
    Right,
}

/// The instrument's sensors/actuators.
pub trait Instrument {
    /// Hardware or link error.
    type Error;
    /// Turns the bearing by one rotation step.
    fn rotate(&mut self, turn: Turn) -> Result<(), Self::Error>;
    /// One EDM range measurement along the current bearing (m); `None` = no return.
    fn measure(&mut self) -> Result<Option<f32>, Self::Error>;
    /// Topological scan at the current bearing (bit i = pixel i, [`SCAN_PIXELS`] bits).
    fn scan(&mut self) -> Result<u32, Self::Error>;

    /// Performs `action` and reports the observation after it.
    fn perform(&mut self, action: Action) -> Result<Observation, Self::Error> {
        let range = match action {
            Action::Measure => self.measure()?,
            Action::RotateLeft => {
                self.rotate(Turn::Left)?;
                None
            }
            Action::RotateRight => {
                self.rotate(Turn::Right)?;
                None
            }
        };
        let scan = self.scan()?;
        Ok(Observation { range, scan })
    }
}

/// Error of [`run_local`].
#[derive(Debug, PartialEq)]
pub enum LocalError<E> {
    /// The controller rejected the plan, parameters or an observation.
    Rejected(WireError),
    /// The instrument failed.
    Instrument(E),
}

/// Runs one episode in-process: `controller` decides, `instrument` answers. Calls
/// `on_step` for every (action, observation). Identical, step for step, to the same
/// episode run over the serial link.
pub fn run_local<I: Instrument>(
    controller: &mut Controller,
    plan: &FloorPlan,
    params: &EpisodeParams,
    instrument: &mut I,
    mut on_step: impl FnMut(Action, &Observation),
) -> Result<EpisodeReport, LocalError<I::Error>> {
    controller.load_plan(plan.clone());
    controller.start(params).map_err(LocalError::Rejected)?;
    loop {
        match controller.next_step() {
            None => return Err(LocalError::Rejected(WireError::UnexpectedRequest)),
            Some(Step::Done(report)) => return Ok(report),
            Some(Step::Act { action, step }) => {
                let obs = instrument.perform(action).map_err(LocalError::Instrument)?;
                on_step(action, &obs);
                controller
                    .observe(step, &obs)
                    .map_err(LocalError::Rejected)?;
            }
        }
    }
}

/// Source of the topological scan on real hardware (camera + junction detector). The
/// image pipeline is outside this crate; [`NoScan`] reports an empty scan.
pub trait ScanSensor {
    /// Current scan bits.
    fn scan(&mut self) -> u32;
}

/// A scan sensor that sees nothing (instrument without camera).
pub struct NoScan;

impl ScanSensor for NoScan {
    fn scan(&mut self) -> u32 {
        0
    }
}

/// Timing/geometry of the bearing drive.
#[derive(Clone, Copy, Debug)]
pub struct StepperConfig {
    /// Motor (micro)steps per rotation step of the episode (e.g. 200·16/54 rounded).
    pub pulses_per_step: u32,
    /// High and low time of one step pulse (µs).
    pub pulse_us: u32,
    /// Settling time after a rotation step before the next measurement (ms).
    pub settle_ms: u32,
}

/// Hardware error of [`HardwareInstrument`].
#[derive(Debug, PartialEq, Eq)]
pub enum HwError<P, U> {
    /// A step/dir pin failed.
    Pin(P),
    /// The EDM UART failed.
    Uart(U),
    /// The EDM closed the line (read returned 0 bytes).
    EdmEof,
    /// The EDM reply did not parse (or exceeded its line buffer).
    EdmProtocol,
}

/// Longest EDM reply line.
pub const EDM_LINE: usize = 32;
/// EDM error code meaning "no return" (no target / signal too weak / out of range).
pub const EDM_NO_RETURN: u16 = 255;

/// The instrument on real hardware: stepper for the bearing, EDM on a UART.
///
/// **EDM line protocol** (generic ASCII; adapt [`parse_edm_line`] to the actual module):
/// the controller sends `M\r\n`; the EDM answers one line, `D <millimetres>\r\n` for a
/// distance or `E <code>\r\n` for an error; code [`EDM_NO_RETURN`] is a no-return, any
/// other code an [`HwError::EdmProtocol`].
pub struct HardwareInstrument<STEP, DIR, D, U, S> {
    step: STEP,
    dir: DIR,
    delay: D,
    edm: U,
    scanner: S,
    config: StepperConfig,
}

impl<STEP, DIR, D, U, S, PE> HardwareInstrument<STEP, DIR, D, U, S>
where
    STEP: OutputPin<Error = PE>,
    DIR: OutputPin<Error = PE>,
    D: DelayNs,
    U: embedded_io::Read + embedded_io::Write,
    S: ScanSensor,
{
    /// Assembles the instrument.
    pub fn new(step: STEP, dir: DIR, delay: D, edm: U, scanner: S, config: StepperConfig) -> Self {
        HardwareInstrument {
            step,
            dir,
            delay,
            edm,
            scanner,
            config,
        }
    }

    /// Gives the parts back.
    pub fn release(self) -> (STEP, DIR, D, U, S) {
        (self.step, self.dir, self.delay, self.edm, self.scanner)
    }
}

/// Parses one EDM reply line (without line terminator).
pub fn parse_edm_line(line: &[u8]) -> Option<Option<f32>> {
    let (tag, rest) = match line {
        [t, b' ', rest @ ..] => (*t, rest),
        _ => return None,
    };
    if rest.is_empty() || rest.len() > 9 || !rest.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let value = rest.iter().fold(0u32, |v, &d| v * 10 + (d - b'0') as u32);
    match tag {
        b'D' => Some(Some(value as f32 / 1000.0)),
        b'E' if value == EDM_NO_RETURN as u32 => Some(None),
        _ => None,
    }
}

impl<STEP, DIR, D, U, S, PE> Instrument for HardwareInstrument<STEP, DIR, D, U, S>
where
    STEP: OutputPin<Error = PE>,
    DIR: OutputPin<Error = PE>,
    D: DelayNs,
    U: embedded_io::Read + embedded_io::Write,
    S: ScanSensor,
{
    type Error = HwError<PE, U::Error>;

    fn rotate(&mut self, turn: Turn) -> Result<(), Self::Error> {
        match turn {
            Turn::Left => self.dir.set_high(),
            Turn::Right => self.dir.set_low(),
        }
        .map_err(HwError::Pin)?;
        for _ in 0..self.config.pulses_per_step {
            self.step.set_high().map_err(HwError::Pin)?;
            self.delay.delay_us(self.config.pulse_us);
            self.step.set_low().map_err(HwError::Pin)?;
            self.delay.delay_us(self.config.pulse_us);
        }
        self.delay.delay_ms(self.config.settle_ms);
        Ok(())
    }

    fn measure(&mut self) -> Result<Option<f32>, Self::Error> {
        self.edm.write_all(b"M\r\n").map_err(HwError::Uart)?;
        self.edm.flush().map_err(HwError::Uart)?;
        let mut line = [0u8; EDM_LINE];
        let mut len = 0;
        loop {
            let mut b = [0u8; 1];
            let n = self.edm.read(&mut b).map_err(HwError::Uart)?;
            if n == 0 {
                return Err(HwError::EdmEof);
            }
            match b[0] {
                b'\r' => {}
                b'\n' => break,
                c => {
                    *line.get_mut(len).ok_or(HwError::EdmProtocol)? = c;
                    len += 1;
                }
            }
        }
        parse_edm_line(&line[..len]).ok_or(HwError::EdmProtocol)
    }

    fn scan(&mut self) -> Result<u32, Self::Error> {
        Ok(self.scanner.scan() & ((1u32 << SCAN_PIXELS) - 1))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as D};
    use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as P};
    use std::vec::Vec;

    /// Scripted embedded-io UART: checks what is written, plays back `rx`.
    struct ScriptUart {
        expect_tx: Vec<u8>,
        tx: Vec<u8>,
        rx: Vec<u8>,
    }

    impl embedded_io::ErrorType for ScriptUart {
        type Error = embedded_io::ErrorKind;
    }
    impl embedded_io::Read for ScriptUart {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            if self.rx.is_empty() || buf.is_empty() {
                return Ok(0);
            }
            buf[0] = self.rx.remove(0);
            Ok(1)
        }
    }
    impl embedded_io::Write for ScriptUart {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.tx.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    fn uart(rx: &[u8], expect_tx: &[u8]) -> ScriptUart {
        ScriptUart {
            expect_tx: expect_tx.to_vec(),
            tx: Vec::new(),
            rx: rx.to_vec(),
        }
    }

    const CFG: StepperConfig = StepperConfig {
        pulses_per_step: 2,
        pulse_us: 5,
        settle_ms: 20,
    };

    #[test]
    fn rotate_left_pulses_step_pin_with_dir_high() {
        let step = Pin::new(&[
            P::set(State::High),
            P::set(State::Low),
            P::set(State::High),
            P::set(State::Low),
        ]);
        let dir = Pin::new(&[P::set(State::High)]);
        let delay = CheckedDelay::new(&[
            D::delay_us(5),
            D::delay_us(5),
            D::delay_us(5),
            D::delay_us(5),
            D::delay_ms(20),
        ]);
        let mut hw = HardwareInstrument::new(step, dir, delay, uart(b"", b""), NoScan, CFG);
        let obs = hw.perform(Action::RotateLeft).unwrap();
        assert_eq!(
            obs,
            Observation {
                range: None,
                scan: 0
            }
        );
        let (mut step, mut dir, mut delay, u, _) = hw.release();
        step.done();
        dir.done();
        delay.done();
        assert!(u.tx.is_empty());
    }

    #[test]
    fn rotate_right_sets_dir_low() {
        let step = Pin::new(&[P::set(State::High), P::set(State::Low)]);
        let dir = Pin::new(&[P::set(State::Low)]);
        let delay = CheckedDelay::new(&[D::delay_us(5), D::delay_us(5), D::delay_ms(20)]);
        let cfg = StepperConfig {
            pulses_per_step: 1,
            ..CFG
        };
        let mut hw = HardwareInstrument::new(step, dir, delay, uart(b"", b""), NoScan, cfg);
        hw.rotate(Turn::Right).unwrap();
        let (mut step, mut dir, mut delay, _, _) = hw.release();
        step.done();
        dir.done();
        delay.done();
    }

    #[test]
    fn measure_parses_distance_and_no_return() {
        let pins = || (Pin::new(&[]), Pin::new(&[]), CheckedDelay::new(&[]));
        let (s, d, dl) = pins();
        let mut hw = HardwareInstrument::new(s, d, dl, uart(b"D 3250\r\n", b"M\r\n"), NoScan, CFG);
        assert_eq!(hw.measure(), Ok(Some(3.25)));
        let (mut s, mut d, mut dl, u, _) = hw.release();
        assert_eq!(u.tx, u.expect_tx);
        s.done();
        d.done();
        dl.done();

        let (s, d, dl) = pins();
        let mut hw = HardwareInstrument::new(s, d, dl, uart(b"E 255\r\n", b"M\r\n"), NoScan, CFG);
        assert_eq!(hw.measure(), Ok(None));
        let (mut s, mut d, mut dl, _, _) = hw.release();
        s.done();
        d.done();
        dl.done();
    }

    #[test]
    fn measure_rejects_garbage_and_eof() {
        for (rx, want) in [
            (&b"E 12\r\n"[..], HwError::EdmProtocol),
            (&b"D 3x\r\n"[..], HwError::EdmProtocol),
            (&b"D 1"[..], HwError::EdmEof),
            (&[b'7'; 40][..], HwError::EdmProtocol),
        ] {
            let mut hw = HardwareInstrument::new(
                Pin::new(&[]),
                Pin::new(&[]),
                CheckedDelay::new(&[]),
                uart(rx, b"M\r\n"),
                NoScan,
                CFG,
            );
            assert_eq!(hw.measure(), Err(want));
            let (mut s, mut d, mut dl, _, _) = hw.release();
            s.done();
            d.done();
            dl.done();
        }
    }
}
