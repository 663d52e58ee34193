//! # activesense-core
//!
//! The `#![no_std]`, heap-free heart of activesense, the reference implementation of
//! "Learning Effective Sparse Sampling Strategies using Deep Active Sensing". Everything
//! that must run on the instrument controller (a Cortex-M4F with 128 KiB of RAM) lives
//! here, so that the host simulator and the firmware execute *the same code* and an
//! episode replayed on either side produces the same actions bit for bit.
//!
//! All arithmetic is `f32` through [`libm`] (never `std` intrinsics), which keeps results
//! identical on x86-64 and on the Cortex-M4F FPU. All storage has fixed capacity
//! ([`heapless`]); bad external input is a typed error, never a panic.
//!
//! | module | paper section |
//! |---|---|
//! | [`geometry`] | 3 (SE(2) conventions) |
//! | [`floorplan`] | 3, 4.1 (the polygonal floor-plan model, ray casting, topological scan) |
//! | [`builtin`] | 3.1 (the committed int8 policies the instrument carries) |
//! | [`agents`] | 3.1, 4.2 (actions, costs, the Table-3 baseline agents) |
//! | [`localization`] | 3.2 (fixed-grid GHT localization: R-table, Algorithms 1–2, belief analysis, staging) |
//! | [`episode`] | 3.1, 4.2 (episode bookkeeping: encoder bearing, costs, action limit) |
//! | [`wire`] | host ⇄ instrument serial protocol (`docs/protocol.md`) |
//! | [`session`] | the device's protocol state machine and episode controller |
//! | [`instrument`] | sensors/actuators trait, embedded-hal hardware instrument |
//! | [`registration`] | 3.3 (Sparse ICP, Algorithm 4, equation 6; annealed perturbation, Algorithm 3) |
//! | [`symmetry`] | 3.4 (edge-chain rotational-symmetry detection, Wolter et al. 1985) |
//! | [`pose_distance`] | 3.4 (symmetry-aware pose distance, Table 2, equations 7–10) |
//! | [`pipeline`] | Fig. 1, 3.1–3.3 (one episode's chain: localize, terminate, refine) |
//! | [`policy`] | 3.1, Fig. 2 (the policy seam: `PolicyInput`, state features, `Policy`) |
//! | [`runner`] | Fig. 1 (the one episode loop every side drives: `EpisodeRunner`) |
//! | [`quantized`] | 3.1 on the instrument (int8 policy blob, integer-only inference, `QuantizedAgent`) |
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod agents;
pub mod builtin;
pub mod episode;
pub mod floorplan;
pub mod geometry;
pub mod instrument;
pub mod localization;
pub mod math;
pub mod pipeline;
pub mod policy;
pub mod pose_distance;
pub mod quantized;
pub mod refine;
pub mod registration;
pub mod runner;
pub mod session;
pub mod stop;
pub mod stop_calibration;
pub mod symmetry;
pub mod wire;

pub use floorplan::{FloorPlan, PlanError, RayHit, MAX_VERTICES};
pub use geometry::{Pose2, Vec2};
