//! The greedy benchmarks of paper §4.3: oracle-based information-gain maximisation (OIGM,
//! eqs. 11–13), its cost-aware variant, and expected-entropy minimisation (EEM, eq. 14,
//! Fox et al. 1998 adapted to the GHT belief).
//!
//! All three plan the same kind of move: a run of pure rotations that ends in one
//! measurement (§4.3: "every pure-rotation action sequence terminating in a single
//! measurement, for every possible bearing"). After each measurement the agent scores every
//! encoder bearing `b = 0..steps_per_turn`, picks the best, turns towards it the short way
//! (left on a tie) and measures there. While it turns the belief does not change, so the
//! plan holds until the measurement; then it plans again. A measurement that returned
//! nothing leaves the belief as it was, so the next plan skips that bearing once.
//!
//! - **OIGM** knows the ground truth. For bearing `b` it casts the noise-free ray from the
//!   true pose (no return beyond the sensor's range or incidence limit: such a bearing is
//!   not a candidate), stages that range in the localizer ([`GhtLocalizer::stage`], which
//!   runs the real vote without committing it) and scores the entropy drop
//!   `IG = H(x_t) − H(x_{t+1} | b)` (eq. 11). The paper's OIGM ignores what reaching `b`
//!   costs. **OIGM-cost** divides the gain by the cost of the sequence
//!   (`rotations·c_rot + c_meas`); a non-positive gain is multiplied by it instead, so
//!   cheaper stays better either way.
//! - **EEM** has no ground truth. Its hypotheses are the belief's poses, sub-sampled by belief
//!   mass: [`EEM_PARTICLES`] draws by systematic (low-variance) resampling of the GHT PMF,
//!   so a peaked belief keeps its few cells and a flat one is covered evenly; with K > 1
//!   each drawn (cell, bin) is split into [`EEM_SUB_HEADINGS`] headings spread over its
//!   bin. For bearing `b`, hypothesis `x` predicts the range `r_x(b)` of its ray (or "no
//!   return"). The pose-conditioned observation domain `O(x)` of eq. 14 is the range bins
//!   of width `σ_o` within `±3σ_o` of `r_x(b)`, with `σ_o² = σ_r² + σ_g²` (sensor noise plus
//!   the half cell the hypothesis' position is uncertain by), and `P(o | x)` the Gaussian
//!   mass of each bin renormalised over `O(x)`; outliers are ignored, as the paper says.
//!   Then `E_o[H(x_{t+1})] = H(o, x) − H(o)` (eq. 14) and EEM takes the bearing with the
//!   smallest value (ties: fewer rotations, then the lower bearing).

use crate::world::sensor::SensorModel;
use activesense_core::episode::EpisodeConfig;
use activesense_core::episode::{Action, ActionCosts};
use activesense_core::localization::GhtLocalizer;
use activesense_core::policy::{Policy, PolicyInput};
use activesense_core::world::geometry::{unit, Vec2};
use activesense_core::{FloorPlan, Pose2};
use std::collections::BTreeMap;
use std::f32::consts::TAU;

/// Hypotheses EEM draws from the belief per decision.
pub const EEM_PARTICLES: usize = 128;
/// Headings each drawn (cell, bin) stands for when the heading is unknown (K > 1).
pub const EEM_SUB_HEADINGS: usize = 4;
/// Half-width of the pose-conditioned observation domain, in `σ_o`.
pub const EEM_DOMAIN_SIGMAS: f32 = 3.0;

/// Encoder bearing index of `bearing` (rad) on a turn of `n` steps.
pub fn bearing_index(bearing: f32, n: u16) -> u16 {
    let n = n.max(1);
    let k = (bearing / (TAU / n as f32)).round() as i64;
    k.rem_euclid(n as i64) as u16
}

/// Rotations from `from` to `to` the short way (left on a tie) and the first action.
pub fn route(from: u16, to: u16, n: u16) -> (u16, Action) {
    let n = n.max(1);
    let left = (to as i32 - from as i32).rem_euclid(n as i32) as u16;
    let right = (n - left) % n;
    if left == 0 {
        (0, Action::Measure)
    } else if left <= right {
        (left, Action::RotateLeft)
    } else {
        (right, Action::RotateRight)
    }
}

/// Cost of the sequence that measures at `to`: the rotations to get there and the
/// measurement.
pub fn sequence_cost(from: u16, to: u16, n: u16, costs: &ActionCosts) -> f32 {
    route(from, to, n).0 as f32 * costs.rotate + costs.measure
}

/// Gain per unit cost: `g / c` for a positive gain, `g · c` otherwise (cheaper is better
/// on both sides of zero).
pub fn per_cost(gain: f32, cost: f32) -> f32 {
    if gain > 0.0 {
        gain / cost
    } else {
        gain * cost
    }
}

/// The best bearing by score (`None` scores are not candidates): highest score, then
/// fewest rotations, then lowest index. `None` when no bearing is a candidate.
pub fn best_bearing(scores: &[Option<f32>], from: u16) -> Option<u16> {
    let n = scores.len() as u16;
    let mut best: Option<(f32, u16, u16)> = None;
    for (b, s) in scores.iter().enumerate() {
        let Some(s) = *s else { continue };
        let b = b as u16;
        let d = route(from, b, n).0;
        let better = match best {
            None => true,
            Some((bs, bd, _)) => s > bs || (s == bs && d < bd),
        };
        if better {
            best = Some((s, d, b));
        }
    }
    best.map(|(_, _, b)| b)
}

/// The noise-free range the sensor returns from `origin` along model-frame `angle`, or
/// `None` where it returns nothing (beyond range, too oblique, or no wall).
pub fn expected_range(
    plan: &FloorPlan,
    sensor: &SensorModel,
    origin: Vec2,
    angle: f32,
) -> Option<f32> {
    plan.ray_cast(origin, unit(angle))
        .filter(|h| h.range <= sensor.max_range && h.incidence <= sensor.max_incidence)
        .map(|h| h.range)
}

/// The move-and-measure bookkeeping both greedy agents share.
#[derive(Clone, Debug, Default)]
struct Planner {
    /// Bearing being turned to.
    target: Option<u16>,
    /// (bearing, ranges before) of the last measurement, to spot a no-return.
    measured: Option<(u16, u16)>,
}

impl Planner {
    /// The next action; `choose(current, skip)` scores the bearings when a plan is needed.
    fn act(
        &mut self,
        input: &PolicyInput<'_>,
        n: u16,
        choose: impl FnOnce(u16, Option<u16>) -> Option<u16>,
    ) -> Action {
        let cur = bearing_index(input.bearing, n);
        if self.target.is_none() {
            // A measurement that added no range was a no-return: skip that bearing once.
            let skip = self
                .measured
                .take()
                .filter(|&(_, before)| before == input.measurements)
                .map(|(b, _)| b);
            // Nothing to aim at (every bearing dark): measure where we are.
            self.target = Some(choose(cur, skip).unwrap_or(cur));
        }
        let target = self.target.unwrap_or(cur);
        let (_, action) = route(cur, target, n);
        if action == Action::Measure {
            self.target = None;
            self.measured = Some((cur, input.measurements));
        }
        action
    }
}

/// OIGM and OIGM-cost (module docs).
pub struct OigmAgent {
    plan: FloorPlan,
    truth: Pose2,
    sensor: SensorModel,
    config: EpisodeConfig,
    cost_aware: bool,
    planner: Planner,
    staging: Box<GhtLocalizer>,
    /// The scores of the last plan, per bearing (for tests and inspection).
    pub last_scores: Vec<Option<f32>>,
}

impl OigmAgent {
    /// An agent for one episode in `plan` with the true AgentPose `truth`.
    pub fn new(
        plan: FloorPlan,
        truth: Pose2,
        sensor: SensorModel,
        config: EpisodeConfig,
        cost_aware: bool,
    ) -> Self {
        OigmAgent {
            plan,
            truth,
            sensor,
            config,
            cost_aware,
            planner: Planner::default(),
            staging: Box::default(),
            last_scores: Vec::new(),
        }
    }

    /// The information gain (eq. 11) of measuring at every bearing, as the truth would
    /// answer; `None` where the sensor would return nothing.
    pub fn gains(&mut self, localizer: &GhtLocalizer) -> Vec<Option<f32>> {
        let n = self.config.steps_per_turn.max(1);
        let step = TAU / n as f32;
        let h_now = localizer.entropy();
        (*self.staging).clone_from(localizer);
        let origin = self.truth.translation();
        (0..n)
            .map(|b| {
                let beta = b as f32 * step;
                let r = expected_range(&self.plan, &self.sensor, origin, self.truth.theta + beta)?;
                let staged = self.staging.stage(beta, r).ok()?;
                Some(h_now - staged.entropy)
            })
            .collect()
    }

    /// Scores (gain, or gain per cost) of every bearing from `cur`.
    fn scores(&mut self, localizer: &GhtLocalizer, cur: u16) -> Vec<Option<f32>> {
        let n = self.config.steps_per_turn.max(1);
        let costs = self.config.costs;
        let cost_aware = self.cost_aware;
        self.gains(localizer)
            .into_iter()
            .enumerate()
            .map(|(b, g)| {
                g.map(|g| {
                    if cost_aware {
                        per_cost(g, sequence_cost(cur, b as u16, n, &costs))
                    } else {
                        g
                    }
                })
            })
            .collect()
    }
}

impl Policy for OigmAgent {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        let n = self.config.steps_per_turn.max(1);
        let mut planner = std::mem::take(&mut self.planner);
        let action = planner.act(input, n, |cur, skip| {
            let mut s = self.scores(input.localizer, cur);
            if let Some(b) = skip {
                s[b as usize] = None;
            }
            let best = best_bearing(&s, cur);
            self.last_scores = s;
            best
        });
        self.planner = planner;
        action
    }
}

/// One pose hypothesis of EEM with its belief mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hypothesis {
    /// The AgentPose.
    pub pose: Pose2,
    /// Its probability (the hypotheses sum to 1).
    pub mass: f32,
}

/// The EEM hypotheses: `particles` systematic draws from the localizer's PMF (flat cell
/// order, offset ½), merged per cell, each split into `sub_headings` headings over its
/// rotation bin when K > 1.
pub fn hypotheses(
    localizer: &GhtLocalizer,
    particles: usize,
    sub_headings: usize,
) -> Vec<Hypothesis> {
    let grid = *localizer.grid();
    let particles = particles.max(1);
    let mut counts: Vec<(usize, u32)> = Vec::new();
    let mut cum = 0.0f64;
    let mut next = 0usize; // particles placed so far
    for i in 0..grid.len() {
        let p = localizer.prob(i) as f64;
        if p <= 0.0 {
            continue;
        }
        cum += p;
        let mut c = 0u32;
        while next < particles && (next as f64 + 0.5) / particles as f64 <= cum {
            next += 1;
            c += 1;
        }
        if c > 0 {
            counts.push((i, c));
        }
    }
    // Rounding can leave the last draws unplaced: they belong to the last cell with mass.
    if next < particles {
        if let Some(last) = counts.last_mut() {
            last.1 += (particles - next) as u32;
        }
    }
    let total: u32 = counts.iter().map(|c| c.1).sum();
    let subs = if grid.rot_bins > 1 {
        sub_headings.max(1)
    } else {
        1
    };
    let width = grid.bin_width();
    let mut out = Vec::with_capacity(counts.len() * subs);
    for (i, c) in counts {
        let pose = grid.pose_of(grid.cell_at(i));
        for s in 0..subs {
            let offset = if subs > 1 {
                ((s as f32 + 0.5) / subs as f32 - 0.5) * width
            } else {
                0.0
            };
            out.push(Hypothesis {
                pose: Pose2::new(pose.x, pose.y, pose.theta + offset),
                mass: c as f32 / total as f32 / subs as f32,
            });
        }
    }
    out
}

/// What one hypothesis predicts for a bearing: `P(o | x)` over its observation domain,
/// as (range bin, probability) pairs, or a certain no-return (`None`).
pub type Prediction = Option<Vec<(i32, f64)>>;

/// Standard normal CDF.
fn phi(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

/// `P(o | x)` for a predicted range `r` (module docs): bins `k` of width `sigma` cover
/// `[k·σ, (k+1)·σ)`, those meeting `r ± 3σ` form the domain, masses renormalised over it.
pub fn observation_pmf(r: f32, sigma: f32) -> Vec<(i32, f64)> {
    let (r, s) = (r as f64, sigma.max(1e-6) as f64);
    let lo = ((r - EEM_DOMAIN_SIGMAS as f64 * s) / s).floor() as i32;
    let hi = ((r + EEM_DOMAIN_SIGMAS as f64 * s) / s).floor() as i32;
    let mut bins: Vec<(i32, f64)> = (lo..=hi)
        .map(|k| {
            let a = (k as f64 * s - r) / s;
            let b = ((k + 1) as f64 * s - r) / s;
            (k, phi(b) - phi(a))
        })
        .collect();
    let z: f64 = bins.iter().map(|b| b.1).sum();
    for b in &mut bins {
        b.1 /= z;
    }
    bins
}

/// Eq. 14: `E_o[H(x_{t+1})] = H(o, x) − H(o)` for hypotheses with masses `mass[i]` and
/// predictions `pred[i]` (a no-return is one more observation symbol).
pub fn expected_entropy(mass: &[f32], pred: &[Prediction]) -> f64 {
    const NO_RETURN: i32 = i32::MIN;
    let mut h_joint = 0.0f64;
    let mut p_obs: BTreeMap<i32, f64> = BTreeMap::new();
    for (&m, p) in mass.iter().zip(pred) {
        let m = m as f64;
        if m <= 0.0 {
            continue;
        }
        match p {
            None => {
                h_joint -= m * m.ln();
                *p_obs.entry(NO_RETURN).or_default() += m;
            }
            Some(bins) => {
                for &(k, q) in bins {
                    let j = m * q;
                    if j > 0.0 {
                        h_joint -= j * j.ln();
                        *p_obs.entry(k).or_default() += j;
                    }
                }
            }
        }
    }
    let h_obs: f64 = p_obs
        .values()
        .filter(|&&p| p > 0.0)
        .map(|&p| -p * p.ln())
        .sum();
    h_joint - h_obs
}

/// EEM (module docs).
pub struct EemAgent {
    plan: FloorPlan,
    sensor: SensorModel,
    config: EpisodeConfig,
    planner: Planner,
    /// Expected entropies of the last plan, per bearing.
    pub last_expected: Vec<Option<f64>>,
}

impl EemAgent {
    /// An agent that knows the room model and the sensor, not the truth.
    pub fn new(plan: FloorPlan, sensor: SensorModel, config: EpisodeConfig) -> Self {
        EemAgent {
            plan,
            sensor,
            config,
            planner: Planner::default(),
            last_expected: Vec::new(),
        }
    }

    /// Expected entropy after measuring at each bearing (eq. 14).
    pub fn expected_entropies(&self, localizer: &GhtLocalizer) -> Vec<Option<f64>> {
        let n = self.config.steps_per_turn.max(1);
        let step = TAU / n as f32;
        let grid = localizer.grid();
        let sigma_g = 0.5 * grid.cell[0].max(grid.cell[1]);
        let sigma_o = (self.sensor.sigma * self.sensor.sigma + sigma_g * sigma_g).sqrt();
        let hyps = hypotheses(localizer, EEM_PARTICLES, EEM_SUB_HEADINGS);
        let mass: Vec<f32> = hyps.iter().map(|h| h.mass).collect();
        (0..n)
            .map(|b| {
                let beta = b as f32 * step;
                let pred: Vec<Prediction> = hyps
                    .iter()
                    .map(|h| {
                        expected_range(
                            &self.plan,
                            &self.sensor,
                            h.pose.translation(),
                            h.pose.theta + beta,
                        )
                        .map(|r| observation_pmf(r, sigma_o))
                    })
                    .collect();
                Some(expected_entropy(&mass, &pred))
            })
            .collect()
    }
}

impl Policy for EemAgent {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        let n = self.config.steps_per_turn.max(1);
        let mut planner = std::mem::take(&mut self.planner);
        let action = planner.act(input, n, |cur, skip| {
            let e = self.expected_entropies(input.localizer);
            let mut s: Vec<Option<f32>> = e.iter().map(|v| v.map(|v| -v as f32)).collect();
            if let Some(b) = skip {
                s[b as usize] = None;
            }
            self.last_expected = e;
            best_bearing(&s, cur)
        });
        self.planner = planner;
        action
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{start_episode, EpisodeSpec};
    use activesense_core::episode::AgentKind;
    use activesense_core::pipeline::runner::EpisodeRunner;

    #[test]
    fn routes_take_the_short_way() {
        assert_eq!(route(0, 0, 54), (0, Action::Measure));
        assert_eq!(route(0, 5, 54), (5, Action::RotateLeft));
        assert_eq!(route(5, 0, 54), (5, Action::RotateRight));
        assert_eq!(route(50, 2, 54), (6, Action::RotateLeft));
        assert_eq!(route(0, 27, 54), (27, Action::RotateLeft));
        assert_eq!(bearing_index(TAU / 54.0 * 53.0, 54), 53);
        assert_eq!(bearing_index(TAU, 54), 0);
        assert_eq!(bearing_index(-TAU / 54.0, 54), 53);
    }

    #[test]
    fn best_bearing_breaks_ties_by_distance_then_index() {
        let s = [Some(1.0), None, Some(2.0), Some(2.0), None];
        assert_eq!(best_bearing(&s, 4), Some(3));
        assert_eq!(best_bearing(&s, 0), Some(2));
        assert_eq!(best_bearing(&[None, None], 0), None);
        assert!(per_cost(0.2, 0.1) > per_cost(0.2, 0.2));
        assert!(per_cost(-0.2, 0.1) > per_cost(-0.2, 0.2));
    }

    /// A started episode on a test plan, after `measure` measurements of heuristic-1.
    fn started(
        rot_bins: u8,
        measurements: usize,
    ) -> (FloorPlan, Pose2, Box<EpisodeRunner>, EpisodeSpec) {
        let mut spec = EpisodeSpec::new(
            crate::world::plans::TEST_SEEDS.start + 3,
            AgentKind::Heuristic1,
        );
        spec.rot_bins = rot_bins;
        let mut runner = Box::new(EpisodeRunner::new_empty());
        let (plan, mut world, _) = start_episode(&spec, &mut runner);
        let truth = world.truth();
        let mut done = 0;
        while done < measurements {
            let action = if runner.state().actions % 7 == 0 {
                Action::Measure
            } else {
                Action::RotateLeft
            };
            let (obs, _) = world.act(action);
            runner.observe(action, &obs).unwrap();
            done += (action == Action::Measure && obs.range.is_some()) as usize;
        }
        (plan, truth, runner, spec)
    }

    #[test]
    fn oigm_picks_the_argmax_of_brute_force_gains() {
        for (rot_bins, m) in [(1, 0), (1, 1), (10, 2)] {
            let (plan, truth, runner, spec) = started(rot_bins, m);
            let loc = runner.pipeline().localizer();
            let mut agent = OigmAgent::new(plan.clone(), truth, spec.sensor, spec.config, false);
            let action = agent.act(&runner.input());
            // Brute force: commit each bearing's true range into a fresh copy of the belief.
            let n = spec.config.steps_per_turn;
            let step = TAU / n as f32;
            let h0 = loc.entropy();
            let mut brute: Vec<Option<f32>> = Vec::new();
            for b in 0..n {
                let beta = b as f32 * step;
                let hit = plan.ray_cast(truth.translation(), unit(truth.theta + beta));
                brute.push(
                    hit.filter(|h| {
                        h.range <= spec.sensor.max_range && h.incidence <= spec.sensor.max_incidence
                    })
                    .map(|h| {
                        let mut copy = Box::new(loc.clone());
                        copy.update(beta, h.range).unwrap();
                        h0 - copy.entropy()
                    }),
                );
            }
            assert_eq!(brute.len(), agent.last_scores.len());
            for (a, b) in agent.last_scores.iter().zip(&brute) {
                match (a, b) {
                    (Some(a), Some(b)) => {
                        assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "{a} vs {b}")
                    }
                    (None, None) => {}
                    other => panic!("candidate sets differ: {other:?}"),
                }
            }
            let cur = bearing_index(runner.input().bearing, n);
            let chosen = best_bearing(&agent.last_scores, cur).unwrap();
            let best = brute.iter().flatten().fold(f32::MIN, |a, &b| a.max(b));
            // The bearing the agent set out for has the largest brute-force gain (up to
            // float noise between staging and committing), and it turned towards it.
            assert!(
                brute[chosen as usize].unwrap() >= best - 1e-4,
                "K = {rot_bins}, {m} measurements"
            );
            assert_eq!(action, route(cur, chosen, n).1);
            assert!(best > 0.0);
        }
    }

    #[test]
    fn eem_matches_brute_force_enumeration() {
        // A 4 m × 4 m square room around the origin; three hypotheses facing +x.
        let plan = FloorPlan::new(&[
            Vec2::new(-2.0, -2.0),
            Vec2::new(2.0, -2.0),
            Vec2::new(2.0, 2.0),
            Vec2::new(-2.0, 2.0),
        ])
        .unwrap();
        let sensor = SensorModel::default();
        let hyps = [
            (Pose2::new(0.0, 0.0, 0.0), 0.5f32), // ranges: east 2.0
            (Pose2::new(1.0, 0.5, 0.0), 0.3),    // east 1.0
            (Pose2::new(-0.95, -1.0, 0.0), 0.2), // east 2.95
        ];
        let sigma = 0.4f32;
        for beta in [0.0f32, std::f32::consts::FRAC_PI_2] {
            let pred: Vec<Prediction> = hyps
                .iter()
                .map(|(p, _)| {
                    expected_range(&plan, &sensor, p.translation(), p.theta + beta)
                        .map(|r| observation_pmf(r, sigma))
                })
                .collect();
            let mass: Vec<f32> = hyps.iter().map(|h| h.1).collect();
            let eq14 = expected_entropy(&mass, &pred);
            // Brute force: every observation bin any hypothesis can produce, the posterior
            // over the hypotheses for it (Bayes), its entropy, weighted by P(o).
            let range = |p: &Pose2| -> f64 {
                // Hand-computed distances to the square's walls along ±x / +y.
                if beta == 0.0 {
                    2.0 - p.x as f64
                } else {
                    2.0 - p.y as f64
                }
            };
            let lik = |k: i32, r: f64| -> f64 {
                let s = sigma as f64;
                let lo = ((r - 3.0 * s) / s).floor() as i32;
                let hi = ((r + 3.0 * s) / s).floor() as i32;
                if k < lo || k > hi {
                    return 0.0;
                }
                let cdf = |x: f64| 0.5 * (1.0 + libm::erf(x / std::f64::consts::SQRT_2));
                let z: f64 = (lo..=hi)
                    .map(|j| cdf(((j + 1) as f64 * s - r) / s) - cdf((j as f64 * s - r) / s))
                    .sum();
                (cdf(((k + 1) as f64 * s - r) / s) - cdf((k as f64 * s - r) / s)) / z
            };
            let mut expected = 0.0f64;
            for k in -10..40 {
                let joint: Vec<f64> = hyps
                    .iter()
                    .map(|(p, m)| *m as f64 * lik(k, range(p)))
                    .collect();
                let po: f64 = joint.iter().sum();
                if po <= 0.0 {
                    continue;
                }
                let h: f64 = joint
                    .iter()
                    .filter(|&&j| j > 0.0)
                    .map(|&j| -(j / po) * (j / po).ln())
                    .sum();
                expected += po * h;
            }
            assert!(
                (eq14 - expected).abs() < 1e-6,
                "β = {beta}: eq. 14 gives {eq14}, enumeration {expected}"
            );
            // Prior entropy bounds it, and this set is informative at β = 0.
            let h0: f64 = mass.iter().map(|&m| -(m as f64) * (m as f64).ln()).sum();
            assert!(expected <= h0 + 1e-12);
            if beta == 0.0 {
                assert!(expected < 0.5 * h0, "{expected} vs prior {h0}");
            }
        }
    }

    #[test]
    fn hypotheses_follow_the_belief_mass() {
        let (_, truth, runner, _) = started(10, 4);
        let loc = runner.pipeline().localizer();
        let h = hypotheses(loc, EEM_PARTICLES, EEM_SUB_HEADINGS);
        let total: f32 = h.iter().map(|x| x.mass).sum();
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        // The heaviest hypothesis lies on the belief's argmax cell.
        let best = h.iter().max_by(|a, b| a.mass.total_cmp(&b.mass)).unwrap();
        let arg = loc.estimate().unwrap();
        assert!((best.pose.x - arg.x).abs() < 1e-4 && (best.pose.y - arg.y).abs() < 1e-4);
        let _ = truth;
        // Before any vote the belief is flat: the draws spread over the room.
        let (_, _, fresh, _) = started(1, 0);
        let flat = hypotheses(fresh.pipeline().localizer(), 64, 1);
        assert!(flat.len() >= 60, "{}", flat.len());
    }
}
