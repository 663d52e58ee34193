//! Post-training quantisation of a float [`PolicyNet`] into the int8 policy blob the
//! instrument runs (`activesense_core::policy::int8`, layout in `docs/policy-blob.md`), and the
//! agreement check between the two.
//!
//! **Quantisation** (TFLite / CMSIS-NN conventions): weights symmetric per output channel
//! (`scale = max|w| / 127`, values in `[−127, 127]`); biases int32 at `input_scale ×
//! weight_scale[c]`; activations asymmetric per tensor, calibrated on the float network's
//! activations (its own forward pass, [`PolicyNet::forward_activations`]) over states
//! recorded while it plays *training* plans greedily
//! (`plans::TRAIN_SEEDS`, never the test range): the observed `[min, max]` widened to
//! contain 0, so 0 is exactly the zero point (ReLU outputs: `[0, max]`, zero point −128).
//! fc_belief and fc_side both requantise straight into the quantisation of fc_joint's input
//! (their concatenation), calibrated on the larger of the two ranges. The heads keep int32
//! outputs at a per-head scale `max_c(input_scale × weight_scale[c])`, so every multiplier
//! is ≤ 1 there and the logits keep the accumulators' full resolution. Multipliers are
//! TFLite's `QuantizeMultiplier` (Q31 mantissa in `[2³⁰, 2³¹)`, power-of-two shift).
//!
//! **Agreement**: the float agent plays the test plans greedily; at every state the int8
//! network decides too ([`action_agreement`] is the fraction of equal argmaxes), and every
//! episode is played again by the int8 agent alone to compare the outcomes.
//!
//! The integer inference is the core's, integer-only, so what the host computes here is
//! bit for bit what the instrument computes from the same blob and the same state.

use activesense_core::episode::InstrumentProfile;
use activesense_core::episode::{Action, AgentKind};
use activesense_core::policy::int8::{
    self as q, LayerTensors, QuantParams, QuantizedAgent, QuantizedPolicy,
};
use activesense_core::policy::{Policy, PolicyInput, SIDE_FEATURES};
use activesense_instrument::episode::{run_episode_with, EpisodeSpec, Trajectory};
use activesense_instrument::learn::agent::{argmax, features, shape_for, LearntAgent, ACTIONS};
use activesense_instrument::learn::net::{PolicyNet, Scratch, ARCH_ID, N_LAYERS};
use activesense_instrument::world::plans;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;

/// Default number of calibration episodes.
pub const DEFAULT_CALIBRATION_EPISODES: usize = 150;

// ---------------------------------------------------------------------------------------
// Calibration.

/// Observed `[min, max]` of one tensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Range {
    /// Smallest value seen.
    pub min: f32,
    /// Largest value seen.
    pub max: f32,
}

impl Default for Range {
    fn default() -> Self {
        Range {
            min: f32::INFINITY,
            max: f32::NEG_INFINITY,
        }
    }
}

impl Range {
    fn observe(&mut self, xs: &[f32]) {
        for &x in xs {
            self.min = self.min.min(x);
            self.max = self.max.max(x);
        }
    }
    fn merge(self, o: Range) -> Range {
        Range {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }
}

/// Activation ranges of every calibrated tensor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Ranges {
    /// States observed.
    pub states: usize,
    /// Belief input.
    pub belief_input: Range,
    /// Side-feature input.
    pub side_input: Range,
    /// conv1 output.
    pub conv1: Range,
    /// conv2 output.
    pub conv2: Range,
    /// fc_belief output.
    pub fc_belief: Range,
    /// fc_side output.
    pub fc_side: Range,
    /// fc_joint output.
    pub fc_joint: Range,
}

impl Ranges {
    /// Runs the network's own forward pass ([`PolicyNet::forward_activations`]) on one
    /// state and widens the ranges by its activations.
    pub fn observe(&mut self, net: &PolicyNet, belief: &[f32], side: &[f32], s: &mut Scratch) {
        let a = net.forward_activations(belief, side, s);
        self.states += 1;
        self.belief_input.observe(belief);
        self.side_input.observe(side);
        self.conv1.observe(a.conv1);
        self.conv2.observe(a.conv2);
        self.fc_belief.observe(a.belief);
        self.fc_side.observe(a.side);
        self.fc_joint.observe(a.joint);
    }

    /// Ranges over `states` (belief, side feature pairs).
    pub fn of(net: &PolicyNet, states: &[(Vec<f32>, Vec<f32>)]) -> Ranges {
        let mut r = Ranges::default();
        let mut scratch = Scratch::new(net.shape);
        for (b, s) in states {
            r.observe(net, b, s, &mut scratch);
        }
        r
    }

    fn merge(self, o: Ranges) -> Ranges {
        Ranges {
            states: self.states + o.states,
            belief_input: self.belief_input.merge(o.belief_input),
            side_input: self.side_input.merge(o.side_input),
            conv1: self.conv1.merge(o.conv1),
            conv2: self.conv2.merge(o.conv2),
            fc_belief: self.fc_belief.merge(o.fc_belief),
            fc_side: self.fc_side.merge(o.fc_side),
            fc_joint: self.fc_joint.merge(o.fc_joint),
        }
    }
}

/// The greedy float agent, handing every state it sees to `sink`.
struct Recording<F: FnMut(&[f32], &[f32])> {
    agent: LearntAgent,
    belief: Vec<f32>,
    side: Vec<f32>,
    sink: F,
}

impl<F: FnMut(&[f32], &[f32])> Policy for Recording<F> {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        features(input, &mut self.belief, &mut self.side);
        (self.sink)(&self.belief, &self.side);
        self.agent.act(input)
    }
}

/// Episode `i` of the calibration set for `rot_bins` on `instrument` (training plans only).
pub fn calibration_specs(
    rot_bins: u8,
    instrument: InstrumentProfile,
    episodes: usize,
    seed: u64,
) -> Vec<EpisodeSpec> {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x7175_616e_7469_7a65);
    (0..episodes)
        .map(|_| {
            let mut spec = EpisodeSpec {
                plan_seed: rng.gen_range(plans::TRAIN_SEEDS),
                episode_seed: rng.gen(),
                rot_bins,
                ..EpisodeSpec::new(0, AgentKind::Learnt)
            };
            spec.config.instrument = instrument;
            spec
        })
        .collect()
}

fn record_episode(net: &Arc<PolicyNet>, spec: &EpisodeSpec, sink: impl FnMut(&[f32], &[f32])) {
    let k = net.shape.rot_bins;
    let mut rec = Recording {
        agent: LearntAgent::new(net.clone()),
        belief: vec![0.0; net.shape.belief_len()],
        side: vec![0.0; SIDE_FEATURES],
        sink,
    };
    debug_assert_eq!(spec.rot_bins as usize, k);
    run_episode_with(spec, &mut rec);
}

/// Activation ranges of `net` over the states of `episodes` greedy episodes on training
/// plans drawn from `seed` (parallel over episodes; the result does not depend on it).
pub fn calibration_ranges(
    net: &PolicyNet,
    instrument: InstrumentProfile,
    episodes: usize,
    seed: u64,
) -> Ranges {
    let net = Arc::new(net.clone());
    let specs = calibration_specs(net.shape.rot_bins as u8, instrument, episodes, seed);
    specs
        .par_iter()
        .map(|spec| {
            let mut r = Ranges::default();
            let mut scratch = Scratch::new(net.shape);
            record_episode(&net, spec, |b, s| r.observe(&net, b, s, &mut scratch));
            r
        })
        .reduce(Ranges::default, Ranges::merge)
}

/// The states (belief, side) of `episodes` greedy calibration episodes, every `stride`-th
/// step (a K = 10 state is 36 KB of floats).
pub fn calibration_states(
    net: &PolicyNet,
    instrument: InstrumentProfile,
    episodes: usize,
    seed: u64,
    stride: usize,
) -> Vec<(Vec<f32>, Vec<f32>)> {
    let net = Arc::new(net.clone());
    let stride = stride.max(1);
    calibration_specs(net.shape.rot_bins as u8, instrument, episodes, seed)
        .par_iter()
        .map(|spec| {
            let mut out = Vec::new();
            let mut i = 0;
            record_episode(&net, spec, |b, s| {
                if i % stride == 0 {
                    out.push((b.to_vec(), s.to_vec()));
                }
                i += 1;
            });
            out
        })
        .flatten()
        .collect()
}

// ---------------------------------------------------------------------------------------
// Quantisation.

/// TFLite's `QuantizeMultiplier`: `m ≈ q · 2^(shift − 31)` with `q` in `[2³⁰, 2³¹)`
/// (or 0 for `m = 0`), the shift clamped to the core's `−31..=30`.
pub fn quantize_multiplier(m: f64) -> (i32, i8) {
    if m.is_nan() || m <= 0.0 || !m.is_finite() {
        return (0, 0);
    }
    // frexp: m = frac · 2^exp, frac in [0.5, 1).
    let mut exp = m.log2().floor() as i32 + 1;
    let mut frac = m / 2f64.powi(exp);
    while frac >= 1.0 {
        frac /= 2.0;
        exp += 1;
    }
    while frac < 0.5 {
        frac *= 2.0;
        exp -= 1;
    }
    let mut qm = (frac * (1u64 << 31) as f64).round() as i64;
    if qm == 1 << 31 {
        qm /= 2;
        exp += 1;
    }
    if exp < -31 {
        return (0, 0);
    }
    if exp > 30 {
        return (i32::MAX, 30);
    }
    (qm as i32, exp as i8)
}

/// Asymmetric int8 parameters covering `[min(lo, 0), max(hi, 0)]`, 0 exactly representable.
pub fn activation_params(r: Range) -> QuantParams {
    let lo = r.min.min(0.0) as f64;
    let mut hi = r.max.max(0.0) as f64;
    if (hi - lo).is_nan() || hi - lo <= 1e-6 {
        hi = lo + 1e-6;
    }
    let scale = ((hi - lo) / 255.0) as f32;
    let zero_point = (-128.0 - lo / scale as f64).round().clamp(-128.0, 127.0) as i32;
    QuantParams { scale, zero_point }
}

struct LayerQ {
    weights: Vec<i8>,
    bias: Vec<i32>,
    multiplier: Vec<i32>,
    shift: Vec<i8>,
    input: QuantParams,
    output: QuantParams,
}

/// Quantises layer `index` of `net` reading `input`; `output` is `None` for an int32 head
/// (then the output scale is the largest per-channel accumulator scale).
fn quantize_layer(
    net: &PolicyNet,
    index: usize,
    input: QuantParams,
    output: Option<QuantParams>,
) -> LayerQ {
    let layer = net.shape.layers()[index];
    let w = &net.params[layer.weights()];
    let b = &net.params[layer.bias()];
    let fan_in = layer.fan_in();
    let w_scales: Vec<f32> = w
        .chunks(fan_in)
        .map(|row| {
            let m = row.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            if m > 0.0 {
                m / 127.0
            } else {
                1.0
            }
        })
        .collect();
    let weights = w
        .chunks(fan_in)
        .zip(&w_scales)
        .flat_map(|(row, s)| {
            row.iter()
                .map(move |v| (v / s).round().clamp(-127.0, 127.0) as i8)
        })
        .collect();
    let acc_scale: Vec<f64> = w_scales
        .iter()
        .map(|&s| input.scale as f64 * s as f64)
        .collect();
    let output = output.unwrap_or_else(|| QuantParams {
        scale: acc_scale.iter().copied().fold(0.0, f64::max) as f32,
        zero_point: 0,
    });
    let bias = b
        .iter()
        .zip(&acc_scale)
        .map(|(&v, s)| {
            (v as f64 / s)
                .round()
                .clamp(i32::MIN as f64, i32::MAX as f64) as i32
        })
        .collect();
    let (multiplier, shift) = acc_scale
        .iter()
        .map(|s| quantize_multiplier(s / output.scale as f64))
        .unzip();
    LayerQ {
        weights,
        bias,
        multiplier,
        shift,
        input,
        output,
    }
}

/// Quantises `net`, trained for `instrument`, with activation ranges `r` into blob bytes.
pub fn quantize_with_ranges(net: &PolicyNet, instrument: InstrumentProfile, r: &Ranges) -> Vec<u8> {
    let belief = activation_params(r.belief_input);
    let side = activation_params(r.side_input);
    let a1 = activation_params(r.conv1);
    let a2 = activation_params(r.conv2);
    let cat = activation_params(r.fc_belief.merge(r.fc_side));
    let joint = activation_params(r.fc_joint);
    let layers = [
        quantize_layer(net, q::L_CONV1, belief, Some(a1)),
        quantize_layer(net, q::L_CONV2, a1, Some(a2)),
        quantize_layer(net, q::L_BELIEF, a2, Some(cat)),
        quantize_layer(net, q::L_SIDE, side, Some(cat)),
        quantize_layer(net, q::L_JOINT, cat, Some(joint)),
        quantize_layer(net, q::L_ACTOR, joint, None),
        quantize_layer(net, q::L_CRITIC, joint, None),
    ];
    const _: () = assert!(N_LAYERS == q::N_LAYERS);
    let tensors = layers.each_ref().map(|l| LayerTensors {
        weights: &l.weights,
        bias: &l.bias,
        multiplier: &l.multiplier,
        shift: &l.shift,
        input: l.input,
        output: l.output,
    });
    let k = net.shape.rot_bins as u8;
    let mut out = vec![0u8; q::blob_len(ARCH_ID, k as usize)];
    let n = q::write_blob(&mut out, ARCH_ID, k, instrument, belief, side, &tensors)
        .expect("tensor lengths follow the architecture");
    out.truncate(n);
    out
}

/// Quantises `net`, calibrating on `calibration` (belief, side) states.
pub fn quantize(
    net: &PolicyNet,
    instrument: InstrumentProfile,
    calibration: &[(Vec<f32>, Vec<f32>)],
) -> Vec<u8> {
    quantize_with_ranges(net, instrument, &Ranges::of(net, calibration))
}

/// Calibrates `net` (trained for `instrument`) on `episodes` training episodes drawn from
/// `seed` and quantises it.
pub fn quantize_calibrated(
    net: &PolicyNet,
    instrument: InstrumentProfile,
    episodes: usize,
    seed: u64,
) -> (Vec<u8>, Ranges) {
    let r = calibration_ranges(net, instrument, episodes, seed);
    (quantize_with_ranges(net, instrument, &r), r)
}

// ---------------------------------------------------------------------------------------
// Agreement.

/// The float agent acting, the int8 network deciding alongside.
struct Shadow<'b> {
    float: LearntAgent,
    int8: QuantizedAgent<'b>,
    states: usize,
    agree: usize,
    max_logit_error: f32,
}

impl Policy for Shadow<'_> {
    fn act(&mut self, input: &PolicyInput<'_>) -> Action {
        let a = self.float.act(input);
        let b = self.int8.act(input);
        self.states += 1;
        self.agree += usize::from(a == b);
        if let (Some((fl, _)), Some(d)) = (self.float.last, self.int8.last) {
            let s = self.int8.policy.logit_scale();
            for (f, i) in fl.iter().zip(d.logits) {
                self.max_logit_error = self.max_logit_error.max((f - i as f32 * s).abs());
            }
        }
        a
    }
}

/// Outcomes of one agent over the agreement episodes.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PlayStats {
    /// Episodes.
    pub episodes: usize,
    /// Fraction recognised (coarse success).
    pub success_rate: f64,
    /// Mean actions per episode.
    pub mean_actions: f64,
    /// Mean measurements per episode.
    pub mean_measurements: f64,
    /// Mean cost per episode.
    pub mean_cost: f64,
    /// Median final pose error over the episodes that have one (m).
    pub median_pose_error: Option<f64>,
}

impl PlayStats {
    fn of(ts: &[Trajectory]) -> Self {
        let n = ts.len().max(1) as f64;
        let mut errors: Vec<f64> = ts
            .iter()
            .filter_map(|t| t.outcome.pose_error.map(f64::from))
            .collect();
        errors.sort_by(f64::total_cmp);
        PlayStats {
            episodes: ts.len(),
            success_rate: ts.iter().filter(|t| t.outcome.recognised).count() as f64 / n,
            mean_actions: ts.iter().map(|t| t.summary.actions as f64).sum::<f64>() / n,
            mean_measurements: ts
                .iter()
                .map(|t| t.summary.measurements as f64)
                .sum::<f64>()
                / n,
            mean_cost: ts.iter().map(|t| t.summary.cost as f64).sum::<f64>() / n,
            median_pose_error: errors.get(errors.len() / 2).copied(),
        }
    }
}

/// Float vs int8 on one rotation setting.
#[derive(Clone, Debug, Serialize)]
pub struct Agreement {
    /// Rotation bins K.
    pub rot_bins: u8,
    /// Test plans played (from `plans::TEST_SEEDS.start`).
    pub plans: usize,
    /// States the float agent met.
    pub states: usize,
    /// States where the int8 argmax equals the float argmax.
    pub agreeing_states: usize,
    /// `agreeing_states / states`.
    pub action_agreement: f64,
    /// Largest |float logit − dequantised int8 logit| over the states.
    pub max_logit_error: f32,
    /// Episodes the int8 agent played with exactly the float agent's actions.
    pub identical_episodes: usize,
    /// The float agent's outcomes.
    pub float: PlayStats,
    /// The int8 agent's outcomes (playing on its own).
    pub int8: PlayStats,
    /// Blob size (bytes) and its CRC-32.
    pub blob_bytes: usize,
    /// CRC-32 of the blob (its last 4 bytes).
    pub blob_crc: u32,
}

/// The evaluation's episode for test plan `plan_seed` on `instrument` (oracle termination,
/// 100 actions).
pub fn test_spec(plan_seed: u32, rot_bins: u8, instrument: InstrumentProfile) -> EpisodeSpec {
    let mut spec = EpisodeSpec::new(plan_seed, AgentKind::Learnt);
    spec.rot_bins = rot_bins;
    spec.config.instrument = instrument;
    spec
}

/// Plays `plans` test plans with the float agent (the int8 network deciding alongside) and
/// again with the int8 agent alone. `blob` must be a valid blob for `net`'s K.
pub fn agreement(net: &PolicyNet, blob: &[u8], plans: usize) -> Result<Agreement, q::BlobError> {
    let policy = QuantizedPolicy::parse(blob)?;
    let k = policy.rot_bins();
    if k as usize != net.shape.rot_bins {
        return Err(q::BlobError::ShapeMismatch);
    }
    let net = Arc::new(net.clone());
    let seeds: Vec<u32> = (0..plans as u32)
        .map(|i| plans::TEST_SEEDS.start + i)
        .collect();
    let runs: Vec<(Trajectory, Trajectory, usize, usize, f32)> = seeds
        .par_iter()
        .map(|&seed| {
            let spec = test_spec(seed, k, policy.instrument());
            let mut shadow = Shadow {
                float: LearntAgent::new(net.clone()),
                int8: QuantizedAgent::new(policy),
                states: 0,
                agree: 0,
                max_logit_error: 0.0,
            };
            let tf = run_episode_with(&spec, &mut shadow);
            let ti = run_episode_with(&spec, &mut QuantizedAgent::new(policy));
            (tf, ti, shadow.states, shadow.agree, shadow.max_logit_error)
        })
        .collect();
    let states: usize = runs.iter().map(|r| r.2).sum();
    let agree: usize = runs.iter().map(|r| r.3).sum();
    let identical = runs
        .iter()
        .filter(|(a, b, ..)| {
            a.steps.len() == b.steps.len()
                && a.steps
                    .iter()
                    .zip(&b.steps)
                    .all(|(x, y)| x.action == y.action)
        })
        .count();
    let (tf, ti): (Vec<Trajectory>, Vec<Trajectory>) =
        runs.iter().map(|r| (r.0.clone(), r.1.clone())).unzip();
    let n = blob.len();
    Ok(Agreement {
        rot_bins: k,
        plans,
        states,
        agreeing_states: agree,
        action_agreement: agree as f64 / states.max(1) as f64,
        max_logit_error: runs.iter().map(|r| r.4).fold(0.0, f32::max),
        identical_episodes: identical,
        float: PlayStats::of(&tf),
        int8: PlayStats::of(&ti),
        blob_bytes: n,
        blob_crc: u32::from_le_bytes(blob[n - 4..].try_into().expect("4 bytes")),
    })
}

/// The fraction of `states` on which the int8 argmax equals the float argmax.
pub fn action_agreement(net: &PolicyNet, blob: &[u8], states: &[(Vec<f32>, Vec<f32>)]) -> f64 {
    let Ok(policy) = QuantizedPolicy::parse(blob) else {
        return 0.0;
    };
    let (bq, sq) = (policy.belief_input(), policy.side_input());
    let mut scratch = Box::new(q::Scratch::new());
    let mut agree = 0;
    for (b, s) in states {
        let bi: Vec<i8> = b.iter().map(|&v| q::quantize_value(v, bq)).collect();
        let mut si = [0i8; SIDE_FEATURES];
        si.iter_mut()
            .zip(s)
            .for_each(|(o, &v)| *o = q::quantize_value(v, sq));
        let fl = net.forward(b, s).logits;
        match policy.infer(&bi, &si, &mut scratch) {
            Ok(d) if ACTIONS[argmax(&fl)] == d.action => agree += 1,
            _ => {}
        }
    }
    agree as f64 / states.len().max(1) as f64
}

/// A randomly initialised network for K with its actor at unit gain (the trainer's ×0.01
/// start makes every logit ≈ 0); for tests and examples.
pub fn random_net(rot_bins: u8, seed: u64) -> PolicyNet {
    let mut net = PolicyNet::new(shape_for(rot_bins), seed);
    let actor = net.shape.layers()[q::L_ACTOR];
    net.params[actor.weights()]
        .iter_mut()
        .for_each(|w| *w *= 100.0);
    net
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multipliers_round_trip() {
        let mut rng = Pcg64::seed_from_u64(2);
        for _ in 0..10_000 {
            let m = 2f64.powf(rng.gen_range(-30.0..20.0));
            let (qm, shift) = quantize_multiplier(m);
            assert!((1 << 30..=i32::MAX).contains(&qm), "{m}: {qm}");
            let back = qm as f64 * 2f64.powi(shift as i32 - 31);
            assert!((back / m - 1.0).abs() < 1e-9, "{m} → {qm}, {shift}");
        }
        assert_eq!(quantize_multiplier(0.5), (1 << 30, 0));
        assert_eq!(quantize_multiplier(1.0), (1 << 30, 1));
        assert_eq!(quantize_multiplier(0.0), (0, 0));
    }

    #[test]
    fn zero_is_exact_in_every_activation() {
        for (lo, hi) in [
            (0.0, 1.0),
            (-1.0, 3.2),
            (0.0, 17.5),
            (-0.3, 0.0),
            (0.0, 0.0),
        ] {
            let p = activation_params(Range { min: lo, max: hi });
            assert!((-128..=127).contains(&p.zero_point));
            assert_eq!(q::quantize_value(0.0, p) as i32, p.zero_point);
            // Both ends representable to within one step.
            let top = (127 - p.zero_point) as f32 * p.scale;
            assert!(top >= hi - p.scale, "{lo} {hi} {p:?}");
        }
        let relu = activation_params(Range { min: 0.0, max: 5.0 });
        assert_eq!(relu.zero_point, -128);
    }

    /// Checks at every state the float agent meets that the int8 belief written directly
    /// equals the quantised float belief, and counts argmax agreement.
    struct Check<'b> {
        float: LearntAgent,
        int8: QuantizedAgent<'b>,
        seen: usize,
        agree: usize,
    }

    impl Policy for Check<'_> {
        fn act(&mut self, input: &PolicyInput<'_>) -> Action {
            let p = self.int8.policy.belief_input();
            let mut f = vec![0.0; input.belief_len()];
            let mut qd = vec![0i8; input.belief_len()];
            assert_eq!(input.write_belief(&mut f), f.len());
            assert_eq!(
                input.write_belief_q(&mut qd, p.scale, p.zero_point),
                f.len()
            );
            assert!(f
                .iter()
                .zip(&qd)
                .all(|(&v, &w)| q::quantize_value(v, p) == w));
            let a = self.float.act(input);
            self.seen += 1;
            self.agree += usize::from(self.int8.act(input) == a);
            a
        }
    }

    #[test]
    fn int8_agrees_with_float_and_blobs_round_trip() {
        for k in [1u8, 10] {
            let net = random_net(k, 1);
            let states = calibration_states(&net, InstrumentProfile::EdmScan, 8, 5, 1);
            assert!(states.len() > 20);
            let blob = quantize(&net, InstrumentProfile::EdmScan, &states);
            // Round trip through the core's validator.
            let p = QuantizedPolicy::parse(&blob).expect("valid blob");
            assert_eq!(p.rot_bins(), k);
            assert_eq!(blob.len(), q::blob_len(ARCH_ID, k as usize));
            assert_eq!(p.belief_input().zero_point, -128, "belief in [0, 1]");
            // Weights dequantise to within half a step of the floats.
            let conv1 = net.shape.layers()[q::L_CONV1];
            let w = &net.params[conv1.weights()];
            let lq = p.layer(q::L_CONV1).unwrap();
            let row_max = w[..conv1.fan_in()].iter().fold(0f32, |m, v| m.max(v.abs()));
            for (f, i) in w[..conv1.fan_in()].iter().zip(lq.weights()) {
                assert!((f - i as f32 * row_max / 127.0).abs() <= row_max / 254.0 + 1e-7);
            }
            // Same blob from the same calibration: deterministic.
            assert_eq!(blob, quantize(&net, InstrumentProfile::EdmScan, &states));
            // Held-out states (other training episodes) and whole test episodes.
            let held_out = calibration_states(&net, InstrumentProfile::EdmScan, 4, 99, 1);
            let agree = action_agreement(&net, &blob, &held_out);
            assert!(agree >= 0.95, "K = {k}: state agreement {agree}");
            let mut seen = 0;
            let mut agreed = 0;
            for seed in plans::TEST_SEEDS.take(3) {
                let mut c = Check {
                    float: LearntAgent::new(Arc::new(net.clone())),
                    int8: QuantizedAgent::new(p),
                    seen: 0,
                    agree: 0,
                };
                run_episode_with(&test_spec(seed, k, InstrumentProfile::EdmScan), &mut c);
                seen += c.seen;
                agreed += c.agree;
            }
            let frac = agreed as f64 / seen as f64;
            assert!(frac >= 0.95, "K = {k}: episode agreement {frac} of {seen}");
        }
    }

    #[test]
    fn agreement_report_is_consistent() {
        let net = random_net(1, 4);
        let (blob, ranges) = quantize_calibrated(&net, InstrumentProfile::EdmScan, 3, 1);
        assert!(ranges.states > 0);
        let a = agreement(&net, &blob, 2).unwrap();
        assert_eq!(a.float.episodes, 2);
        assert_eq!(a.int8.episodes, 2);
        assert!(a.agreeing_states <= a.states);
        assert!(a.identical_episodes <= 2);
        assert_eq!(a.blob_bytes, blob.len());
        let other = random_net(10, 4);
        assert!(agreement(&other, &blob, 1).is_err(), "K mismatch");
    }
}
