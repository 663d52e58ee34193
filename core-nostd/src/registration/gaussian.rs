//! The annealing's perturbations (Algorithm 3): standard normals from a seeded [`Pcg32`]
//! through Box–Muller in f32 (libm), so a seed fixes the registration on every target.

use super::*;

/// Standard-normal samples from a seeded [`Pcg32`] via Box–Muller in f32 (libm), identical
/// on every target.
#[derive(Clone, Debug)]
pub struct GaussianRng {
    rng: Pcg32,
    spare: Option<f32>,
}

impl GaussianRng {
    /// Seeds the generator.
    pub fn new(seed: u64) -> Self {
        GaussianRng {
            rng: Pcg32::seed_from_u64(seed),
            spare: None,
        }
    }

    /// Uniform in the open interval (0, 1) with 24-bit resolution.
    pub fn uniform(&mut self) -> f32 {
        ((self.rng.next_u32() >> 8) as f32 + 0.5) * (1.0 / 16_777_216.0)
    }

    /// One N(0, 1) sample.
    pub fn normal(&mut self) -> f32 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = sqrt(-2.0 * ln(u1));
        let a = TAU * u2;
        self.spare = Some(r * sin(a));
        r * cos(a)
    }
}
