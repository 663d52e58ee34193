//! Accuracy benchmark of the sparse registration (paper §3.3) on the test plans.
//!
//! For each test plan the agent is placed as in an episode ([`SimWorld`]); it takes
//! `measurements` EDM readings spread evenly over the turn at multiples of the rotation
//! step (a no-return advances one step and retries, as an agent would), through the
//! simulated sensor (σ = 1 cm noise, 5 % uniform outliers by default). The coarse pose the
//! localizer would hand over is simulated as the truth displaced uniformly within one grid
//! cell (± half a cell of `extent / cells` per axis, `extent` the larger bounding-box side)
//! and, for K = 10, within one 36° rotation bin (± 18°); for K = 1 the heading is exact and
//! the registration keeps it ([`IcpParams::fixed_heading`]).
//!
//! Each trial is registered twice: plain Sparse ICP (Algorithm 4) and the annealed
//! registration (Algorithm 3). Reported per setting and method: the position error
//! `‖â − a‖`, the heading error, and the symmetry-aware pose distance of §3.4
//! ([`PoseDistance::agent_distance`]), each as median / p90 / p99 / max and a histogram.

use activesense_core::episode::EpisodeConfig;
use activesense_core::registration::pose_distance::PoseDistance;
use activesense_core::registration::{
    register, sparse_icp, AnnealParams, IcpParams, Measurement, Observations,
};
use activesense_core::world::math::{wrap_angle, TAU};
use activesense_core::world::symmetry::SymmetryTolerance;
use activesense_core::Pose2;
use activesense_instrument::world::plans;
use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::SimWorld;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Benchmark options.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchOptions {
    /// Number of test plans (taken from the start of [`plans::TEST_SEEDS`]).
    pub plans: usize,
    /// Measurements per trial.
    pub measurements: usize,
    /// Grid cells across the larger room side (the coarse position error is within one
    /// cell).
    pub cells: f32,
    /// Sensor model (noise, outliers, no-return limits).
    pub sensor: SensorModel,
    /// Registration parameters (the K = 1 runs set `icp.fixed_heading`).
    pub params: AnnealParams,
    /// Seed of the measurement / coarse-pose stream.
    pub seed: u64,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            plans: 1000,
            measurements: 6,
            cells: 30.0,
            sensor: SensorModel::default(),
            params: AnnealParams::default(),
            seed: 1,
        }
    }
}

/// Order statistics and a histogram of one error quantity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Stats {
    /// Number of samples.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Maximum.
    pub max: f64,
    /// `(upper bound, count)`: samples `≤ bound` and above the previous bound; the last
    /// bound is infinite.
    pub histogram: Vec<(f64, usize)>,
}

impl Stats {
    fn new(values: &[f64], bounds: &[f64]) -> Self {
        let mut v: Vec<f64> = values.to_vec();
        v.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| -> f64 {
            if v.is_empty() {
                return f64::NAN;
            }
            // Nearest-rank percentile.
            let k = ((p * v.len() as f64).ceil() as usize).clamp(1, v.len());
            v[k - 1]
        };
        let mut histogram = Vec::new();
        let mut lo = f64::NEG_INFINITY;
        for &b in bounds.iter().chain(std::iter::once(&f64::INFINITY)) {
            histogram.push((b, v.iter().filter(|&&x| x > lo && x <= b).count()));
            lo = b;
        }
        Stats {
            n: v.len(),
            mean: v.iter().sum::<f64>() / v.len().max(1) as f64,
            median: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            max: v.last().copied().unwrap_or(f64::NAN),
            histogram,
        }
    }
}

/// Results of one (setting, method) pair.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MethodReport {
    /// `"K=10"` or `"K=1"`.
    pub setting: String,
    /// `"sparse-icp"` or `"annealed"`.
    pub method: String,
    /// Position error `‖â − a‖` (m).
    pub position_error: Stats,
    /// Heading error (degrees).
    pub heading_error_deg: Stats,
    /// Symmetry-aware pose distance (m).
    pub pose_distance: Stats,
    /// Registration error `E` at the result (m).
    pub registration_error: Stats,
    /// Fraction of trials with position error below 2 cm.
    pub below_2cm: f64,
    /// Mean wall-clock time per registration (µs, this host, release or debug as built).
    pub mean_time_us: f64,
}

/// One trial (kept in the JSON output).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Trial {
    /// Plan seed.
    pub plan_seed: u32,
    /// Setting (`"K=10"` / `"K=1"`).
    pub setting: String,
    /// Ground-truth AgentPose.
    pub truth: Pose2,
    /// Coarse (initial) AgentPose.
    pub initial: Pose2,
    /// Measurements used `(bearing, range)`.
    pub measurements: Vec<(f32, f32)>,
    /// How many of them were simulated outliers.
    pub outliers: usize,
    /// Sparse-ICP result.
    pub icp: Pose2,
    /// Annealed result.
    pub annealed: Pose2,
    /// Annealed position error (m).
    pub annealed_position_error: f32,
}

/// The benchmark report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    /// Options used.
    pub options: BenchOptions,
    /// Per setting and method.
    pub methods: Vec<MethodReport>,
    /// Every trial.
    pub trials: Vec<Trial>,
}

const METRE_BOUNDS: [f64; 8] = [0.001, 0.005, 0.01, 0.02, 0.05, 0.1, 0.5, 2.0];
const DEGREE_BOUNDS: [f64; 7] = [0.05, 0.1, 0.5, 1.0, 5.0, 18.0, 90.0];

#[derive(Default)]
struct Acc {
    pos: Vec<f64>,
    head: Vec<f64>,
    dist: Vec<f64>,
    err: Vec<f64>,
    time_us: f64,
}

impl Acc {
    fn add(&mut self, truth: &Pose2, est: &Pose2, e: f32, pd: &PoseDistance, us: f64) {
        self.pos
            .push((est.translation() - truth.translation()).norm() as f64);
        self.head
            .push(wrap_angle(est.theta - truth.theta).abs().to_degrees() as f64);
        self.dist.push(pd.agent_distance(truth, est) as f64);
        self.err.push(e as f64);
        self.time_us += us;
    }

    fn report(&self, setting: &str, method: &str) -> MethodReport {
        let n = self.pos.len().max(1) as f64;
        MethodReport {
            setting: setting.into(),
            method: method.into(),
            position_error: Stats::new(&self.pos, &METRE_BOUNDS),
            heading_error_deg: Stats::new(&self.head, &DEGREE_BOUNDS),
            pose_distance: Stats::new(&self.dist, &METRE_BOUNDS),
            registration_error: Stats::new(&self.err, &METRE_BOUNDS),
            below_2cm: self.pos.iter().filter(|&&p| p < 0.02).count() as f64 / n,
            mean_time_us: self.time_us / n,
        }
    }
}

/// Takes `n` measurements evenly over the turn from the true pose; returns them and the
/// number of simulated outliers.
fn take_measurements(world: &SimWorld, n: usize, rng: &mut Pcg32) -> (Vec<Measurement>, usize) {
    let config = EpisodeConfig::default();
    let steps = config.steps_per_turn as i32;
    let rot = config.rot_step();
    let start: i32 = rng.gen_range(0..steps);
    let stride = (steps / n.max(1) as i32).max(1);
    let truth = world.truth();
    let mut out = Vec::new();
    let mut outliers = 0;
    for j in 0..n as i32 {
        for retry in 0..stride {
            let k = start + j * stride + retry;
            let beta = wrap_angle(k as f32 * rot);
            let (r, kind) =
                world
                    .sensor()
                    .measure(world.plan(), truth.translation(), truth.theta + beta, rng);
            if let Some(r) = r {
                if r > 0.0 {
                    outliers += (kind == activesense_instrument::world::sensor::RangeKind::Outlier)
                        as usize;
                    out.push(Measurement::new(beta, r));
                    break;
                }
            }
        }
    }
    (out, outliers)
}

/// Runs the benchmark.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Report> {
    opts.sensor.validate().map_err(anyhow::Error::msg)?;
    anyhow::ensure!(opts.measurements >= 2, "need at least 2 measurements");
    anyhow::ensure!(opts.cells > 0.0, "cells must be positive");
    let settings = [("K=10", 10u32), ("K=1", 1u32)];
    let mut accs: Vec<(Acc, Acc)> = settings.iter().map(|_| Default::default()).collect();
    let mut trials = Vec::new();
    let tol = SymmetryTolerance::default();
    for seed in plans::TEST_SEEDS.take(opts.plans) {
        let plan = plans::generate(seed);
        let pd = PoseDistance::new(&plan, &tol);
        let (lo, hi) = plan.bounds();
        let cell = (hi.x - lo.x).max(hi.y - lo.y) / opts.cells;
        for (si, &(name, k)) in settings.iter().enumerate() {
            let world = SimWorld::new(
                plan.clone(),
                opts.sensor,
                EpisodeConfig::default(),
                seed as u64 ^ opts.seed.rotate_left(32),
            );
            let mut rng = Pcg32::seed_from_u64(opts.seed ^ ((seed as u64) << 8) ^ k as u64);
            let truth = world.truth();
            let (meas, outliers) = take_measurements(&world, opts.measurements, &mut rng);
            let half_bin = 0.5 * TAU / k as f32;
            let initial = Pose2::new(
                truth.x + cell * rng.gen_range(-0.5f32..0.5),
                truth.y + cell * rng.gen_range(-0.5f32..0.5),
                if k == 1 {
                    truth.theta
                } else {
                    truth.theta + rng.gen_range(-half_bin..half_bin)
                },
            );
            let obs =
                Observations::from_slice(&meas).map_err(|e| anyhow::anyhow!("plan {seed}: {e}"))?;
            let mut params = opts.params;
            params.icp.fixed_heading = k == 1;
            let icp_params: IcpParams = params.icp;
            let (icp, icp_e, t_icp) = if obs.len() >= 2 {
                let t0 = Instant::now();
                let r = sparse_icp(&plan, &obs, &initial, &icp_params)
                    .map_err(|e| anyhow::anyhow!("plan {seed}: {e}"))?;
                (r.pose, r.error, t0.elapsed().as_secs_f64() * 1e6)
            } else {
                (initial, f32::INFINITY, 0.0)
            };
            let (ann, ann_e, t_ann) = if obs.len() >= 2 {
                let t0 = Instant::now();
                let r = register(&plan, &obs, &initial, &params)
                    .map_err(|e| anyhow::anyhow!("plan {seed}: {e}"))?;
                (r.pose, r.error, t0.elapsed().as_secs_f64() * 1e6)
            } else {
                (initial, f32::INFINITY, 0.0)
            };
            accs[si].0.add(&truth, &icp, icp_e, &pd, t_icp);
            accs[si].1.add(&truth, &ann, ann_e, &pd, t_ann);
            trials.push(Trial {
                plan_seed: seed,
                setting: name.into(),
                truth,
                initial,
                measurements: meas.iter().map(|m| (m.bearing, m.range)).collect(),
                outliers,
                icp,
                annealed: ann,
                annealed_position_error: (ann.translation() - truth.translation()).norm(),
            });
        }
    }
    let mut methods = Vec::new();
    for (si, &(name, _)) in settings.iter().enumerate() {
        methods.push(accs[si].0.report(name, "sparse-icp"));
        methods.push(accs[si].1.report(name, "annealed"));
    }
    Ok(Report {
        options: opts.clone(),
        methods,
        trials,
    })
}

/// Human-readable summary lines.
pub fn summary(r: &Report) -> String {
    let mut s = format!(
        "registration benchmark: {} plans, {} measurements, sigma {} m, outliers {:.0} %, coarse pose within 1/{} of the room extent\n",
        r.options.plans,
        r.options.measurements,
        r.options.sensor.sigma,
        100.0 * r.options.sensor.outlier_prob,
        r.options.cells
    );
    s += "setting method      | position error (cm): median   p90    p99    max | pose dist (cm): median   p90    p99 | heading (deg): median  p90 | <2cm  | time (ms)\n";
    for m in &r.methods {
        s += &format!(
            "{:<7} {:<11} |                   {:7.3} {:6.2} {:6.2} {:6.1} |              {:7.3} {:6.2} {:6.2} |         {:7.3} {:5.2} | {:4.1}% | {:.2}\n",
            m.setting,
            m.method,
            100.0 * m.position_error.median,
            100.0 * m.position_error.p90,
            100.0 * m.position_error.p99,
            100.0 * m.position_error.max,
            100.0 * m.pose_distance.median,
            100.0 * m.pose_distance.p90,
            100.0 * m.pose_distance.p99,
            m.heading_error_deg.median,
            m.heading_error_deg.p90,
            100.0 * m.below_2cm,
            m.mean_time_us / 1000.0
        );
    }
    for m in &r.methods {
        s += &format!(
            "{} {} position-error histogram (m, count):",
            m.setting, m.method
        );
        for (b, c) in &m.position_error.histogram {
            if b.is_finite() {
                s += &format!(" ≤{b}:{c}");
            } else {
                s += &format!(" >:{c}");
            }
        }
        s += "\n";
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_run_is_sane_and_reproducible() {
        let opts = BenchOptions {
            plans: 8,
            ..Default::default()
        };
        let a = run(&opts).unwrap();
        assert_eq!(a.methods.len(), 4);
        assert_eq!(a.trials.len(), 16);
        for m in &a.methods {
            assert_eq!(m.position_error.n, 8);
            let total: usize = m.position_error.histogram.iter().map(|h| h.1).sum();
            assert_eq!(total, 8);
            assert!(m.position_error.median <= m.position_error.p90);
        }
        let b = run(&opts).unwrap();
        for (x, y) in a.trials.iter().zip(&b.trials) {
            assert_eq!(x.annealed, y.annealed);
        }
    }

    #[test]
    fn stats_percentiles() {
        let v: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        let s = Stats::new(&v, &[10.0, 50.0]);
        assert_eq!((s.median, s.p90, s.p99, s.max), (50.0, 90.0, 99.0, 100.0));
        assert_eq!(
            s.histogram,
            vec![(10.0, 10), (50.0, 40), (f64::INFINITY, 50)]
        );
    }
}
