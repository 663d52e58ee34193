//! Loss helpers for the A2C trainer, which computes the output gradients (`dlogits`,
//! `dvalue`) itself: the categorical over the actions, its entropy and their gradients.

use super::N_ACTIONS;

/// Log-probabilities of the categorical over the actions; max-shifted so large logits do
/// not overflow.
pub fn log_softmax(logits: &[f32; N_ACTIONS]) -> [f32; N_ACTIONS] {
    let m = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let lse = m + logits.iter().map(|l| (l - m).exp()).sum::<f32>().ln();
    logits.map(|l| l - lse)
}

/// Action probabilities.
pub fn softmax(logits: &[f32; N_ACTIONS]) -> [f32; N_ACTIONS] {
    log_softmax(logits).map(f32::exp)
}

/// Entropy `−Σ p·log p` of the categorical (nats); `ln 3` at most.
pub fn entropy(logits: &[f32; N_ACTIONS]) -> f32 {
    let lp = log_softmax(logits);
    -lp.iter().map(|l| l.exp() * l).sum::<f32>()
}

/// `∂ log p(action) / ∂ logits = onehot(action) − p`.
pub fn log_prob_grad(logits: &[f32; N_ACTIONS], action: usize) -> [f32; N_ACTIONS] {
    let mut g = softmax(logits).map(|p| -p);
    g[action] += 1.0;
    g
}

/// `∂ entropy / ∂ logits = −p·(log p + H)`.
pub fn entropy_grad(logits: &[f32; N_ACTIONS]) -> [f32; N_ACTIONS] {
    let lp = log_softmax(logits);
    let h = -lp.iter().map(|l| l.exp() * l).sum::<f32>();
    lp.map(|l| -l.exp() * (l + h))
}
