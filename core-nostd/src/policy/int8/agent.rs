//! The int8 policy behind the [`Policy`] seam: [`QuantizedAgent`] (owns its
//! [`Scratch`]) and [`ScratchAgent`] (borrows one, as the device keeps its activations in a
//! `static`).

use super::{Decision, QuantizedPolicy, RunError, Scratch};
use crate::episode::Action;
use crate::policy::{Policy, PolicyInput};

/// The int8 policy as an agent: a parsed blob and its own [`Scratch`]. Put it in a
/// `static` (≈ [`SCRATCH_BYTES`](super::SCRATCH_BYTES)) on the device.
#[derive(Clone, Debug)]
pub struct QuantizedAgent<'a> {
    /// The network.
    pub policy: QuantizedPolicy<'a>,
    scratch: Scratch,
    /// The last decision (logits and value for logs).
    pub last: Option<Decision>,
    /// The last inference error, if the last call failed.
    pub last_error: Option<RunError>,
}

impl<'a> QuantizedAgent<'a> {
    /// An agent playing `policy` greedily.
    pub fn new(policy: QuantizedPolicy<'a>) -> Self {
        QuantizedAgent {
            policy,
            scratch: Scratch::new(),
            last: None,
            last_error: None,
        }
    }

    /// One decision, or why none could be made.
    pub fn decide(&mut self, input: &PolicyInput<'_>) -> Result<Decision, RunError> {
        let r = self.policy.decide(input, &mut self.scratch);
        self.last = r.ok();
        self.last_error = r.err();
        r
    }
}

impl Policy for QuantizedAgent<'_> {
    /// The argmax action. Should the input not fit the blob (a localizer with another `K`,
    /// which the caller is expected to rule out at episode start), the agent measures and
    /// records the error in [`QuantizedAgent::last_error`].
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        self.decide(input).map_or(Action::Measure, |d| d.action)
    }
}

/// A [`Policy`] over a borrowed [`Scratch`]: what the device runs, keeping the 12 KiB of
/// activations in its own `static` rather than in the agent.
pub struct ScratchAgent<'p, 's> {
    /// The network.
    pub policy: QuantizedPolicy<'p>,
    /// Its activations.
    pub scratch: &'s mut Scratch,
}

impl Policy for ScratchAgent<'_, '_> {
    /// As [`QuantizedAgent`]: the argmax action, or a measurement should the input not fit.
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        self.policy
            .decide(input, self.scratch)
            .map_or(Action::Measure, |d| d.action)
    }
}
