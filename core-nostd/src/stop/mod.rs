//! The calibrated stop: an instrument has no ground truth, so it stops when the
//! *estimated probability that its registration is wrong* falls below the user's risk
//! `P` ([`crate::episode::EpisodeConfig::stop_risk`], default 1 %).
//!
//! **What "wrong" means.** Under this stop the instrument answers with its refined pose,
//! so the answer is right when the cell that pose lies in is a coarse success (the
//! paper's criterion, applied to the answered pose instead of the belief argmax). The two
//! differ where the refinement leaves the argmax's cell: heuristic-1 at K = 10 on 300 test
//! plans, in 256 such moments the refined pose's cell was right 198 times and the argmax
//! 37 times (`cargo run --release -p activesense-sim --example stop_trace -- 300 10`).
//!
//! The belief's peak mass alone over-states its confidence once the heading is unknown
//! (K = 10: heuristic-1 stated 0.94 and was right 0.80 of the time, `docs/EVALUATION.md`).
//! What the belief cannot see, the readings can: a wrong pose leaves readings it does not
//! explain. So the estimate is a logistic model `P(wrong) = σ(w·x + b)` over
//! [`StopFeatures`] (belief and readings together), one per rotation setting, fitted on
//! training plans (seeds below the test set) by `activesense calibrate`, which writes
//! [`crate::stop::calibration`]. The features are computed only once the belief's peak mass
//! reaches [`GATE_PEAK_MASS`] (below it the instrument keeps measuring without running the
//! refinement); the calibration data is gathered under the same gate.
//!
//! **Rivals** ([`rivals`]). What the belief cannot say well, whether another pose
//! explains the readings as well as the answer, the range likelihood can: the strongest
//! other belief modes are fitted too, and the likelihood margin of the answer over the best
//! of them is a feature. With it the gate could come down from 0.5 to [`GATE_PEAK_MASS`]:
//! the stop no longer waits for the voting belief to sharpen.

pub mod calibration;
pub mod calibration_edm;
pub mod rivals;

use crate::episode::{AgentKind, InstrumentProfile};
use crate::registration::pose_distance::Tolerance;
use crate::world::math::{exp, ln};
use serde::{Deserialize, Serialize};

/// Peak mass from which the stop features are computed (and the stop considered). At 0.5
/// (before the rival check) the gate opened after 4–5 readings with the heading known and
/// 6–9 without, though the answer was often within tolerance earlier (`docs/LEARNING.md`,
/// "The stop that reads rivals"); the rival margin now says what the peak mass could not,
/// and the gate only keeps the refinement from running on a belief with no mode at all.
pub const GATE_PEAK_MASS: f32 = 0.1;

/// Length scale (m) of the edge feature: about the registration's own error.
pub const EDGE_SCALE: f32 = 0.02;

/// Number of features of [`StopFeatures::to_vector`].
pub const FEATURES: usize = 18;

/// Range noise (m) the answer's precision ([`StopFeatures::precision`]) is computed with: the
/// EDM's own σ. Only the ratio between answers matters to the fitted model.
pub const PRECISION_SIGMA: f32 = 0.01;

/// Range residual (m) within which a reading counts towards the answer's precision: the
/// 3σ of the range model that says which readings a pose explains
/// ([`crate::registration::RangeModel`]).
pub const PRECISION_GATE: f32 = 0.09;

/// Knee of the rival margin's two pieces (nats): about one reading a rival cannot explain
/// ([`rivals`]).
pub const MARGIN_KNEE: f32 = 10.0;

/// Largest wall leverage ([`crate::registration::precision::WallLeverage::worst`]: how far
/// the answer moves per metre of one wall's as-built offset, its corners moving with it)
/// at which the stop answers with the heading known; above it the runner aims at the
/// bearing that lowers it ([`crate::pipeline::aim`]).
///
/// **Why.** On building sites (`--site site` moves one wall 3–6 cm off its line) most
/// confident wrong answers with the heading known were 5–7 cm off, every reading
/// explained and no direction resting on one wall: the readings lay on the moved wall
/// and on its neighbours near the shared corners, which move with it, so the fit followed
/// the offset (`activesense episode --seed 1000241 --rot-bins 1 --instrument edm --site
/// site --termination confident`: readings on walls 5, 6, 6 and 7, wall 6 moved 5.8 cm,
/// the answer 5.4 cm off at a stated 0.04 %). Above 0.9 a wall 5.5 cm off carries the
/// answer past the surveyor's 5 cm. On 600 validation plans' building sites (learnt, K = 1)
/// all but two confident wrong answers had leverages of 0.93–1.63; a third of the right
/// ones were above 0.9 too, and pay for the rule with a reading or two more. Tried as a
/// stop feature instead (refitted tables), it changed nothing at K = 1 and cost right
/// answers at K = 10 (`docs/EVALUATION.md`, "The wall leverage"). Only with the heading
/// known, as aiming.
pub const MAX_WALL_LEVERAGE: f32 = 0.9;

/// Largest wall leverage with the heading unknown (the position's, heading free) at which
/// the stop answers on the EDM-only profile ([`LeverageVeto`]): a wall as far off its line
/// as the surveyor's tolerance moves the answer at most as far.
pub const VETO_WALL_LEVERAGE: f32 = 1.0;

/// Largest heading leverage (rad per metre of one wall's as-built offset,
/// [`crate::registration::precision::WallLeverage::worst_heading`]) at which the stop
/// answers with the heading unknown on the EDM-only profile ([`LeverageVeto`]): a wall
/// 5 cm off its line turns the answer at most 0.57°.
///
/// **Why these bounds.** On 1000 validation plans per site level (learnt, K = 10, stated
/// 1 %), the veto at 1.0 / 0.2 took wrong answers from 7 to 1 on plans, 4 to 1 in furnished
/// rooms and 11 to 8 on building sites (1.5 % of answers), for 0.1, 0.9 and 1.2 points of
/// right answers. With the runner aiming where only the veto holds an answer back
/// ([`crate::pipeline::Pipeline::aim`]), 0.85 / 0.2 held validation sites to 4 wrong of 463
/// (0.86 %) for 1.4 points of the plans' right answers, but the test plans to 5 of 457
/// (1.1 %) for 2.2 (`docs/lab/stop.md`, "Aiming where the veto holds an answer back").
pub const VETO_WALL_HEADING_LEVERAGE: f32 = 0.2;

/// How far the worst wall's drawn position carries into an answer with the heading
/// unknown ([`crate::registration::precision::WallLeverage`] with three unknowns): the
/// stop's veto on the EDM-only profile, read after its estimate.
///
/// **Why a veto, not a rule before the estimate.** On building sites (one wall 3–6 cm off
/// its line) most wrong K = 10 answers explained every reading: the fit followed the moved
/// wall, and nothing the estimate reads can see it (`docs/lab/stop.md`, "The wall leverage
/// with the heading unknown"). As a rule before the estimate, the decision points it
/// refused left the calibration's fit (19,232 of 26,572 kept), the refitted model lost
/// what it knew about flips, and its 1 % threshold loosened tenfold. As a veto the model
/// is fitted, and the tables placed, on every decision point as without it: the veto only
/// takes answers away (`activesense_lab::calibrate::score` says why the tables are not
/// placed on what it lets through).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeverageVeto {
    /// Worst position shift per metre of one wall's offset (infinite where the readings
    /// leave a direction free).
    pub position: f32,
    /// Worst heading shift (rad) per metre of one wall's offset.
    pub heading: f32,
}

impl LeverageVeto {
    /// The worst walls' leverages of `lever`, the heading free.
    pub fn of(lever: &crate::registration::precision::WallLeverage) -> Self {
        Self {
            position: lever.worst(false),
            heading: lever.worst_heading(),
        }
    }

    /// The stop does not answer: one wall's offset would carry past [`VETO_WALL_LEVERAGE`]
    /// or [`VETO_WALL_HEADING_LEVERAGE`] into the answer (NaN counts as past).
    pub fn vetoes(&self) -> bool {
        !(self.position <= VETO_WALL_LEVERAGE && self.heading <= VETO_WALL_HEADING_LEVERAGE)
    }

    /// How far past the veto's bounds the worse of the two leverages stands, as a share of
    /// its bound (above 1 where [`Self::vetoes`]; NaN counts as infinite): what the runner
    /// lowers when it aims ([`crate::pipeline::Pipeline::aim`]).
    pub fn excess(&self) -> f32 {
        if self.position.is_nan() || self.heading.is_nan() {
            return f32::INFINITY;
        }
        (self.position / VETO_WALL_LEVERAGE).max(self.heading / VETO_WALL_HEADING_LEVERAGE)
    }
}

/// Share of the distinct bearings that, left unexplained by the answer (with at least
/// [`MISMATCH_MIN_READINGS`] of them), means the room does not match its plan: the answer
/// says so in words (`instrument::answer`), and with the heading unknown the stop does not
/// answer ([`room_mismatch`]).
pub const MISMATCH_SHARE: f32 = 0.25;

/// Fewest unexplained bearings for [`MISMATCH_SHARE`] to count: one stray return is the
/// EDM's outlier rate at work, not a room unlike its plan.
pub const MISMATCH_MIN_READINGS: u16 = 2;

/// True when an answer that explains `explained` of `readings` distinct bearings leaves
/// [`MISMATCH_SHARE`] of them (and [`MISMATCH_MIN_READINGS`]) unexplained.
///
/// **Why the stop refuses it with the heading unknown.** A pose with three unknowns can fit
/// a subset of the readings somewhere else in the room; furniture and obstacles then pass
/// for the readings it leaves out. On 1000 validation plans (learnt, EDM only, K = 10) the
/// answers it would have refused were 2 of 3 wrong ones in furnished rooms and 3 of 5 on
/// building sites, among them a 5.5 m, 80° one stated at 0.9 % with 4 of 7 readings
/// explained, against 9 of 854 and 17 of 422 right ones (none on plain plans). With the
/// heading given it would have refused 124 right answers in furnished rooms and no wrong
/// one, so there the answer only says it (`docs/EVALUATION.md`, "A room that does not match
/// its plan, refused").
pub fn room_mismatch(readings: u16, explained: u16) -> bool {
    let off = readings.saturating_sub(explained);
    off >= MISMATCH_MIN_READINGS && f32::from(off) >= MISMATCH_SHARE * f32::from(readings)
}

/// Readings at which the stop score equals the estimate ([`stop_score`]).
pub const SCORE_REFERENCE_READINGS: f32 = 8.0;

/// What the threshold table is compared with: the estimate `risk` times
/// [`SCORE_REFERENCE_READINGS`] / `bearings` (the distinct bearings measured,
/// [`StopFeatures::readings`]), so that the threshold on the estimate grows in proportion
/// to the evidence taken. Repeats do not count: a range repeated at one bearing checks
/// nothing new, and must not loosen the threshold.
///
/// **Why.** The estimate rises with the readings by itself (the episodes that run long are
/// the hard ones, and the fit sees it), so a fixed threshold got ever harder to cross, and
/// the episodes it left unanswered at the action limit were the ones the instrument had
/// already paid most for. A first crossing late in an episode is rare, so a higher
/// threshold there adds few wrong answers; the table, fitted on first crossings of this
/// score, keeps the stated risk. On the calibration plans (learnt and heuristic-1, both
/// K, the threshold fitted on one half for 1 % and checked on the other) it answered
/// as many or more episodes at the same or a lower wrong rate
/// (`docs/EVALUATION.md`, "The stated risk and the threshold").
pub fn stop_score(risk: f32, bearings: u16) -> f32 {
    risk * SCORE_REFERENCE_READINGS / f32::from(bearings.max(1))
}

/// What the stop compares with its threshold table at the decision point `f` whose
/// estimate is `risk`: its [`stop_score`], infinite where the veto holds
/// ([`StopFeatures::vetoed`]), so that no threshold answers there.
pub fn decision_score(f: &StopFeatures, risk: f32) -> f32 {
    if f.vetoed() {
        f32::INFINITY
    } else {
        stop_score(risk, f.readings)
    }
}

/// What the stop estimate looks at, after a measurement.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StopFeatures {
    /// Belief mass around the argmax and its symmetric equivalents
    /// ([`crate::localization::GhtLocalizer::peak_mass`]).
    pub peak_mass: f32,
    /// Entropy of the belief (nats).
    pub entropy: f32,
    /// Distinct bearings measured so far (a range repeated at one bearing checks nothing new:
    /// counting readings let an agent that repeats itself look certain).
    pub readings: u16,
    /// Readings taken at a bearing already measured. Repeating a range sharpens the voting
    /// belief without adding evidence, so a belief built on repeats over-states itself.
    pub repeats: u16,
    /// Distinct bearings whose readings the refined pose explains (within 3σ,
    /// [`crate::registration::RangeFit::explained_bearings`]).
    pub explained: u16,
    /// Unknowns of the pose (2 with the heading known, 3 without).
    pub unknowns: u8,
    /// Smallest eigenvalue of the readings' normalised information matrix at the argmax
    /// ([`crate::registration::observability`]).
    pub observability: f32,
    /// How far the refined pose lies from the argmax cell's centre, in cells (Chebyshev):
    /// above 1.5 the refinement says the argmax is not where the readings are.
    pub offset_cells: f32,
    /// How far the refined heading lies from the argmax bin's heading, in bins (0 with the
    /// heading known).
    pub offset_bins: f32,
    /// Distance (m) from the refined position to the nearest edge of the cell it lies in
    /// (the answer's cell). Coarse success asks the truth to lie in that cell, so a right
    /// registration a centimetre from the edge is a coin toss.
    pub edge_margin: f32,
    /// The refined pose lies in the argmax's cell, its heading within one bin of the
    /// argmax's: the coarse and the fine estimate agree. Where they do not, the refinement
    /// has overruled the belief, which is usually right but less certain.
    pub agrees: bool,
    /// Likelihood margin (nats) of the answer over the best rival belief mode
    /// ([`rivals::check`]); 0 when the rivals were not searched.
    #[serde(default)]
    pub rival_margin: f32,
    /// How precisely the readings the answer explains fix it ([`AnswerPrecision`]); `None`
    /// when they leave a direction free.
    #[serde(default)]
    pub precision: Option<AnswerPrecision>,
    /// The wall leverage the stop vetoes by ([`LeverageVeto`]); `None` where it does not
    /// (the heading known, or the paper's sensor). Not an input of the estimate.
    #[serde(default)]
    pub leverage: Option<LeverageVeto>,
}

/// Standard deviations of the answer from the information of the readings it explains
/// ([`crate::registration::precision::pose_covariance`] at [`PRECISION_SIGMA`]).
///
/// **Why the stop reads them.** Most wrong answers at K = 10 were not another pose: they
/// were the right one, off by 0.5–1.3° in heading or by 5–50 cm (27 of 36 wrong first
/// stops on the calibration plans). Every reading is explained (3σ of the range model is
/// 9 cm), and the rivals are beaten, so nothing else the stop reads can tell them from a
/// right answer; how tightly the readings' geometry pins the pose can. With these features
/// the logistic model reaches 1 % wrong first stops 0.9 ranges earlier on the learnt
/// policy's K = 10 calibration episodes (`docs/EVALUATION.md`, "The answer's precision").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnswerPrecision {
    /// Of the position, `√(σx² + σy²)` (m).
    pub position: f32,
    /// Of the heading (rad; 0 when it is known).
    pub heading: f32,
    /// How well the explained readings agree with the plan at the answer: the
    /// a-posteriori variance factor of their range residuals
    /// ([`crate::registration::precision::PoseCovariance::variance_factor`], at
    /// [`PRECISION_SIGMA`]).
    ///
    /// **Why the stop reads it.** As-built walls stand centimetres off their drawn lines
    /// (`--site site`): readings within the 9 cm gate are "explained" and the geometry
    /// pins the pose, yet the answer carries a wall's offset. What shows it is readings
    /// that disagree by more than the EDM's noise (on the site level's wrong answers, K = 1,
    /// the residuals' χ² was at the 0.04 % and 1.5 % tails).
    #[serde(default = "unit_variance_factor")]
    pub variance_factor: f32,
}

fn unit_variance_factor() -> f32 {
    1.0
}

impl StopFeatures {
    /// The stop's veto holds here ([`LeverageVeto::vetoes`]): no answer, whatever the
    /// estimate.
    pub fn vetoed(&self) -> bool {
        self.leverage.is_some_and(|l| l.vetoes())
    }

    /// The model's input vector: logit of the peak mass, entropy, ln(readings), readings
    /// left unexplained, explained readings beyond the unknowns (capped at 10: the checks
    /// the fit passed), observability, the refined pose's offsets from the argmax (cells,
    /// bins), closeness to the cell's edge `exp(−margin / 2 cm)`, the fraction of
    /// bearings left unexplained, repeated readings per distinct bearing, whether the
    /// refined pose and the argmax disagree, and the rival margin in two linear pieces
    /// (below and above [`MARGIN_KNEE`], in tens of nats): a logistic model cannot bend by
    /// itself, and the first unexplained reading of a rival is worth more than the rest.
    /// Then the answer's precision: whether it has none, and the logs of its position and
    /// heading standard deviations in units of the surveyor's tolerance (5 cm, 0.5°),
    /// clamped to [10⁻³, 10]; last, the log of the residuals' variance factor clamped to
    /// [0.1, 100] (0 without a precision).
    pub fn to_vector(&self) -> [f32; FEATURES] {
        let m = if self.rival_margin.is_nan() {
            0.0
        } else {
            self.rival_margin
                .clamp(-rivals::MARGIN_CAP, rivals::MARGIN_CAP)
        };
        let p = self.peak_mass.clamp(1e-4, 1.0 - 1e-4);
        let unexplained = self.readings.saturating_sub(self.explained) as f32;
        let checks = (self.explained as f32 - self.unknowns as f32).clamp(-3.0, 10.0);
        [
            ln(p / (1.0 - p)),
            self.entropy,
            ln((self.readings as f32).max(1.0)),
            unexplained,
            checks,
            self.observability,
            self.offset_cells,
            self.offset_bins,
            exp(-self.edge_margin.max(0.0) / EDGE_SCALE),
            unexplained / (self.readings as f32).max(1.0),
            self.repeats as f32 / (self.readings as f32).max(1.0),
            if self.agrees { 0.0 } else { 1.0 },
            m.min(MARGIN_KNEE) / 10.0,
            (m - MARGIN_KNEE).max(0.0) / 10.0,
            if self.precision.is_some() { 0.0 } else { 1.0 },
            self.precision.map_or(0.0, |p| {
                log_ratio(p.position, Tolerance::SURVEYOR.position_m)
            }),
            self.precision.map_or(0.0, |p| {
                log_ratio(p.heading, Tolerance::SURVEYOR.heading_rad)
            }),
            self.precision.map_or(0.0, |p| {
                ln(if p.variance_factor.is_nan() {
                    100.0
                } else {
                    p.variance_factor.clamp(0.1, 100.0)
                })
            }),
        ]
    }
}

/// `ln(sigma / tolerance)`, the ratio clamped to [10⁻³, 10] (a NaN reads as the upper end).
fn log_ratio(sigma: f32, tolerance: f32) -> f32 {
    let r = sigma / tolerance;
    ln(if r.is_nan() {
        10.0
    } else {
        r.clamp(1e-3, 10.0)
    })
}

/// `t` with every row no looser than any row of a larger stated risk (a running minimum
/// from the top): a smaller risk never stops earlier than a larger one.
///
/// **Why.** Tables kept on each site level (`activesense calibrate --site mixed`) take each
/// row from the levels that can keep it: building sites keep 3 % and 10 % but not 1 %, so
/// the fitted EDM-only K = 1 table came out looser at 1 % than at 3 %. Read as it stands,
/// `--stop-risk 0.01` would have stopped before `--stop-risk 0.03` (the frontier's 1 % point
/// cheaper than its 3 % point); a stated risk that is not kept on sites must not buy a
/// looser stop than one that is.
pub fn no_looser_than_above(t: &[f32; STATED_RISKS.len()]) -> [f32; STATED_RISKS.len()] {
    let mut out = *t;
    for i in (0..out.len() - 1).rev() {
        out[i] = out[i].min(out[i + 1]);
    }
    out
}

/// The stated risks of [`StopModel::thresholds`] (the frontier's settings).
pub const STATED_RISKS: [f32; 5] = [0.001, 0.003, 0.01, 0.03, 0.1];

/// Agents a [`StopModel`] can hold a threshold table of their own for.
pub const AGENT_TABLES: usize = 2;

/// A threshold table fitted on one agent's episodes alone ([`StopModel::agent_tables`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AgentTable {
    /// The agent (the learnt policy's table serves its int8 form too).
    pub agent: AgentKind,
    /// As [`StopModel::thresholds`].
    pub thresholds: [f32; STATED_RISKS.len()],
}

/// A fitted logistic model of `P(wrong)` for one rotation setting, and the thresholds that
/// make a stated risk mean what it says.
///
/// **Why a threshold table.** The estimate is calibrated per decision point, but the stop
/// answers at the *first* point whose estimate falls below the threshold, and an episode
/// offers many points: stopping at "estimate below P" gave 0.4 % wrong answers at P = 10 %
/// with the heading known, so a user who asked for 1 % paid for 0.1 %.
/// `activesense calibrate` therefore also measures, on its fitting episodes, the wrong
/// answers of the first crossing for every threshold, and stores for each stated risk of
/// [`STATED_RISKS`] the largest threshold whose first crossings (and every smaller
/// threshold's) were wrong at most that often; [`StopModel::threshold_for`] interpolates.
///
/// **Why tables per agent.** How often a first crossing is wrong depends on how the agent
/// measures, not only on the estimate: at K = 10 the table pooled over five agents gave
/// the learnt policy 0.3 % wrong answers where 1 % was stated (`docs/EVALUATION.md`). The
/// agents an instrument runs (the learnt policy, heuristic-1) get a table fitted on their
/// own episodes ([`StopModel::agent_tables`]); every other agent uses the pooled one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StopModel {
    /// Rotation bins K it was fitted for.
    pub rot_bins: u8,
    /// Weights of [`StopFeatures::to_vector`].
    pub weights: [f32; FEATURES],
    /// Bias.
    pub bias: f32,
    /// The threshold on [`StopModel::risk`] for each stated risk of [`STATED_RISKS`]
    /// (positive, non-decreasing), pooled over the calibration agents: for agents without
    /// a table of their own.
    pub thresholds: [f32; STATED_RISKS.len()],
    /// Tables fitted on one agent's episodes each.
    #[serde(default)]
    pub agent_tables: [Option<AgentTable>; AGENT_TABLES],
}

impl StopModel {
    /// The threshold table `agent`'s stop uses: its own, else the pooled one.
    pub fn table_for(&self, agent: AgentKind) -> &[f32; STATED_RISKS.len()] {
        let agent = match agent {
            AgentKind::LearntInt8 => AgentKind::Learnt,
            a => a,
        };
        self.agent_tables
            .iter()
            .flatten()
            .find(|t| t.agent == agent)
            .map_or(&self.thresholds, |t| &t.thresholds)
    }

    /// The threshold the estimate must fall below for a stated risk `p` when `agent`
    /// measures ([`StopModel::table_for`] made [`no_looser_than_above`], interpolated by
    /// [`interpolate_table`]).
    pub fn threshold_for(&self, agent: AgentKind, p: f32) -> f32 {
        interpolate_table(&no_looser_than_above(self.table_for(agent)), p)
    }

    /// The calibrated risk of an answer whose [`stop_score`] is `score`: the smallest stated
    /// risk P (of `--stop-risk`, in `(0, 1]`) at which `agent`'s stop would answer with it,
    /// the inverse of [`Self::threshold_for`]. This is the number `--stop-risk` bounds;
    /// the score itself is the model's raw estimate, not a probability of this answer.
    pub fn calibrated_risk(&self, agent: AgentKind, score: f32) -> f32 {
        if score.is_nan() {
            return 1.0;
        }
        // threshold_for grows with P: bisect in ln P between 1e-6 and 1.
        let (mut lo, mut hi) = (ln(1e-6), 0.0f32);
        if score < self.threshold_for(agent, exp(lo)) {
            return exp(lo);
        }
        if score >= self.threshold_for(agent, 1.0) {
            return 1.0;
        }
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if score < self.threshold_for(agent, exp(mid)) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        exp(hi)
    }

    /// Whether the estimate `risk` after `bearings` distinct bearings lets `agent`'s stop
    /// answer at the stated risk `p` (its [`stop_score`] is below the threshold).
    pub fn stops(&self, agent: AgentKind, risk: f32, bearings: u16, p: f32) -> bool {
        stop_score(risk, bearings) < self.threshold_for(agent, p)
    }

    /// [`Self::stops`] at the decision point `f` whose estimate is `risk`, with its veto
    /// ([`decision_score`]).
    pub fn stops_on(&self, agent: AgentKind, f: &StopFeatures, risk: f32, p: f32) -> bool {
        decision_score(f, risk) < self.threshold_for(agent, p)
    }

    /// The estimated probability that the answered pose's cell is wrong.
    pub fn risk(&self, f: &StopFeatures) -> f32 {
        let x = f.to_vector();
        let z = self
            .weights
            .iter()
            .zip(x.iter())
            .fold(self.bias, |acc, (w, v)| acc + w * v);
        // σ(z), written so that neither branch overflows.
        if z >= 0.0 {
            1.0 / (1.0 + exp(-z))
        } else {
            let e = exp(z);
            e / (1.0 + e)
        }
    }

    /// The built-in model of `instrument` for `rot_bins` (the paper's sensor:
    /// [`crate::stop::calibration::MODELS`]; EDM only: [`crate::stop::calibration_edm::MODELS`],
    /// each fitted on its own profile's episodes): the one fitted for that K, else the one
    /// fitted for the nearest K.
    pub fn built_in(instrument: InstrumentProfile, rot_bins: u8) -> &'static StopModel {
        let models = match instrument {
            InstrumentProfile::EdmScan => crate::stop::calibration::MODELS,
            InstrumentProfile::Edm => crate::stop::calibration_edm::MODELS,
        };
        let mut best = &models[0];
        for m in models.iter() {
            if m.rot_bins.abs_diff(rot_bins) < best.rot_bins.abs_diff(rot_bins) {
                best = m;
            }
        }
        best
    }

    /// The built-in model for `rot_bins` of the paper's sensor ([`Self::built_in`]).
    pub fn for_rot_bins(rot_bins: u8) -> &'static StopModel {
        Self::built_in(InstrumentProfile::EdmScan, rot_bins)
    }
}

/// The threshold of table `t` (one entry per [`STATED_RISKS`]) for a stated risk `p`:
/// interpolated linearly in `ln p` and `ln threshold`, and proportional to `p` beyond the
/// table's ends; 0 (never stop) for a `p` that is not a positive number.
pub fn interpolate_table(t: &[f32; STATED_RISKS.len()], p: f32) -> f32 {
    if p.is_nan() || p <= 0.0 {
        return 0.0;
    }
    let s = &STATED_RISKS;
    let last = s.len() - 1;
    if p <= s[0] {
        return t[0] * p / s[0];
    }
    if p >= s[last] {
        return (t[last] * p / s[last]).min(1.0);
    }
    let i = (1..=last).find(|&i| p <= s[i]).unwrap_or(last);
    let f = (ln(p) - ln(s[i - 1])) / (ln(s[i]) - ln(s[i - 1]));
    exp(ln(t[i - 1].max(1e-9)) + f * (ln(t[i].max(1e-9)) - ln(t[i - 1].max(1e-9))))
}

#[cfg(test)]
mod calibrated_risk_tests {
    use super::*;

    /// The calibrated risk inverts the threshold table: a score just under P's threshold
    /// is answered at P and given a risk ≤ P, and the stop answers at the risk it is given.
    #[test]
    fn the_calibrated_risk_inverts_the_threshold_table() {
        for instrument in InstrumentProfile::ALL {
            for k in [1u8, 10] {
                let m = StopModel::built_in(instrument, k);
                for agent in [AgentKind::Learnt, AgentKind::Heuristic1, AgentKind::Blind0] {
                    for &p in &STATED_RISKS {
                        let score = m.threshold_for(agent, p) * 0.999;
                        let r = m.calibrated_risk(agent, score);
                        assert!(r <= p * 1.0001, "{agent:?} K = {k}: {r} > {p}");
                        assert!(score < m.threshold_for(agent, r * 1.0001));
                    }
                    assert_eq!(m.calibrated_risk(agent, f32::NAN), 1.0);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(peak: f32, readings: u16, explained: u16) -> StopFeatures {
        StopFeatures {
            peak_mass: peak,
            entropy: 2.0,
            readings,
            repeats: 0,
            explained,
            unknowns: 3,
            observability: 0.2,
            offset_cells: 0.3,
            offset_bins: 0.1,
            edge_margin: 0.1,
            agrees: true,
            rival_margin: 12.0,
            precision: None,
            leverage: None,
        }
    }

    /// The committed tables, both profiles, every K and agent: a smaller stated risk never
    /// has a larger threshold (a user asking for less risk never gets a looser stop, and
    /// [`StopModel::calibrated_risk`] bisects them).
    #[test]
    fn the_committed_threshold_tables_are_monotone() {
        let models = calibration::MODELS.iter().chain(calibration_edm::MODELS);
        for m in models {
            let tables = core::iter::once(m.thresholds)
                .chain(m.agent_tables.iter().flatten().map(|t| t.thresholds));
            for t in tables {
                assert!(
                    t.windows(2).all(|w| w[0] <= w[1]),
                    "K = {}: {t:?}",
                    m.rot_bins
                );
            }
        }
    }

    /// The veto holds past either bound, and on NaN; the decision score is then infinite.
    #[test]
    fn the_leverage_veto_holds_past_either_bound() {
        let at = |position, heading| LeverageVeto { position, heading };
        assert!(!at(VETO_WALL_LEVERAGE, VETO_WALL_HEADING_LEVERAGE).vetoes());
        assert!(at(VETO_WALL_LEVERAGE * 1.01, 0.0).vetoes());
        assert!(at(0.0, VETO_WALL_HEADING_LEVERAGE * 1.01).vetoes());
        assert!(at(f32::NAN, 0.0).vetoes());
        assert!(at(f32::INFINITY, 0.0).vetoes());
        let mut f = features(0.99, 8, 8);
        assert_eq!(decision_score(&f, 0.001), stop_score(0.001, 8));
        f.leverage = Some(at(2.0, 0.0));
        assert!(f.vetoed());
        assert_eq!(decision_score(&f, 0.001), f32::INFINITY);
        let m = StopModel::built_in(InstrumentProfile::Edm, 10);
        assert!(!m.stops_on(AgentKind::Learnt, &f, 0.0, 0.1));
    }

    #[test]
    fn risk_is_a_probability_and_follows_the_weights() {
        let m = StopModel {
            rot_bins: 10,
            weights: [
                -1.0, 0.0, 0.0, 2.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0,
            ],
            bias: 0.5,
            thresholds: [0.001, 0.003, 0.01, 0.03, 0.1],
            agent_tables: [None; AGENT_TABLES],
        };
        let sure = m.risk(&features(0.999, 8, 8));
        let unsure = m.risk(&features(0.6, 8, 5));
        assert!((0.0..=1.0).contains(&sure) && (0.0..=1.0).contains(&unsure));
        assert!(sure < 0.01 && unsure > 0.9, "{sure} {unsure}");
        // Extreme inputs stay finite.
        let extreme = StopModel {
            weights: [1e6; FEATURES],
            ..m
        };
        assert_eq!(extreme.risk(&features(1.0, 500, 0)), 1.0);
        let extreme = StopModel {
            weights: [-1e6; FEATURES],
            ..m
        };
        assert_eq!(extreme.risk(&features(1.0, 500, 500)), 0.0);
    }

    #[test]
    fn the_precision_features_are_logs_of_the_tolerance_ratio() {
        let last4 = |f: &StopFeatures| {
            let v = f.to_vector();
            [
                v[FEATURES - 4],
                v[FEATURES - 3],
                v[FEATURES - 2],
                v[FEATURES - 1],
            ]
        };
        let precision = |position: f32, heading: f32, variance_factor: f32| AnswerPrecision {
            position,
            heading,
            variance_factor,
        };
        // No precision: the flag, and the logs read zero.
        assert_eq!(last4(&features(0.9, 8, 8)), [1.0, 0.0, 0.0, 0.0]);
        // At the tolerance itself (5 cm, 0.5°) both logs are 0; a tenth is ln 0.1. Readings
        // that scatter as the EDM does (variance factor 1) read 0 too.
        let mut f = features(0.9, 8, 8);
        f.precision = Some(precision(0.05, 0.5f32.to_radians(), 1.0));
        let v = last4(&f);
        assert_eq!(v[0], 0.0);
        assert!(
            v[1].abs() < 1e-5 && v[2].abs() < 1e-5 && v[3] == 0.0,
            "{v:?}"
        );
        f.precision = Some(precision(0.005, 0.05f32.to_radians(), 9.0));
        let v = last4(&f);
        assert!((v[1] - 0.1f32.ln()).abs() < 1e-4 && (v[2] - 0.1f32.ln()).abs() < 1e-4);
        assert!((v[3] - 9f32.ln()).abs() < 1e-5, "{v:?}");
        // A known heading (σ = 0), a huge σ and a NaN stay finite: clamped to [1e-3, 10]
        // (the variance factor to [0.1, 100], a NaN reading as its upper end).
        f.precision = Some(precision(f32::NAN, 0.0, f32::NAN));
        let v = last4(&f);
        assert!((v[1] - 10f32.ln()).abs() < 1e-5, "{v:?}");
        assert!((v[2] - 1e-3f32.ln()).abs() < 1e-4, "{v:?}");
        assert!((v[3] - 100f32.ln()).abs() < 1e-5, "{v:?}");
        f.precision = Some(precision(1e9, f32::INFINITY, 0.0));
        let v = last4(&f);
        assert!((v[1] - 10f32.ln()).abs() < 1e-5 && (v[2] - 10f32.ln()).abs() < 1e-5);
        assert!((v[3] - 0.1f32.ln()).abs() < 1e-5, "{v:?}");
    }

    #[test]
    fn a_quarter_of_the_bearings_unexplained_is_a_mismatch() {
        // 3 of 7 off (the 5.5 m wrong answer of `stop::room_mismatch`), 2 of 8: mismatch.
        assert!(room_mismatch(7, 4));
        assert!(room_mismatch(8, 6));
        // One stray return is not; nor 2 of 9; nor anything with all explained.
        assert!(!room_mismatch(4, 3));
        assert!(!room_mismatch(9, 7));
        assert!(!room_mismatch(12, 12));
        // Counts that cannot happen (more explained than read) are no mismatch either.
        assert!(!room_mismatch(3, 5));
    }

    #[test]
    fn the_threshold_interpolates_the_table() {
        let t = [0.002, 0.006, 0.02, 0.05, 0.2];
        // At the table's points, between them (log-log), and beyond its ends.
        assert!((interpolate_table(&t, 0.01) - 0.02).abs() < 1e-6);
        assert!((interpolate_table(&t, 0.003) - 0.006).abs() < 1e-6);
        let mid = interpolate_table(&t, (0.01f32 * 0.03).sqrt());
        assert!((mid - (0.02f32 * 0.05).sqrt()).abs() < 1e-5, "{mid}");
        assert!((interpolate_table(&t, 0.0005) - 0.001).abs() < 1e-6);
        assert!((interpolate_table(&t, 0.2) - 0.4).abs() < 1e-6);
        assert_eq!(interpolate_table(&t, 0.9), 1.0);
        // A stated risk that is no positive number never stops.
        let m = StopModel {
            rot_bins: 1,
            weights: [0.0; FEATURES],
            bias: 0.0,
            thresholds: t,
            agent_tables: [None; AGENT_TABLES],
        };
        for p in [0.0, -0.1, f32::NAN] {
            assert_eq!(interpolate_table(&t, p), 0.0);
            assert!(!m.stops(AgentKind::Learnt, 0.0, 8, p));
        }
        // Monotone in the stated risk.
        let mut last = 0.0;
        for i in 1..200 {
            let t = interpolate_table(&t, i as f32 * 0.001);
            assert!(t >= last, "{i}: {t} < {last}");
            last = t;
        }
    }

    #[test]
    fn an_agent_with_a_table_of_its_own_uses_it_and_the_others_the_pooled_one() {
        let own = [0.004, 0.012, 0.04, 0.1, 0.4];
        let m = StopModel {
            rot_bins: 10,
            weights: [0.0; FEATURES],
            bias: 0.0,
            thresholds: [0.002, 0.006, 0.02, 0.05, 0.2],
            agent_tables: [
                None,
                Some(AgentTable {
                    agent: AgentKind::Learnt,
                    thresholds: own,
                }),
            ],
        };
        assert_eq!(m.table_for(AgentKind::Learnt), &own);
        // The int8 form is the same policy: it shares the table.
        assert_eq!(m.table_for(AgentKind::LearntInt8), &own);
        assert_eq!(m.table_for(AgentKind::Heuristic1), &m.thresholds);
        assert!((m.threshold_for(AgentKind::Learnt, 0.01) - 0.04).abs() < 1e-6);
        assert!((m.threshold_for(AgentKind::Heuristic1, 0.01) - 0.02).abs() < 1e-6);
        assert!(m.stops(AgentKind::Learnt, 0.03, 8, 0.01));
        assert!(!m.stops(AgentKind::Heuristic1, 0.03, 8, 0.01));
        // The threshold grows with the readings: the same estimate stops after 16.
        assert!(m.stops(AgentKind::Heuristic1, 0.03, 16, 0.01));
        assert!(!m.stops(AgentKind::Learnt, 0.03, 4, 0.01));
        assert_eq!(stop_score(0.03, 8), 0.03);
        assert_eq!(stop_score(0.03, 0), stop_score(0.03, 1));
    }

    /// A table looser at 1 % than at 3 % (a level kept 3 % but not 1 %) is read as the 3 %
    /// row at 1 %; tables that are already non-decreasing are read as they are.
    #[test]
    fn a_smaller_risk_never_stops_looser() {
        let t = [0.008, 0.007, 0.02, 0.012, 0.12];
        assert_eq!(no_looser_than_above(&t), [0.007, 0.007, 0.012, 0.012, 0.12]);
        let sorted = [0.001, 0.003, 0.01, 0.03, 0.1];
        assert_eq!(no_looser_than_above(&sorted), sorted);
        for instrument in InstrumentProfile::ALL {
            for k in [1u8, 10] {
                let m = StopModel::built_in(instrument, k);
                for agent in [AgentKind::Learnt, AgentKind::Heuristic1, AgentKind::Blind0] {
                    let at = |p| m.threshold_for(agent, p);
                    // Equal rows interpolate through exp(ln t): equal up to rounding.
                    assert!(STATED_RISKS
                        .windows(2)
                        .all(|w| at(w[0]) <= at(w[1]) * (1.0 + 1e-5)));
                }
            }
        }
    }

    #[test]
    fn every_setting_has_a_model() {
        for k in [1u8, 2, 5, 10, 36] {
            let m = StopModel::for_rot_bins(k);
            assert!(m.weights.iter().all(|w| w.is_finite()) && m.bias.is_finite());
            let tables = m.agent_tables.iter().flatten().map(|t| &t.thresholds);
            for t in core::iter::once(&m.thresholds).chain(tables) {
                assert!(t.windows(2).all(|w| 0.0 < w[0] && w[0] <= w[1]), "{t:?}");
            }
        }
        assert_eq!(StopModel::for_rot_bins(1).rot_bins, 1);
        assert_eq!(StopModel::for_rot_bins(10).rot_bins, 10);
    }
}
