//! The seven baseline agents of the paper's Table 3 (§3.1, §4.2), run on the instrument
//! and on the host alike: a seeded [`Pcg32`] and integer thresholds only, so a blind
//! agent's choice involves no floating point and host and device take the same actions
//! for the same seed. The reading of Table 3 is in [`crate::episode::actions`].

use crate::episode::{Action, AgentKind};
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;

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
