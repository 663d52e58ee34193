//! The discrete action set, its costs and the agent kinds (paper §3.1, §4.2, Table 3):
//! what an episode is made of. The running baseline agents themselves live in
//! [`crate::policy::baselines`].
//!
//! The agents live in the core (not the simulator) because the firmware runs them on the
//! instrument until the learnt policy arrives, and host and device must take the same
//! actions for the same seed.
//!
//! **Reading of Table 3.** "Samples a depth measurement every k-th action" is read as:
//! actions 0, k, 2k, … are measurements, every other action is a left rotation. This is
//! the reading that reproduces the paper's Table 4 ratios: heuristic-1 (k = 6) reports 3.199
//! measurements and 11.539 rotations, i.e. 5 rotations between consecutive measurements with
//! the episode ending on a measurement (5 × 2.2 = 11). heuristic-0 alternates starting with a
//! measurement (9.32 measurements vs 8.54 rotations).

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
        Self::DEFAULT
    }
}

impl ActionCosts {
    /// The §4.2 costs: 0.005 per rotation, 0.05 per measurement.
    pub const DEFAULT: ActionCosts = ActionCosts {
        rotate: 0.005,
        measure: 0.05,
    };

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
    /// The learnt policy quantised to int8 ([`crate::policy::int8`]): what the instrument
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

    /// True for the seven Table-3 baselines (which [`BaselineAgent`](crate::policy::BaselineAgent) plays).
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
    pub(crate) fn period(self) -> Option<u32> {
        match self {
            AgentKind::Heuristic0 => Some(2),
            AgentKind::Heuristic1 => Some(6),
            AgentKind::Heuristic2 => Some(18),
            AgentKind::Heuristic3 => Some(54),
            _ => None,
        }
    }

    /// Probabilities in percent of (left, right, measure) for the blind agents.
    pub(crate) fn pmf_percent(self) -> Option<(u32, u32, u32)> {
        match self {
            AgentKind::Blind0 => Some((75, 0, 25)),
            AgentKind::Blind1 => Some((50, 0, 50)),
            AgentKind::Blind2 => Some((33, 33, 34)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
