//! Side-by-side benchmark of the GHT localizer (`activesense_core::localization`) and the
//! classical grid Markov localizer ([`crate::baselines::classical`]) on the same generated test plans,
//! in one run (paper §3.2, Table 1): up-front cost (R-table vs ray-cast tables), cost per
//! measurement update, memory, and recognition (symmetry-aware coarse success of the
//! argmax) after k measurements at several outlier rates.
//!
//! Measurements come from the simulator's EDM model ([`SensorModel`]: Gaussian noise,
//! uniform outliers over `(0, max_range)`, no return beyond 75° incidence) at encoder
//! bearings drawn uniformly from the 54 reachable ones; both localizers see the same
//! readings. Agents are placed by [`SimWorld`] (uniform in the disc about the visual centre,
//! uniform heading).
//!
//! Symmetry orders for the coarse-success test come from [`cyclic_order`], a vertex-set
//! check that stands in for the project's symmetry detector.

use crate::baselines::classical::{ClassicalConfig, ClassicalLocalizer};
use activesense_core::episode::EpisodeConfig;
use activesense_core::localization::{GhtLocalizer, LocalizerConfig};
use activesense_core::world::geometry::rotate;
use activesense_core::world::math::TAU;
use activesense_core::{FloorPlan, Pose2};
use activesense_instrument::world::plans::{self, TEST_SEEDS};
use activesense_instrument::world::sensor::SensorModel;
use activesense_instrument::world::SimWorld;
use anyhow::{anyhow, Result};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::time::Instant;

/// What to run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchOptions {
    /// Number of test plans (seeds `TEST_SEEDS.start ..`).
    pub plans: usize,
    /// Agent placements per plan and outlier rate.
    pub trials_per_plan: usize,
    /// Seed of the measurement streams.
    pub seed: u64,
    /// Localizer configuration shared by both methods (default 30 × 30 × 10, 4 sub-bins).
    pub config: LocalizerConfig,
    /// Classical sensor model.
    pub classical: ClassicalConfig,
    /// EDM range noise σ (m).
    pub sensor_sigma: f32,
    /// Outlier rates to test.
    pub outlier_rates: Vec<f32>,
    /// Measurement counts at which recognition is recorded (ascending).
    pub ks: Vec<usize>,
    /// Also run the GHT with these sub-bin counts (rotation-smear study); empty to skip.
    pub smear_sub_bins: Vec<u8>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            plans: 20,
            trials_per_plan: 3,
            seed: 1,
            config: LocalizerConfig::DEFAULT,
            classical: ClassicalConfig::default(),
            sensor_sigma: 0.01,
            outlier_rates: vec![0.0, 0.1, 0.3],
            ks: vec![1, 2, 4, 6, 8, 12],
            smear_sub_bins: vec![1, 2, 4, 8],
        }
    }
}

/// Recognition rate of both methods at one outlier rate and measurement count.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RecognitionRow {
    /// Outlier probability of the sensor.
    pub outlier_rate: f32,
    /// Measurements committed.
    pub k: usize,
    /// Fraction of trials whose GHT argmax passes the coarse-success test.
    pub ght: f64,
    /// Same for the classical localizer.
    pub classical: f64,
    /// Trials.
    pub trials: usize,
}

/// GHT recognition for one sub-bin count (rotation-smear study).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SmearRow {
    /// Rotation hypotheses per bin.
    pub sub_bins: u8,
    /// Outlier probability.
    pub outlier_rate: f32,
    /// Measurements committed.
    pub k: usize,
    /// GHT recognition rate.
    pub ght: f64,
    /// Mean GHT update time (µs).
    pub ght_update_us: f64,
}

/// The benchmark result.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    /// The options it ran with.
    pub options: BenchOptions,
    /// Plan seeds used.
    pub seeds: Vec<u32>,
    /// Symmetry order found for each plan (same order as `seeds`).
    pub symmetry_orders: Vec<u8>,
    /// Mean R-table size (perimeter points).
    pub rtable_points: f64,
    /// Mean interior cells per layer.
    pub interior_cells: f64,
    /// Mean up-front cost of the GHT (reset: grid, interior mask, R-table), µs.
    pub ght_upfront_us: f64,
    /// Mean up-front cost of the classical localizer (ray-cast tables), µs.
    pub classical_upfront_us: f64,
    /// Mean ray casts of the classical precomputation.
    pub classical_ray_casts: f64,
    /// Mean cost of one GHT measurement update, µs.
    pub ght_update_us: f64,
    /// Mean cost of one classical measurement update, µs.
    pub classical_update_us: f64,
    /// Mean cost of one GHT staging call (hypothetical update + entropy), µs.
    pub ght_stage_us: f64,
    /// GHT up-front + 10 updates, µs (means).
    pub ght_total_10_us: f64,
    /// Classical up-front + 10 updates, µs (means).
    pub classical_total_10_us: f64,
    /// `classical_total_10_us / ght_total_10_us`.
    pub speedup_total_10: f64,
    /// `size_of::<GhtLocalizer>()`: the whole GHT state (bytes).
    pub ght_state_bytes: usize,
    /// Mean heap + inline bytes of the classical localizer.
    pub classical_bytes: f64,
    /// Recognition table.
    pub recognition: Vec<RecognitionRow>,
    /// GHT recognition at 30% outliers after 12 measurements (NaN if not run).
    pub recognition_ght_30pct: f64,
    /// Classical recognition at 30% outliers after 12 measurements (NaN if not run).
    pub recognition_classical_30pct: f64,
    /// Rotation-smear study (GHT only).
    pub smear: Vec<SmearRow>,
}

/// Largest `n ∈ {8, 6, 5, 4, 3, 2}` such that rotating the (centred) outline's vertex set by
/// `2π/n` about the origin maps it onto itself within 1 cm; 1 otherwise. A stand-in for the
/// project's symmetry detector.
pub fn cyclic_order(plan: &FloorPlan) -> u8 {
    for n in [8u8, 6, 5, 4, 3, 2] {
        let phi = TAU / n as f32;
        let ok = plan.vertices().all(|v| {
            let r = rotate(v, phi);
            plan.vertices().any(|w| (w - r).norm() < 0.01)
        });
        if ok {
            return n;
        }
    }
    1
}

/// One simulated measurement stream: `(bearing, range)` pairs with a return.
fn stream(
    plan: &FloorPlan,
    truth: &Pose2,
    sensor: &SensorModel,
    n: usize,
    rng: &mut Pcg32,
) -> Vec<(f32, f32)> {
    let step = TAU / 54.0;
    let mut out = Vec::with_capacity(n);
    let mut tries = 0;
    while out.len() < n && tries < 100 * n {
        tries += 1;
        let k: u32 = rng.gen_range(0..54);
        let beta = k as f32 * step;
        let (r, _) = sensor.measure(plan, truth.translation(), truth.theta + beta, rng);
        if let Some(r) = r.filter(|&r| r > 0.0) {
            out.push((beta, r));
        }
    }
    out
}

/// Runs the benchmark.
pub fn run(opts: &BenchOptions) -> Result<Report> {
    opts.config.validate().map_err(|e| anyhow!("{e}"))?;
    let kmax = opts.ks.iter().copied().max().unwrap_or(0);
    let seeds: Vec<u32> = (TEST_SEEDS.start..TEST_SEEDS.end)
        .take(opts.plans)
        .collect();
    let mut ght = Box::new(GhtLocalizer::new_empty());
    let mut rng = Pcg32::seed_from_u64(opts.seed);
    let mut sym = Vec::new();
    let (mut up_g, mut up_c, mut casts, mut cbytes, mut pts, mut cells) =
        (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut t_g, mut n_g, mut t_c, mut n_c, mut t_s, mut n_s) =
        (0.0f64, 0usize, 0.0f64, 0usize, 0.0f64, 0usize);
    // [rate][k] -> (ght ok, classical ok, trials)
    let mut rec = vec![vec![(0usize, 0usize, 0usize); opts.ks.len()]; opts.outlier_rates.len()];
    let mut smear =
        vec![
            vec![vec![(0usize, 0usize, 0.0f64, 0usize); opts.ks.len()]; opts.outlier_rates.len()];
            opts.smear_sub_bins.len()
        ];
    let known = opts.config.rot_bins == 1;
    for &seed in &seeds {
        let plan = plans::generate(seed);
        let n_sym = cyclic_order(&plan);
        sym.push(n_sym);
        let t0 = Instant::now();
        ght.reset(&plan, &opts.config)
            .map_err(|e| anyhow!("seed {seed}: {e}"))?;
        up_g += t0.elapsed().as_secs_f64() * 1e6;
        pts += ght.rtable().len() as f64;
        cells += ght.interior_cells() as f64;
        let t0 = Instant::now();
        let mut cl = ClassicalLocalizer::new(&plan, &opts.config, &opts.classical)?;
        up_c += t0.elapsed().as_secs_f64() * 1e6;
        casts += cl.ray_casts() as f64;
        cbytes += cl.memory_bytes() as f64;
        for (ri, &q) in opts.outlier_rates.iter().enumerate() {
            let sensor = SensorModel {
                sigma: opts.sensor_sigma,
                outlier_prob: q,
                max_range: opts.classical.max_range,
                ..SensorModel::default()
            };
            for t in 0..opts.trials_per_plan {
                let wseed = (seed as u64) << 16 | (ri as u64) << 8 | t as u64;
                let truth =
                    SimWorld::new(plan.clone(), sensor, EpisodeConfig::default(), wseed).truth();
                let ms = stream(&plan, &truth, &sensor, kmax, &mut rng);
                if known {
                    ght.set_known_heading(truth.theta);
                    let cfg = LocalizerConfig {
                        known_heading: truth.theta,
                        ..opts.config
                    };
                    let t0 = Instant::now();
                    cl = ClassicalLocalizer::new(&plan, &cfg, &opts.classical)?;
                    up_c += t0.elapsed().as_secs_f64() * 1e6
                        / (opts.outlier_rates.len() * opts.trials_per_plan) as f64;
                } else {
                    ght.clear();
                }
                cl.clear();
                let mut ki = 0;
                for (i, &(b, r)) in ms.iter().enumerate() {
                    if i % 4 == 0 {
                        let t0 = Instant::now();
                        let st = ght.stage(b, r);
                        t_s += t0.elapsed().as_secs_f64() * 1e6;
                        n_s += 1;
                        std::hint::black_box(st.ok());
                    }
                    let t0 = Instant::now();
                    ght.update(b, r).map_err(|e| anyhow!("{e}"))?;
                    t_g += t0.elapsed().as_secs_f64() * 1e6;
                    n_g += 1;
                    let t0 = Instant::now();
                    cl.update(b, r)?;
                    t_c += t0.elapsed().as_secs_f64() * 1e6;
                    n_c += 1;
                    while ki < opts.ks.len() && opts.ks[ki] == i + 1 {
                        let e = &mut rec[ri][ki];
                        e.0 += ght.coarse_success(&truth, n_sym) as usize;
                        e.1 += cl.coarse_success(&truth, n_sym) as usize;
                        e.2 += 1;
                        ki += 1;
                    }
                }
                // Rotation-smear study: the same stream through GHT variants.
                if !known {
                    for (si, &sb) in opts.smear_sub_bins.iter().enumerate() {
                        let cfg = LocalizerConfig {
                            sub_bins: sb,
                            ..opts.config
                        };
                        let mut g = Box::new(GhtLocalizer::new_empty());
                        g.reset(&plan, &cfg).map_err(|e| anyhow!("{e}"))?;
                        let mut ki = 0;
                        for (i, &(b, r)) in ms.iter().enumerate() {
                            let t0 = Instant::now();
                            g.update(b, r).map_err(|e| anyhow!("{e}"))?;
                            let dt = t0.elapsed().as_secs_f64() * 1e6;
                            while ki < opts.ks.len() && opts.ks[ki] == i + 1 {
                                let e = &mut smear[si][ri][ki];
                                e.0 += g.coarse_success(&truth, n_sym) as usize;
                                e.1 += 1;
                                ki += 1;
                            }
                            let e = &mut smear[si][ri][0];
                            e.2 += dt;
                            e.3 += 1;
                        }
                    }
                }
            }
        }
    }
    let np = seeds.len().max(1) as f64;
    let ght_update_us = t_g / n_g.max(1) as f64;
    let classical_update_us = t_c / n_c.max(1) as f64;
    let ght_upfront_us = up_g / np;
    let classical_upfront_us = up_c / np;
    let ght_total_10_us = ght_upfront_us + 10.0 * ght_update_us;
    let classical_total_10_us = classical_upfront_us + 10.0 * classical_update_us;
    let mut recognition = Vec::new();
    let (mut g30, mut c30) = (f64::NAN, f64::NAN);
    for (ri, &q) in opts.outlier_rates.iter().enumerate() {
        for (ki, &k) in opts.ks.iter().enumerate() {
            let (g, c, n) = rec[ri][ki];
            let row = RecognitionRow {
                outlier_rate: q,
                k,
                ght: g as f64 / n.max(1) as f64,
                classical: c as f64 / n.max(1) as f64,
                trials: n,
            };
            if (q - 0.3).abs() < 1e-6 && k == 12 {
                g30 = row.ght;
                c30 = row.classical;
            }
            recognition.push(row);
        }
    }
    let mut smear_rows = Vec::new();
    for (si, &sb) in opts.smear_sub_bins.iter().enumerate() {
        for (ri, &q) in opts.outlier_rates.iter().enumerate() {
            let upd = smear[si][ri][0].2 / smear[si][ri][0].3.max(1) as f64;
            for (ki, &k) in opts.ks.iter().enumerate() {
                let (g, n, _, _) = smear[si][ri][ki];
                if n > 0 {
                    smear_rows.push(SmearRow {
                        sub_bins: sb,
                        outlier_rate: q,
                        k,
                        ght: g as f64 / n as f64,
                        ght_update_us: upd,
                    });
                }
            }
        }
    }
    Ok(Report {
        options: opts.clone(),
        seeds,
        symmetry_orders: sym,
        rtable_points: pts / np,
        interior_cells: cells / np,
        ght_upfront_us,
        classical_upfront_us,
        classical_ray_casts: casts / np,
        ght_update_us,
        classical_update_us,
        ght_stage_us: t_s / n_s.max(1) as f64,
        ght_total_10_us,
        classical_total_10_us,
        speedup_total_10: classical_total_10_us / ght_total_10_us,
        ght_state_bytes: std::mem::size_of::<GhtLocalizer>(),
        classical_bytes: cbytes / np,
        recognition,
        recognition_ght_30pct: g30,
        recognition_classical_30pct: c30,
        smear: smear_rows,
    })
}

/// The report as markdown tables.
pub fn markdown(r: &Report) -> String {
    let c = &r.options.config;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "### GHT vs classical grid localization: {} test plans, {} × {} × {} grid, {} sub-bins, {} trials per plan and outlier rate\n",
        r.seeds.len(),
        c.nx,
        c.ny,
        c.rot_bins,
        c.effective_sub_bins(),
        r.options.trials_per_plan
    );
    let _ = writeln!(s, "| | GHT | classical | ratio (classical / GHT) |");
    let _ = writeln!(s, "|---|---:|---:|---:|");
    let _ = writeln!(
        s,
        "| up-front work (µs) | {:.0} | {:.0} | {:.1} |",
        r.ght_upfront_us,
        r.classical_upfront_us,
        r.classical_upfront_us / r.ght_upfront_us
    );
    let _ = writeln!(
        s,
        "| one measurement update (µs) | {:.1} | {:.1} | {:.2} |",
        r.ght_update_us,
        r.classical_update_us,
        r.classical_update_us / r.ght_update_us
    );
    let _ = writeln!(
        s,
        "| up-front + 10 updates (µs) | {:.0} | {:.0} | **{:.1}** |",
        r.ght_total_10_us, r.classical_total_10_us, r.speedup_total_10
    );
    let _ = writeln!(
        s,
        "| memory (bytes) | {} | {:.0} | {:.0} |",
        r.ght_state_bytes,
        r.classical_bytes,
        r.classical_bytes / r.ght_state_bytes as f64
    );
    let _ = writeln!(
        s,
        "| table size | {:.0} R-table points | {:.0} ray casts | |",
        r.rtable_points, r.classical_ray_casts
    );
    let _ = writeln!(s, "\nGHT staging (hypothetical update + entropy): {:.1} µs. Mean interior cells per layer: {:.0}.\n", r.ght_stage_us, r.interior_cells);
    let _ = writeln!(
        s,
        "Recognition (symmetry-aware coarse success of the argmax):\n"
    );
    let _ = writeln!(s, "| outliers | k | GHT | classical | trials |");
    let _ = writeln!(s, "|---:|---:|---:|---:|---:|");
    for row in &r.recognition {
        let _ = writeln!(
            s,
            "| {:.0}% | {} | {:.3} | {:.3} | {} |",
            row.outlier_rate * 100.0,
            row.k,
            row.ght,
            row.classical,
            row.trials
        );
    }
    if !r.smear.is_empty() {
        let _ = writeln!(
            s,
            "\nRotation smear (GHT, recognition by sub-bins per rotation bin):\n"
        );
        let ks = &r.options.ks;
        let _ = write!(s, "| sub-bins | outliers | update µs |");
        for k in ks {
            let _ = write!(s, " k={k} |");
        }
        let _ = writeln!(s);
        let _ = write!(s, "|---:|---:|---:|");
        for _ in ks {
            let _ = write!(s, "---:|");
        }
        let _ = writeln!(s);
        for sb in &r.options.smear_sub_bins {
            for q in &r.options.outlier_rates {
                let rows: Vec<&SmearRow> = r
                    .smear
                    .iter()
                    .filter(|x| x.sub_bins == *sb && x.outlier_rate == *q)
                    .collect();
                if rows.is_empty() {
                    continue;
                }
                let _ = write!(
                    s,
                    "| {} | {:.0}% | {:.0} |",
                    sb,
                    q * 100.0,
                    rows[0].ght_update_us
                );
                for x in rows {
                    let _ = write!(s, " {:.3} |", x.ght);
                }
                let _ = writeln!(s);
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_run_reports_every_field() {
        let opts = BenchOptions {
            plans: 1,
            trials_per_plan: 1,
            outlier_rates: vec![0.3],
            ks: vec![12],
            smear_sub_bins: vec![1],
            ..BenchOptions::default()
        };
        let r = run(&opts).unwrap();
        assert!(r.ght_state_bytes <= 48 * 1024);
        assert!(r.speedup_total_10 > 1.0 && r.speedup_total_10.is_finite());
        assert!(r.recognition_ght_30pct.is_finite() && r.recognition_classical_30pct.is_finite());
        assert_eq!(r.smear.len(), 1);
        let json = serde_json::to_string(&r).unwrap();
        assert!(json.contains("\"speedup_total_10\"") && json.contains("\"ght_update_us\""));
        assert!(markdown(&r).contains("up-front + 10 updates"));
    }

    #[test]
    fn cyclic_order_of_simple_shapes() {
        let sq = FloorPlan::new(&[
            activesense_core::world::geometry::v2(-2.0, -2.0),
            activesense_core::world::geometry::v2(2.0, -2.0),
            activesense_core::world::geometry::v2(2.0, 2.0),
            activesense_core::world::geometry::v2(-2.0, 2.0),
        ])
        .unwrap();
        assert_eq!(cyclic_order(&sq), 4);
        let rect = FloorPlan::new(&[
            activesense_core::world::geometry::v2(-3.0, -2.0),
            activesense_core::world::geometry::v2(3.0, -2.0),
            activesense_core::world::geometry::v2(3.0, 2.0),
            activesense_core::world::geometry::v2(-3.0, 2.0),
        ])
        .unwrap();
        assert_eq!(cyclic_order(&rect), 2);
    }
}
