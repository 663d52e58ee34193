//! What one refinement may spend, and on what: the named budgets of the
//! multi-hypothesis refinement ([`crate::registration::refine`]), apart from the search
//! that spends them. A budget caps the leave-out hypotheses, the heading sweep, the ICPs
//! inside the annealing and its rounds, and says whether the previous reading's answer is
//! carried; `refine`'s module docs measure what each cap costs and saves.

use crate::registration::{AnnealParams, IcpParams};
use serde::{Deserialize, Serialize};

/// Leave-out hypotheses only up to this many readings; beyond it the ICP's percentile
/// rejection drops outliers by itself (it keeps 80 % of the pairs).
pub const LEAVE_OUT_MAX_READINGS: usize = 10;
/// How the refinement chooses its hypotheses: the named [`Budget`]s.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Search {
    /// [`Budget::EXHAUSTIVE`]: the refinement as first built, with no cap; kept as the
    /// reference the others are measured against.
    Exhaustive,
    /// [`Budget::SCREENED`]: after every reading past the stop gate.
    Screened,
}

impl Search {
    /// The budget this search spends.
    pub const fn budget(self) -> Budget {
        match self {
            Search::Exhaustive => Budget::EXHAUSTIVE,
            Search::Screened => Budget::SCREENED,
        }
    }
}

/// What one refinement may spend, and on what. `u16::MAX` / `u8::MAX` leave a
/// quantity to the registration parameters (or to convergence).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Budget {
    /// Single leave-outs tried: the worst this many readings the all-readings fit leaves
    /// unexplained ([`crate::registration::fits::unexplained_readings`]), and then a second one only
    /// for the worst reading the winning single leave-out leaves unexplained. `u8::MAX`:
    /// every reading, and every second one around the winning single leave-out.
    pub leave_outs: u8,
    /// ICP iterations per heading-sweep start ([`crate::registration::register_multistart_capped`]):
    /// the sweep only picks the annealing's start.
    pub sweep_iterations: u16,
    /// Sweep starts run on to convergence after the short sweep, the best first.
    pub sweep_keep: u8,
    /// ICP iterations inside each annealing round (an ICP that has not converged by then
    /// oscillates between correspondence sets).
    pub icp_iterations: u16,
    /// Rounds of the winner's final annealing.
    pub final_rounds: u16,
    /// The final annealing starts where the screening left the winner (`true`), or again
    /// from the belief argmax after a heading sweep (`false`, as the exhaustive search does).
    pub final_from_winner: bool,
    /// After one more reading, re-fit the previous reading's refinement from its pose
    /// ([`refine_after`](crate::registration::refine::refine_after)) instead of searching afresh.
    pub carry: bool,
    /// Up to this many readings every annealing draws its configured perturbations per
    /// round; past it, proportionally fewer ([`Budget::perturbations`]). Every ICP
    /// iteration searches one correspondence per reading, so this keeps the annealing's
    /// work per refinement from growing with a long episode (uncapped, a 27-reading
    /// update took 54.6 M instructions on the device). `u8::MAX`: never fewer.
    pub full_readings: u8,
    /// ICP iterations inside each annealing round past [`Budget::full_readings`]
    /// readings (at most [`Budget::icp_iterations`]): a long episode's pose is pinned by
    /// its many readings, so its ICPs converge in a few iterations or oscillate; each
    /// iteration there costs a correspondence per reading.
    pub long_icp_iterations: u16,
    /// Rounds of the winner's final annealing past [`Budget::full_readings`] readings (at
    /// most [`Budget::final_rounds`]): a fresh search that late is one hypothesis (no
    /// leave-outs), and its final annealing was most of a worst-case update.
    pub long_final_rounds: u16,
    /// Re-fit the winner once more by plain ICP without percentile rejection
    /// ([`polish`](crate::registration::refine::polish)), kept when it scores better. The rejection keeps `⌈0.8 n⌉` pairs, so from
    /// five readings on it may drop the one reading that pins a direction (four readings on
    /// two parallel walls leave the pose free along them), and every hypothesis, the
    /// all-readings one included, then settles 10–50 cm off with that reading unexplained.
    pub polish: bool,
}

impl Budget {
    /// Every leave-one-out set, and every leave-two-out set around the best single
    /// leave-out (`1 + n + (n − 1)` screened registrations), each after a heading sweep
    /// run to convergence; the winner re-registered from the belief argmax with the full
    /// annealing.
    pub const EXHAUSTIVE: Budget = Budget {
        leave_outs: u8::MAX,
        sweep_iterations: u16::MAX,
        sweep_keep: 0,
        icp_iterations: u16::MAX,
        final_rounds: u16::MAX,
        final_from_winner: false,
        carry: false,
        full_readings: u8::MAX,
        long_icp_iterations: u16::MAX,
        long_final_rounds: u16::MAX,
        polish: false,
    };
    /// Leave-outs only for the worst [`SCREEN_CANDIDATES`] unexplained readings, a short
    /// sweep, capped ICPs and a short final annealing from the screened winner: most
    /// refinements are then two registrations (module docs).
    pub const SCREENED: Budget = Budget {
        leave_outs: SCREEN_CANDIDATES as u8,
        sweep_iterations: 8,
        sweep_keep: 0,
        icp_iterations: 30,
        final_rounds: 10,
        final_from_winner: true,
        carry: true,
        full_readings: LEAVE_OUT_MAX_READINGS as u8,
        long_icp_iterations: 30,
        long_final_rounds: 10,
        polish: false,
    };

    /// What the refinement after each reading past the stop gate spends (the calibrated
    /// stop's features come from it, [`crate::stop`]): [`Budget::SCREENED`] with the
    /// annealing's ICPs stopped at [`PER_READING_LONG_ICP_ITERATIONS`] past
    /// [`Budget::full_readings`] readings. With the heading known nothing is carried: there
    /// is no heading sweep, so a fresh search is cheap, and the carried re-fit stays in the
    /// previous reading's basin, which left confident K = 1 answers 0.5 mm further from the
    /// truth (learnt: 5.6 against 5.1 mm, outside the interval; `docs/EVALUATION.md`). It
    /// tries the screened leave-outs, not every one: every leave-out, after every reading of
    /// a long K = 1 episode, was its worst on-device update (40.9 M instructions);
    /// the end of the episode still tries every one ([`Budget::end_of_episode`]).
    pub const fn per_reading(heading_known: bool) -> Budget {
        if heading_known {
            Budget {
                carry: false,
                long_icp_iterations: PER_READING_LONG_ICP_ITERATIONS,
                long_final_rounds: PER_READING_LONG_FINAL_ROUNDS,
                polish: true,
                ..Budget::SCREENED
            }
        } else {
            Budget {
                full_readings: PER_READING_FULL_READINGS_UNKNOWN_HEADING,
                long_icp_iterations: PER_READING_LONG_ICP_ITERATIONS,
                long_final_rounds: PER_READING_LONG_FINAL_ROUNDS,
                polish: true,
                ..Budget::SCREENED
            }
        }
    }

    /// What the episode's last refinement spends when none was kept from the readings
    /// before ([`crate::pipeline::Pipeline::refine_final`]). It runs once per episode, so it
    /// buys back the accuracy the screened search loses (module docs, "The end of the
    /// episode"): with the heading known every reading is left out in turn (no heading
    /// sweep per hypothesis, so this is cheap); without, the worst three unexplained
    /// readings, the two best sweep starts run on to convergence, and half the final
    /// annealing (its other five rounds moved the mean pose error by 0.1 mm).
    pub const fn end_of_episode(heading_known: bool) -> Budget {
        if heading_known {
            Budget {
                leave_outs: u8::MAX,
                carry: false,
                ..Budget::SCREENED
            }
        } else {
            Budget {
                leave_outs: 3,
                carry: false,
                sweep_keep: 2,
                final_rounds: 5,
                ..Budget::SCREENED
            }
        }
    }

    /// Whether every leave-out is tried.
    pub(crate) fn exhaustive_leave_outs(&self) -> bool {
        self.leave_outs == u8::MAX
    }

    /// Perturbations per annealing round for `readings` readings, of `configured`: all of
    /// them up to [`Budget::full_readings`], beyond it `configured · full_readings /
    /// readings` rounded up (at least one), so perturbations times readings stays about
    /// constant.
    pub fn perturbations(&self, configured: u8, readings: usize) -> u8 {
        let full = self.full_readings as usize;
        if readings <= full {
            return configured;
        }
        (configured as usize * full).div_ceil(readings).max(1) as u8
    }

    /// `params` within this budget for `readings` readings: the ICP's iterations capped at
    /// [`Budget::icp_iterations`], the rounds at `rounds`, the perturbations at
    /// [`Budget::perturbations`].
    pub(crate) fn cap(&self, params: &AnnealParams, rounds: u16, readings: usize) -> AnnealParams {
        let iterations = if readings > self.full_readings as usize {
            self.icp_iterations.min(self.long_icp_iterations)
        } else {
            self.icp_iterations
        };
        AnnealParams {
            icp: IcpParams {
                max_iterations: params.icp.max_iterations.min(iterations),
                ..params.icp
            },
            max_rounds: params.max_rounds.min(rounds),
            perturbations: self.perturbations(params.perturbations, readings),
            ..*params
        }
    }
}

/// [`Budget::full_readings`] of the per-reading refinement with the heading unknown
/// ([`Budget::per_reading`]): from the ninth reading on, a fresh search draws fewer
/// perturbations, shorter ICPs and a short final annealing, as past the tenth before.
///
/// **Why.** The device's worst K = 10 measurement update was a fresh search at nine readings
/// (EDM only, int8 learnt, plan 1000007: the carried re-fit left the new reading unexplained
/// four readings in a row), 43.5 M instructions against the 40 M budget. From eight the
/// worst of the benchmark's 20 episodes was 37.8 M and the mean 7.6 → 7.3 M (the tables of
/// the time; `results/mcu-bench/` has today's), and on the 1000 test plans the no-oracle
/// rows moved by at most two episodes per row at every site level (`docs/EVALUATION.md`,
/// "The device's worst update, within budget").
pub const PER_READING_FULL_READINGS_UNKNOWN_HEADING: u8 = 8;

/// ICP iterations per annealing round of the per-reading refinement past
/// [`Budget::full_readings`] readings ([`Budget::per_reading`]).
pub const PER_READING_LONG_ICP_ITERATIONS: u16 = 12;

/// Final annealing rounds of the per-reading refinement past [`Budget::full_readings`]
/// readings ([`Budget::per_reading`]).
pub const PER_READING_LONG_FINAL_ROUNDS: u16 = 2;

/// Single leave-outs the screened search tries: the worst unexplained readings.
pub const SCREEN_CANDIDATES: usize = 2;
