//! The optimiser: Adam with bias correction, and the global gradient-norm clip applied
//! before each step.

/// Scales `grad` so its L2 norm is at most `max_norm`; returns the norm before clipping
/// (accumulated in f64, sequentially, so it is reproducible). A non-finite norm leaves the
/// gradient as it is: the caller should skip that update.
pub fn clip_global_norm(grad: &mut [f32], max_norm: f32) -> f32 {
    let norm = grad
        .iter()
        .map(|&g| f64::from(g) * f64::from(g))
        .sum::<f64>()
        .sqrt() as f32;
    if norm.is_finite() && norm > max_norm {
        let scale = max_norm / (norm + 1e-6);
        for g in grad.iter_mut() {
            *g *= scale;
        }
    }
    norm
}

/// Adam (Kingma & Ba 2015) with bias correction, PyTorch's update order. `eps` is 1e-5, the
/// usual RL choice (CleanRL, SB3), larger than the 1e-8 default to damp tiny second moments.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// Steps taken so far.
    pub t: u32,
    /// First-moment estimate per parameter.
    pub m: Vec<f32>,
    /// Second-moment estimate per parameter.
    pub v: Vec<f32>,
}

impl Adam {
    pub fn new(n_params: usize, lr: f32) -> Self {
        Adam {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-5,
            t: 0,
            m: vec![0.0; n_params],
            v: vec![0.0; n_params],
        }
    }

    /// One descent step: `params −= lr·m̂ / (√v̂ + eps)`.
    pub fn step(&mut self, params: &mut [f32], grad: &[f32]) {
        assert_eq!(params.len(), self.m.len(), "params length");
        assert_eq!(grad.len(), self.m.len(), "grad length");
        self.t += 1;
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2_sqrt = (1.0 - self.beta2.powi(self.t as i32)).sqrt();
        let step = self.lr / bc1;
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        for (((p, &g), m), v) in params
            .iter_mut()
            .zip(grad)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= step * *m / (v.sqrt() / bc2_sqrt + eps);
        }
    }
}
