//! The host ⇄ instrument serial protocol, shared byte for byte by the firmware and the
//! host: the messages ([`messages`]) and their framing ([`framing`]: COBS, CRC-32, the
//! fixed-buffer accumulator, the episode trace hash). The full specification is
//! `docs/protocol.md`; this module is its reference implementation.
//!
//! **Layering.** The protocol sits above the pipeline in the module tree but imports only
//! [`crate::limits`], [`crate::world`], [`crate::episode`] (the episode's parameters,
//! actions and observations are what the messages carry), the [`crate::checksum`] leaf
//! and one leaf error type, [`crate::policy::int8::error::BlobError`]: a rejected policy
//! upload reports the blob parser's exact reason (`PolicyError::Invalid`). That leaf
//! imports nothing; a protocol-level copy of its variants would be a second list that has
//! to stay in step with the parser's by hand, on the wire byte for byte.
//!
//! **Frame** = COBS( postcard((id: u16, message)) ‖ CRC-32(postcard bytes) as 4 bytes LE ) ‖ 0x00.
//!
//! * `id` is the request id; every host request (non-zero id) gets exactly one reply
//!   carrying the same id. Replies to frames whose id cannot be trusted (bad COBS, bad
//!   CRC, undecodable, oversized) carry [`NO_ID`].
//! * CRC-32 is the IEEE/ISO-HDLC CRC (reflected polynomial `0xEDB88320`, init and xorout
//!   `0xFFFFFFFF`; check value of `"123456789"` is `0xCBF43926`).
//! * A frame is at most [`MAX_FRAME`] bytes on the wire including the delimiter; the
//!   CRC-protected payload at most [`MAX_PAYLOAD`] bytes.
//! * Empty frames (two delimiters in a row) are ignored, so a sender may emit a lone
//!   `0x00` at any time to resynchronise the receiver.
//!
//! Encoding and decoding never panic and never allocate: every failure is a [`FrameError`].

pub mod framing;
pub mod messages;

pub use crate::episode::{EpisodeParams, ObservationError, ParamError};
pub use framing::*;
pub use messages::*;

/// Protocol version; bumped on every incompatible change of a message or of the framing.
pub const PROTOCOL_VERSION: u16 = 10;
/// The id carried by device replies to frames whose own id could not be read.
pub const NO_ID: u16 = 0;
/// Largest CRC-protected payload (postcard bytes + 4 CRC bytes).
pub const MAX_PAYLOAD: usize = 1000;
/// Largest frame on the wire: COBS adds one byte per 254 plus one, then the delimiter.
pub const MAX_FRAME: usize = MAX_PAYLOAD + MAX_PAYLOAD / 254 + 2;
/// Vertex capacity of a `LoadPlan` message. Larger than [`crate::MAX_VERTICES`] on
/// purpose, so that a plan with too many vertices is answered with the typed
/// `InvalidPlan(TooManyVertices)` rather than a decode error. Beyond this the frame
/// exceeds [`MAX_PAYLOAD`] and is answered with `Oversized`.
pub const MAX_WIRE_VERTICES: usize = 120;
/// Ring capacity of a `LoadPlan` message: above [`crate::limits::MAX_RINGS`] for the same
/// reason, so too many columns are answered with the typed `InvalidPlan(TooManyRings)`.
pub const MAX_WIRE_RINGS: usize = 16;
/// Largest rotation-bin count an episode may ask for.
pub const MAX_ROT_BINS: u8 = crate::limits::MAX_ROT_BINS as u8;
pub use crate::limits::MAX_EPISODE_ACTIONS;

/// Capability bit: runs the Table-3 baseline agents.
pub const CAP_BASELINE_AGENTS: u32 = 1 << 0;
/// Capability bit: accepts ground truth for simulation episodes.
pub const CAP_GROUND_TRUTH: u32 = 1 << 1;
/// Capability bit: coarse GHT localization (ends episodes early, reports the coarse pose).
pub const CAP_LOCALIZATION: u32 = 1 << 2;
/// Capability bit: sparse registration (reports the refined pose).
pub const CAP_REGISTRATION: u32 = 1 << 3;
/// Capability bit: per-update cycle counts are measured (otherwise reported as zero).
pub const CAP_CYCLE_COUNTS: u32 = 1 << 4;
/// Capability bit: honours `Shutdown` by stopping (QEMU: the emulator exits with 0).
pub const CAP_SHUTDOWN: u32 = 1 << 5;
/// Capability: the device runs the int8 learnt policy (`AgentKind::LearntInt8`) from policies
/// in its flash; [`Request::PolicyInfo`] says which `K` it has.
pub const CAP_LEARNT_POLICY: u32 = 1 << 6;
/// Capability: policies can be uploaded into RAM ([`Request::PolicyBegin`]).
pub const CAP_POLICY_UPLOAD: u32 = 1 << 7;
/// Payload bytes of one [`Request::PolicyChunk`].
pub const POLICY_CHUNK: usize = 512;
