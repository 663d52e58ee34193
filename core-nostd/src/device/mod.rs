//! The device: the episode [`Controller`] (the instrument's decision maker, in
//! [`controller`]), the [`Session`] state machine that serves the protocol of
//! [`crate::protocol`] over any `embedded_io` byte stream (in [`session`]), and the
//! sensors/actuators seam with its implementations ([`instrument`]).
//!
//! **Who decides.** The device owns the decisions: it chooses every action (the baseline
//! agents now, the learnt policy later), keeps the episode's encoder bearing
//! ([`EpisodeState`](crate::episode::EpisodeState)), collects the measurements, and — once they land — runs the GHT
//! localization and the sparse registration. The instrument's sensors only answer. In
//! simulation the host plays the sensors: each device reply `Act { step, action }` is an
//! action request, the host's `Observe { step, observation }` is the sensors' answer.
//!
//! **Robustness.** Bytes go through a fixed-size [`FrameAccumulator`](crate::protocol::FrameAccumulator). Garbage, truncated,
//! oversized, CRC-bad and undecodable frames are each answered with one
//! [`Response::Error`](crate::protocol::Response::Error) (id [`NO_ID`](crate::protocol::NO_ID) when the frame's own id cannot be trusted) and the
//! link resynchronises on the next `0x00`. Out-of-sequence requests get
//! `Error(OutOfSequence)` / `Error(StepMismatch)`; a duplicated request id re-sends the
//! cached reply (retransmission after a lost reply). A host that goes silent mid-episode
//! for longer than [`SessionConfig::timeout_ms`] has its episode abandoned by
//! [`Session::poll`]; a new `Hello` always opens a fresh session, whatever the state.
//! Nothing here panics on input or blocks except on the link itself.
//!
//! **Memory.** [`Session::new`] is a `const fn`, so the firmware places the whole state
//! (frame buffers, plan, and the episode runner with its localizer) in a `static`.
//!
//! **Decisions.** The controller drives an [`EpisodeRunner`](crate::pipeline::runner::EpisodeRunner) (the same loop the host
//! simulator, the evaluation and the trainer run): every returned range is voted into the GHT localizer in [`Controller::observe`];
//! [`Controller::next_step`] ends the episode with [`EpisodeEnd::Localized`](crate::protocol::EpisodeEnd::Localized) when the
//! termination rule fires, and at the end of every episode reports the coarse (belief
//! argmax) and refined (sparse registration) AgentPoses.

pub mod controller;
pub mod instrument;
pub mod laser;
pub mod session;

pub use controller::*;
pub use session::*;
