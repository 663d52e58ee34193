//! Framing of the protocol (`docs/protocol.md`): COBS, the CRC-32 trailer, the
//! fixed-buffer frame accumulator, and the episode trace hash.
//!
//! **Frame** = COBS( postcard((id: u16, message)) ‖ CRC-32(postcard bytes) as 4 bytes LE ) ‖ 0x00.
//! Encoding and decoding never panic and never allocate: every failure is a [`FrameError`].

use super::{WireError, MAX_FRAME, MAX_PAYLOAD, NO_ID};
pub use crate::checksum::{crc32, Crc32};
use crate::episode::{Action, Observation};
use serde::{de::DeserializeOwned, Serialize};

/// Local encode/decode failures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Output buffer too small / message larger than [`MAX_PAYLOAD`].
    TooLarge,
    /// Not valid COBS, or shorter than a CRC.
    Framing,
    /// CRC mismatch.
    Crc,
    /// The payload did not decode into the expected message type (or had trailing bytes).
    Decode,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::TooLarge => "frame too large",
            FrameError::Framing => "not a valid COBS frame",
            FrameError::Crc => "CRC mismatch",
            FrameError::Decode => "not a valid message",
        })
    }
}

impl FrameError {
    /// The [`WireError`] the device answers a bad frame with.
    pub fn to_wire(self) -> WireError {
        match self {
            FrameError::TooLarge => WireError::Oversized,
            FrameError::Framing => WireError::Framing,
            FrameError::Crc => WireError::Crc,
            FrameError::Decode => WireError::Decode,
        }
    }
}

/// Fingerprint of an episode's (action, observation) stream, computed identically by the
/// device and the host: per step, the action id byte (0 left, 1 right, 2 measure), the
/// range as 4 LE bytes of its f32 bits (`0xFFFF_FFFF` for no range), the scan as 4 LE bytes.
#[derive(Clone, Copy, Debug, Default)]
pub struct TraceHash(Crc32);

impl TraceHash {
    /// Empty trace.
    pub const fn new() -> Self {
        TraceHash(Crc32::new())
    }
    /// Books one step.
    pub fn push(&mut self, action: Action, obs: &Observation) {
        let a = match action {
            Action::RotateLeft => 0u8,
            Action::RotateRight => 1,
            Action::Measure => 2,
        };
        let r = obs.range.map(f32::to_bits).unwrap_or(0xFFFF_FFFF);
        self.0.update(&[a]);
        self.0.update(&r.to_le_bytes());
        self.0.update(&obs.scan.to_le_bytes());
    }
    /// The fingerprint.
    pub fn value(&self) -> u32 {
        self.0.finish()
    }
}

// ---------------------------------------------------------------------------------------
// COBS

/// COBS-encodes `src` into `dst` (no delimiter); returns the encoded length. Our own
/// codec, not the `cobs` crate: `docs/protocol.md` ("CRC-32 and COBS") has the measured
/// reasons (frame bytes, buffer bounds, error rules).
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Result<usize, FrameError> {
    let mut code_idx = 0usize;
    let mut out = 1usize;
    let mut code = 1u8;
    if dst.is_empty() {
        return Err(FrameError::TooLarge);
    }
    for &b in src {
        if b == 0 {
            *dst.get_mut(code_idx).ok_or(FrameError::TooLarge)? = code;
            code_idx = out;
            out += 1;
            code = 1;
        } else {
            *dst.get_mut(out).ok_or(FrameError::TooLarge)? = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                *dst.get_mut(code_idx).ok_or(FrameError::TooLarge)? = code;
                code_idx = out;
                out += 1;
                code = 1;
            }
        }
    }
    *dst.get_mut(code_idx).ok_or(FrameError::TooLarge)? = code;
    Ok(out)
}

/// Decodes a COBS block (without delimiter) in place; returns the decoded length.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    let mut r = 0usize;
    let mut w = 0usize;
    let n = buf.len();
    while r < n {
        let code = buf[r];
        if code == 0 {
            return Err(FrameError::Framing);
        }
        r += 1;
        let run = code as usize - 1;
        if r + run > n {
            return Err(FrameError::Framing);
        }
        for i in 0..run {
            let b = buf[r + i];
            if b == 0 {
                return Err(FrameError::Framing);
            }
            // w <= r - 1 < r + i always: each code byte yields at most one output zero.
            buf[w] = b;
            w += 1;
        }
        r += run;
        if code != 0xFF && r < n {
            buf[w] = 0;
            w += 1;
        }
    }
    Ok(w)
}

// ---------------------------------------------------------------------------------------
// Frames

/// Encodes `(id, msg)` as a complete frame (COBS + trailing `0x00`) into `out`; returns
/// the number of bytes to send.
pub fn encode_frame<M: Serialize>(id: u16, msg: &M, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_PAYLOAD];
    let body = postcard::to_slice(&(id, msg), &mut raw[..MAX_PAYLOAD - 4])
        .map_err(|_| FrameError::TooLarge)?;
    let n = body.len();
    let crc = crc32(&raw[..n]);
    raw[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let len = cobs_encode(&raw[..n + 4], out)?;
    *out.get_mut(len).ok_or(FrameError::TooLarge)? = 0;
    Ok(len + 1)
}

/// Decodes one frame body (the bytes between delimiters, delimiter excluded) in place.
pub fn decode_frame<M: DeserializeOwned>(buf: &mut [u8]) -> Result<(u16, M), FrameError> {
    decode_frame_with_id(buf).map_err(|(e, _)| e)
}

/// Reads the request id of a frame whose message did not decode (CRC was good), so a
/// `Decode` error can still be correlated. Works on the *decoded* payload.
fn peek_id(body: &[u8]) -> Option<u16> {
    postcard::take_from_bytes::<u16>(body)
        .ok()
        .map(|(id, _)| id)
}

/// What the accumulator produced from the bytes fed so far.
#[derive(Debug)]
pub enum Feed<'a> {
    /// More bytes needed.
    Pending,
    /// An empty frame (resynchronisation delimiter): ignore.
    Empty,
    /// A complete frame body (COBS-encoded, delimiter stripped), ready for
    /// [`decode_frame`] (which decodes in place).
    Frame(&'a mut [u8]),
    /// The frame exceeded [`MAX_FRAME`]; the bytes up to and including this delimiter
    /// were discarded.
    Oversized,
}

/// Fixed-buffer frame accumulator: collects bytes up to a `0x00` delimiter.
///
/// Overflow puts it into a discard state until the next delimiter, so one oversized frame
/// costs exactly one `Oversized` event and the link resynchronises on the next frame.
pub struct FrameAccumulator {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflow: bool,
}

impl Default for FrameAccumulator {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameAccumulator {
    /// An empty accumulator.
    pub const fn new() -> Self {
        FrameAccumulator {
            buf: [0; MAX_FRAME],
            len: 0,
            overflow: false,
        }
    }

    /// Drops any partial frame.
    pub fn clear(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// True when a partial frame is buffered.
    pub fn is_partial(&self) -> bool {
        self.len > 0 || self.overflow
    }

    /// Feeds one byte.
    pub fn push(&mut self, b: u8) -> Feed<'_> {
        if b == 0 {
            let (len, over) = (self.len, self.overflow);
            self.clear();
            if over {
                return Feed::Oversized;
            }
            if len == 0 {
                return Feed::Empty;
            }
            return Feed::Frame(&mut self.buf[..len]);
        }
        if self.overflow {
            return Feed::Pending;
        }
        // The delimiter is not stored, so a full frame body is at most MAX_FRAME - 1.
        if self.len >= MAX_FRAME - 1 {
            self.overflow = true;
            self.len = 0;
            return Feed::Pending;
        }
        self.buf[self.len] = b;
        self.len += 1;
        Feed::Pending
    }
}

/// Decodes a frame body; on a CRC-good but undecodable payload also returns the id.
pub fn decode_frame_with_id<M: DeserializeOwned>(
    buf: &mut [u8],
) -> Result<(u16, M), (FrameError, u16)> {
    let n = cobs_decode_in_place(buf).map_err(|e| (e, NO_ID))?;
    if n < 5 {
        return Err((FrameError::Framing, NO_ID));
    }
    let (body, crc) = buf[..n].split_at(n - 4);
    let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if crc32(body) != want {
        return Err((FrameError::Crc, NO_ID));
    }
    match postcard::take_from_bytes::<(u16, M)>(body) {
        Ok((v, [])) => Ok(v),
        _ => Err((FrameError::Decode, peek_id(body).unwrap_or(NO_ID))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{ActionCosts, AgentKind, EpisodeConfig, Observation, Termination};
    use crate::protocol::{EpisodeParams, Request, MAX_WIRE_VERTICES, PROTOCOL_VERSION};
    use crate::world::geometry::{v2, Pose2};
    use heapless::Vec as HVec;

    #[test]
    fn cobs_round_trip_edge_cases() {
        let cases: [&[u8]; 6] = [&[], &[0], &[0, 0], &[1, 2, 0, 3], &[0xFF; 254], &[7; 600]];
        for src in cases {
            let mut enc = [0u8; 1024];
            let n = cobs_encode(src, &mut enc).unwrap();
            assert!(!enc[..n].contains(&0));
            let d = cobs_decode_in_place(&mut enc[..n]).unwrap();
            assert_eq!(&enc[..d], src);
        }
    }

    /// Frames byte for byte: a block of 254 non-zero bytes at the end is followed by the
    /// code byte 0x01 (the `cobs` crate omits it), and a `StartEpisode` frame: protocol v5's
    /// payload (encoded by the code before the one `EpisodeParams`) and, since v9, the
    /// instrument profile's byte, then the frame's CRC.
    #[test]
    fn frame_bytes_are_protocol_v9() {
        let mut enc = [0u8; 300];
        let n = cobs_encode(&[0xFF; 254], &mut enc).unwrap();
        assert_eq!((n, enc[0], enc[255]), (256, 0xFF, 0x01));
        const V9_START_EPISODE: [u8; 50] = [
            17, 42, 3, 4, 239, 155, 175, 205, 248, 172, 209, 145, 1, 54, 100, 10, 1, 1, 4, 128, 62,
            1, 1, 1, 2, 63, 1, 3, 128, 190, 1, 9, 128, 63, 22, 1, 205, 204, 76, 61, 1, 1, 2, 62, 5,
            38, 247, 45, 129, 0,
        ];
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(42, &Request::StartEpisode(episode_params()), &mut out).unwrap();
        assert_eq!(out[..n], V9_START_EPISODE);
        let mut f = V9_START_EPISODE;
        assert_eq!(
            decode_frame::<Request>(&mut f[..49]).unwrap(),
            (42, Request::StartEpisode(episode_params()))
        );
    }

    /// Protocol v6: `DeviceInfo` ends with `max_reply_ms` (a varint), byte for byte.
    #[test]
    fn hello_reply_bytes_are_protocol_v6() {
        use crate::protocol::{DeviceInfo, GridInfo, Response};
        let mut firmware = heapless::String::new();
        firmware.push_str("fw").unwrap();
        let info = DeviceInfo {
            protocol: 6,
            firmware,
            grid: GridInfo {
                cells_x: 30,
                cells_y: 30,
                cell_mm: 0,
            },
            max_vertices: 64,
            max_actions: 500,
            max_rot_bins: 10,
            scan_pixels: 20,
            max_frame: MAX_FRAME as u16,
            capabilities: 0xFF,
            max_reply_ms: 20_000,
        };
        let mut raw = [0u8; 64];
        let body = postcard::to_slice(&(0u16, Response::Hello(info.clone())), &mut raw).unwrap();
        // ... capabilities 0xFF (varint FF 01), then max_reply_ms 20000 (varint A0 9C 01).
        assert_eq!(&body[body.len() - 5..], &[0xFF, 0x01, 0xA0, 0x9C, 0x01]);
        const V6_HELLO: [u8; 27] = [
            1, 1, 7, 6, 2, 102, 119, 30, 30, 17, 64, 244, 3, 10, 20, 237, 7, 255, 1, 160, 156, 1,
            147, 178, 202, 218, 0,
        ];
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(0, &Response::Hello(info.clone()), &mut out).unwrap();
        assert_eq!(out[..n], V6_HELLO);
        let mut f = V6_HELLO;
        assert_eq!(
            decode_frame::<Response>(&mut f[..n - 1]).unwrap(),
            (0, Response::Hello(info))
        );
    }

    fn roundtrip(msg: &Request) {
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(42, msg, &mut out).unwrap();
        assert_eq!(out[n - 1], 0);
        assert!(!out[..n - 1].contains(&0));
        let mut acc = FrameAccumulator::new();
        let mut got = None;
        for &b in &out[..n] {
            if let Feed::Frame(f) = acc.push(b) {
                got = Some(decode_frame::<Request>(f).unwrap());
            }
        }
        assert_eq!(got, Some((42, msg.clone())));
    }

    #[test]
    fn messages_round_trip() {
        roundtrip(&Request::Hello {
            protocol: PROTOCOL_VERSION,
        });
        roundtrip(&Request::Observe {
            step: 7,
            observation: Observation {
                range: Some(3.25),
                scan: 0b1011,
            },
        });
        let mut v = HVec::new();
        for i in 0..MAX_WIRE_VERTICES {
            v.push([i as f32, -(i as f32)]).unwrap();
        }
        // The largest LoadPlan: every vertex, every ring end, every opening bit.
        let mut rings = HVec::new();
        for r in 0..crate::protocol::MAX_WIRE_RINGS {
            rings.push(200 + r as u8).unwrap();
        }
        roundtrip(&Request::LoadPlan {
            vertices: v.clone(),
            rings,
            openings: u64::MAX,
        });
        // A room with a column and a door, as the host sends it.
        let p = crate::FloorPlan::with_columns_and_doors(
            &[v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)],
            &[&[v2(3.5, 1.5), v2(3.5, 2.5), v2(4.5, 2.5), v2(4.5, 1.5)]],
            &[(v2(1.0, 0.0), v2(2.0, 0.0))],
            0.02,
        )
        .unwrap();
        let msg = Request::LoadPlan {
            vertices: HVec::from_slice(p.raw()).unwrap(),
            rings: HVec::from_slice(p.ring_ends()).unwrap(),
            openings: p.openings(),
        };
        roundtrip(&msg);
        let Request::LoadPlan {
            vertices,
            rings,
            openings,
        } = msg
        else {
            unreachable!()
        };
        assert_eq!(
            crate::FloorPlan::from_parts(&vertices, &rings, openings).as_ref(),
            Ok(&p)
        );
        roundtrip(&Request::LoadPlan {
            vertices: v,
            rings: heapless::Vec::new(),
            openings: 0,
        });
    }

    fn episode_params() -> EpisodeParams {
        EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 0x0123_4567_89AB_CDEF,
            rot_bins: 10,
            known_heading: Some(0.25),
            ground_truth: Some(Pose2::new(0.5, -0.25, 1.0)),
            initial_scan: 0b1_0110,
            termination: Termination::Confident,
            config: EpisodeConfig {
                steps_per_turn: 54,
                max_actions: 100,
                costs: ActionCosts::default(),
                stop_risk: 0.05,
                instrument: crate::episode::InstrumentProfile::EdmScan,
                min_observability: 0.125,
            },
        }
    }

    #[test]
    fn episode_params_round_trip_with_stop_rule() {
        let p = episode_params();
        roundtrip(&Request::StartEpisode(p));
        let mut off = p;
        off.config.stop_risk = 1.0;
        off.config.min_observability = 0.0;
        roundtrip(&Request::StartEpisode(off));
        // v4 layout: the two f32 follow the rule, stop_risk first, each 4 raw LE bytes; since
        // v9 the instrument profile's byte closes the message.
        let mut raw = [0u8; MAX_PAYLOAD];
        let body = postcard::to_slice(&(42u16, Request::StartEpisode(p)), &mut raw).unwrap();
        let n = body.len() - 1;
        assert_eq!(body[n], 0, "the paper's sensor");
        assert_eq!(&body[n - 8..n - 4], &0.05f32.to_le_bytes());
        assert_eq!(&body[n - 4..n], &0.125f32.to_le_bytes());
        // A v3 StartEpisode (the same message without the two fields) no longer decodes.
        let crc = crc32(&body[..n - 8]);
        raw[n - 8..n - 4].copy_from_slice(&crc.to_le_bytes());
        let mut v3 = [0u8; MAX_FRAME];
        let m = cobs_encode(&raw[..n - 4], &mut v3).unwrap();
        assert_eq!(
            decode_frame_with_id::<Request>(&mut v3[..m]).unwrap_err(),
            (FrameError::Decode, 42)
        );
    }

    #[test]
    fn corruption_is_detected() {
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(3, &Request::Ping { nonce: 9 }, &mut out).unwrap();
        for i in 0..n - 1 {
            for bit in 0..8 {
                let mut f = out;
                f[i] ^= 1 << bit;
                if f[i] == 0 {
                    continue; // a new delimiter: a truncated frame, covered elsewhere
                }
                assert!(
                    decode_frame::<Request>(&mut f[..n - 1]).is_err(),
                    "byte {i} bit {bit}"
                );
            }
        }
    }

    #[test]
    fn oversized_frames_resync() {
        let mut acc = FrameAccumulator::new();
        for _ in 0..MAX_FRAME + 10 {
            assert!(matches!(acc.push(0x55), Feed::Pending));
        }
        assert!(matches!(acc.push(0), Feed::Oversized));
        let mut out = [0u8; MAX_FRAME];
        let n = encode_frame(1, &Request::Status, &mut out).unwrap();
        let mut ok = false;
        for &b in &out[..n] {
            if let Feed::Frame(f) = acc.push(b) {
                ok = decode_frame::<Request>(f).unwrap() == (1, Request::Status);
            }
        }
        assert!(ok);
    }

    #[test]
    fn decode_error_keeps_id() {
        // A valid CRC over an id followed by an unknown enum variant.
        let mut raw = [0u8; 16];
        let body = postcard::to_slice(&(77u16, 200u8), &mut raw).unwrap().len();
        let crc = crc32(&raw[..body]);
        raw[body..body + 4].copy_from_slice(&crc.to_le_bytes());
        let mut enc = [0u8; 32];
        let n = cobs_encode(&raw[..body + 4], &mut enc).unwrap();
        let e = decode_frame_with_id::<Request>(&mut enc[..n]).unwrap_err();
        assert_eq!(e, (FrameError::Decode, 77));
    }

    proptest::proptest! {
        #[test]
        fn decoder_never_panics(data in proptest::collection::vec(proptest::num::u8::ANY, 0..1200)) {
            let mut acc = FrameAccumulator::new();
            for b in data {
                if let Feed::Frame(f) = acc.push(b) {
                    let _ = decode_frame_with_id::<Request>(f);
                }
            }
        }
    }
}
