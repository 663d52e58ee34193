//! The protocol's messages (`docs/protocol.md`): [`Request`] (host → device) and
//! [`Response`] (device → host) with every payload and error type they carry. The episode
//! parameters ([`EpisodeParams`]) are the episode layer's own type, whose serde form is the
//! `StartEpisode` payload.

use super::{MAX_FRAME, MAX_WIRE_RINGS, MAX_WIRE_VERTICES, POLICY_CHUNK, PROTOCOL_VERSION};
use crate::episode::{Action, EpisodeParams, Observation, ObservationError, ParamError};
use crate::policy::int8::error::BlobError;
use crate::world::floorplan::PlanError;
use crate::world::geometry::Pose2;
use heapless::{String as HString, Vec as HVec};
use serde::{Deserialize, Serialize};

/// Host → device messages.
// LoadPlan dominates the size (≈ 970 B); no heap for boxing, and a request lives on the
// stack only while it is handled.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Opens (or re-opens) a session; aborts any running episode. Answered by
    /// [`Response::Hello`], or `Error(VersionMismatch)` when `protocol` differs.
    Hello {
        /// The host's [`PROTOCOL_VERSION`].
        protocol: u16,
    },
    /// Liveness check, answered by [`Response::Pong`] with the same nonce.
    Ping {
        /// Echoed back.
        nonce: u32,
    },
    /// Loads the floor-plan model (model frame, `[x, y]` in metres): the outline
    /// counter-clockwise, then each column clockwise, with the door openings. Validated with
    /// [`crate::FloorPlan::from_parts`]; answered by [`Response::PlanLoaded`] or
    /// `Error(InvalidPlan(..))`. Since protocol v10 (rings and openings).
    LoadPlan {
        /// Every ring's vertices, concatenated (outline first).
        vertices: HVec<[f32; 2], MAX_WIRE_VERTICES>,
        /// Exclusive end index of each ring; empty for the outline alone.
        rings: HVec<u8, MAX_WIRE_RINGS>,
        /// Bit `i` set: wall `i` (from vertex `i` to the next of its ring) is a door opening.
        openings: u64,
    },
    /// Starts an episode on the loaded plan; answered by the first action request
    /// ([`Response::Act`]) or an error.
    StartEpisode(EpisodeParams),
    /// The instrument's answer to the action request `step`; answered by the next action
    /// request or by [`Response::Done`].
    Observe {
        /// The step of the [`Response::Act`] this answers.
        step: u16,
        /// What the instrument saw after performing the action.
        observation: Observation,
    },
    /// Asks for [`Response::Status`].
    Status,
    /// Aborts the running episode; answered by [`Response::Aborted`] (or `Ack` when idle).
    Abort,
    /// Returns the device to its power-on state (plan dropped, counters cleared); the
    /// host must send `Hello` again. Answered by `Ack`.
    Reset,
    /// Stops the device (firmware under QEMU: exits the emulator with status 0 after the
    /// `Ack` has been sent).
    Shutdown,
    /// Starts uploading an int8 policy blob (`docs/policy-blob.md`) of `len` bytes whose
    /// own CRC-32 (its last 4 bytes, over everything before them) is `crc`, for `rot_bins`. Only between episodes; an episode started before
    /// the commit cancels the upload. Answered by `Ack` or `Error(Policy(..))`.
    PolicyBegin {
        /// The K the blob is for.
        rot_bins: u8,
        /// Blob length in bytes.
        len: u32,
        /// The blob's CRC-32 (IEEE) over all but its last 4 bytes.
        crc: u32,
    },
    /// The next piece of the blob, at byte `offset` (chunks in order). Answered by `Ack`.
    PolicyChunk {
        /// Offset of `data` in the blob; must equal the bytes received so far.
        offset: u32,
        /// Up to [`POLICY_CHUNK`] bytes.
        data: HVec<u8, POLICY_CHUNK>,
    },
    /// Checks the uploaded blob (length, CRC, structure, K) and, when it is sound, puts it
    /// in service for its K. A rejected blob leaves the policy in service untouched.
    /// Answered by [`Response::PolicyInfo`] or `Error(Policy(..))`.
    PolicyCommit,
    /// Which policy serves `rot_bins`; answered by [`Response::PolicyInfo`].
    PolicyInfo {
        /// The K asked about.
        rot_bins: u8,
    },
}

/// Device → host messages.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Response {
    /// Answer to `Hello`: who the device is.
    Hello(DeviceInfo),
    /// Answer to `Ping`.
    Pong {
        /// The request's nonce.
        nonce: u32,
    },
    /// The plan was accepted.
    PlanLoaded(PlanSummary),
    /// Action request: the device decided the next action; the host (or the instrument)
    /// performs it and answers with `Observe { step, .. }`.
    Act {
        /// 0-based action index within the episode.
        step: u16,
        /// What to do.
        action: Action,
    },
    /// The episode ended (localized or action limit).
    Done(EpisodeReport),
    /// The episode was aborted on request.
    Aborted(EpisodeReport),
    /// Answer to `Status`.
    Status(DeviceStatus),
    /// Generic acknowledgement (`Reset`, `Shutdown`, `Abort` while idle).
    Ack,
    /// The request (or frame) was rejected; the device state is unchanged unless stated.
    Error(WireError),
    /// The policy serving one K.
    PolicyInfo(PolicyInfo),
}

/// Where the policy serving a K comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PolicySource {
    /// No policy for this K: `LearntInt8` episodes are refused.
    None,
    /// Built into the firmware (flash).
    BuiltIn,
    /// Uploaded over the link (RAM; gone at power-off or `Reset`).
    Uploaded,
}

/// Answer to [`Request::PolicyInfo`] and [`Request::PolicyCommit`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PolicyInfo {
    /// The K.
    pub rot_bins: u8,
    /// Where the serving policy comes from.
    pub source: PolicySource,
    /// Its blob length (0 for none).
    pub len: u32,
    /// Its blob's own CRC-32 (the last 4 bytes; 0 for none).
    pub crc: u32,
}

/// Why a policy upload request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum PolicyError {
    /// Longer than the device's upload slot, or `rot_bins` out of range.
    TooLarge {
        /// The slot's capacity in bytes.
        capacity: u32,
    },
    /// A chunk at the wrong offset.
    ChunkOffset {
        /// The offset the device expects next.
        expected: u32,
    },
    /// A chunk that would run past the announced length.
    Overrun,
    /// Commit before all announced bytes arrived.
    Incomplete {
        /// Bytes received.
        received: u32,
    },
    /// The received bytes do not have the announced CRC-32.
    Checksum,
    /// The blob is not a valid int8 policy.
    Invalid(BlobError),
    /// The blob is for another K than announced.
    WrongRotBins {
        /// The K inside the blob.
        found: u8,
    },
    /// No upload in progress (or it was cancelled by an episode).
    NoUpload,
}

impl core::fmt::Display for PolicyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PolicyError::TooLarge { capacity } => write!(
                f,
                "larger than the device's {capacity}-byte slot (or K out of range)"
            ),
            PolicyError::ChunkOffset { expected } => {
                write!(f, "chunk out of order (device expected offset {expected})")
            }
            PolicyError::Overrun => f.write_str("more bytes than announced"),
            PolicyError::Incomplete { received } => {
                write!(f, "commit after only {received} bytes")
            }
            PolicyError::Checksum => f.write_str("the bytes do not have the announced CRC-32"),
            PolicyError::Invalid(e) => write!(f, "not a valid int8 policy: {e}"),
            PolicyError::WrongRotBins { found } => {
                write!(f, "the blob is for K = {found}, not the announced K")
            }
            PolicyError::NoUpload => {
                f.write_str("no upload in progress (an episode started since cancels it)")
            }
        }
    }
}

/// Static description of the device, sent in answer to `Hello`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// The device's [`PROTOCOL_VERSION`].
    pub protocol: u16,
    /// Firmware (or host-emulated device) version string.
    pub firmware: HString<24>,
    /// Localizer accumulator grid (all zero while no localizer is built in).
    pub grid: GridInfo,
    /// Largest accepted plan ([`crate::MAX_VERTICES`]).
    pub max_vertices: u8,
    /// Largest accepted action limit.
    pub max_actions: u16,
    /// Largest accepted rotation-bin count.
    pub max_rot_bins: u8,
    /// Pixels per topological scan ([`crate::episode::SCAN_PIXELS`]).
    pub scan_pixels: u8,
    /// [`MAX_FRAME`] of the device.
    pub max_frame: u16,
    /// `CAP_*` bits.
    pub capabilities: u32,
    /// The longest the device may take to answer one request (ms): its slowest update
    /// (the calibrated stop's end-of-episode chain at K = 10). The host waits this long
    /// (plus a margin) before it re-sends a request. Since protocol v6.
    pub max_reply_ms: u32,
}

/// The localizer's accumulator grid dimensions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GridInfo {
    /// Cells along x.
    pub cells_x: u16,
    /// Cells along y.
    pub cells_y: u16,
    /// Cell side in millimetres.
    pub cell_mm: u16,
}

/// Answer to a valid `LoadPlan`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanSummary {
    /// Vertex count.
    pub vertices: u8,
    /// Perimeter (m).
    pub perimeter: f32,
    /// Largest vertex distance from the perimeter centroid (m).
    pub max_radius: f32,
}

/// Why an episode ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum EpisodeEnd {
    /// The localizer reached its success criterion.
    Localized,
    /// The action limit was reached.
    ActionLimit,
    /// The host aborted it.
    Aborted,
}

/// Cycle statistics of the device's per-action update: book the observation (for a
/// returned range: the GHT vote and the termination check) and choose the next action.
///
/// "Cycles" are ticks of the device's cycle clock (`SessionConfig::cycle_clock`); the
/// firmware uses TIM2, which under QEMU with `-icount shift=0` advances by exactly one per
/// executed guest instruction (see `firmware/src/main.rs` and `cargo xtask mcu-bench`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct UpdateStats {
    /// Updates measured.
    pub updates: u32,
    /// Sum of cycles over all updates.
    pub total_cycles: u64,
    /// Largest single update.
    pub max_cycles: u32,
}

impl UpdateStats {
    /// Books one update of `cycles`.
    pub fn record(&mut self, cycles: u32) {
        self.updates = self.updates.saturating_add(1);
        self.total_cycles = self.total_cycles.saturating_add(cycles as u64);
        self.max_cycles = self.max_cycles.max(cycles);
    }
}

/// Per-episode cycle statistics, split by what the update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EpisodeCycles {
    /// Updates after a measurement with a return (localizer vote + termination check).
    pub vote: UpdateStats,
    /// Updates after a rotation (no vote).
    pub rotation: UpdateStats,
    /// Updates after a measurement without a return (no vote).
    pub no_return: UpdateStats,
    /// The end-of-episode chain: coarse read-out of the belief, sparse registration and
    /// symmetry recognition (0 for an aborted episode).
    pub finish: u32,
    /// The policy's decisions alone (feature extraction + the agent's choice; part of every
    /// update above): the int8 network for `LearntInt8`, a counter step for the baselines.
    pub decision: UpdateStats,
}

impl EpisodeCycles {
    /// All per-action updates together (vote + rotation + no-return).
    pub fn updates(&self) -> UpdateStats {
        let mut all = self.vote;
        for s in [self.rotation, self.no_return] {
            all.updates = all.updates.saturating_add(s.updates);
            all.total_cycles = all.total_cycles.saturating_add(s.total_cycles);
            all.max_cycles = all.max_cycles.max(s.max_cycles);
        }
        all
    }
}

/// The result of an episode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeReport {
    /// Why it ended.
    pub end: EpisodeEnd,
    /// Actions taken.
    pub actions: u16,
    /// Measurement actions.
    pub measurements: u16,
    /// Rotation actions.
    pub rotations: u16,
    /// Measurements without return.
    pub no_returns: u16,
    /// Sum of action costs.
    pub cost: f32,
    /// Final encoder position (rotation steps).
    pub bearing_index: u16,
    /// CRC-32 over the episode's (action, observation) stream, see [`TraceHash`](super::TraceHash).
    pub trace_hash: u32,
    /// Coarse AgentPose from the GHT localizer (the belief argmax; `None` when no
    /// measurement returned). With `Termination::Confident`, the cell the refined pose lies
    /// in ([`crate::pipeline::Pipeline::answer_cell`]).
    pub coarse: Option<Pose2>,
    /// Refined AgentPose from the sparse registration (`None` with fewer than two
    /// measurements).
    pub refined: Option<Pose2>,
    /// Coarse success of `coarse` against the ground truth, when one was supplied.
    pub recognised: Option<bool>,
    /// The calibrated stop's estimate of P(wrong registration) for this answer
    /// ([`crate::pipeline::PipelineResult::stop_risk`]; `None` below the stop gate). Since
    /// protocol v5.
    pub stop_risk: Option<f32>,
    /// Returned ranges the answer is based on: all of them, or fewer when a confident episode
    /// reached its action limit and answers with its lowest-risk moment
    /// ([`crate::pipeline::PipelineResult::answer_readings`]). Since protocol v5.
    pub answer_readings: u16,
    /// Cycle statistics of this episode's updates and of its end-of-episode chain.
    pub cycles: EpisodeCycles,
}

/// Session phase as reported by `Status`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Phase {
    /// No `Hello` yet (power-on, after `Reset` or after a host timeout).
    Closed,
    /// Session open, no episode running.
    Ready,
    /// An episode is running; `Observe` expected.
    Episode,
}

/// Link-level counters since power-on / `Reset`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkStats {
    /// Frames that decoded correctly.
    pub frames_ok: u32,
    /// Frames rejected for COBS, CRC, decode or size errors.
    pub frames_bad: u32,
    /// Requests rejected as out of sequence (id or step).
    pub sequence_errors: u32,
    /// Replies re-sent for a duplicated request id.
    pub retransmissions: u32,
    /// Episodes abandoned because the host went silent.
    pub timeouts: u32,
    /// Episodes completed (`Done`).
    pub episodes: u32,
}

/// Answer to `Status`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceStatus {
    /// Session phase.
    pub phase: Phase,
    /// Vertices of the loaded plan (0: none).
    pub plan_vertices: u8,
    /// Actions taken in the running episode.
    pub episode_actions: u16,
    /// Link counters.
    pub link: LinkStats,
    /// Cycle statistics over all updates since power-on / `Reset`.
    pub cycles: UpdateStats,
    /// The main stack's high-water mark (zero where the device does not measure it).
    /// Since protocol v8.
    pub stack: StackUsage,
}

/// How deep the device's stack has been since power-on (not cleared by `Reset`): the
/// firmware paints its free stack at boot and finds the lowest word overwritten.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StackUsage {
    /// Deepest stack seen (bytes below the top of RAM); 0: not measured.
    pub high_water: u32,
    /// The stack's room: from the top of RAM down to the statics (bytes); 0: not measured.
    pub size: u32,
}

/// Errors the device reports in [`Response::Error`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireError {
    /// The frame is not valid COBS (or too short to hold a CRC).
    Framing,
    /// CRC mismatch.
    Crc,
    /// The payload is not a valid message.
    Decode,
    /// The frame exceeded [`MAX_FRAME`]; bytes were discarded up to the next delimiter.
    Oversized,
    /// No session: send `Hello` first.
    NoSession,
    /// `Hello` with a different protocol version; carries the device's.
    VersionMismatch {
        /// The device's [`PROTOCOL_VERSION`].
        device: u16,
    },
    /// The request id is neither the next one nor a retransmission.
    OutOfSequence {
        /// The id the device expected.
        expected: u16,
    },
    /// The request is not valid in the current phase (e.g. `Observe` with no episode).
    UnexpectedRequest,
    /// `Observe` for the wrong step.
    StepMismatch {
        /// The step the device waits for.
        expected: u16,
    },
    /// `LoadPlan` rejected by floor-plan validation.
    InvalidPlan(PlanError),
    /// `StartEpisode` without a loaded plan.
    NoPlan,
    /// `StartEpisode` rejected.
    InvalidParams(ParamError),
    /// `Observe` rejected.
    InvalidObservation(ObservationError),
    /// A policy upload request rejected.
    Policy(PolicyError),
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            WireError::Framing => write!(f, "malformed frame (COBS)"),
            WireError::Crc => write!(f, "frame CRC mismatch"),
            WireError::Decode => write!(f, "undecodable message"),
            WireError::Oversized => write!(f, "frame larger than {MAX_FRAME} bytes"),
            WireError::NoSession => write!(f, "no session (send Hello first)"),
            WireError::VersionMismatch { device } => write!(
                f,
                "protocol version mismatch: device speaks {device}, host {PROTOCOL_VERSION}"
            ),
            WireError::OutOfSequence { expected } => {
                write!(f, "request id out of sequence (expected {expected})")
            }
            WireError::UnexpectedRequest => write!(f, "request not valid in this phase"),
            WireError::StepMismatch { expected } => {
                write!(f, "observation for the wrong step (expected {expected})")
            }
            WireError::InvalidPlan(e) => write!(f, "invalid floor-plan: {e}"),
            WireError::NoPlan => write!(f, "no floor-plan loaded"),
            WireError::InvalidParams(e) => write!(f, "invalid episode parameters: {e}"),
            WireError::InvalidObservation(e) => write!(f, "invalid observation: {e}"),
            WireError::Policy(e) => write!(f, "policy upload refused: {e}"),
        }
    }
}
