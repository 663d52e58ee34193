//! Actions, their costs and the seven baseline agents of the paper's Table 3 (§3.1, §4.2).
//!
//! The agents live in the core (not the simulator) because the firmware runs them on the
//! instrument until the learnt policy arrives, and host and device must take the same
//! actions for the same seed. Randomness comes from a seeded [`Pcg32`] and integer
//! thresholds only, so no floating point is involved in a blind agent's choice.
//!
//! **Reading of Table 3.** "Samples a depth measurement every k-th action" is read as:
//! actions 0, k, 2k, … are measurements, every other action is a left rotation. This is
//! the reading that reproduces the paper's Table 4 ratios: heuristic-1 (k = 6) reports 3.199
//! measurements and 11.539 rotations, i.e. 5 rotations between consecutive measurements with
//! the episode ending on a measurement (5 × 2.2 = 11). heuristic-0 alternates starting with a
//! measurement (9.32 measurements vs 8.54 rotations).

use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};

/// One action of the discrete action set (§3.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Action {
    /// Turn the instrument counter-clockwise by one rotation step.
    RotateLeft,
    /// Turn the instrument clockwise by one rotation step.
    RotateRight,
    /// Take one EDM range measurement along the current bearing.
    Measure,
}

impl Action {
    /// Short lowercase name used in logs and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Action::RotateLeft => "rotate-left",
            Action::RotateRight => "rotate-right",
            Action::Measure => "measure",
        }
    }

    /// Change of the bearing index (in rotation steps) this action causes.
    pub fn bearing_delta(self) -> i32 {
        match self {
            Action::RotateLeft => 1,
            Action::RotateRight => -1,
            Action::Measure => 0,
        }
    }
}

/// Per-action costs (§4.2: 0.05 per measurement, 0.005 per rotation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActionCosts {
    /// Cost of one rotation step.
    pub rotate: f32,
    /// Cost of one measurement.
    pub measure: f32,
}

impl Default for ActionCosts {
    fn default() -> Self {
        ActionCosts {
            rotate: 0.005,
            measure: 0.05,
        }
    }
}

impl ActionCosts {
    /// The cost of `a`.
    pub fn of(&self, a: Action) -> f32 {
        match a {
            Action::Measure => self.measure,
            _ => self.rotate,
        }
    }
}

/// The Table-3 baseline agents.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum AgentKind {
    /// Left rotation 75 %, measurement 25 %.
    Blind0,
    /// Left rotation 50 %, measurement 50 %.
    Blind1,
    /// Right 33 %, left 33 %, measurement 34 %.
    Blind2,
    /// Alternates measurement and left rotation.
    Heuristic0,
    /// Left rotations, a measurement every 6th action.
    Heuristic1,
    /// Left rotations, a measurement every 18th action.
    Heuristic2,
    /// Left rotations, a measurement every 54th action.
    Heuristic3,
    /// The learnt actor-critic policy (§3.1); not a Table-3 baseline, so not in
    /// [`AgentKind::ALL`]. The host runs it from a policy file.
    Learnt,
    /// The learnt policy quantised to int8 ([`crate::quantized`]): what the instrument
    /// runs, and the host too, bit for bit.
    LearntInt8,
    /// Oracle-based information-gain maximisation (§4.3, eqs. 11–13): a greedy benchmark
    /// that stages every bearing's measurement as the ground truth would answer it. Host
    /// only (`activesense_sim::greedy`): it needs the ground truth.
    Oigm,
    /// OIGM with the gain divided by the cost of the rotations and the measurement that
    /// reach the bearing (the paper's OIGM ignores rotation cost). Host only.
    OigmCost,
    /// Expected-entropy minimisation (§4.3, eq. 14; Fox et al. 1998 on the GHT belief).
    /// Host only (`activesense_sim::greedy`).
    Eem,
}

impl AgentKind {
    /// All seven, in Table-3 order.
    pub const ALL: [AgentKind; 7] = [
        AgentKind::Blind0,
        AgentKind::Blind1,
        AgentKind::Blind2,
        AgentKind::Heuristic0,
        AgentKind::Heuristic1,
        AgentKind::Heuristic2,
        AgentKind::Heuristic3,
    ];

    /// The paper's name (`blind-0`, …, `heuristic-3`).
    pub fn name(self) -> &'static str {
        match self {
            AgentKind::Blind0 => "blind-0",
            AgentKind::Blind1 => "blind-1",
            AgentKind::Blind2 => "blind-2",
            AgentKind::Heuristic0 => "heuristic-0",
            AgentKind::Heuristic1 => "heuristic-1",
            AgentKind::Heuristic2 => "heuristic-2",
            AgentKind::Heuristic3 => "heuristic-3",
            AgentKind::Learnt => "learnt",
            AgentKind::LearntInt8 => "learnt-int8",
            AgentKind::Oigm => "oigm",
            AgentKind::OigmCost => "oigm-cost",
            AgentKind::Eem => "eem",
        }
    }

    /// True for the seven Table-3 baselines (which [`BaselineAgent`] plays).
    pub fn is_baseline(self) -> bool {
        AgentKind::ALL.contains(&self)
    }

    /// The §4.3 greedy benchmarks (host-side agents: the instrument refuses them).
    pub const GREEDY: [AgentKind; 3] = [AgentKind::Oigm, AgentKind::OigmCost, AgentKind::Eem];

    /// True for the greedy benchmarks.
    pub fn is_greedy(self) -> bool {
        AgentKind::GREEDY.contains(&self)
    }

    /// Parses a paper name (`learnt` included).
    pub fn from_name(s: &str) -> Option<AgentKind> {
        AgentKind::ALL
            .iter()
            .copied()
            .chain([AgentKind::Learnt, AgentKind::LearntInt8])
            .chain(AgentKind::GREEDY)
            .find(|a| a.name() == s)
    }

    /// Stable small integer id (wire protocol).
    pub fn id(self) -> u8 {
        self as u8
    }

    /// Inverse of [`AgentKind::id`].
    pub fn from_id(id: u8) -> Option<AgentKind> {
        match id {
            7 => Some(AgentKind::Learnt),
            8 => Some(AgentKind::LearntInt8),
            9 => Some(AgentKind::Oigm),
            10 => Some(AgentKind::OigmCost),
            11 => Some(AgentKind::Eem),
            _ => AgentKind::ALL.get(id as usize).copied(),
        }
    }

    /// Period k of the "measure every k-th action" heuristics.
    fn period(self) -> Option<u32> {
        match self {
            AgentKind::Heuristic0 => Some(2),
            AgentKind::Heuristic1 => Some(6),
            AgentKind::Heuristic2 => Some(18),
            AgentKind::Heuristic3 => Some(54),
            _ => None,
        }
    }

    /// Probabilities in percent of (left, right, measure) for the blind agents.
    fn pmf_percent(self) -> Option<(u32, u32, u32)> {
        match self {
            AgentKind::Blind0 => Some((75, 0, 25)),
            AgentKind::Blind1 => Some((50, 0, 50)),
            AgentKind::Blind2 => Some((33, 33, 34)),
            _ => None,
        }
    }
}

/// A running baseline agent: its kind, its own PRNG and the number of actions taken.
#[derive(Clone, Debug)]
pub struct BaselineAgent {
    kind: AgentKind,
    rng: Pcg32,
    step: u32,
}

impl BaselineAgent {
    /// A fresh agent; `seed` fixes every random choice it will make.
    pub fn new(kind: AgentKind, seed: u64) -> Self {
        BaselineAgent {
            kind,
            rng: Pcg32::seed_from_u64(seed),
            step: 0,
        }
    }

    /// The agent's kind.
    pub fn kind(&self) -> AgentKind {
        self.kind
    }

    /// Chooses the next action. Baselines ignore observations by definition (Table 3).
    pub fn next_action(&mut self) -> Action {
        let step = self.step;
        self.step += 1;
        if let Some(k) = self.kind.period() {
            return if step % k == 0 {
                Action::Measure
            } else {
                Action::RotateLeft
            };
        }
        // Unbiased-enough draw in [0, 100): high 32 bits of a 32x32 product.
        let r = ((self.rng.next_u32() as u64 * 100) >> 32) as u32;
        let (left, right, _measure) = self.kind.pmf_percent().unwrap_or((0, 0, 100));
        if r < left {
            Action::RotateLeft
        } else if r < left + right {
            Action::RotateRight
        } else {
            Action::Measure
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(kind: AgentKind, n: usize, seed: u64) -> [usize; 3] {
        let mut a = BaselineAgent::new(kind, seed);
        let mut c = [0; 3];
        for _ in 0..n {
            match a.next_action() {
                Action::RotateLeft => c[0] += 1,
                Action::RotateRight => c[1] += 1,
                Action::Measure => c[2] += 1,
            }
        }
        c
    }

    #[test]
    fn names_round_trip() {
        let every = AgentKind::ALL
            .into_iter()
            .chain([AgentKind::Learnt, AgentKind::LearntInt8])
            .chain(AgentKind::GREEDY);
        for (i, k) in every.enumerate() {
            assert_eq!(AgentKind::from_name(k.name()), Some(k));
            assert_eq!(AgentKind::from_id(k.id()), Some(k));
            assert_eq!(k.id() as usize, i, "ids are dense and stable");
            assert_eq!(k.is_baseline(), i < 7);
            assert_eq!(k.is_greedy(), i >= 9);
        }
        assert_eq!(AgentKind::from_id(12), None);
        assert_eq!(AgentKind::from_name("heuristic-9"), None);
        assert_eq!(AgentKind::from_name("learnt"), Some(AgentKind::Learnt));
        assert_eq!(
            AgentKind::from_id(AgentKind::Learnt.id()),
            Some(AgentKind::Learnt)
        );
    }

    #[test]
    fn blind_frequencies_match_table_3() {
        let n = 200_000;
        for (kind, expect) in [
            (AgentKind::Blind0, [0.75, 0.0, 0.25]),
            (AgentKind::Blind1, [0.5, 0.0, 0.5]),
            (AgentKind::Blind2, [0.33, 0.33, 0.34]),
        ] {
            let c = counts(kind, n, 7);
            for i in 0..3 {
                let f = c[i] as f64 / n as f64;
                // 5 sigma of a binomial proportion at n = 200k is < 0.006.
                assert!(
                    (f - expect[i]).abs() < 0.006,
                    "{kind:?} action {i}: {f} vs {}",
                    expect[i]
                );
            }
        }
    }

    #[test]
    fn heuristics_are_periodic() {
        for (kind, k) in [
            (AgentKind::Heuristic0, 2),
            (AgentKind::Heuristic1, 6),
            (AgentKind::Heuristic2, 18),
            (AgentKind::Heuristic3, 54),
        ] {
            let mut a = BaselineAgent::new(kind, 1);
            for step in 0..540u32 {
                let act = a.next_action();
                assert_eq!(
                    act == Action::Measure,
                    step % k == 0,
                    "{kind:?} step {step}"
                );
                assert_ne!(act, Action::RotateRight);
            }
        }
    }

    #[test]
    fn seeded_and_reproducible() {
        let run = |seed| {
            let mut a = BaselineAgent::new(AgentKind::Blind2, seed);
            (0..64)
                .map(|_| a.next_action())
                .collect::<heapless::Vec<_, 64>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }
}
