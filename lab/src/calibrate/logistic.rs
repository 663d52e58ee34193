//! The fit of the stop's logistic model (`activesense calibrate`): Newton–Raphson with a
//! ridge penalty and step halving, over the [`FEATURES`] stop features and a bias.

use activesense_core::stop::FEATURES;

/// Logistic regression `P(y) = σ(w·x + b)` by Newton–Raphson with an L2 penalty `ridge`
/// on `w`; returns `(w, b)`. Each Newton step is halved until the penalised log-loss does
/// not rise, so (quasi-)separable data cannot make the weights run away.
pub fn fit_logistic(xs: &[[f64; FEATURES]], ys: &[bool], ridge: f64) -> ([f64; FEATURES], f64) {
    const D: usize = FEATURES + 1;
    let ext = |x: &[f64; FEATURES]| -> [f64; D] {
        std::array::from_fn(|k| if k < FEATURES { x[k] } else { 1.0 })
    };
    let loss = |beta: &[f64; D]| -> f64 {
        let mut l = 0.0;
        for (x, &y) in xs.iter().zip(ys) {
            let z: f64 = ext(x).iter().zip(beta).map(|(a, b)| a * b).sum();
            // log(1 + e^z) − y·z, written so that neither branch overflows.
            let softplus = if z > 0.0 {
                z + (-z).exp().ln_1p()
            } else {
                z.exp().ln_1p()
            };
            l += softplus - if y { z } else { 0.0 };
        }
        l + 0.5 * ridge * beta[..FEATURES].iter().map(|b| b * b).sum::<f64>()
    };
    let mut beta = [0.0f64; D];
    // Start the bias at the base rate.
    let p0 = (ys.iter().filter(|&&y| y).count() as f64 + 0.5) / (ys.len() as f64 + 1.0);
    beta[FEATURES] = (p0 / (1.0 - p0)).ln();
    let mut current = loss(&beta);
    for _ in 0..100 {
        let mut grad = [0.0f64; D];
        let mut hess = [[0.0f64; D]; D];
        for (x, &y) in xs.iter().zip(ys) {
            let xe = ext(x);
            let z: f64 = xe.iter().zip(&beta).map(|(a, b)| a * b).sum();
            let p = 1.0 / (1.0 + (-z).exp());
            let r = p - y as u8 as f64;
            let w = (p * (1.0 - p)).max(1e-12);
            for a in 0..D {
                grad[a] += r * xe[a];
                for b in 0..D {
                    hess[a][b] += w * xe[a] * xe[b];
                }
            }
        }
        for a in 0..FEATURES {
            grad[a] += ridge * beta[a];
            hess[a][a] += ridge;
        }
        let Some(step) = solve(hess, grad) else { break };
        let mut scale = 1.0;
        let mut accepted = false;
        for _ in 0..40 {
            let trial: [f64; D] = std::array::from_fn(|a| beta[a] - scale * step[a]);
            let l = loss(&trial);
            if l.is_finite() && l <= current {
                beta = trial;
                accepted = current - l > 1e-10 * current.abs().max(1.0);
                current = l;
                break;
            }
            scale *= 0.5;
        }
        if !accepted {
            break;
        }
    }
    (std::array::from_fn(|k| beta[k]), beta[FEATURES])
}

/// Gaussian elimination with partial pivoting; `None` for a singular system.
fn solve<const D: usize>(mut a: [[f64; D]; D], mut b: [f64; D]) -> Option<[f64; D]> {
    for c in 0..D {
        let p = (c..D).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-12 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        let (pivot_rows, rest) = a.split_at_mut(c + 1);
        let pivot = &pivot_rows[c];
        for (r, row) in rest.iter_mut().enumerate() {
            let f = row[c] / pivot[c];
            for (x, p) in row[c..].iter_mut().zip(&pivot[c..]) {
                *x -= f * p;
            }
            b[c + 1 + r] -= f * b[c];
        }
    }
    let mut x = [0.0f64; D];
    for r in (0..D).rev() {
        let s: f64 = (r + 1..D).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The fit recovers a known logistic model from its own samples.
    #[test]
    fn logistic_fit_recovers_known_weights() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let w_true = [1.5, -0.5, 0.0, 2.0, -1.0, 0.5, -0.7, 1.0, 0.3, -1.2, 0.8];
        let b_true = -1.0;
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for _ in 0..20_000 {
            let x: [f64; FEATURES] = std::array::from_fn(|_| rng.gen_range(-2.0..2.0));
            let z = b_true + w_true.iter().zip(&x).map(|(w, v)| w * v).sum::<f64>();
            let p = 1.0 / (1.0 + (-z).exp());
            xs.push(x);
            ys.push(rng.gen_bool(p));
        }
        let (w, b) = fit_logistic(&xs, &ys, 1e-6);
        for (got, want) in w.iter().zip(&w_true) {
            assert!((got - want).abs() < 0.12, "{w:?} vs {w_true:?}");
        }
        assert!((b - b_true).abs() < 0.12, "{b}");
    }

    /// Perfectly separable data (the first feature decides the label) must not make the
    /// weights run away: the step halving and the ridge keep them finite and moderate.
    #[test]
    fn logistic_fit_stays_finite_on_separable_data() {
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for i in 0..2000 {
            let v = (i as f64 / 1000.0) - 1.0;
            let mut x = [0.0; FEATURES];
            x[0] = v;
            x[1] = (i % 7) as f64;
            xs.push(x);
            ys.push(v > 0.0);
        }
        let (w, b) = fit_logistic(&xs, &ys, 1e-3);
        assert!(w.iter().all(|v| v.is_finite() && v.abs() < 1e4), "{w:?}");
        assert!(b.is_finite() && b.abs() < 1e4);
        assert!(w[0] > 10.0, "the deciding feature dominates: {w:?}");
    }
}
