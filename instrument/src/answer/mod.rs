//! What the instrument answers, as a surveyor reads it: the station's position in
//! the plan's own coordinates (the file's units and axes, f64), its heading with the
//! convention stated (degrees and gon), the precision of the fit (standard deviations from
//! the registration's information matrix, or "underdetermined"), the readings it rests on,
//! the stated risk, and **every pose the room leaves consistent** with the readings: a
//! symmetric room with the heading unknown gives several, each with its probability, and the
//! answer says "ambiguous" instead of naming one. `--heading-hint DEG±TOL` breaks such a tie.
//!
//! One type, [`Answer`], printed ([`Answer::to_text`]) and written (serde JSON) by every
//! command that reports a pose: `episode`, `sim`, `serial run` (and the GeoCOM station).
//! It is built from the loaded plan's frame ([`PlanFrame`]), the episode's outcome (pose,
//! readings, symmetry, risk) and, in simulation, the truth ([`AnswerInput`]).
//!
//! **Frames.** The pipeline works in the model frame (metres, origin at the perimeter
//! centroid, [`crate::world::planfile`]); [`PlanFrame::to_plan`] puts a model point back into
//! the file's coordinates. Easting is the file's first coordinate, northing its second. The
//! heading is the direction of the instrument's encoder bearing 0, counter-clockwise from the
//! plan's +x (easting) axis; `azimuth_gon` gives the same direction clockwise from +y
//! (northing), as a surveyor's orientation.
//!
//! **Precision.** `sigma_*` are one standard deviation from
//! [`activesense_core::registration::precision::pose_covariance`] with the range noise
//! [`PRECISION_SIGMA_FACTOR`] × the sensor's σ; `activesense answer-coverage` measures how
//! often the true pose lies within the printed 2σ (`activesense_lab::coverage`).

mod fit;
mod text;

use crate::episode::Trajectory;
use crate::world::planfile::PlanFrame;
use activesense_core::episode::{
    Action, AgentKind, EpisodeConfig, EpisodeParams, EpisodeState, InstrumentProfile, Observation,
};
use activesense_core::protocol::EpisodeReport;
use activesense_core::registration::precision::{pose_covariance, PoseCovariance};
use activesense_core::registration::{Measurement, Observations};
use activesense_core::world::symmetry::{symmetry_order, SymmetryTolerance};
use activesense_core::{FloorPlan, Pose2};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The range noise the precision assumes, in units of the sensor's σ: the fit adds its own
/// imprecision to the EDM's (ICP convergence, f32), measured by `answer-coverage` on
/// *training* plans (the README's coverage figure is on test plans).
pub const PRECISION_SIGMA_FACTOR: f32 = 1.15;

/// A reading counts toward the precision when its range residual at the answer is within
/// this (m): the stop's own gate (3 × the range model's 3 cm σ), so that the answer's
/// precision and wall words read the readings the stop read.
pub const PRECISION_GATE: f32 = activesense_core::stop::PRECISION_GATE;

/// The heading convention, stated in every answer.
pub const HEADING_CONVENTION: &str =
    "direction of encoder bearing 0, counter-clockwise from the plan's +x (easting) axis";

/// An approximate heading from the user (`--heading-hint DEG±TOL`): the instrument's
/// compass or the site plan. In the answer's heading convention.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeadingHint {
    /// Heading (degrees, [`HEADING_CONVENTION`]).
    pub deg: f64,
    /// Tolerance (degrees).
    pub tol: f64,
}

/// Parses `DEG±TOL` (also `DEG+-TOL` or `DEG/TOL`), e.g. `160±20`.
pub fn parse_heading_hint(s: &str) -> Result<HeadingHint, String> {
    let bad = || {
        format!(
            "'{s}' is not a heading hint (expected DEG±TOL, e.g. 160±20 or 160+-20: the heading in degrees, counter-clockwise from the plan's +x axis, and how far off it may be)"
        )
    };
    let (d, t) = s
        .split_once('±')
        .or_else(|| s.split_once("+-"))
        .or_else(|| s.split_once('/'))
        .ok_or_else(bad)?;
    let deg: f64 = d.trim().parse().map_err(|_| bad())?;
    let tol: f64 = t.trim().parse().map_err(|_| bad())?;
    if !deg.is_finite() || !tol.is_finite() || !(0.0..180.0).contains(&tol) {
        return Err(bad());
    }
    Ok(HeadingHint { deg, tol })
}

/// One pose the readings leave consistent, in plan coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Easting (file units).
    pub easting: f64,
    /// Northing (file units).
    pub northing: f64,
    /// Heading (degrees in (−180, 180], [`HEADING_CONVENTION`]).
    pub heading_deg: f64,
    /// Heading (gon in [0, 400), same convention).
    pub heading_gon: f64,
    /// Probability that this is the station's pose, given the readings (and the hint).
    pub probability: f64,
    /// Standard deviations of this candidate (file units, degrees); `None` when the fit is
    /// underdetermined.
    pub sigma_e: Option<f64>,
    /// See `sigma_e`.
    pub sigma_n: Option<f64>,
    /// Where it comes from: `answer`, or `room symmetry C{n}, turned by {deg}°`.
    pub source: String,
}

/// How well the readings determine the pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Determination {
    /// More explained readings than unknowns: the fit was checked by the spare ones.
    Redundant,
    /// As many explained readings as unknowns: the precision is the sensor model's alone.
    Exact,
    /// Fewer explained readings than unknowns, or readings that leave a direction free.
    Underdetermined,
    /// No pose at all (no range returned).
    None,
}

/// One reading of the answer (scene frame).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Encoder bearing (degrees, counter-clockwise).
    pub bearing_deg: f64,
    /// Range (file units).
    pub range: f64,
    /// The range the plan predicts along this bearing from the answer (file units); `None`
    /// when there is no answer or the beam meets no wall of the plan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected: Option<f64>,
    /// How the reading compares with the plan at the answer.
    #[serde(default)]
    pub fit: ReadingFit,
    /// The plan's wall the beam meets at the answer (1-based, as `plan show` numbers them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall: Option<usize>,
}

/// How one reading compares with the range the plan predicts at the answer: the beam model
/// of *Probabilistic Robotics* §6.3 in words. A short reading is something in front of the
/// wall the plan does not draw (furniture, a column, a person); a long one reads through the
/// wall (an open door, glass) — or says the answer is wrong.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReadingFit {
    /// Within the fit's gate of the predicted range.
    #[default]
    Explained,
    /// Shorter than the plan predicts: something stands in front of the wall.
    Short,
    /// Longer than the plan predicts: through the wall, or a wrong answer.
    Long,
    /// The plan predicts no wall along this bearing from the answer.
    NoWall,
    /// Through a door of the plan: no wall is drawn there, whatever lies beyond reads as
    /// it may; not counted against the plan.
    ThroughDoor,
}

/// Share of readings that, once not explained by the plan at the answer, makes the answer
/// say the room does not match its plan (with at least [`MISMATCH_MIN_READINGS`]).
pub const MISMATCH_SHARE: f64 = activesense_core::stop::MISMATCH_SHARE as f64;

/// Fewest unexplained readings that make the answer say the room does not match its plan
/// (one stray return is the EDM's outlier rate at work, not a room unlike its plan).
pub const MISMATCH_MIN_READINGS: usize = activesense_core::stop::MISMATCH_MIN_READINGS as usize;

/// Variance factor of the explained readings' residuals
/// ([`PoseCovariance::variance_factor`]) above which the answer warns that they disagree
/// with the plan: residuals twice the EDM's σ rms. Readings that scatter as the EDM does
/// exceed it with probability e⁻⁴ ≈ 1.8 % at two spare readings and far less with more; a
/// wall 5 cm off its drawn line read against one on its line exceeds it.
pub const DISAGREEING_VARIANCE_FACTOR: f32 = 4.0;

/// The answer checked against the simulated truth (simulation only).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthCheck {
    /// True easting (file units).
    pub easting: f64,
    /// True northing (file units).
    pub northing: f64,
    /// True heading (degrees).
    pub heading_deg: f64,
    /// Distance of the answer's position (the first candidate) from the truth (file units).
    pub position_error: f64,
    /// Heading of the answer minus the true heading (degrees, wrapped).
    pub heading_error_deg: f64,
    /// The candidate nearest the truth (index into `candidates`).
    pub nearest: usize,
    /// Its easting, northing and heading errors (file units, degrees): what the printed
    /// σ are checked against.
    pub nearest_errors: [f64; 3],
}

/// The instrument's answer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    /// The room: plan file name or `plan SEED`.
    pub plan: String,
    /// Length unit of every position, σ and range (the file's).
    pub unit: String,
    /// Metres per `unit`.
    pub metres_per_unit: f64,
    /// What the coordinates are.
    pub coordinates: String,
    /// The heading convention ([`HEADING_CONVENTION`]).
    pub heading_convention: String,
    /// `refined`, `coarse` (fewer than two readings) or `none`.
    pub estimate: String,
    /// Station easting (file units); `None` without an estimate.
    pub easting: Option<f64>,
    /// Station northing (file units).
    pub northing: Option<f64>,
    /// Heading (degrees in (−180, 180]).
    pub heading_deg: Option<f64>,
    /// Heading (gon in [0, 400)).
    pub heading_gon: Option<f64>,
    /// The same direction as an azimuth: clockwise from +y (northing), gon in [0, 400).
    pub azimuth_gon: Option<f64>,
    /// True when the heading was given to the instrument (K = 1), not estimated.
    pub heading_given: bool,
    /// Standard deviation of the easting (file units); `None` when underdetermined.
    pub sigma_e: Option<f64>,
    /// Standard deviation of the northing (file units).
    pub sigma_n: Option<f64>,
    /// Standard deviation of the heading (degrees; 0 when given).
    pub sigma_heading_deg: Option<f64>,
    /// How well the readings determine the pose.
    pub determination: Determination,
    /// The precision in words (what the σ rest on, or why there are none).
    pub precision: String,
    /// Unknowns of the pose (2 with the heading given, 3 without).
    pub unknowns: u8,
    /// The readings the answer rests on.
    pub readings: Vec<Reading>,
    /// How many of them the pose explains (the others were left out as outliers).
    pub readings_explained: u16,
    /// The risk that this answer is wrong, as `--stop-risk` states risks: the smallest
    /// stated risk at which the calibrated stop answers with it (its tables, inverted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub risk: Option<f64>,
    /// The calibrated stop's raw estimate (the model's score before its tables), when it
    /// has one: for analysis, not the answer's risk.
    pub stop_risk: Option<f64>,
    /// Every pose consistent with the readings, most probable first (the answer's first).
    pub candidates: Vec<Candidate>,
    /// True when more than one candidate remains: no single pose is certain.
    pub ambiguous: bool,
    /// Why it is ambiguous, or what resolved it.
    pub ambiguity: Option<String>,
    /// The user's heading hint, if given.
    pub heading_hint: Option<HeadingHint>,
    /// The answer against the truth (simulation only).
    pub truth: Option<TruthCheck>,
    /// When the readings say the room does not match its plan, that, in words (how many
    /// readings hit something not on the plan, near which walls).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mismatch: Option<String>,
    /// When the answer rests on one wall's drawn position (a direction fixed by one wall
    /// alone; or a wall whose offset would carry into it, with the heading given, or with
    /// it unknown on the EDM-only profile), that, in words, with the reading that would
    /// settle it: the calibrated stop does not answer such a geometry, and [`Self::risk`]
    /// is then `None`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_reliance: Option<String>,
}

/// What an [`Answer`] is built from.
pub struct AnswerInput<'a> {
    /// The room's label.
    pub label: String,
    /// The room (model frame).
    pub plan: &'a FloorPlan,
    /// Where the model frame lies in the file's coordinates.
    pub frame: &'a PlanFrame,
    /// The answer's AgentPose (model frame), refined or coarse.
    pub pose: Option<Pose2>,
    /// Whether `pose` is the refined registration.
    pub refined: bool,
    /// The readings the answer rests on (scene frame).
    pub readings: &'a [Measurement],
    /// The heading was given (K = 1).
    pub heading_known: bool,
    /// The room's cyclic symmetry order.
    pub symmetry_order: u8,
    /// The stop's risk estimate.
    pub stop_risk: Option<f32>,
    /// Whose stop tables state the risk: the agent, the instrument and K.
    pub stop_tables: Option<(AgentKind, InstrumentProfile, u8)>,
    /// The simulated truth.
    pub truth: Option<Pose2>,
    /// The user's heading hint.
    pub hint: Option<HeadingHint>,
    /// The sensor's range noise σ (m).
    pub range_sigma: f32,
}

/// Degrees in (−180, 180].
fn deg(rad: f64) -> f64 {
    let d = rad.to_degrees() % 360.0;
    if d > 180.0 {
        d - 360.0
    } else if d <= -180.0 {
        d + 360.0
    } else {
        d
    }
}

/// Gon in [0, 400) of a heading in degrees.
fn gon(deg: f64) -> f64 {
    (deg / 0.9).rem_euclid(400.0)
}

impl Answer {
    /// Builds the answer (see the module documentation).
    pub fn new(i: &AnswerInput<'_>) -> Answer {
        let frame = i.frame;
        let unknowns = if i.heading_known { 2 } else { 3 };
        let readings: Vec<Reading> = i
            .readings
            .iter()
            .map(|m| Reading {
                bearing_deg: (m.bearing as f64).to_degrees(),
                range: frame.length_to_plan(m.range as f64),
                expected: None,
                fit: ReadingFit::Explained,
                wall: None,
            })
            .collect();
        let coordinates = if frame.bbox_centre == [0.0; 2] && frame.centroid == [0.0; 2] {
            "model frame of a generated plan (origin at its perimeter centroid)".to_string()
        } else {
            "the plan file's own coordinates (easting = its x, northing = its y)".to_string()
        };
        let mut a = Answer {
            plan: i.label.clone(),
            unit: frame.unit.clone(),
            metres_per_unit: frame.scale,
            coordinates,
            heading_convention: HEADING_CONVENTION.to_string(),
            estimate: match (i.pose, i.refined) {
                (None, _) => "none",
                (Some(_), true) => "refined",
                (Some(_), false) => "coarse",
            }
            .to_string(),
            easting: None,
            northing: None,
            heading_deg: None,
            heading_gon: None,
            azimuth_gon: None,
            heading_given: i.heading_known,
            sigma_e: None,
            sigma_n: None,
            sigma_heading_deg: None,
            determination: Determination::None,
            precision: "no estimate: no range returned".to_string(),
            unknowns,
            readings,
            readings_explained: 0,
            risk: calibrated_risk(i),
            stop_risk: i.stop_risk.map(f64::from),
            candidates: Vec::new(),
            ambiguous: false,
            ambiguity: None,
            heading_hint: i.hint,
            truth: None,
            mismatch: None,
            wall_reliance: None,
        };
        let Some(pose) = i.pose else {
            return a;
        };
        fit::compare_with_plan(&mut a, i.plan, &pose, i.readings, frame);
        // Precision from the information matrix of the readings the pose explains.
        let obs = Observations::from_slice(i.readings).ok();
        if i.refined {
            // The stop's leverage veto holds on the EDM-only profile with the heading
            // unknown (`Pipeline::leverage_veto`).
            let veto = !i.heading_known
                && i.stop_tables
                    .is_some_and(|(_, instrument, _)| instrument == InstrumentProfile::Edm);
            a.wall_reliance = obs
                .as_ref()
                .and_then(|o| fit::wall_reliance(i.plan, o, &pose, i.heading_known, veto));
            // The stop answers such a geometry at no stated risk.
            if a.wall_reliance.is_some() {
                a.risk = None;
            }
        }
        let cov = obs.as_ref().map(|o| {
            pose_covariance(
                i.plan,
                o,
                &pose,
                i.heading_known,
                PRECISION_SIGMA_FACTOR * i.range_sigma,
                PRECISION_GATE,
            )
        });
        let cov: Option<PoseCovariance> = match cov {
            Some(Ok(c)) => {
                a.readings_explained = c.used;
                a.determination = if c.exactly_determined() {
                    Determination::Exact
                } else {
                    Determination::Redundant
                };
                a.precision = if c.exactly_determined() {
                    format!(
                        "from {} of {} readings for {unknowns} unknowns: exactly determined, no spare reading checked the fit (the σ are the sensor model's alone)",
                        c.used,
                        i.readings.len()
                    )
                } else {
                    format!(
                        "from {} of {} readings for {unknowns} unknowns (range σ {:.1} mm{})",
                        c.used,
                        i.readings.len(),
                        1000.0 * PRECISION_SIGMA_FACTOR * i.range_sigma,
                        if c.left_out > 0 {
                            format!("; {} left out as outliers", c.left_out)
                        } else {
                            String::new()
                        }
                    )
                };
                let sigma_mm = 1000.0 * PRECISION_SIGMA_FACTOR * i.range_sigma;
                if !c.exactly_determined() && c.variance_factor.is_finite() {
                    let rms_mm = sigma_mm * c.variance_factor.max(0.0).sqrt();
                    a.precision
                        .push_str(&format!("; residuals {rms_mm:.1} mm rms"));
                    if c.variance_factor > DISAGREEING_VARIANCE_FACTOR {
                        a.precision.push_str(&format!(
                            "; WARNING: the readings disagree with the plan by more than the EDM's noise ({rms_mm:.1} mm rms against σ {sigma_mm:.1} mm): a wall may stand off its drawn line"
                        ));
                    }
                }
                if 2 * (c.used as usize) < i.readings.len() {
                    a.precision.push_str(&format!(
                        "; WARNING: only {} of {} readings fit this pose, it is likely wrong",
                        c.used,
                        i.readings.len()
                    ));
                }
                Some(c)
            }
            Some(Err(e)) => {
                a.determination = Determination::Underdetermined;
                a.precision = format!(
                    "{e} ({} readings taken): no precision can be given; take more readings",
                    i.readings.len()
                );
                None
            }
            None => {
                a.determination = Determination::Underdetermined;
                a.precision = format!(
                    "{} readings for {unknowns} unknowns: no precision can be given",
                    i.readings.len()
                );
                None
            }
        };
        if !i.refined && a.determination != Determination::Underdetermined {
            a.precision = format!("coarse estimate only (a grid cell), {}", a.precision);
        }
        let sig = |c: &PoseCovariance, phi: f64| {
            // The covariance of a twin turned by phi: R Σ Rᵀ.
            let (s, co) = phi.sin_cos();
            let (xx, xy, yy) = (c.cov[0][0] as f64, c.cov[0][1] as f64, c.cov[1][1] as f64);
            let e = co * co * xx - 2.0 * s * co * xy + s * s * yy;
            let n = s * s * xx + 2.0 * s * co * xy + co * co * yy;
            (
                frame.length_to_plan(e.max(0.0).sqrt()),
                frame.length_to_plan(n.max(0.0).sqrt()),
            )
        };
        // Candidates: the answer and, with the heading unknown, its images under the room's
        // symmetry (rotations about the perimeter centroid, the model origin), which explain
        // the readings exactly as well.
        let n = if i.heading_known {
            1
        } else {
            i.symmetry_order.max(1) as usize
        };
        let mut cands: Vec<Candidate> = (0..n)
            .map(|k| {
                let phi = 2.0 * PI * k as f64 / n as f64;
                let (s, c) = phi.sin_cos();
                let (x, y) = (pose.x as f64, pose.y as f64);
                let p = frame.to_plan([c * x - s * y, s * x + c * y]);
                let h = deg(pose.theta as f64 + phi);
                let (se, sn) = cov.as_ref().map(|cv| sig(cv, phi)).unzip();
                Candidate {
                    easting: p[0],
                    northing: p[1],
                    heading_deg: h,
                    heading_gon: gon(h),
                    probability: 1.0 / n as f64,
                    sigma_e: se,
                    sigma_n: sn,
                    source: if k == 0 {
                        "answer".to_string()
                    } else {
                        format!("room symmetry C{n}, turned by {:.0}°", phi.to_degrees())
                    },
                }
            })
            .collect();
        if n > 1 {
            a.ambiguity = Some(format!(
                "the room has {n}-fold symmetry (C{n}) and the heading is unknown: {n} poses explain the readings equally well"
            ));
        }
        if let Some(h) = i.hint {
            let within = |c: &Candidate| (deg((c.heading_deg - h.deg).to_radians())).abs() <= h.tol;
            let kept: Vec<Candidate> = cands.iter().filter(|c| within(c)).cloned().collect();
            if kept.is_empty() {
                a.ambiguity = Some(format!(
                    "no candidate lies within the heading hint {}±{}°: all are kept (check the hint)",
                    h.deg, h.tol
                ));
            } else {
                if kept.len() < cands.len() {
                    a.ambiguity = Some(if kept.len() == 1 {
                        format!(
                            "resolved by the heading hint {}±{}° ({} of {} candidates ruled out)",
                            h.deg,
                            h.tol,
                            cands.len() - 1,
                            cands.len()
                        )
                    } else {
                        format!(
                            "the heading hint {}±{}° leaves {} of {} candidates",
                            h.deg,
                            h.tol,
                            kept.len(),
                            cands.len()
                        )
                    });
                }
                let total: f64 = kept.iter().map(|c| c.probability).sum();
                cands = kept;
                for c in &mut cands {
                    c.probability /= total;
                }
            }
        }
        a.ambiguous = cands.len() > 1;
        let first = &cands[0];
        a.easting = Some(first.easting);
        a.northing = Some(first.northing);
        a.heading_deg = Some(first.heading_deg);
        a.heading_gon = Some(first.heading_gon);
        a.azimuth_gon = Some(gon(90.0 - first.heading_deg));
        a.sigma_e = first.sigma_e;
        a.sigma_n = first.sigma_n;
        a.sigma_heading_deg = cov
            .as_ref()
            .map(|c| (c.sigma_heading() as f64).to_degrees());
        if let Some(t) = i.truth {
            let p = frame.to_plan([t.x as f64, t.y as f64]);
            let h = deg(t.theta as f64);
            let errs: Vec<[f64; 3]> = cands
                .iter()
                .map(|c| {
                    [
                        c.easting - p[0],
                        c.northing - p[1],
                        deg((c.heading_deg - h).to_radians()),
                    ]
                })
                .collect();
            let dist = |e: &[f64; 3]| (e[0] * e[0] + e[1] * e[1]).sqrt();
            let nearest = (0..errs.len())
                .min_by(|&x, &y| {
                    let key = |e: &[f64; 3]| dist(e) + 1e-3 * e[2].abs();
                    key(&errs[x]).total_cmp(&key(&errs[y]))
                })
                .unwrap_or(0);
            a.truth = Some(TruthCheck {
                easting: p[0],
                northing: p[1],
                heading_deg: h,
                position_error: dist(&errs[0]),
                heading_error_deg: errs[0][2],
                nearest,
                nearest_errors: errs[nearest],
            });
        }
        a.candidates = cands;
        a
    }

    /// The answer of a simulated in-process episode (`episode`), with the episode's truth.
    pub fn of_trajectory(t: &Trajectory, hint: Option<HeadingHint>) -> Answer {
        let frame = t
            .spec
            .user_plan
            .as_ref()
            .map(|p| p.frame.clone())
            .unwrap_or_default();
        let readings: Vec<Measurement> = t
            .steps
            .iter()
            .filter_map(|s| s.range.map(|r| Measurement::new(s.bearing, r)))
            .take(t.outcome.answer_readings as usize)
            .collect();
        let o = &t.outcome;
        Answer::new(&AnswerInput {
            label: t.spec.plan_label(),
            plan: &t.plan,
            frame: &frame,
            pose: o.refined.map(|r| r.pose).or(o.coarse),
            refined: o.refined.is_some(),
            readings: &readings,
            heading_known: t.spec.rot_bins == 1,
            symmetry_order: o.symmetry_order,
            stop_risk: o.stop_risk,
            stop_tables: Some((t.spec.agent, t.spec.config.instrument, t.spec.rot_bins)),
            truth: Some(t.truth),
            hint,
            range_sigma: t.spec.sensor.sigma,
        })
    }
}

impl Answer {
    /// The answer a device reported (`sim`, `serial run`, the station): its report, the
    /// exchanged steps (for the readings), the episode's parameters (known heading, truth
    /// in simulation) and the plan it was loaded with.
    #[allow(clippy::too_many_arguments)]
    pub fn of_report(
        label: String,
        plan: &FloorPlan,
        frame: &PlanFrame,
        params: &EpisodeParams,
        report: &EpisodeReport,
        steps: &[(Action, Observation)],
        range_sigma: f32,
        hint: Option<HeadingHint>,
    ) -> Answer {
        let readings = readings_of_steps(params.config, steps, report.answer_readings);
        Answer::new(&AnswerInput {
            label,
            plan,
            frame,
            pose: report.refined.or(report.coarse),
            refined: report.refined.is_some(),
            readings: &readings,
            heading_known: params.known_heading.is_some(),
            symmetry_order: symmetry_order(plan, &SymmetryTolerance::default()),
            stop_risk: report.stop_risk,
            stop_tables: Some((params.agent, params.config.instrument, params.rot_bins)),
            truth: params.ground_truth,
            hint,
            range_sigma,
        })
    }
}

/// The answer's risk as the calibrated stop states risks ([`Answer::risk`]): its raw
/// estimate, scored over the distinct bearings read, through the tables of its agent,
/// instrument and K.
fn calibrated_risk(i: &AnswerInput<'_>) -> Option<f64> {
    let (agent, instrument, k) = i.stop_tables?;
    let raw = i.stop_risk?;
    let mut bearings: Vec<u32> = i.readings.iter().map(|m| m.bearing.to_bits()).collect();
    bearings.sort_unstable();
    bearings.dedup();
    let score = activesense_core::stop::stop_score(raw, bearings.len() as u16);
    let model = activesense_core::stop::StopModel::built_in(instrument, k);
    Some(f64::from(model.calibrated_risk(agent, score)))
}

/// The answer's readings of a remote episode: the returned ranges of `steps` at the encoder
/// bearing each was taken at, the first `answer_readings` of them.
pub fn readings_of_steps(
    config: EpisodeConfig,
    steps: &[(Action, Observation)],
    answer_readings: u16,
) -> Vec<Measurement> {
    let mut state = EpisodeState::new(config);
    let mut out = Vec::new();
    for (a, o) in steps {
        state.apply(*a);
        if let (Action::Measure, Some(r)) = (a, o.range) {
            out.push(Measurement::new(state.bearing(), r));
        }
    }
    out.truncate(answer_readings as usize);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use activesense_core::world::geometry::{rotate, unit};

    fn rect() -> FloorPlan {
        crate::fixtures::rect(12.0, 8.0)
    }

    /// Exact readings from `pose` at `bearings` (scene frame).
    fn readings(plan: &FloorPlan, pose: &Pose2, bearings: &[f32]) -> Vec<Measurement> {
        bearings
            .iter()
            .map(|&b| {
                let hit = plan
                    .ray_cast(pose.translation(), rotate(unit(b), pose.theta))
                    .unwrap();
                Measurement::new(b, hit.range)
            })
            .collect()
    }

    fn input<'a>(
        plan: &'a FloorPlan,
        frame: &'a PlanFrame,
        pose: Pose2,
        r: &'a [Measurement],
        heading_known: bool,
    ) -> AnswerInput<'a> {
        AnswerInput {
            label: "rect".into(),
            plan,
            frame,
            pose: Some(pose),
            refined: true,
            readings: r,
            heading_known,
            symmetry_order: 2,
            stop_risk: Some(0.004),
            stop_tables: None,
            truth: Some(pose),
            hint: None,
            range_sigma: 0.01,
        }
    }

    /// Readings that scatter as the EDM does are stated as residuals and nothing more;
    /// readings on one wall 5 cm long (the wall stands off its drawn line, still within the
    /// 9 cm that count as explained) make the answer warn in words.
    #[test]
    fn readings_that_disagree_with_the_plan_are_warned_of() {
        let plan = rect();
        let frame = PlanFrame::default();
        let pose = Pose2::new(1.0, 0.5, 0.3);
        let bearings = [0.0, 0.9, 1.7, 2.6, 3.4, 4.3, 5.1, 5.8];
        let clean = readings(&plan, &pose, &bearings);
        let a = Answer::new(&input(&plan, &frame, pose, &clean, false));
        assert!(
            a.precision.contains("residuals 0.0 mm rms"),
            "{}",
            a.precision
        );
        assert!(!a.precision.contains("disagree"), "{}", a.precision);
        let wall = |m: &Measurement| {
            plan.ray_cast(pose.translation(), rotate(unit(m.bearing), pose.theta))
                .unwrap()
                .wall
        };
        let moved = wall(&clean[0]);
        let off: Vec<Measurement> = clean
            .iter()
            .map(|m| {
                let extra = if wall(m) == moved { 0.05 } else { 0.0 };
                Measurement::new(m.bearing, m.range + extra)
            })
            .collect();
        let a = Answer::new(&input(&plan, &frame, pose, &off, false));
        assert!(a.readings.iter().all(|r| r.fit == ReadingFit::Explained));
        assert!(
            a.precision.contains(
                "WARNING: the readings disagree with the plan by more than the EDM's noise"
            ),
            "{}",
            a.precision
        );
        assert!(a.to_text().contains("a wall may stand off its drawn line"));
    }

    /// Readings the plan explains stay quiet; a room whose readings hit things the plan does
    /// not draw says so, with the bearing, the measured and the expected range, and the walls.
    #[test]
    fn a_room_unlike_its_plan_is_said_in_words() {
        let plan = rect();
        let frame = PlanFrame::default();
        let pose = Pose2::new(1.0, 0.5, 0.3);
        let bearings = [0.0, 0.9, 1.7, 2.6, 3.4, 4.3, 5.1, 5.8];
        let clean = readings(&plan, &pose, &bearings);
        let a = Answer::new(&input(&plan, &frame, pose, &clean, false));
        assert!(a.readings.iter().all(|r| r.fit == ReadingFit::Explained));
        assert_eq!(a.mismatch, None);
        assert!(!a.to_text().contains("does not match"));
        // One stray reading is the EDM's outlier rate at work, not a room unlike its plan.
        let mut one = clean.clone();
        one[2] = Measurement::new(one[2].bearing, one[2].range - 0.6);
        let a = Answer::new(&input(&plan, &frame, pose, &one, false));
        assert_eq!(a.readings[2].fit, ReadingFit::Short);
        assert_eq!(a.mismatch, None);
        assert!(a
            .to_text()
            .contains("short: something in front of the wall"));
        // Cabinets in front of two walls and a door: the room is not its plan.
        let mut cluttered = one;
        cluttered[4] = Measurement::new(cluttered[4].bearing, cluttered[4].range - 0.5);
        cluttered[6] = Measurement::new(cluttered[6].bearing, cluttered[6].range + 2.0);
        let a = Answer::new(&input(&plan, &frame, pose, &cluttered, false));
        let words = a
            .mismatch
            .clone()
            .expect("three of eight readings off the plan");
        assert!(
            words.starts_with("the room does not match its plan: 3 of 8 readings are not on the plan (2 hit something in front of the plan's walls near walls"),
            "{words}"
        );
        assert!(
            words.contains("1 read beyond the plan's walls near wall"),
            "{words}"
        );
        let text = a.to_text();
        assert!(text.contains("ROOM DOES NOT MATCH THE PLAN"), "{text}");
        let expected = a.readings[6].expected.unwrap();
        assert!((a.readings[6].range - expected - 2.0).abs() < 1e-3);
        assert!(
            text.contains(&format!("{:.3} m expected", expected)),
            "{text}"
        );
    }

    #[test]
    fn hints_parse_and_refuse() {
        assert_eq!(
            parse_heading_hint("160±20"),
            Ok(HeadingHint {
                deg: 160.0,
                tol: 20.0
            })
        );
        assert_eq!(parse_heading_hint("-12.5+-5").unwrap().deg, -12.5);
        assert_eq!(parse_heading_hint("90/10").unwrap().tol, 10.0);
        for bad in ["160", "north±5", "10±-1", "10±200", "NaN±5"] {
            assert!(parse_heading_hint(bad).is_err(), "{bad}");
        }
        assert_eq!(gon(90.0), 100.0);
        assert_eq!(gon(-90.0), 300.0);
        assert!((deg(3.0 * PI) - 180.0).abs() < 1e-9);
    }

    #[test]
    fn a_symmetric_room_lists_both_twins_in_plan_coordinates() {
        let plan = rect();
        // The plan file was in millimetres around (2 600 123 000, 1 200 456 000).
        let frame = PlanFrame {
            unit: "mm".into(),
            scale: 0.001,
            bbox_centre: [2.600_123e9, 1.200_456e9],
            centroid: [0.0, 0.0],
        };
        let pose = Pose2::new(2.0, -1.0, 0.5);
        let r = readings(&plan, &pose, &[0.0, 1.3, 2.6, 3.9, 5.2]);
        let a = Answer::new(&input(&plan, &frame, pose, &r, false));
        assert!(a.ambiguous && a.candidates.len() == 2);
        // By hand: (2, −1) m from the centre, and its twin turned by 180°.
        assert!((a.candidates[0].easting - (2.600_123e9 + 2000.0)).abs() < 1e-3);
        assert!((a.candidates[1].northing - (1.200_456e9 + 1000.0)).abs() < 1e-3);
        assert!((a.candidates[1].heading_deg - deg(0.5 + PI)).abs() < 1e-4);
        assert!(
            a.sigma_e.unwrap() > 1.0 && a.sigma_e.unwrap() < 100.0,
            "{a:?}"
        );
        assert_eq!(a.truth.as_ref().unwrap().nearest, 0);
        assert!(a.to_text().contains("AMBIGUOUS: 2 poses"));
        // A hint near the twin's heading keeps the twin only.
        let hint = HeadingHint {
            deg: deg(0.5 + PI) + 5.0,
            tol: 20.0,
        };
        let a = Answer::new(&AnswerInput {
            hint: Some(hint),
            ..input(&plan, &frame, pose, &r, false)
        });
        assert!(!a.ambiguous && a.candidates.len() == 1);
        assert!((a.easting.unwrap() - (2.600_123e9 - 2000.0)).abs() < 1e-3);
        assert_eq!(a.candidates[0].probability, 1.0);
        // With the heading given, the twin is not a candidate.
        let a = Answer::new(&input(&plan, &frame, pose, &r, true));
        assert!(!a.ambiguous && a.heading_given);
        assert_eq!(a.sigma_heading_deg, Some(0.0));
    }

    #[test]
    fn an_underdetermined_fit_prints_no_precision() {
        let plan = rect();
        let frame = PlanFrame::default();
        let pose = Pose2::new(2.0, -1.0, 0.5);
        let r = readings(&plan, &pose, &[0.0, 1.3]);
        let a = Answer::new(&input(&plan, &frame, pose, &r, false));
        assert_eq!(a.determination, Determination::Underdetermined);
        assert_eq!(
            (a.sigma_e, a.sigma_n, a.sigma_heading_deg),
            (None, None, None)
        );
        let text = a.to_text();
        assert!(text.contains("precision: UNDERDETERMINED"), "{text}");
        let line = text.lines().find(|l| l.contains("precision")).unwrap();
        assert!(!line.contains('±'), "{line}");
        // Two readings with the heading given: exactly determined, said so.
        let a = Answer::new(&input(&plan, &frame, pose, &r, true));
        assert_eq!(a.determination, Determination::Exact);
        assert!(a.to_text().contains("exactly determined"));
    }
}
