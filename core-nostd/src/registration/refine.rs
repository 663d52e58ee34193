//! Multi-hypothesis refinement: the end-of-episode registration of Fig. 1 (paper §3.3),
//! made robust to what a handful of readings cannot vote out.
//!
//! **The tail it removes.** With 2–4 readings the ICP's percentile rejection keeps every
//! pair (it must keep [`IcpParams::min_pairs`]), so one wild range (5 % of EDM readings)
//! drags the fit to the edge of the trust region. On the 1000 test plans, episodes with an
//! outlier made 73 % (K = 1) and 77 % (K = 10) of heuristic-1's mean pose error
//! (`docs/EVALUATION.md`, "Registration without a tail").
//!
//! **Hypotheses.** Around the belief argmax (inside the usual trust region): all readings;
//! every "all but one" set; and "all but two" around the best single leave-out — when there
//! are more readings than unknowns and at most [`LEAVE_OUT_MAX_READINGS`] of them. Each is
//! screened with a cheaper annealing ([`screening`]); the winner is registered again with
//! the full one.
//!
//! **Score (MAP).** Every hypothesis is scored on *all* readings, excluded or not:
//! `ln p(readings | pose)` under the EDM's range model ([`RangeModel`]: a reading is
//! explained or an outlier, so one unexplained reading costs a bounded amount) plus `ln` of
//! the belief's probability mass around the fitted pose ([`neighbourhood_mass`]): a fit that
//! slid to where the belief has no mass pays for it. Ties go to the earlier hypothesis (all
//! readings before fewer).
//!
//! **Other belief modes were tried and left out.** Refining the two strongest other modes
//! too (each in its own trust region, switching only when it explained more readings) made
//! recognised episodes worse: blind-1 at K = 10 went from 0.115 to 0.253 m mean pose error,
//! heuristic-0 at K = 1 from 0.061 to 0.091 m, and heuristic-1 did not change. In
//! near-symmetric rooms the mirrored mode explains the readings as well as the true one,
//! and the belief has already weighed that ambiguity.
//!
//! **Cost.** As first built ([`Search::Exhaustive`]) the refinement registered
//! `1 + n + (n − 1)` hypotheses, each after a 9-heading sweep of ICPs run to a 10 µm
//! tolerance, and re-ran the winner from the belief argmax with the full annealing; under
//! the calibrated stop it ran from scratch after every reading past the gate. `cargo xtask
//! mcu-bench --episodes 20 --termination confident` (heuristic-1, K = 10) counted 224 M guest
//! instructions per measurement update on average, 1.64 G at worst. Measured on the host
//! first (a temporary counter of `match_pairs` calls and pairs, not kept; 100 test plans,
//! heuristic-1, K = 10, confident
//! episodes, every refinement of the episode): the exhaustive search evaluated 40.6 k
//! correspondences per refinement; 75 % of what remained after screening the hypotheses
//! was the heading sweep. What the pipeline runs now ([`Search::Screened`]):
//!
//! * **Screening by the range likelihood.** Leave-outs are tried only for readings the
//!   all-readings fit leaves unexplained ([`registration::unexplained_readings`]), the
//!   worst [`SCREEN_CANDIDATES`]; the second leave-out only the worst reading the winning
//!   single leave-out still leaves unexplained. 7.3 k correspondences per refinement;
//!   same mean pose error (0.3030 m against 0.3029 m, capped at 1 m) and right answer
//!   cells (978 against 977 of 1213).
//! * **A short sweep** (8 ICP iterations per start, [`Budget::sweep_iterations`]: it
//!   only picks the annealing's start), ICPs inside the annealing cut at
//!   [`Budget::icp_iterations`] and the final annealing at [`Budget::final_rounds`] rounds,
//!   from the screened winner instead of a second sweep: 2.8 k correspondences, 0.3046 m,
//!   977 right cells. (The ICP and round caps alone changed neither figure.)
//! * **Carrying the previous reading's refinement** ([`refine_after`]) under the calibrated
//!   stop: re-fit from the previous pose with the screening annealing, kept when it
//!   explains every reading it uses. 1.4 k correspondences per refinement, 0.3032 m, 979
//!   right cells.
//! * **Past [`LEAVE_OUT_MAX_READINGS`] readings** the work per refinement no longer grows
//!   with the episode's length as it did: the annealing draws proportionally fewer
//!   perturbations ([`Budget::full_readings`]), and a carried re-fit is kept when it
//!   explains at least as many readings as the previous refinement did (no leave-out can
//!   drop a wild range there, so "every reading it uses" had sent every later update to a
//!   fresh search). The soak's 27-reading episode (plan 1000023, episode seed 30, int8 learnt,
//!   K = 10, stop risk 5 %) went from 20.7 M to 13.9 M instructions per measurement update
//!   on average; its worst update (53 M, a fresh search after the belief argmax left the
//!   trust region, plus the fine argmax re-voting all 16 readings around its new centre)
//!   still grows with the readings.
//! * Bit-identical speed-ups underneath: one pass over the walls per correspondence with
//!   squared distances (libm's `sqrtf` is software on the M4F), the heading's sine and
//!   cosine once per pose, visibility without the incidence angle; and the coarse-to-fine
//!   argmax of every vote made incremental ([`GhtLocalizer::refine_argmax`]).
//!
//! **The end of the episode** ([`Budget::end_of_episode`]). The screened search, run once
//! at the end of an oracle-stopped episode, cost accuracy there that the figures above (all
//! refinements of confident episodes, errors capped at 1 m) did not show: on the main job's
//! 1000 test plans the mean pose error of recognised episodes rose outside its 95 % interval
//! (heuristic-1 K = 10: 0.072 → 0.096 m; blind-1 K = 10: 0.118 → 0.154; blind-0 K = 1:
//! 0.037 → 0.046). The tail came from two places (`results/refine-budget/budgets.md`,
//! `cargo run --release -p activesense-sim --example refine_budget -- 1000`): with the heading
//! known, leave-outs of readings the wrong fit still "explains" (every leave-out: 0.0365 m,
//! better than the exhaustive 0.0373); without, sweep starts ranked after 8 ICP iterations,
//! before they reach their basin (the two best run on to convergence, with three
//! leave-outs: heuristic-1 0.069 m, blind-1 0.146). This runs once per episode, so it may
//! cost more than the per-reading search; on the device it keeps the oracle end of episode
//! at 7.9 M instructions mean, 33.7 M worst (`results/mcu-bench/`). The per-reading search,
//! which the calibrated stop was fitted on, is unchanged.
//!
//! Tried and not taken: with the exhaustive search, a 3-heading sweep instead of 9 (0.075 m mean pose
//! error over recognised episodes, heuristic-1, K = 10, 1000 test plans) and starting the
//! leave-out fits from the all-readings fit without a sweep (0.091 m), against 0.070 m; the
//! sweep is kept, only shortened.
//!
//! The exhaustive search stays ([`refine_with`]) as the reference `host-sim/tests/refine_search.rs`
//! measures the screened one against on recorded episodes. Instruction counts before and
//! after are in `results/mcu-bench/` and the README.

use crate::localization::grid::CellIndex;
use crate::localization::GhtLocalizer;
use crate::registration::{
    self, AnnealParams, IcpParams, Observations, RangeFit, RangeModel, Registration,
    RegistrationError, MAX_EXCLUDED, NOT_EXCLUDED,
};
use crate::world::floorplan::FloorPlan;
use crate::world::geometry::Pose2;
use crate::world::math::ln;
use serde::{Deserialize, Serialize};

pub use crate::registration::budget::{
    Budget, Search, LEAVE_OUT_MAX_READINGS, PER_READING_LONG_FINAL_ROUNDS,
    PER_READING_LONG_ICP_ITERATIONS, SCREEN_CANDIDATES,
};

/// Floor of the prior mass (a pose where the belief has no mass is not impossible: the
/// belief is coarse).
const MIN_PRIOR_MASS: f32 = 1e-6;

/// The winning hypothesis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// The registration of the winning hypothesis.
    pub registration: Registration,
    /// How well its pose explains all readings.
    pub fit: RangeFit,
    /// `ln` of the belief mass around its pose.
    pub log_prior: f32,
    /// Readings it left out ([`NOT_EXCLUDED`] = unused slot).
    pub excluded: [u16; MAX_EXCLUDED],
    /// Hypotheses registered.
    pub hypotheses: u16,
}

impl Refinement {
    /// The MAP score: log-likelihood plus log-prior.
    pub fn score(&self) -> f32 {
        self.fit.log_likelihood + self.log_prior
    }

    /// Readings left out by the winning hypothesis.
    pub fn excluded_count(&self) -> usize {
        self.excluded.iter().filter(|&&e| e != NOT_EXCLUDED).count()
    }
}

/// What the refinement needs besides the readings.
#[derive(Clone, Copy)]
pub struct RefineInput<'a> {
    /// The centred plan.
    pub plan: &'a FloorPlan,
    /// The readings.
    pub obs: &'a Observations,
    /// The belief (argmax and prior).
    pub localizer: &'a GhtLocalizer,
    /// Registration parameters (trust region, fixed heading, seed) of the winning
    /// hypothesis's final registration.
    pub params: AnnealParams,
    /// The cheaper annealing that screens the hypotheses ([`screening`]).
    pub screen: AnnealParams,
    /// Half-width of the heading sweep (0 with the heading known).
    pub heading_span: f32,
    /// Heading starts of the sweep.
    pub starts: u8,
    /// Unknowns of the pose (2 with the heading known, 3 without).
    pub unknowns: usize,
    /// The range model of the likelihood.
    pub model: RangeModel,
}

/// PMF mass of the cells within one cell / bin of the cell holding `pose` (the coarse
/// tolerance, as in [`GhtLocalizer::peak_mass`], without symmetric equivalents).
pub fn neighbourhood_mass(loc: &GhtLocalizer, pose: &Pose2) -> f32 {
    let grid = loc.grid();
    let Some(c) = grid.cell_of_pose(pose) else {
        return 0.0;
    };
    let bins = grid.rot_bins.max(1) as i16;
    let db_range: &[i16] = match bins {
        1 => &[0],
        2 => &[0, 1],
        _ => &[-1, 0, 1],
    };
    let mut mass = 0.0;
    for dy in -1i16..=1 {
        for dx in -1i16..=1 {
            let (x, y) = (c.ix as i16 + dx, c.iy as i16 + dy);
            if x < 0 || y < 0 || x >= grid.nx as i16 || y >= grid.ny as i16 {
                continue;
            }
            for &db in db_range {
                let bin = (c.bin as i16 + db).rem_euclid(bins) as u8;
                let i = grid.index(CellIndex {
                    ix: x as u8,
                    iy: y as u8,
                    bin,
                });
                mass += loc.prob(i);
            }
        }
    }
    mass
}

/// The annealing that screens hypotheses: a quarter of the perturbations and rounds of
/// `full` (the heading sweep is kept). Only the winner gets the full annealing, so the
/// refinement costs about as much as one full registration plus the screening.
pub fn screening(full: &AnnealParams) -> AnnealParams {
    AnnealParams {
        perturbations: (full.perturbations / 4).max(1),
        max_rounds: (full.max_rounds / 4).max(1),
        patience: (full.patience / 3).max(1),
        ..*full
    }
}

/// Registers and scores one hypothesis: start `centre`, readings `exclude` left out.
fn hypothesis(
    input: &RefineInput<'_>,
    params: &AnnealParams,
    centre: &Pose2,
    exclude: [u16; MAX_EXCLUDED],
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let params = AnnealParams {
        icp: IcpParams {
            exclude,
            ..params.icp
        },
        ..*params
    };
    let sweep_iterations = budget.sweep_iterations;
    let registration = registration::register_multistart_capped(
        input.plan,
        input.obs,
        centre,
        &params,
        input.heading_span,
        input.starts,
        sweep_iterations,
        budget.sweep_keep,
    )?;
    let fit = registration::range_fit(input.plan, input.obs, &registration.pose, &input.model);
    let log_prior = ln(neighbourhood_mass(input.localizer, &registration.pose).max(MIN_PRIOR_MASS));
    Ok(Refinement {
        registration,
        fit,
        log_prior,
        excluded: exclude,
        hypotheses: 1,
    })
}

/// One screened hypothesis around `centre` with every reading: what a rival belief mode
/// explains (the calibrated stop compares the answer with it). Its polish runs within the
/// budget's ICP iterations, as the answer's does: uncapped, a rival's polish on a long
/// K = 10 episode ran to the ICP's 100 iterations per call, and the worst device update
/// fell from 67.0 M to 59.0 M instructions when it was capped (the answers on 1000
/// validation plans unchanged).
pub fn rival_fit(
    input: &RefineInput<'_>,
    centre: &Pose2,
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let n = input.obs.len();
    let screen = budget.cap(&input.screen, u16::MAX, n);
    let input = RefineInput {
        starts: input.starts.min(RIVAL_STARTS),
        params: budget.cap(&input.params, u16::MAX, n),
        ..*input
    };
    let r = hypothesis(
        &input,
        &screen,
        centre,
        [NOT_EXCLUDED; MAX_EXCLUDED],
        budget,
    )?;
    Ok(polish_within(&input, r, budget))
}

/// Heading starts of a rival's sweep ([`rival_fit`]) when the heading is unknown: as many
/// as the answer's (`pipeline::REGISTRATION_STARTS`). With three, a rival's fit missed its
/// basin often enough that the rival margin over-stated the answer: on the learnt policy's
/// K = 10 calibration episodes (4000 plans) the stop needed 9.18 ranges for 1 % wrong first
/// stops, with nine 8.89 (`lab/scripts/stop_features.py --quarters`), and on 1000 validation plans
/// it cost 0.594 instead of 0.632 at a stated 1 % (`docs/EVALUATION.md`, "A rival fitted
/// from every heading start"). Each rival's cost is its annealing, not its sweep: the
/// device's K = 10 update went from 10.8 M to 11.3 M instructions on average with the
/// refitted stop, the worst unchanged (`cargo xtask mcu-bench --agent learnt-int8
/// --termination confident`).
pub const RIVAL_STARTS: u8 = 9;

/// Keeps the better of `best` and `cand` (the earlier one on ties).
fn keep_better(best: &mut Option<Refinement>, cand: Result<Refinement, RegistrationError>) {
    if let Ok(c) = cand {
        if best.as_ref().is_none_or(|b| c.score() > b.score()) {
            *best = Some(c);
        }
    }
}

/// All hypotheses around `centre`; the best of them.
fn refine_around(
    input: &RefineInput<'_>,
    centre: &Pose2,
    hypotheses: &mut u16,
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let n = input.obs.len();
    let none = [NOT_EXCLUDED; MAX_EXCLUDED];
    let full = hypothesis(input, &input.screen, centre, none, budget);
    *hypotheses += 1;
    let all_pose = full.as_ref().ok().map(|r| r.registration.pose);
    let mut best = None;
    let first_error = full.err();
    keep_better(&mut best, full);
    if n <= LEAVE_OUT_MAX_READINGS && n > input.unknowns {
        if budget.exhaustive_leave_outs() {
            for i in 0..n {
                let mut ex = none;
                ex[0] = i as u16;
                keep_better(
                    &mut best,
                    hypothesis(input, &input.screen, centre, ex, budget),
                );
                *hypotheses += 1;
            }
        } else if let Some(pose) = all_pose {
            let worst = registration::unexplained_readings::<LEAVE_OUT_MAX_READINGS>(
                input.plan,
                input.obs,
                &pose,
                &input.model,
                &[],
            );
            for &i in worst.iter().take(budget.leave_outs as usize) {
                let mut ex = none;
                ex[0] = i;
                keep_better(
                    &mut best,
                    hypothesis(input, &input.screen, centre, ex, budget),
                );
                *hypotheses += 1;
            }
        }
        // A second outlier: leave out one more, around the best single leave-out.
        let single = best
            .as_ref()
            .filter(|b| b.excluded_count() == 1)
            .map(|b| (b.excluded[0], b.registration.pose));
        if let Some((i, pose)) = single.filter(|_| n > input.unknowns + 1) {
            if budget.exhaustive_leave_outs() {
                for j in (0..n as u16).filter(|&j| j != i) {
                    keep_better(
                        &mut best,
                        hypothesis(input, &input.screen, centre, [i, j], budget),
                    );
                    *hypotheses += 1;
                }
            } else {
                let worst = registration::unexplained_readings::<1>(
                    input.plan,
                    input.obs,
                    &pose,
                    &input.model,
                    &[i],
                );
                for &j in worst.iter() {
                    keep_better(
                        &mut best,
                        hypothesis(input, &input.screen, centre, [i, j], budget),
                    );
                    *hypotheses += 1;
                }
            }
        }
    }
    match (best, first_error) {
        (Some(b), _) => Ok(b),
        (None, Some(e)) => Err(e),
        (None, None) => Err(RegistrationError::TooFewObservations),
    }
}

/// The multi-hypothesis refinement (module docs) around the belief argmax; `Err` when no
/// hypothesis registers (fewer than two readings, invalid parameters) or before any vote.
pub fn refine(input: &RefineInput<'_>) -> Result<Refinement, RegistrationError> {
    refine_within(input, &Budget::SCREENED)
}

/// [`refine`] with the hypothesis search `search`.
pub fn refine_with(
    input: &RefineInput<'_>,
    search: Search,
) -> Result<Refinement, RegistrationError> {
    refine_within(input, &search.budget())
}

/// [`refine`] within `budget`.
pub fn refine_within(
    input: &RefineInput<'_>,
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let Some(argmax) = input.localizer.argmax() else {
        return Err(RegistrationError::TooFewObservations);
    };
    let centre = input.localizer.grid().pose_of(argmax);
    refine_at(input, &centre, budget)
}

/// [`refine_within`] around `centre` instead of the belief argmax (its trust region is
/// `centre`'s): the refinement of another belief mode (the stop's rival that explains the
/// readings better than the argmax does, [`crate::stop::rivals`]).
pub fn refine_at(
    input: &RefineInput<'_>,
    centre: &Pose2,
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let n = input.obs.len();
    let final_rounds = if n > budget.full_readings as usize {
        budget.final_rounds.min(budget.long_final_rounds)
    } else {
        budget.final_rounds
    };
    let input = RefineInput {
        params: budget.cap(&input.params, final_rounds, n),
        screen: budget.cap(&input.screen, u16::MAX, n),
        ..*input
    };
    let centre = *centre;
    let mut hypotheses = 0u16;
    let best = refine_around(&input, &centre, &mut hypotheses, budget)?;
    let mut out = if budget.final_from_winner {
        // The full annealing from where the screening left the winner (its sweep and
        // screened annealing are not repeated).
        finish_from(&input, &centre, &best)?
    } else {
        // The winner, registered again with the full annealing.
        hypothesis(&input, &input.params, &centre, best.excluded, budget)?
    };
    out.hypotheses = hypotheses + 1;
    Ok(polish_within(&input, out, budget))
}

/// [`polish`] when `budget` asks for it, else `r` as it is.
fn polish_within(input: &RefineInput<'_>, r: Refinement, budget: &Budget) -> Refinement {
    if budget.polish {
        polish(input, r)
    } else {
        r
    }
}

/// One plain ICP from `r`'s pose with every pair kept (its left-out readings stay out),
/// scored as the hypotheses are; the better of the two ([`Budget::polish`]).
pub fn polish(input: &RefineInput<'_>, r: Refinement) -> Refinement {
    let icp = IcpParams {
        keep_fraction: 1.0,
        reject_median_factor: 0.0,
        exclude: r.excluded,
        ..input.params.icp
    };
    let Ok(registration) =
        registration::sparse_icp(input.plan, input.obs, &r.registration.pose, &icp)
    else {
        return r;
    };
    let fit = registration::range_fit(input.plan, input.obs, &registration.pose, &input.model);
    let log_prior = ln(neighbourhood_mass(input.localizer, &registration.pose).max(MIN_PRIOR_MASS));
    let polished = Refinement {
        registration,
        fit,
        log_prior,
        ..r
    };
    if polished.score() > r.score() {
        polished
    } else {
        r
    }
}

/// The refinement after one more reading, from `previous` (the refinement of the readings
/// before it): when the previous pose still lies in the trust region of the belief argmax,
/// the previous hypothesis (its readings left out, the new one in) is re-fitted from the
/// previous pose with the screening annealing, and kept when it explains every reading it
/// uses; otherwise, or when the new reading is one it does not explain, the refinement
/// starts afresh ([`refine`]). A reading that agrees with the pose so far moves it by
/// millimetres, so the sweep, the leave-outs and the full annealing would find the same
/// basin again; that is where the per-reading cost went (module docs). The re-fit and the
/// fresh search spend within `budget`.
pub fn refine_after(
    input: &RefineInput<'_>,
    previous: &Refinement,
    budget: &Budget,
) -> Result<Refinement, RegistrationError> {
    let Some(argmax) = input.localizer.argmax() else {
        return Err(RegistrationError::TooFewObservations);
    };
    let centre = input.localizer.grid().pose_of(argmax);
    let start = previous.registration.pose;
    let n = input.obs.len();
    let carried = registration::in_trust_region(&start, &centre, &input.params.icp)
        .then(|| {
            let capped = budget.cap(&input.screen, u16::MAX, n);
            let screen = AnnealParams {
                icp: IcpParams {
                    exclude: previous.excluded,
                    ..capped.icp
                },
                ..capped
            };
            registration::register_centred(input.plan, input.obs, &start, &centre, &screen).ok()
        })
        .flatten()
        .map(|registration| {
            let fit =
                registration::range_fit(input.plan, input.obs, &registration.pose, &input.model);
            (registration, fit)
        })
        .filter(|(r, fit)| {
            if n > LEAVE_OUT_MAX_READINGS {
                // No leave-out removes an outlier this far into the episode, so "explains
                // every reading it uses" would reject every re-fit once one wild range is
                // in: it is kept when it explains at least as many readings as the previous
                // one did (none lost; the new one may be a wild range too, which a fresh
                // search would not explain either). Before this rule every later update
                // of such an episode searched afresh (module docs).
                fit.explained >= previous.fit.explained
            } else {
                registration::unexplained_readings::<1>(
                    input.plan,
                    input.obs,
                    &r.pose,
                    &input.model,
                    &previous.excluded,
                )
                .is_empty()
            }
        });
    match carried {
        Some((registration, fit)) => {
            let log_prior =
                ln(neighbourhood_mass(input.localizer, &registration.pose).max(MIN_PRIOR_MASS));
            let r = Refinement {
                registration,
                fit,
                log_prior,
                excluded: previous.excluded,
                hypotheses: 1,
            };
            Ok(polish_within(input, r, budget))
        }
        None => refine_within(input, budget),
    }
}

/// Refinements of other belief modes an episode keeps ([`keep_alternate`]): when the
/// argmax flips between two or three near-twins of a room (a near-symmetric plan the
/// symmetry test does not call symmetric), each return re-fits from that mode's last
/// refinement instead of searching afresh. Why: on plan 1000002 (K = 10, int8 learnt
/// policy, calibrated stop) the argmax alternated between two cells 180° apart from the
/// eighth reading on, and every flip was a fresh search, the worst update 55.3 M
/// instructions at 32 readings. 3 × 60 bytes of RAM.
pub const ALTERNATE_MODES: usize = 3;

/// The refinement a carried re-fit ([`refine_after`]) starts from: `last` when its pose
/// lies in the trust region of the belief argmax, else the newest of `alternates` that does;
/// `None` when none does (search afresh).
pub fn carry_start(
    input: &RefineInput<'_>,
    last: Option<&Refinement>,
    alternates: &[Option<Refinement>],
) -> Option<Refinement> {
    let argmax = input.localizer.argmax()?;
    let centre = input.localizer.grid().pose_of(argmax);
    let fits = |r: &&Refinement| {
        registration::in_trust_region(&r.registration.pose, &centre, &input.params.icp)
    };
    last.filter(fits)
        .or_else(|| alternates.iter().flatten().find(fits))
        .copied()
}

/// Books `old`, the refinement `new` replaces as the episode's last, among `alternates`
/// (newest first) when the two lie at different modes (neither pose within the other's
/// trust region): it takes the place of the alternate at its own mode, else of the oldest.
/// An alternate at `new`'s mode is dropped either way (`new` is that mode's refinement now).
pub fn keep_alternate(
    alternates: &mut [Option<Refinement>],
    old: &Refinement,
    new: &Refinement,
    icp: &IcpParams,
) {
    let same = |a: &Refinement, b: &Refinement| {
        registration::in_trust_region(&a.registration.pose, &b.registration.pose, icp)
    };
    for slot in alternates.iter_mut() {
        if slot.as_ref().is_some_and(|a| same(a, new)) {
            *slot = None;
        }
    }
    if alternates.is_empty() || same(old, new) {
        return;
    }
    // Where `old` goes: its own mode's slot, else the last (oldest) one; the slots before
    // it move down by one, so the newest is first.
    let at = alternates
        .iter()
        .position(|a| a.as_ref().is_some_and(|a| same(a, old)))
        .or_else(|| alternates.iter().position(Option::is_none))
        .unwrap_or(alternates.len() - 1);
    for i in (1..=at).rev() {
        alternates[i] = alternates[i - 1];
    }
    alternates[0] = Some(*old);
}

/// The full annealing from the screened winner `best`; the better of the two by score.
fn finish_from(
    input: &RefineInput<'_>,
    centre: &Pose2,
    best: &Refinement,
) -> Result<Refinement, RegistrationError> {
    let params = AnnealParams {
        icp: IcpParams {
            exclude: best.excluded,
            ..input.params.icp
        },
        ..input.params
    };
    let registration = registration::register_centred(
        input.plan,
        input.obs,
        &best.registration.pose,
        centre,
        &params,
    )?;
    if registration.score > best.registration.score {
        return Ok(*best);
    }
    let fit = registration::range_fit(input.plan, input.obs, &registration.pose, &input.model);
    let log_prior = ln(neighbourhood_mass(input.localizer, &registration.pose).max(MIN_PRIOR_MASS));
    Ok(Refinement {
        registration,
        fit,
        log_prior,
        excluded: best.excluded,
        hypotheses: 1,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::fixtures::{centred_rect, l_room_8x6};
    use crate::localization::LocalizerConfig;
    use crate::registration::Measurement;
    use crate::world::geometry::{length, unit, v2};

    /// Three readings with the heading known, the last one an outlier: the plain
    /// registration is dragged off by it, the refinement leaves it out.
    #[test]
    fn an_outlier_among_three_readings_is_left_out() {
        let plan = l_room_8x6();
        let truth = Pose2::new(-1.2, -0.9, 0.3);
        // Model-frame rays at 0, 2.0 and 3.6 rad: the x = 8, y = 6 and x = 0 walls.
        let bearings = [-0.3f32, 1.7, 3.3];
        let mut obs = Observations::new();
        let mut loc = GhtLocalizer::new_empty();
        loc.reset(&plan, &LocalizerConfig::known_heading(truth.theta))
            .unwrap();
        for (k, &b) in bearings.iter().enumerate() {
            let true_range = plan
                .ray_cast(truth.translation(), unit(truth.theta + b))
                .unwrap()
                .range;
            let range = if k == 2 { 0.6 * true_range } else { true_range };
            obs.push(Measurement::new(b, range)).unwrap();
            loc.update(b, range).unwrap();
        }
        let mut params = AnnealParams::default();
        params.icp.fixed_heading = true;
        params.icp.trust_translation = loc.grid().cell[0].max(loc.grid().cell[1]);
        // Start from the truth's cell, as a coarse success would.
        let centre = loc.grid().pose_of(loc.grid().cell_of_pose(&truth).unwrap());
        let plain = registration::register(&plan, &obs, &centre, &params).unwrap();
        let plain_error = (plain.pose.translation() - truth.translation()).norm();
        assert!(
            plain_error > 0.05,
            "the outlier drags the plain fit: {plain_error}"
        );

        let input = known_heading_input(&plan, &obs, &loc, params);
        // Refine around the truth's cell directly (a coarse success; the belief's own
        // argmax may be a neighbour with three votes this sparse).
        let mut n = 0;
        let r = refine_around(&input, &centre, &mut n, &Budget::EXHAUSTIVE).unwrap();
        assert_eq!(r.excluded, [2, NOT_EXCLUDED]);
        assert_eq!(r.fit.explained, 2);
        assert_eq!(
            n,
            1 + 3,
            "the full set and three leave-one-outs (no second level at n = 3)"
        );
        let err = (r.registration.pose.translation() - truth.translation()).norm();
        assert!(
            err < 0.01,
            "refined error {err}: {r:?} truth {truth:?} centre {centre:?}"
        );
        // The whole refinement picks the same or an equally good hypothesis.
        let all = refine(&input).unwrap();
        assert!(all.score() >= r.score() - 1e-3);
    }

    /// A heading-known refinement input with the default range model and screening.
    pub(crate) fn known_heading_input<'a>(
        plan: &'a FloorPlan,
        obs: &'a Observations,
        loc: &'a GhtLocalizer,
        params: AnnealParams,
    ) -> RefineInput<'a> {
        RefineInput {
            plan,
            obs,
            localizer: loc,
            params,
            screen: screening(&params),
            heading_span: 0.0,
            starts: 1,
            unknowns: 2,
            model: RangeModel::default(),
        }
    }

    /// Readings at `bearings` (model frame, heading known) from `truth` in `plan`, voted.
    pub(crate) fn readings(
        plan: &FloorPlan,
        truth: &Pose2,
        bearings: &[f32],
    ) -> (Observations, GhtLocalizer) {
        let mut obs = Observations::new();
        let mut loc = GhtLocalizer::new_empty();
        loc.reset(plan, &LocalizerConfig::known_heading(truth.theta))
            .unwrap();
        for &b in bearings {
            let r = plan
                .ray_cast(truth.translation(), unit(truth.theta + b))
                .unwrap()
                .range;
            obs.push(Measurement::new(b, r)).unwrap();
            loc.update(b, r).unwrap();
        }
        (obs, loc)
    }

    /// Four readings on two parallel walls and one across: a pose slid along the walls
    /// explains the four, and the percentile rejection lets a fit stay there; the polish,
    /// which keeps every pair, brings it back to the pose all five agree on.
    #[test]
    fn the_polish_recovers_the_reading_rejection_dropped() {
        let plan = centred_rect(10.0, 6.0);
        let truth = Pose2::new(1.0, 0.5, 0.0);
        let deg = core::f32::consts::PI / 180.0;
        let (obs, loc) = readings(
            &plan,
            &truth,
            &[90.0 * deg, -90.0 * deg, 80.0 * deg, -80.0 * deg, 0.0],
        );
        let mut params = AnnealParams::default();
        params.icp.fixed_heading = true;
        params.icp.trust_translation = 1.0;
        let input = known_heading_input(&plan, &obs, &loc, params);
        let slid = Pose2::new(1.4, 0.5, 0.0);
        let fit = registration::range_fit(&plan, &obs, &slid, &input.model);
        assert_eq!(
            fit.explained, 4,
            "the slid pose explains the four on the long walls"
        );
        let mut start = at(slid.x, slid.y, slid.theta);
        start.fit = fit;
        start.log_prior = ln(neighbourhood_mass(&loc, &slid).max(MIN_PRIOR_MASS));
        let polished = polish(&input, start);
        assert!(polished.score() > start.score(), "{polished:?}");
        assert_eq!(polished.fit.explained, 5);
        let err = (polished.registration.pose.translation() - truth.translation()).norm();
        assert!(err < 0.01, "{err}");
        // Never worse: polishing the polished result changes nothing for the worse.
        assert!(polish(&input, polished).score() >= polished.score());
    }

    /// Past `full_readings` the annealing's perturbations shrink so that perturbations
    /// times readings stays about constant; the exhaustive budget never shrinks them.
    #[test]
    fn perturbations_shrink_past_full_readings() {
        let b = Budget::SCREENED;
        assert_eq!(b.full_readings as usize, LEAVE_OUT_MAX_READINGS);
        assert_eq!(b.perturbations(16, 3), 16);
        assert_eq!(b.perturbations(16, 10), 16);
        assert_eq!(b.perturbations(16, 20), 8);
        assert_eq!(b.perturbations(16, 27), 6);
        assert_eq!(b.perturbations(4, 17), 3);
        assert_eq!(b.perturbations(4, 200), 1);
        assert_eq!(Budget::EXHAUSTIVE.perturbations(16, 200), 16);
        assert_eq!(Budget::end_of_episode(false).perturbations(16, 40), 4);
        // Without the heading the per-reading search shrinks from the ninth reading on.
        let k10 = Budget::per_reading(false);
        assert_eq!(k10.perturbations(16, 8), 16);
        assert_eq!(k10.perturbations(16, 9), 15);
        assert_eq!(k10.perturbations(16, 16), 8);
        assert_eq!(Budget::per_reading(true).perturbations(16, 10), 16);
    }

    fn at(x: f32, y: f32, theta: f32) -> Refinement {
        Refinement {
            registration: Registration {
                pose: Pose2::new(x, y, theta),
                error: 0.0,
                score: 0.0,
                inliers: 0,
                relaxed: 0,
                iterations: 0,
                rounds: 0,
                converged: true,
            },
            fit: RangeFit {
                log_likelihood: 0.0,
                explained: 0,
                bearings: 0,
                explained_bearings: 0,
            },
            log_prior: 0.0,
            excluded: [NOT_EXCLUDED; MAX_EXCLUDED],
            hypotheses: 1,
        }
    }

    /// The alternates keep one refinement per mode, newest first, the oldest dropped
    /// when full; the mode the episode is at now is never among them.
    #[test]
    fn alternates_keep_one_refinement_per_mode() {
        let icp = IcpParams {
            trust_translation: 0.5,
            trust_rotation: 0.3,
            ..IcpParams::default()
        };
        let (a, a2) = (at(0.0, 0.0, 0.0), at(0.1, 0.0, 0.05));
        let (b, c, d) = (at(3.0, 0.0, 3.1), at(0.0, 3.0, 1.5), at(-3.0, 0.0, -1.5));
        let mut alt = [None; ALTERNATE_MODES];
        // Same mode: nothing kept.
        keep_alternate(&mut alt, &a, &a2, &icp);
        assert_eq!(alt, [None; ALTERNATE_MODES]);
        // a → b: a kept; b → a2 (back to a's mode): b kept, a's old entry dropped.
        keep_alternate(&mut alt, &a, &b, &icp);
        assert_eq!(alt[0], Some(a));
        keep_alternate(&mut alt, &b, &a2, &icp);
        assert_eq!(alt, [Some(b), None, None]);
        // a2 → c → d → a: b, a2, c kept newest first, then the oldest (b) drops for d.
        keep_alternate(&mut alt, &a2, &c, &icp);
        keep_alternate(&mut alt, &c, &d, &icp);
        assert_eq!(alt, [Some(c), Some(a2), Some(b)]);
        keep_alternate(&mut alt, &d, &a, &icp);
        assert_eq!(
            alt,
            [Some(d), Some(c), Some(b)],
            "a2's mode is the current one"
        );
        let e = at(3.0, 3.0, 0.0);
        keep_alternate(&mut alt, &a, &e, &icp);
        assert_eq!(alt, [Some(a), Some(d), Some(c)], "the oldest (b) dropped");
    }

    /// A station set up by a door: readings through it end somewhere behind the door,
    /// where the plan draws nothing. They are what the plan predicts ("beyond the door"):
    /// explained, never a leave-out candidate, and the refinement still finds the station
    /// (before, every such reading was a misfit and the stop never answered: the
    /// station sweep's column-and-door room, `docs/EVALUATION.md`, "Readings through a door").
    #[test]
    fn readings_through_a_door_are_explained_and_do_not_pull_the_fit() {
        // 6 × 4 m, a 1 m door in the bottom wall (x = 1..2), the station 0.4 m above it.
        let outline = [v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 4.0), v2(0.0, 4.0)];
        let door = (v2(2.0, 0.0), v2(1.0, 0.0));
        let plan = FloorPlan::with_columns_and_doors(&outline, &[], &[door], 0.02)
            .unwrap()
            .centered();
        let truth = Pose2::new(-1.5, -1.6, 0.3);
        let mut obs = Observations::new();
        let mut through = 0;
        for k in 0..12 {
            let b = -3.0 + 0.5 * k as f32;
            let d = unit(truth.theta + b);
            let r = match plan.door_exit(truth.translation(), d) {
                // The corridor's far wall, 2.5 m behind the door.
                Some(t) => {
                    through += 1;
                    t + 2.5
                }
                None => plan.ray_cast(truth.translation(), d).unwrap().range,
            };
            obs.push(Measurement::new(b, r)).unwrap();
        }
        assert!(through >= 3, "{through} readings through the door");
        let model = RangeModel::default();
        let fit = registration::range_fit(&plan, &obs, &truth, &model);
        assert_eq!(fit.explained, 12);
        let none = registration::unexplained_readings::<4>(&plan, &obs, &truth, &model, &[]);
        assert!(none.is_empty(), "{none:?}");
        // Short of the door (someone standing in it) is not through it.
        let mut blocked = obs.clone();
        let d = (0..12)
            .map(|k| -3.0 + 0.5 * k as f32)
            .find(|&b| {
                plan.door_exit(truth.translation(), unit(truth.theta + b))
                    .is_some()
            })
            .unwrap();
        let t = plan
            .door_exit(truth.translation(), unit(truth.theta + d))
            .unwrap();
        blocked.push(Measurement::new(d, t - 0.3)).unwrap();
        assert_eq!(
            registration::range_fit(&plan, &blocked, &truth, &model).explained,
            12
        );
        // The refinement from a start 0.2 m and 3° off lands on the station.
        let start = Pose2::new(truth.x + 0.15, truth.y - 0.13, truth.theta + 0.05);
        let r = registration::register(&plan, &obs, &start, &AnnealParams::default()).unwrap();
        let e = r.pose.translation() - truth.translation();
        assert!(
            length(e) < 0.01 && (r.pose.theta - truth.theta).abs() < 0.005,
            "{:?} against {truth:?}",
            r.pose
        );
    }

    #[test]
    fn range_fit_counts_explained_readings_and_bounds_an_outlier() {
        let plan = l_room_8x6();
        let pose = Pose2::new(0.5, -1.0, -0.4);
        let mut obs = Observations::new();
        for k in 0..4 {
            let b = 0.3 + 1.5 * k as f32;
            let r = plan
                .ray_cast(pose.translation(), unit(pose.theta + b))
                .unwrap()
                .range;
            obs.push(Measurement::new(b, r)).unwrap();
        }
        let model = RangeModel::default();
        let good = registration::range_fit(&plan, &obs, &pose, &model);
        assert_eq!(good.explained, 4);
        assert_eq!((good.bearings, good.explained_bearings), (4, 4));
        // A range repeated at a bearing already measured is another reading, not another check.
        let mut repeated = obs.clone();
        let again = plan
            .ray_cast(pose.translation(), unit(pose.theta + 0.3))
            .unwrap()
            .range;
        repeated.push(Measurement::new(0.3, again)).unwrap();
        let r = registration::range_fit(&plan, &repeated, &pose, &model);
        assert_eq!((r.explained, r.bearings, r.explained_bearings), (5, 4, 4));
        obs.push(Measurement::new(2.0, 40.0)).unwrap();
        let with_outlier = registration::range_fit(&plan, &obs, &pose, &model);
        assert_eq!(with_outlier.explained, 4);
        // One unexplained reading costs exactly the outlier density's log (its Gaussian
        // term underflows), not an unbounded square.
        let outlier_term = libm::logf(model.outlier_prob / model.max_range);
        assert!((with_outlier.log_likelihood - good.log_likelihood - outlier_term).abs() < 1e-3);
    }
}
