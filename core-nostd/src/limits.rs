//! Every capacity and every default of the core in one leaf module (it imports nothing):
//! plan size, localizer grid, episode length, observation log, scan width and the stop
//! rule's defaults, with the compile-time checks that tie them together. Every other
//! module takes its limits from here (re-exporting them where they belong to its API), so
//! a capacity is written down exactly once.

/// Largest number of floor-plan vertices ([`crate::FloorPlan`]).
pub const MAX_VERTICES: usize = 64;
/// Largest number of rings of a floor-plan: its outline and up to eight columns
/// ([`crate::FloorPlan`]; the columns share [`MAX_VERTICES`] with the outline).
pub const MAX_RINGS: usize = 9;

/// Largest number of localizer translation cells along x.
pub const MAX_NX: usize = 30;
/// Largest number of localizer translation cells along y.
pub const MAX_NY: usize = 30;
/// Largest number of localizer rotation bins K.
pub const MAX_ROT_BINS: usize = 10;

/// Pixels in one topological scan (§4.1).
pub const SCAN_PIXELS: usize = 20;

/// Default rotation steps per full turn (rotation step 2π/54, §4.2 / Table 3).
pub const DEFAULT_STEPS_PER_TURN: u16 = 54;
/// Action limit used for evaluation (Table 4).
pub const EVAL_MAX_ACTIONS: u16 = 100;
/// Action limit used for training (§4.2).
pub const TRAIN_MAX_ACTIONS: u16 = 500;
/// Largest action limit an episode may ask for (the training limit, §4.2); the protocol
/// refuses more.
pub const MAX_EPISODE_ACTIONS: u16 = TRAIN_MAX_ACTIONS;

/// Fixed capacity of an observation set: every measurement of the longest episode
/// ([`MAX_EPISODE_ACTIONS`] actions, all of them measurements at worst), so no reading is
/// ever dropped.
pub const MAX_OBSERVATIONS: usize = MAX_EPISODE_ACTIONS as usize;

/// The default of the confident stop's risk ([`crate::episode::EpisodeConfig::stop_risk`]):
/// stop when the estimated probability of a wrong registration is below 1 %.
pub const DEFAULT_STOP_RISK: f32 = 0.01;

// Every measurement of the longest episode reaches the registration: none is dropped.
const _: () = assert!(MAX_OBSERVATIONS >= MAX_EPISODE_ACTIONS as usize);
const _: () = assert!(EVAL_MAX_ACTIONS <= MAX_EPISODE_ACTIONS);
// The grid indices and K travel as u8 (cells, protocol), the scan as a u32 bit mask.
const _: () = assert!(MAX_NX <= 255 && MAX_NY <= 255 && MAX_ROT_BINS <= 255);
const _: () = assert!(SCAN_PIXELS <= 32);
const _: () = assert!(MAX_VERTICES <= 255);
// Ring ends travel as u8; door openings are a u64 bit mask over the walls.
const _: () = assert!(MAX_RINGS <= 255 && MAX_VERTICES <= 64);
const _: () = assert!(DEFAULT_STOP_RISK > 0.0 && DEFAULT_STOP_RISK <= 1.0);
