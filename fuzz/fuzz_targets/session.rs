//! Fuzzes the frame decoder and the device session state machine: arbitrary bytes (with
//! the input's first byte choosing how they are split into reads and how time advances)
//! must never panic, and every reply the device writes must itself be a valid frame.
#![no_main]

use activesense_core::device::{Session, SessionConfig};
use activesense_core::protocol::{decode_frame, Feed, FrameAccumulator, Response};
use libfuzzer_sys::fuzz_target;

struct Sink(Vec<u8>);
impl embedded_io::ErrorType for Sink {
    type Error = core::convert::Infallible;
}
impl embedded_io::Write for Sink {
    fn write(&mut self, b: &[u8]) -> Result<usize, Self::Error> {
        self.0.extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&ctl, rest)) = data.split_first() else { return };
    let mut s = Box::new(Session::new(SessionConfig {
        firmware: "fuzz",
        timeout_ms: 50,
        max_reply_ms: 1000,
        cycle_clock: None,
        // The firmware's policies: learnt-int8 episodes and uploads are fuzzed too.
        policies: &activesense_core::policy::builtin::POLICIES,
        stack_usage: None,
    }));
    let mut out = Sink(Vec::new());
    let chunk = 1 + (ctl as usize & 31);
    let mut now = 0u32;
    for part in rest.chunks(chunk) {
        let _ = s.feed(part, now, &mut out);
        now = now.wrapping_add((ctl >> 5) as u32 * 20);
        s.poll(now);
    }
    let mut acc = FrameAccumulator::new();
    for &b in &out.0 {
        if let Feed::Frame(f) = acc.push(b) {
            decode_frame::<Response>(f).expect("device emitted an invalid frame");
        }
    }
});
