//! The host ⇄ instrument serial protocol: messages, framing, CRC and a fixed-buffer frame
//! accumulator. The full specification is `docs/protocol.md`; this module is its
//! reference implementation and is shared, byte for byte, by the firmware and the host.
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

use crate::agents::{Action, AgentKind};
use crate::episode::Observation;
use crate::floorplan::PlanError;
use crate::geometry::Pose2;
pub use crate::pipeline::Termination;
use heapless::{String as HString, Vec as HVec};
use serde::{de::DeserializeOwned, Deserialize, Serialize};

/// Protocol version; bumped on every incompatible change of a message or of the framing.
pub const PROTOCOL_VERSION: u16 = 5;
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
/// Largest rotation-bin count an episode may ask for.
pub const MAX_ROT_BINS: u8 = crate::localization::MAX_ROT_BINS as u8;
/// Largest action limit an episode may ask for (the training limit, §4.2).
pub const MAX_EPISODE_ACTIONS: u16 = crate::episode::TRAIN_MAX_ACTIONS;

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
    /// Loads the floor-plan model (model frame, counter-clockwise `[x, y]` in metres).
    /// Validated with [`crate::FloorPlan::from_raw`]; answered by [`Response::PlanLoaded`]
    /// or `Error(InvalidPlan(..))`.
    LoadPlan {
        /// Outline vertices.
        vertices: HVec<[f32; 2], MAX_WIRE_VERTICES>,
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
    Invalid(crate::quantized::BlobError),
    /// The blob is for another K than announced.
    WrongRotBins {
        /// The K inside the blob.
        found: u8,
    },
    /// No upload in progress (or it was cancelled by an episode).
    NoUpload,
}

/// Parameters of one episode.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeParams {
    /// The deciding agent.
    pub agent: AgentKind,
    /// Seed of the agent's PRNG.
    pub seed: u64,
    /// Rotation steps per turn (rotation step 2π / this); 1..=3600.
    pub steps_per_turn: u16,
    /// Action limit, 1..=[`MAX_EPISODE_ACTIONS`].
    pub max_actions: u16,
    /// Rotation bins K of the localizer, 1..=[`MAX_ROT_BINS`]; K = 1 needs `known_heading`.
    pub rot_bins: u8,
    /// The model-frame heading of encoder bearing 0 when orientation is known (K = 1).
    pub known_heading: Option<f32>,
    /// Simulation only: the true AgentPose (scene→model), for the device's statistics.
    pub ground_truth: Option<Pose2>,
    /// The instrument's topological scan before the first action.
    pub initial_scan: u32,
    /// When the episode stops early ([`Termination::Oracle`] needs `ground_truth`).
    pub termination: Termination,
    /// The confident stop's risk ([`crate::pipeline::PipelineParams::stop_risk`]):
    /// [`Termination::Confident`] stops only once the estimated probability that the
    /// registration is wrong is below this. Finite, 0 < P <= 1 (else
    /// [`ParamError::InvalidStopRisk`]); the host's default is
    /// [`crate::pipeline::DEFAULT_STOP_RISK`]. Since protocol v4.
    pub stop_risk: f32,
    /// The observability stop test ([`crate::pipeline::PipelineParams::min_observability`]):
    /// stop only once the smallest eigenvalue of the readings' normalised information
    /// matrix reaches this. Finite, 0 <= τ <= 1, 0 = off (else
    /// [`ParamError::InvalidObservability`]). Since protocol v4.
    pub min_observability: f32,
}

impl EpisodeParams {
    /// The check of [`EpisodeParams::stop_risk`] and [`EpisodeParams::min_observability`]
    /// (the device runs it in `Controller::check_params`; NaN and infinities are refused).
    pub fn check_stop_rule(&self) -> Result<(), ParamError> {
        if !(self.stop_risk.is_finite() && self.stop_risk > 0.0 && self.stop_risk <= 1.0) {
            return Err(ParamError::InvalidStopRisk);
        }
        if !(self.min_observability.is_finite() && (0.0..=1.0).contains(&self.min_observability)) {
            return Err(ParamError::InvalidObservability);
        }
        Ok(())
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
    /// CRC-32 over the episode's (action, observation) stream, see [`TraceHash`].
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
}

/// Why an `EpisodeParams` was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ParamError {
    /// `steps_per_turn` is 0 or above 3600.
    StepsPerTurn,
    /// `max_actions` is 0 or above [`MAX_EPISODE_ACTIONS`].
    MaxActions,
    /// `rot_bins` is 0 or above [`MAX_ROT_BINS`].
    RotBins,
    /// `rot_bins == 1` without a `known_heading`.
    KnownHeadingRequired,
    /// `known_heading` or `ground_truth` is NaN/inf.
    NonFinite,
    /// The ground-truth position lies outside the plan.
    GroundTruthOutside,
    /// Oracle termination without a ground truth.
    GroundTruthRequired,
    /// The localizer cannot take this plan (not centred on its perimeter centroid, or
    /// more perimeter than its R-table holds).
    PlanNotLocalizable,
    /// The requested agent does not run on this device (the learnt policy, until the
    /// device carries one).
    AgentUnavailable,
    /// `stop_risk` is NaN, infinite, not above 0 or above 1.
    InvalidStopRisk,
    /// `min_observability` is NaN, infinite, below 0 or above 1.
    InvalidObservability,
}

/// Why an observation was rejected (the episode stays at the same step).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObservationError {
    /// The range is NaN or infinite.
    NonFiniteRange,
    /// The range is negative.
    NegativeRange,
    /// A rotation action reported a range.
    RangeOnRotation,
    /// Scan bits beyond [`crate::episode::SCAN_PIXELS`] are set.
    ScanBits,
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
            WireError::InvalidParams(e) => write!(f, "invalid episode parameters: {e:?}"),
            WireError::InvalidObservation(e) => write!(f, "invalid observation: {e:?}"),
            WireError::Policy(e) => write!(f, "policy upload refused: {e:?}"),
        }
    }
}

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

// ---------------------------------------------------------------------------------------
// CRC-32 (IEEE), nibble-table implementation: 64 bytes of table, fine for ~1 KiB frames.

const fn crc_table() -> [u32; 16] {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
}

const CRC_TABLE: [u32; 16] = crc_table();

/// Incremental CRC-32 (IEEE).
#[derive(Clone, Copy, Debug)]
pub struct Crc32(u32);

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    /// A fresh CRC.
    pub const fn new() -> Self {
        Crc32(0xFFFF_FFFF)
    }
    /// Feeds bytes.
    pub fn update(&mut self, data: &[u8]) {
        let mut c = self.0;
        for &b in data {
            c ^= b as u32;
            c = (c >> 4) ^ CRC_TABLE[(c & 15) as usize];
            c = (c >> 4) ^ CRC_TABLE[(c & 15) as usize];
        }
        self.0 = c;
    }
    /// The CRC of everything fed so far.
    pub fn finish(&self) -> u32 {
        !self.0
    }
}

/// CRC-32 (IEEE) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(data);
    c.finish()
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

/// COBS-encodes `src` into `dst` (no delimiter); returns the encoded length.
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
    use crate::episode::Observation;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

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
        roundtrip(&Request::LoadPlan { vertices: v });
    }

    fn episode_params() -> EpisodeParams {
        EpisodeParams {
            agent: AgentKind::Heuristic1,
            seed: 0x0123_4567_89AB_CDEF,
            steps_per_turn: 54,
            max_actions: 100,
            rot_bins: 10,
            known_heading: Some(0.25),
            ground_truth: Some(Pose2::new(0.5, -0.25, 1.0)),
            initial_scan: 0b1_0110,
            termination: Termination::Confident,
            stop_risk: 0.05,
            min_observability: 0.125,
        }
    }

    #[test]
    fn episode_params_round_trip_with_stop_rule() {
        let p = episode_params();
        roundtrip(&Request::StartEpisode(p));
        let mut off = p;
        off.stop_risk = 1.0;
        off.min_observability = 0.0;
        roundtrip(&Request::StartEpisode(off));
        // v4 layout: the two f32 close the message, stop_risk first, each 4 raw LE bytes.
        let mut raw = [0u8; MAX_PAYLOAD];
        let body = postcard::to_slice(&(42u16, Request::StartEpisode(p)), &mut raw).unwrap();
        let n = body.len();
        assert_eq!(&body[n - 8..n - 4], &0.05f32.to_le_bytes());
        assert_eq!(&body[n - 4..], &0.125f32.to_le_bytes());
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
    fn stop_rule_validation() {
        assert_eq!(episode_params().check_stop_rule(), Ok(()));
        for risk in [f32::NAN, 0.0, -0.01, 1.5, f32::INFINITY, f32::NEG_INFINITY] {
            let mut p = episode_params();
            p.stop_risk = risk;
            assert_eq!(
                p.check_stop_rule(),
                Err(ParamError::InvalidStopRisk),
                "{risk}"
            );
        }
        for tau in [-1.0, f32::NAN, 1.01, f32::INFINITY, -0.0001] {
            let mut p = episode_params();
            p.min_observability = tau;
            assert_eq!(
                p.check_stop_rule(),
                Err(ParamError::InvalidObservability),
                "{tau}"
            );
        }
        for (risk, tau) in [(1.0, 0.0), (f32::MIN_POSITIVE, 1.0), (0.01, 0.5)] {
            let mut p = episode_params();
            p.stop_risk = risk;
            p.min_observability = tau;
            assert_eq!(p.check_stop_rule(), Ok(()), "{risk} {tau}");
        }
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
