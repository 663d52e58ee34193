//! The actor-critic policy network (paper Fig. 2, after Chaplot et al. 2018), sized for a
//! Cortex-M4: architecture id 2, `"conv8-4-fc32"`. Forward and backward are written by hand
//! in f32 so training needs no framework, runs on two CPU cores, and is bit-reproducible.
//!
//! ```text
//! belief K×30×30 ─ conv1 3×3/2 K→8 ─ ReLU ─ conv2 3×3/2 8→4 ─ ReLU ─ flatten 256
//!                  (8×15×15)                (4×8×8)                     │
//!                                                   fc_belief 256→32 ─ ReLU ─┐
//! side S ────────────────────────────────────────── fc_side   S→32    ─ ReLU ─┴ concat 64
//!   ─ fc_joint 64→32 ─ ReLU ─┬─ actor  32→3 logits (0 rotate-left, 1 rotate-right, 2 measure)
//!                            └─ critic 32→1 value
//! ```
//!
//! Why so small (architecture 1 had 16 channels after conv2, a 1024→64 fc_belief and 64
//! hidden units, 83 K parameters): the int8 policy must fit a RAM slot on the instrument,
//! next to the localizer, so a user can upload a new one without reflashing; 15 K
//! parameters make a ≈ 16 KB blob. `docs/LEARNING.md` has the measurements behind it.
//!
//! Both convolutions use zero padding 1. Inputs: the belief map is `K` planes of 30×30,
//! layout `[plane][y][x]` row-major, values in `[0, 1]`; the side features are `S` floats.
//!
//! **Parameter layout.** All parameters live in one flat `Vec<f32>`, layer after layer in the
//! order of [`NetShape::layers`] (conv1, conv2, fc_belief, fc_side, fc_joint, actor, critic);
//! within a layer the weights come first, then the biases. Conv weights are
//! `[out][in][ky][kx]`, linear weights `[out][in]` (row `o` is contiguous, so a forward output
//! is one dot product). The conv2 output is flattened channel-major, `[c][y][x]`.
//!
//! **Determinism.** A batch is cut into chunks of [`GRAD_CHUNK`] samples; each chunk
//! accumulates its gradient into its own buffer and the buffers are summed in chunk order.
//! The float operations done therefore never depend on the rayon thread count, so the same
//! inputs give bit-identical gradients on 1 or 16 threads.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use std::ops::Range;

/// Architecture id written in policy files.
pub const ARCH_ID: u16 = 2;
/// Human-readable architecture name.
pub const ARCH_NAME: &str = "conv8-4-fc32";
/// Side of the square belief map (cells).
pub const GRID: usize = 30;
/// Largest supported number of rotation bins `K` (belief planes).
pub const MAX_ROT_BINS: usize = 10;
/// Actions: 0 rotate-left, 1 rotate-right, 2 measure.
pub const N_ACTIONS: usize = 3;
/// Samples per gradient chunk. Fixed (not derived from the thread count) so the summation
/// order, hence every gradient bit, is the same however many threads run the chunks.
pub const GRAD_CHUNK: usize = 8;
/// Convolution kernel side, stride and zero padding (both conv layers).
pub const CONV_KERNEL: usize = 3;
/// Convolution stride.
pub const CONV_STRIDE: usize = 2;
/// Convolution zero padding.
pub const CONV_PAD: usize = 1;

const C1: usize = 8;
const C2: usize = 4;
const S1: usize = 15; // conv1 output side: (30 + 2 - 3) / 2 + 1
const S2: usize = 8; // conv2 output side: (15 + 2 - 3) / 2 + 1
const P0: usize = GRID * GRID;
const P1: usize = S1 * S1;
const P2: usize = S2 * S2;
const FLAT: usize = C2 * P2;
const HIDDEN: usize = 32;
const KK: usize = CONV_KERNEL * CONV_KERNEL;

// One sample's kept activations (all post-ReLU), back to back: conv1 | conv2 | fc_belief |
// fc_side | fc_joint. fc_belief and fc_side are adjacent so they *are* the concat.
const A1: usize = C1 * P1;
const OFF_HB: usize = A1 + FLAT;
const OFF_HJ: usize = OFF_HB + 2 * HIDDEN;
const ACTS: usize = OFF_HJ + HIDDEN;

/// Input sizes of a network; everything else is fixed by the architecture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NetShape {
    /// Rotation bins `K` = belief planes, `1..=MAX_ROT_BINS`.
    pub rot_bins: usize,
    /// Length `S` of the side-feature vector.
    pub side: usize,
}

/// What a layer computes (for the int8 quantiser and the firmware port).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerKind {
    /// `CONV_KERNEL`² kernel, stride `CONV_STRIDE`, zero padding `CONV_PAD`, square maps.
    Conv {
        in_ch: usize,
        out_ch: usize,
        in_size: usize,
        out_size: usize,
    },
    /// Fully connected, weight `[outputs][inputs]`.
    Linear { inputs: usize, outputs: usize },
}

/// One layer's place in the flat parameter vector: weights at `offset..offset + weight_len`,
/// then `bias_len` biases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layer {
    pub name: &'static str,
    pub kind: LayerKind,
    /// Whether a ReLU follows (false for the two heads).
    pub relu: bool,
    pub offset: usize,
    pub weight_len: usize,
    pub bias_len: usize,
}

impl Layer {
    /// Weights and biases together.
    pub fn len(&self) -> usize {
        self.weight_len + self.bias_len
    }
    /// Never true; present because `len` is.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn weights(&self) -> Range<usize> {
        self.offset..self.offset + self.weight_len
    }
    pub fn bias(&self) -> Range<usize> {
        self.offset + self.weight_len..self.offset + self.len()
    }
    /// Weights feeding one output (one row of the weight matrix): the fan-in.
    pub fn fan_in(&self) -> usize {
        match self.kind {
            LayerKind::Conv { in_ch, .. } => in_ch * KK,
            LayerKind::Linear { inputs, .. } => inputs,
        }
    }
    /// Multiply-accumulates per sample.
    pub fn macs(&self) -> usize {
        match self.kind {
            LayerKind::Conv { out_size, .. } => self.weight_len * out_size * out_size,
            LayerKind::Linear { .. } => self.weight_len,
        }
    }
}

/// Index of each layer in [`NetShape::layers`].
const L_CONV1: usize = 0;
const L_CONV2: usize = 1;
const L_BELIEF: usize = 2;
const L_SIDE: usize = 3;
const L_JOINT: usize = 4;
const L_ACTOR: usize = 5;
const L_CRITIC: usize = 6;
/// Number of layers.
pub const N_LAYERS: usize = 7;

impl NetShape {
    /// Floats in one belief map: `K·30·30`.
    pub fn belief_len(&self) -> usize {
        self.rot_bins * P0
    }

    /// The layers in parameter order (an array, so the hot paths can call it freely).
    pub fn layers(&self) -> [Layer; N_LAYERS] {
        let conv = |in_ch, out_ch, in_size, out_size| LayerKind::Conv {
            in_ch,
            out_ch,
            in_size,
            out_size,
        };
        let lin = |inputs, outputs| LayerKind::Linear { inputs, outputs };
        let specs = [
            ("conv1", conv(self.rot_bins, C1, GRID, S1), true),
            ("conv2", conv(C1, C2, S1, S2), true),
            ("fc_belief", lin(FLAT, HIDDEN), true),
            ("fc_side", lin(self.side, HIDDEN), true),
            ("fc_joint", lin(2 * HIDDEN, HIDDEN), true),
            ("actor", lin(HIDDEN, N_ACTIONS), false),
            ("critic", lin(HIDDEN, 1), false),
        ];
        let mut offset = 0;
        specs.map(|(name, kind, relu)| {
            let (weight_len, bias_len) = match kind {
                LayerKind::Conv { in_ch, out_ch, .. } => (out_ch * in_ch * KK, out_ch),
                LayerKind::Linear { inputs, outputs } => (outputs * inputs, outputs),
            };
            let layer = Layer {
                name,
                kind,
                relu,
                offset,
                weight_len,
                bias_len,
            };
            offset += layer.len();
            layer
        })
    }

    /// Length of the flat parameter vector.
    pub fn param_count(&self) -> usize {
        let last = self.layers()[N_LAYERS - 1];
        last.offset + last.len()
    }

    /// Multiply-accumulates for one decision (one forward pass), biases and ReLUs not counted.
    pub fn macs(&self) -> usize {
        self.layers().iter().map(Layer::macs).sum()
    }

    fn assert_valid(&self) {
        assert!(
            (1..=MAX_ROT_BINS).contains(&self.rot_bins),
            "rot_bins must be 1..={MAX_ROT_BINS}, got {}",
            self.rot_bins
        );
    }
}

/// One decision's network output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Output {
    /// Unnormalised action scores (0 rotate-left, 1 rotate-right, 2 measure).
    pub logits: [f32; N_ACTIONS],
    /// The critic's state-value estimate.
    pub value: f32,
}

/// The network: its shape and its flat parameters (layout in the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyNet {
    pub shape: NetShape,
    pub params: Vec<f32>,
}

impl PolicyNet {
    /// Deterministic initialisation from `seed`. Hidden layers: He/Kaiming-uniform over the
    /// fan-in, `U(±√(6/fan_in))`, right for ReLU. Heads: `U(±√(3/fan_in))` (unit gain), scaled
    /// ×0.01 for the actor so the first policy is near-uniform (every action explored), ×1 for
    /// the critic. Biases 0. Panics unless `1 <= rot_bins <= MAX_ROT_BINS`.
    pub fn new(shape: NetShape, seed: u64) -> Self {
        shape.assert_valid();
        let mut rng = Pcg64::seed_from_u64(seed);
        let mut params = vec![0.0; shape.param_count()];
        for (i, layer) in shape.layers().iter().enumerate() {
            let fan_in = layer.fan_in() as f32;
            let bound = match i {
                L_ACTOR => 0.01 * (3.0 / fan_in).sqrt(),
                L_CRITIC => (3.0 / fan_in).sqrt(),
                _ => (6.0 / fan_in).sqrt(),
            };
            for w in &mut params[layer.weights()] {
                *w = rng.gen_range(-bound..bound);
            }
        }
        PolicyNet { shape, params }
    }

    /// Wraps existing parameters; `None` if their count does not fit the shape.
    pub fn from_params(shape: NetShape, params: Vec<f32>) -> Option<Self> {
        (params.len() == shape.param_count() && (1..=MAX_ROT_BINS).contains(&shape.rot_bins))
            .then_some(PolicyNet { shape, params })
    }

    /// One decision. Allocates a [`Scratch`]; use [`PolicyNet::forward_with`] in loops.
    pub fn forward(&self, belief: &[f32], side: &[f32]) -> Output {
        self.forward_with(belief, side, &mut Scratch::new(self.shape))
    }

    /// One decision without allocating. Bit-identical to the matching row of
    /// [`PolicyNet::forward_batch`] (same code, same order).
    pub fn forward_with(&self, belief: &[f32], side: &[f32], scratch: &mut Scratch) -> Output {
        self.check_inputs(belief, side, 1);
        assert_eq!(scratch.shape, self.shape, "scratch built for another shape");
        let Scratch {
            acts, col1, col2, ..
        } = scratch;
        forward_sample(&self.shape, &self.params, belief, side, acts, col1, col2)
    }

    /// Batched forward of `b` samples (`belief`: `b·K·900`, `side`: `b·S`, sample-major) that
    /// keeps in `cache` what [`PolicyNet::backward_batch`] needs. Returns logits and values.
    pub fn forward_batch(
        &self,
        belief: &[f32],
        side: &[f32],
        b: usize,
        cache: &mut BatchCache,
    ) -> (Vec<[f32; N_ACTIONS]>, Vec<f32>) {
        self.check_inputs(belief, side, b);
        cache.prepare(self.shape, b);
        let (bl, sl) = (self.shape.belief_len(), self.shape.side);
        let stride = bl + sl;
        for i in 0..b {
            let row = &mut cache.inputs[i * stride..(i + 1) * stride];
            row[..bl].copy_from_slice(&belief[i * bl..(i + 1) * bl]);
            row[bl..].copy_from_slice(&side[i * sl..(i + 1) * sl]);
        }
        let (shape, params) = (&self.shape, &self.params[..]);
        cache
            .inputs
            .par_chunks(stride * GRAD_CHUNK)
            .zip(cache.acts.par_chunks_mut(ACTS * GRAD_CHUNK))
            .zip(cache.outputs.par_chunks_mut(GRAD_CHUNK))
            .zip(cache.work.par_iter_mut())
            .for_each(|(((inputs, acts), outputs), work)| {
                let s = &mut work.scratch;
                for ((input, act), out) in inputs
                    .chunks(stride)
                    .zip(acts.chunks_mut(ACTS))
                    .zip(outputs.iter_mut())
                {
                    let (bel, sd) = input.split_at(bl);
                    *out = forward_sample(shape, params, bel, sd, act, &mut s.col1, &mut s.col2);
                }
            });
        let logits = cache.outputs.iter().map(|o| o.logits).collect();
        let values = cache.outputs.iter().map(|o| o.value).collect();
        (logits, values)
    }

    /// Backpropagates `dlogits` (`b·3`) and `dvalues` (`b`), the loss gradients w.r.t. the
    /// outputs of the last [`PolicyNet::forward_batch`], and *adds* the parameter gradient
    /// summed over the batch to `grad` (`param_count` long). Deterministic for any thread count.
    pub fn backward_batch(
        &self,
        cache: &mut BatchCache,
        dlogits: &[f32],
        dvalues: &[f32],
        grad: &mut [f32],
    ) {
        let b = cache.b;
        assert_eq!(
            cache.shape,
            Some(self.shape),
            "cache filled by another shape"
        );
        assert_eq!(dlogits.len(), b * N_ACTIONS, "dlogits length");
        assert_eq!(dvalues.len(), b, "dvalues length");
        assert_eq!(grad.len(), self.shape.param_count(), "grad length");
        let (shape, params) = (&self.shape, &self.params[..]);
        let bl = shape.belief_len();
        let stride = bl + shape.side;
        let BatchCache {
            inputs, acts, work, ..
        } = cache;
        work.par_iter_mut()
            .zip(inputs.par_chunks(stride * GRAD_CHUNK))
            .zip(acts.par_chunks(ACTS * GRAD_CHUNK))
            .zip(dlogits.par_chunks(N_ACTIONS * GRAD_CHUNK))
            .zip(dvalues.par_chunks(GRAD_CHUNK))
            .for_each(|((((work, inputs), acts), dls), dvs)| {
                let ChunkWork { grad, scratch } = work;
                grad.fill(0.0);
                for (((input, act), dl), &dv) in inputs
                    .chunks(stride)
                    .zip(acts.chunks(ACTS))
                    .zip(dls.chunks(N_ACTIONS))
                    .zip(dvs)
                {
                    let (bel, sd) = input.split_at(bl);
                    let dl = [dl[0], dl[1], dl[2]];
                    backward_sample(
                        shape,
                        params,
                        bel,
                        sd,
                        act,
                        dl,
                        dv,
                        Some(grad),
                        scratch,
                        None,
                        false,
                    );
                }
            });
        // Sum the chunk buffers in chunk order. Parallel over parameter ranges only: each
        // element still sees chunk 0, 1, 2, ... in that order.
        let work = &cache.work;
        grad.par_chunks_mut(4096).enumerate().for_each(|(si, g)| {
            let span = si * 4096..si * 4096 + g.len();
            for w in work {
                for (gi, ci) in g.iter_mut().zip(&w.grad[span.clone()]) {
                    *gi += ci;
                }
            }
        });
    }

    /// Gradient of `dlogits·logits + dvalue·value` w.r.t. the inputs (belief, side) for one
    /// sample, plain backprop through the ReLUs. For saliency maps; allocates.
    pub fn input_gradient(
        &self,
        belief: &[f32],
        side: &[f32],
        dlogits: [f32; N_ACTIONS],
        dvalue: f32,
    ) -> (Vec<f32>, Vec<f32>) {
        let mut s = Scratch::new(self.shape);
        self.forward_with(belief, side, &mut s);
        let mut dbelief = vec![0.0; self.shape.belief_len()];
        let mut dside = vec![0.0; self.shape.side];
        let acts = std::mem::take(&mut s.acts);
        backward_sample(
            &self.shape,
            &self.params,
            belief,
            side,
            &acts,
            dlogits,
            dvalue,
            None,
            &mut s,
            Some((&mut dbelief, &mut dside)),
            false,
        );
        (dbelief, dside)
    }

    /// Guided back-propagation (Springenberg et al. 2014) of the logit of `action` to the
    /// inputs, for one sample: the backward pass of `logits[action]` in which every ReLU
    /// passes the gradient only where its forward output was positive *and* the incoming
    /// gradient is positive ([`guided_relu_mask`]). Returns the maps over the belief
    /// (`K·900`, layout of the input) and over the side features. The inputs themselves are
    /// not behind a ReLU, so the maps can hold negative values (a negative first-layer
    /// weight); the inspection tool shows their positive part. Allocates.
    pub fn guided_backprop(
        &self,
        belief: &[f32],
        side: &[f32],
        action: usize,
    ) -> (Vec<f32>, Vec<f32>) {
        assert!(action < N_ACTIONS, "action {action} out of range");
        let mut s = Scratch::new(self.shape);
        self.forward_with(belief, side, &mut s);
        let mut dbelief = vec![0.0; self.shape.belief_len()];
        let mut dside = vec![0.0; self.shape.side];
        let mut dlogits = [0.0; N_ACTIONS];
        dlogits[action] = 1.0;
        let acts = std::mem::take(&mut s.acts);
        backward_sample(
            &self.shape,
            &self.params,
            belief,
            side,
            &acts,
            dlogits,
            0.0,
            None,
            &mut s,
            Some((&mut dbelief, &mut dside)),
            true,
        );
        (dbelief, dside)
    }

    fn check_inputs(&self, belief: &[f32], side: &[f32], b: usize) {
        assert_eq!(belief.len(), b * self.shape.belief_len(), "belief length");
        assert_eq!(side.len(), b * self.shape.side, "side length");
    }
}

/// Reusable per-sample buffers: activations, im2col matrices and backward temporaries.
#[derive(Clone, Debug)]
pub struct Scratch {
    shape: NetShape,
    acts: Vec<f32>,
    col1: Vec<f32>,
    col2: Vec<f32>,
    dcol: Vec<f32>,
    da1: Vec<f32>,
    da2: Vec<f32>,
    dhj: Vec<f32>,
    dcat: Vec<f32>,
}

impl Scratch {
    pub fn new(shape: NetShape) -> Self {
        shape.assert_valid();
        let r1 = shape.rot_bins * KK;
        Scratch {
            shape,
            acts: vec![0.0; ACTS],
            col1: vec![0.0; r1 * P1],
            col2: vec![0.0; C1 * KK * P2],
            dcol: vec![0.0; (r1 * P1).max(C1 * KK * P2)],
            da1: vec![0.0; A1],
            da2: vec![0.0; FLAT],
            dhj: vec![0.0; HIDDEN],
            dcat: vec![0.0; 2 * HIDDEN],
        }
    }
}

#[derive(Clone, Debug)]
struct ChunkWork {
    grad: Vec<f32>,
    scratch: Scratch,
}

/// What a batched forward keeps for its backward: a copy of the inputs, every sample's
/// activations, and one gradient buffer + scratch per [`GRAD_CHUNK`]-sample chunk. Reuse it
/// across updates to avoid reallocating.
#[derive(Clone, Debug, Default)]
pub struct BatchCache {
    shape: Option<NetShape>,
    b: usize,
    inputs: Vec<f32>,
    acts: Vec<f32>,
    outputs: Vec<Output>,
    work: Vec<ChunkWork>,
}

impl BatchCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// Samples held by the last forward.
    pub fn batch_len(&self) -> usize {
        self.b
    }

    fn prepare(&mut self, shape: NetShape, b: usize) {
        if self.shape != Some(shape) {
            self.work.clear();
            self.shape = Some(shape);
        }
        self.b = b;
        self.inputs
            .resize(b * (shape.belief_len() + shape.side), 0.0);
        self.acts.resize(b * ACTS, 0.0);
        let blank = Output {
            logits: [0.0; N_ACTIONS],
            value: 0.0,
        };
        self.outputs.resize(b, blank);
        let chunks = b.div_ceil(GRAD_CHUNK);
        self.work.truncate(chunks);
        while self.work.len() < chunks {
            self.work.push(ChunkWork {
                grad: vec![0.0; shape.param_count()],
                scratch: Scratch::new(shape),
            });
        }
    }
}

// ---------------------------------------------------------------------------------------
// Loss helpers for the A2C trainer (which computes dlogits / dvalue itself).

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

// ---------------------------------------------------------------------------------------
// Per-sample kernels. Forward and backward of one sample; the batch paths call exactly these.

fn split_wb<'a>(params: &'a [f32], layer: &Layer) -> (&'a [f32], &'a [f32]) {
    (&params[layer.weights()], &params[layer.bias()])
}

fn forward_sample(
    shape: &NetShape,
    params: &[f32],
    belief: &[f32],
    side: &[f32],
    acts: &mut [f32],
    col1: &mut [f32],
    col2: &mut [f32],
) -> Output {
    let layers = shape.layers();
    let (a1, rest) = acts.split_at_mut(A1);
    let (a2, rest) = rest.split_at_mut(FLAT);
    let (hcat, hj) = rest.split_at_mut(2 * HIDDEN);

    let (w, b) = split_wb(params, &layers[L_CONV1]);
    im2col(shape.rot_bins, GRID, S1, belief, col1);
    conv_forward(w, b, col1, a1);
    relu(a1);

    let (w, b) = split_wb(params, &layers[L_CONV2]);
    im2col(C1, S1, S2, a1, col2);
    conv_forward(w, b, col2, a2);
    relu(a2);

    let (hb, hs) = hcat.split_at_mut(HIDDEN);
    let (w, b) = split_wb(params, &layers[L_BELIEF]);
    linear(w, b, a2, hb);
    relu(hb);
    let (w, b) = split_wb(params, &layers[L_SIDE]);
    linear(w, b, side, hs);
    relu(hs);

    let (w, b) = split_wb(params, &layers[L_JOINT]);
    linear(w, b, hcat, hj);
    relu(hj);

    let mut logits = [0.0; N_ACTIONS];
    let (w, b) = split_wb(params, &layers[L_ACTOR]);
    linear(w, b, hj, &mut logits);
    let mut value = [0.0];
    let (w, b) = split_wb(params, &layers[L_CRITIC]);
    linear(w, b, hj, &mut value);
    Output {
        logits,
        value: value[0],
    }
}

/// Backward of one sample from the output gradients. Adds parameter gradients into `grad`
/// when given; writes input gradients into `input_grad` when given (then the first-layer
/// parameter gradients are still added if `grad` is given).
#[allow(clippy::too_many_arguments)]
fn backward_sample(
    shape: &NetShape,
    params: &[f32],
    belief: &[f32],
    side: &[f32],
    acts: &[f32],
    dlogits: [f32; N_ACTIONS],
    dvalue: f32,
    mut grad: Option<&mut [f32]>,
    s: &mut Scratch,
    input_grad: Option<(&mut [f32], &mut [f32])>,
    guided: bool,
) {
    // Plain backprop masks a ReLU's gradient where its output was 0; guided backprop
    // (Springenberg et al. 2014) also where the incoming gradient is negative.
    let mask: fn(&mut [f32], &[f32]) = if guided { guided_relu_mask } else { relu_mask };
    let layers = shape.layers();
    let (a1, rest) = acts.split_at(A1);
    let (a2, rest) = rest.split_at(FLAT);
    let (hcat, hj) = rest.split_at(2 * HIDDEN);
    let (hb, hs) = hcat.split_at(HIDDEN);
    // Heads: both read hj.
    let (dinput, dside) = match input_grad {
        Some((db, ds)) => (Some(db), Some(ds)),
        None => (None, None),
    };
    s.dhj.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_ACTOR]);
    linear_backward(
        w,
        hj,
        &dlogits,
        layer_grad(&mut grad, &layers[L_ACTOR]),
        Some(&mut s.dhj),
    );
    let (w, _) = split_wb(params, &layers[L_CRITIC]);
    linear_backward(
        w,
        hj,
        &[dvalue],
        layer_grad(&mut grad, &layers[L_CRITIC]),
        Some(&mut s.dhj),
    );
    mask(&mut s.dhj, hj);

    s.dcat.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_JOINT]);
    linear_backward(
        w,
        hcat,
        &s.dhj,
        layer_grad(&mut grad, &layers[L_JOINT]),
        Some(&mut s.dcat),
    );
    mask(&mut s.dcat, hcat);
    let (dhb, dhs) = s.dcat.split_at(HIDDEN);

    let (w, _) = split_wb(params, &layers[L_SIDE]);
    if let Some(ds) = dside {
        ds.fill(0.0);
        linear_backward(
            w,
            side,
            dhs,
            layer_grad(&mut grad, &layers[L_SIDE]),
            Some(ds),
        );
    } else {
        linear_backward(w, side, dhs, layer_grad(&mut grad, &layers[L_SIDE]), None);
    }
    debug_assert_eq!(hs.len(), dhs.len());

    s.da2.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_BELIEF]);
    linear_backward(
        w,
        a2,
        dhb,
        layer_grad(&mut grad, &layers[L_BELIEF]),
        Some(&mut s.da2),
    );
    mask(&mut s.da2, a2);
    debug_assert_eq!(hb.len(), dhb.len());

    // conv2: recompute its im2col from a1 rather than keeping it per sample.
    let (w, _) = split_wb(params, &layers[L_CONV2]);
    im2col(C1, S1, S2, a1, &mut s.col2);
    let dcol2 = &mut s.dcol[..C1 * KK * P2];
    conv_backward(
        C2,
        w,
        &s.col2,
        &s.da2,
        layer_grad(&mut grad, &layers[L_CONV2]),
        Some(&mut *dcol2),
    );
    s.da1.fill(0.0);
    col2im_add(C1, S1, S2, dcol2, &mut s.da1);
    mask(&mut s.da1, a1);

    let (w, _) = split_wb(params, &layers[L_CONV1]);
    im2col(shape.rot_bins, GRID, S1, belief, &mut s.col1);
    match dinput {
        Some(dbel) => {
            let dcol1 = &mut s.dcol[..shape.rot_bins * KK * P1];
            conv_backward(
                C1,
                w,
                &s.col1,
                &s.da1,
                layer_grad(&mut grad, &layers[L_CONV1]),
                Some(&mut *dcol1),
            );
            dbel.fill(0.0);
            col2im_add(shape.rot_bins, GRID, S1, dcol1, dbel);
        }
        None => conv_backward(
            C1,
            w,
            &s.col1,
            &s.da1,
            layer_grad(&mut grad, &layers[L_CONV1]),
            None,
        ),
    }
}

/// The (weight, bias) gradient slices of `layer`, when parameter gradients are wanted.
fn layer_grad<'a>(
    grad: &'a mut Option<&mut [f32]>,
    layer: &Layer,
) -> Option<(&'a mut [f32], &'a mut [f32])> {
    grad.as_deref_mut()
        .map(|g| g[layer.offset..layer.offset + layer.len()].split_at_mut(layer.weight_len))
}

// ---------------------------------------------------------------------------------------
// Layer kernels. Written as contiguous-slice loops the compiler vectorises.

/// Dot product with 8 independent accumulators: f32 sums are not reassociated by the
/// compiler, so one accumulator would run serially; 8 lanes vectorise (and the order is
/// fixed, so results are reproducible).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    debug_assert_eq!(a.len(), b.len());
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for j in 0..8 {
            acc[j] += x[j] * y[j];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

#[inline]
fn sum(a: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let c = a.chunks_exact(8);
    let tail: f32 = c.remainder().iter().sum();
    for x in c {
        for j in 0..8 {
            acc[j] += x[j];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// `y += a·x`.
#[inline]
fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

fn relu(v: &mut [f32]) {
    for x in v {
        *x = if *x > 0.0 { *x } else { 0.0 };
    }
}

/// Zeroes the gradient where the ReLU output was 0 (derivative 0 at the kink).
fn relu_mask(d: &mut [f32], y: &[f32]) {
    for (di, yi) in d.iter_mut().zip(y) {
        if *yi <= 0.0 {
            *di = 0.0;
        }
    }
}

/// The guided-back-propagation ReLU rule: the gradient `d` passes where the ReLU output
/// `y` was positive and `d` itself is positive; everywhere else it becomes 0.
pub fn guided_relu_mask(d: &mut [f32], y: &[f32]) {
    debug_assert_eq!(d.len(), y.len());
    for (di, yi) in d.iter_mut().zip(y) {
        if *yi <= 0.0 || *di <= 0.0 {
            *di = 0.0;
        }
    }
}

/// `y = W·x + b` with `W` `[out][in]`.
fn linear(w: &[f32], b: &[f32], x: &[f32], y: &mut [f32]) {
    let n = x.len();
    for (o, yo) in y.iter_mut().enumerate() {
        *yo = b[o] + dot(&w[o * n..(o + 1) * n], x);
    }
}

/// Backward of `y = W·x + b` given `dy`: `dW += dy·xᵀ`, `db += dy`, `dx += Wᵀ·dy`.
/// Rows with `dy = 0` (dead ReLUs) are skipped.
fn linear_backward(
    w: &[f32],
    x: &[f32],
    dy: &[f32],
    dwb: Option<(&mut [f32], &mut [f32])>,
    dx: Option<&mut [f32]>,
) {
    let n = x.len();
    if let Some((dw, db)) = dwb {
        for (o, &g) in dy.iter().enumerate() {
            if g != 0.0 {
                db[o] += g;
                axpy(&mut dw[o * n..(o + 1) * n], g, x);
            }
        }
    }
    if let Some(dx) = dx {
        for (o, &g) in dy.iter().enumerate() {
            if g != 0.0 {
                axpy(dx, g, &w[o * n..(o + 1) * n]);
            }
        }
    }
}

/// Unfolds a `cin × size_in²` map into the `[cin·9][size_out²]` patch matrix of a 3×3,
/// stride 2, pad 1 convolution; row `(c·3 + ky)·3 + kx` matches the weight layout.
fn im2col(cin: usize, size_in: usize, size_out: usize, input: &[f32], col: &mut [f32]) {
    let p = size_out * size_out;
    for c in 0..cin {
        let plane = &input[c * size_in * size_in..(c + 1) * size_in * size_in];
        for ky in 0..CONV_KERNEL {
            for kx in 0..CONV_KERNEL {
                let r = (c * CONV_KERNEL + ky) * CONV_KERNEL + kx;
                let row = &mut col[r * p..(r + 1) * p];
                for oy in 0..size_out {
                    let dst = &mut row[oy * size_out..(oy + 1) * size_out];
                    let iy = (oy * CONV_STRIDE + ky).wrapping_sub(CONV_PAD);
                    if iy >= size_in {
                        dst.fill(0.0);
                        continue;
                    }
                    let src = &plane[iy * size_in..(iy + 1) * size_in];
                    for (ox, d) in dst.iter_mut().enumerate() {
                        let ix = (ox * CONV_STRIDE + kx).wrapping_sub(CONV_PAD);
                        *d = if ix < size_in { src[ix] } else { 0.0 };
                    }
                }
            }
        }
    }
}

/// Adjoint of [`im2col`]: scatters patch-matrix gradients back onto the input map (`+=`).
fn col2im_add(cin: usize, size_in: usize, size_out: usize, col: &[f32], dinput: &mut [f32]) {
    let p = size_out * size_out;
    for c in 0..cin {
        let plane = &mut dinput[c * size_in * size_in..(c + 1) * size_in * size_in];
        for ky in 0..CONV_KERNEL {
            for kx in 0..CONV_KERNEL {
                let r = (c * CONV_KERNEL + ky) * CONV_KERNEL + kx;
                let row = &col[r * p..(r + 1) * p];
                for oy in 0..size_out {
                    let iy = (oy * CONV_STRIDE + ky).wrapping_sub(CONV_PAD);
                    if iy >= size_in {
                        continue;
                    }
                    let src = &row[oy * size_out..(oy + 1) * size_out];
                    let dst = &mut plane[iy * size_in..(iy + 1) * size_in];
                    for (ox, g) in src.iter().enumerate() {
                        let ix = (ox * CONV_STRIDE + kx).wrapping_sub(CONV_PAD);
                        if ix < size_in {
                            dst[ix] += g;
                        }
                    }
                }
            }
        }
    }
}

/// `out[o] = b[o] + Σ_r W[o][r]·col[r]`: the convolution as a small matmul. Row-outer so each
/// patch row is read once and the few output rows stay in L1.
fn conv_forward(w: &[f32], b: &[f32], col: &[f32], out: &mut [f32]) {
    let cout = b.len();
    let p = out.len() / cout;
    let rows = w.len() / cout;
    for (o, ob) in out.chunks_exact_mut(p).enumerate() {
        ob.fill(b[o]);
    }
    for r in 0..rows {
        let cr = &col[r * p..(r + 1) * p];
        for (o, ob) in out.chunks_exact_mut(p).enumerate() {
            axpy(ob, w[o * rows + r], cr);
        }
    }
}

/// Backward of [`conv_forward`] for `cout` output channels: `dW[o][r] += dout[o]·col[r]`,
/// `db[o] += Σ dout[o]`, and `dcol[r] = Σ_o W[o][r]·dout[o]` when wanted (overwritten).
fn conv_backward(
    cout: usize,
    w: &[f32],
    col: &[f32],
    dout: &[f32],
    dwb: Option<(&mut [f32], &mut [f32])>,
    dcol: Option<&mut [f32]>,
) {
    let rows = w.len() / cout;
    let p = dout.len() / cout;
    if let Some((dw, db)) = dwb {
        for (o, d) in dout.chunks_exact(p).enumerate() {
            db[o] += sum(d);
            let dwo = &mut dw[o * rows..(o + 1) * rows];
            for (r, g) in dwo.iter_mut().enumerate() {
                *g += dot(d, &col[r * p..(r + 1) * p]);
            }
        }
    }
    if let Some(dcol) = dcol {
        for (r, dc) in dcol.chunks_exact_mut(p).enumerate() {
            dc.fill(0.0);
            for (o, d) in dout.chunks_exact(p).enumerate() {
                let wv = w[o * rows + r];
                if wv != 0.0 {
                    axpy(dc, wv, d);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: NetShape = NetShape {
        rot_bins: 2,
        side: 5,
    };
    const REAL: NetShape = NetShape {
        rot_bins: 10,
        side: 108,
    };

    /// A network with every parameter (biases and the actor head included) at a healthy
    /// random scale, so every layer has gradient and the ReLUs are a mix of on and off.
    fn lively_net(shape: NetShape, seed: u64) -> PolicyNet {
        let mut net = PolicyNet::new(shape, seed);
        let mut rng = Pcg64::seed_from_u64(seed ^ 0xabcd);
        for layer in shape.layers() {
            let bound = (6.0 / layer.fan_in() as f32).sqrt();
            for w in &mut net.params[layer.weights()] {
                *w = rng.gen_range(-bound..bound);
            }
            for b in &mut net.params[layer.bias()] {
                *b = rng.gen_range(-0.1..0.1);
            }
        }
        net
    }

    fn random_inputs(shape: NetShape, b: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut rng = Pcg64::seed_from_u64(seed);
        let belief = (0..b * shape.belief_len())
            .map(|_| rng.gen::<f32>())
            .collect();
        let side = (0..b * shape.side)
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        (belief, side)
    }

    fn random_vec(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = Pcg64::seed_from_u64(seed);
        (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
    }

    /// Independent f64 reference: direct (not im2col) convolution straight from the
    /// documented parameter layout.
    /// f64 reference of a fully-connected layer (with its ReLU when it has one).
    fn ref_linear(layer: &Layer, p: &[f64], x: &[f64]) -> Vec<f64> {
        let (w, b) = (&p[layer.weights()], &p[layer.bias()]);
        (0..layer.bias_len)
            .map(|o| {
                let s = b[o] + (0..x.len()).map(|i| w[o * x.len() + i] * x[i]).sum::<f64>();
                if layer.relu {
                    s.max(0.0)
                } else {
                    s
                }
            })
            .collect()
    }

    fn reference(shape: &NetShape, p: &[f64], belief: &[f64], side: &[f64]) -> ([f64; 3], f64) {
        let layers = shape.layers();
        let conv = |layer: &Layer, input: &[f64]| {
            let LayerKind::Conv {
                in_ch,
                out_ch,
                in_size,
                out_size,
            } = layer.kind
            else {
                panic!("not a conv")
            };
            let (w, b) = (&p[layer.weights()], &p[layer.bias()]);
            let mut out = vec![0.0; out_ch * out_size * out_size];
            for o in 0..out_ch {
                for oy in 0..out_size {
                    for ox in 0..out_size {
                        let mut s = b[o];
                        for c in 0..in_ch {
                            for ky in 0..3 {
                                for kx in 0..3 {
                                    let iy = (2 * oy + ky) as isize - 1;
                                    let ix = (2 * ox + kx) as isize - 1;
                                    if iy < 0
                                        || ix < 0
                                        || iy >= in_size as isize
                                        || ix >= in_size as isize
                                    {
                                        continue;
                                    }
                                    let (iy, ix) = (iy as usize, ix as usize);
                                    s += w[((o * in_ch + c) * 3 + ky) * 3 + kx]
                                        * input[(c * in_size + iy) * in_size + ix];
                                }
                            }
                        }
                        out[(o * out_size + oy) * out_size + ox] = s.max(0.0);
                    }
                }
            }
            out
        };
        let lin = |layer: &Layer, x: &[f64]| ref_linear(layer, p, x);
        let a1 = conv(&layers[0], belief);
        let a2 = conv(&layers[1], &a1);
        let mut cat = lin(&layers[2], &a2);
        cat.extend(lin(&layers[3], side));
        let hj = lin(&layers[4], &cat);
        let l = lin(&layers[5], &hj);
        let v = lin(&layers[6], &hj);
        ([l[0], l[1], l[2]], v[0])
    }

    fn to64(v: &[f32]) -> Vec<f64> {
        v.iter().map(|&x| f64::from(x)).collect()
    }

    #[test]
    fn layout_sizes_and_macs() {
        let k1 = NetShape {
            rot_bins: 1,
            side: 108,
        };
        assert_eq!(k1.param_count(), 14_296);
        assert_eq!(REAL.param_count(), 14_944);
        assert_eq!(k1.macs(), 48_456);
        assert_eq!(REAL.macs(), 194_256);
        let names: Vec<_> = REAL.layers().iter().map(|l| l.name).collect();
        assert_eq!(
            names,
            [
                "conv1",
                "conv2",
                "fc_belief",
                "fc_side",
                "fc_joint",
                "actor",
                "critic"
            ]
        );
        let mut next = 0;
        for l in REAL.layers() {
            assert_eq!(l.offset, next, "{} not contiguous", l.name);
            next = l.bias().end;
        }
        assert_eq!(next, REAL.param_count());
    }

    #[test]
    fn same_seed_same_params_other_seed_other_params() {
        let a = PolicyNet::new(REAL, 7);
        let b = PolicyNet::new(REAL, 7);
        let c = PolicyNet::new(REAL, 8);
        assert_eq!(a.params, b.params);
        assert_ne!(a.params, c.params);
        // Biases start at 0, the actor head small, the critic head not.
        let layers = REAL.layers();
        assert!(layers
            .iter()
            .all(|l| a.params[l.bias()].iter().all(|&x| x == 0.0)));
        let max_abs = |l: &Layer| {
            a.params[l.weights()]
                .iter()
                .fold(0.0f32, |m, x| m.max(x.abs()))
        };
        assert!(max_abs(&layers[L_ACTOR]) < 0.01 * (3.0f32 / HIDDEN as f32).sqrt());
        assert!(max_abs(&layers[L_CRITIC]) > 0.1);
    }

    #[test]
    fn forward_matches_f64_reference() {
        let net = lively_net(SMALL, 3);
        let (belief, side) = random_inputs(SMALL, 1, 4);
        let out = net.forward(&belief, &side);
        let (l, v) = reference(&SMALL, &to64(&net.params), &to64(&belief), &to64(&side));
        for (a, b) in out
            .logits
            .iter()
            .chain([&out.value])
            .zip(l.iter().chain([&v]))
        {
            assert!(
                (f64::from(*a) - b).abs() <= 1e-4 * (1.0 + b.abs()),
                "{a} vs {b}"
            );
        }
        assert!(
            l.iter().any(|x| x.abs() > 1e-2),
            "degenerate test network: {l:?}"
        );
    }

    #[test]
    fn single_forward_equals_batch_rows_bitwise() {
        let net = lively_net(REAL, 5);
        let b = 11; // not a multiple of GRAD_CHUNK
        let (belief, side) = random_inputs(REAL, b, 6);
        let (logits, values) = net.forward_batch(&belief, &side, b, &mut BatchCache::new());
        let mut s = Scratch::new(REAL);
        let (bl, sl) = (REAL.belief_len(), REAL.side);
        for i in 0..b {
            let one = net.forward_with(
                &belief[i * bl..(i + 1) * bl],
                &side[i * sl..(i + 1) * sl],
                &mut s,
            );
            assert_eq!(
                one.logits.map(f32::to_bits),
                logits[i].map(f32::to_bits),
                "row {i}"
            );
            assert_eq!(one.value.to_bits(), values[i].to_bits(), "row {i}");
        }
    }

    /// Analytic gradients of `L = Σ_samples Σ_i c_i·logit_i + d·value` against central
    /// differences of the independent f64 reference, for weights and biases of every layer.
    /// An entry is skipped only if its finite difference is inconsistent at two step sizes
    /// (a ReLU kink between them); skips must stay rare.
    #[test]
    fn parameter_gradients_match_finite_differences() {
        let shape = SMALL;
        let b = 3;
        let net = lively_net(shape, 11);
        let (belief, side) = random_inputs(shape, b, 12);
        let c = random_vec(b * N_ACTIONS, 13);
        let d = random_vec(b, 14);

        let mut cache = BatchCache::new();
        net.forward_batch(&belief, &side, b, &mut cache);
        let mut grad = vec![0.0; shape.param_count()];
        net.backward_batch(&mut cache, &c, &d, &mut grad);

        let (bl, sl) = (shape.belief_len(), shape.side);
        let (bel64, side64) = (to64(&belief), to64(&side));
        let loss = |p: &[f64]| {
            (0..b)
                .map(|i| {
                    let (l, v) = reference(
                        &shape,
                        p,
                        &bel64[i * bl..(i + 1) * bl],
                        &side64[i * sl..(i + 1) * sl],
                    );
                    (0..3).map(|a| f64::from(c[i * 3 + a]) * l[a]).sum::<f64>()
                        + f64::from(d[i]) * v
                })
                .sum::<f64>()
        };
        let mut p = to64(&net.params);
        let mut fd = |j: usize, eps: f64| {
            let orig = p[j];
            p[j] = orig + eps;
            let up = loss(&p);
            p[j] = orig - eps;
            let down = loss(&p);
            p[j] = orig;
            (up - down) / (2.0 * eps)
        };

        let mut rng = Pcg64::seed_from_u64(15);
        let (mut checked, mut skipped) = (0, 0);
        for layer in shape.layers() {
            for (range, n) in [(layer.weights(), 12), (layer.bias(), 6)] {
                let mut nonzero = 0;
                // Half uniformly at random, half among entries with a nonzero analytic
                // gradient (dead ReLUs zero many weight gradients; both kinds are checked).
                let live: Vec<usize> = range.clone().filter(|&j| grad[j] != 0.0).collect();
                let picks: Vec<usize> = if range.len() <= n {
                    range.clone().collect()
                } else {
                    let mut v: Vec<usize> =
                        (0..n / 2).map(|_| rng.gen_range(range.clone())).collect();
                    v.extend(
                        (0..n / 2).filter_map(|_| live.get(rng.gen_range(0..live.len().max(1)))),
                    );
                    v
                };
                for &j in &picks {
                    let (n1, n2) = (fd(j, 1e-4), fd(j, 3e-5));
                    if (n1 - n2).abs() > 1e-6 * (1.0 + n1.abs()) {
                        skipped += 1;
                        continue;
                    }
                    checked += 1;
                    let a = f64::from(grad[j]);
                    assert!(
                        (a - n1).abs() <= 1e-4 + 2e-3 * n1.abs(),
                        "{} param {j}: analytic {a}, numeric {n1}",
                        layer.name
                    );
                    if n1.abs() > 1e-4 {
                        nonzero += 1;
                    }
                }
                assert!(
                    nonzero * 2 >= picks.len(),
                    "{}: gradient check nearly vacuous",
                    layer.name
                );
            }
        }
        assert!(
            skipped * 10 <= checked,
            "{skipped} kinks vs {checked} checked"
        );
    }

    #[test]
    fn guided_relu_mask_hand_set_masks() {
        // Output y > 0 and gradient d > 0: passes; any other combination: blocked. Plain
        // ReLU backprop (relu_mask) passes the negative gradient of an active unit.
        let y = [1.0f32, 1.0, 0.0, 0.0, 2.5, 0.0];
        let d = [0.5f32, -0.5, 0.5, -0.5, 3.0, 0.0];
        let mut g = d;
        guided_relu_mask(&mut g, &y);
        assert_eq!(g, [0.5, 0.0, 0.0, 0.0, 3.0, 0.0]);
        let mut p = d;
        relu_mask(&mut p, &y);
        assert_eq!(p, [0.5, -0.5, 0.0, 0.0, 3.0, 0.0]);
    }

    /// A network with a handful of nonzero weights, small enough to back-propagate by hand:
    ///
    /// ```text
    /// conv1: a1₀(y,x) = relu(b(2y,2x)),  a1₁(y,x) = relu(2·b(2y,2x))   (kernel centres 1, 2)
    /// conv2: a2₀(y,x) = relu(a1₀(2y,2x)), a2₁(y,x) = relu(a1₁(2y,2x))  (so a2ᵢ(y,x) ∝ b(4y,4x))
    /// fc_belief: hb₀ = relu(a2₀(0,1) + a2₁(0,2)) = b(0,4) + 2·b(0,8),  hb₁ = relu(a2₀(0,1)) = b(0,4)
    /// fc_side:   hs₀ = relu(side₀),  hs₁ = relu(side₁)
    /// fc_joint:  hj₀ = relu(hb₀ + hs₀),  hj₁ = relu(hb₁ + hs₁)
    /// actor:     logit₂ (measure) = hj₀ − hj₁,  logit₀ = hj₁;  critic: v = hj₀
    /// ```
    ///
    /// With b(0,4) = 0.5, b(0,8) = 0.25, side = (1, −1): hb = (1, 0.5), hs = (1, 0),
    /// hj = (2, 0.5), logit₂ = 1.5. For the measure logit the gradient at hj is (1, −1):
    /// plain backprop carries the −1 down hj₁ → hb₁ → b(0,4), where it cancels the +1 from
    /// hb₀, so ∂logit₂/∂b(0,4) = 0 and ∂/∂b(0,8) = 2; guided backprop stops the −1 at hj₁,
    /// so its map is b(0,4): 1, b(0,8): 2, and side: (1, 0) (hs₁ is off in both).
    fn hand_net() -> PolicyNet {
        let shape = NetShape {
            rot_bins: 1,
            side: 2,
        };
        let mut p = vec![0.0f32; shape.param_count()];
        let l = shape.layers();
        let centre = 4; // [ky=1][kx=1]
                        // conv1 weights [out][in=1][3][3]
        p[l[L_CONV1].offset + centre] = 1.0;
        p[l[L_CONV1].offset + KK + centre] = 2.0;
        // conv2 weights [out][in=8][3][3]: out 0 ← in 0, out 1 ← in 1
        p[l[L_CONV2].offset + centre] = 1.0;
        p[l[L_CONV2].offset + (C1 + 1) * KK + centre] = 1.0;
        // fc_belief [32][256]; a2 flat index = c·64 + y·8 + x
        let fb = l[L_BELIEF].offset;
        p[fb + 1] = 1.0; // hb0 ← a2₀(0,1)
        p[fb + 64 + 2] = 1.0; // hb0 ← a2₁(0,2)
        p[fb + FLAT + 1] = 1.0; // hb1 ← a2₀(0,1)
                                // fc_side [32][2]
        let fs = l[L_SIDE].offset;
        p[fs] = 1.0;
        p[fs + 2 + 1] = 1.0;
        // fc_joint [32][64]: input = hb (0..32) | hs (32..64)
        let fj = l[L_JOINT].offset;
        p[fj] = 1.0;
        p[fj + HIDDEN] = 1.0;
        p[fj + 64 + 1] = 1.0;
        p[fj + 64 + HIDDEN + 1] = 1.0;
        // actor [3][32], critic [1][32]
        let fa = l[L_ACTOR].offset;
        p[fa + 2 * HIDDEN] = 1.0;
        p[fa + 2 * HIDDEN + 1] = -1.0;
        p[fa + 1] = 1.0;
        p[l[L_CRITIC].offset] = 1.0;
        PolicyNet::from_params(shape, p).unwrap()
    }

    #[test]
    fn guided_backprop_hand_computed_tiny_net() {
        let net = hand_net();
        let mut belief = vec![0.0f32; GRID * GRID];
        belief[4] = 0.5; // b(0,4)
        belief[8] = 0.25; // b(0,8)
        let side = [1.0f32, -1.0];
        let out = net.forward(&belief, &side);
        assert_eq!(out.logits, [0.5, 0.0, 1.5]);
        assert_eq!(out.value, 2.0);

        let (gb, gs) = net.guided_backprop(&belief, &side, 2);
        let mut want = vec![0.0f32; GRID * GRID];
        want[4] = 1.0;
        want[8] = 2.0;
        assert_eq!(gb, want, "guided map over the belief");
        assert_eq!(gs, [1.0, 0.0], "guided map over the side features");

        // Plain backprop of the same logit: the −1 through hj₁ cancels at b(0,4).
        let (pb, ps) = net.input_gradient(&belief, &side, [0.0, 0.0, 1.0], 0.0);
        let mut plain = vec![0.0f32; GRID * GRID];
        plain[8] = 2.0;
        assert_eq!(pb, plain);
        assert_eq!(ps, [1.0, 0.0]);

        // The rotate-left logit (= hj₁): only positive gradients on its path, so guided
        // and plain agree, b(0,4): 1, side: (0, 0) since hs₁ is off.
        let (gb0, gs0) = net.guided_backprop(&belief, &side, 0);
        let mut want0 = vec![0.0f32; GRID * GRID];
        want0[4] = 1.0;
        assert_eq!(gb0, want0);
        assert_eq!(gs0, [0.0, 0.0]);
        // rotate-right's logit is constant 0: nothing lights up.
        let (gb1, gs1) = net.guided_backprop(&belief, &side, 1);
        assert!(gb1.iter().chain(&gs1).all(|&g| g == 0.0));
    }

    /// Independent f64 guided back-propagation: direct convolutions (no im2col), the
    /// transposed convolution written out, the guided rule applied at every ReLU.
    fn reference_guided(
        shape: &NetShape,
        p: &[f64],
        belief: &[f64],
        side: &[f64],
        action: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let layers = shape.layers();
        let dims = |l: &Layer| match l.kind {
            LayerKind::Conv {
                in_ch,
                out_ch,
                in_size,
                out_size,
            } => (in_ch, out_ch, in_size, out_size),
            _ => panic!("not a conv"),
        };
        // Calls f(o, c, out_index, in_index, weight) for every tap inside the input.
        let taps = |l: &Layer, f: &mut dyn FnMut(usize, usize, f64)| {
            let (in_ch, out_ch, in_size, out_size) = dims(l);
            let w = &p[l.weights()];
            for o in 0..out_ch {
                for oy in 0..out_size {
                    for ox in 0..out_size {
                        for c in 0..in_ch {
                            for ky in 0..3 {
                                for kx in 0..3 {
                                    let iy = (2 * oy + ky) as isize - 1;
                                    let ix = (2 * ox + kx) as isize - 1;
                                    if iy < 0
                                        || ix < 0
                                        || iy >= in_size as isize
                                        || ix >= in_size as isize
                                    {
                                        continue;
                                    }
                                    let oi = (o * out_size + oy) * out_size + ox;
                                    let ii = (c * in_size + iy as usize) * in_size + ix as usize;
                                    f(oi, ii, w[((o * in_ch + c) * 3 + ky) * 3 + kx]);
                                }
                            }
                        }
                    }
                }
            }
        };
        let conv = |l: &Layer, x: &[f64]| {
            let (_, out_ch, _, out_size) = dims(l);
            let b = &p[l.bias()];
            let per = out_size * out_size;
            let mut y: Vec<f64> = (0..out_ch * per).map(|i| b[i / per]).collect();
            taps(l, &mut |oi, ii, w| y[oi] += w * x[ii]);
            y.iter().map(|v| v.max(0.0)).collect::<Vec<f64>>()
        };
        let conv_back = |l: &Layer, dy: &[f64], n_in: usize| {
            let mut dx = vec![0.0; n_in];
            taps(l, &mut |oi, ii, w| dx[ii] += w * dy[oi]);
            dx
        };
        let lin = |l: &Layer, x: &[f64]| ref_linear(l, p, x);
        let lin_back = |l: &Layer, dy: &[f64], n_in: usize| {
            let w = &p[l.weights()];
            (0..n_in)
                .map(|i| (0..dy.len()).map(|o| w[o * n_in + i] * dy[o]).sum::<f64>())
                .collect::<Vec<f64>>()
        };
        let guide = |d: Vec<f64>, y: &[f64]| {
            d.iter()
                .zip(y)
                .map(|(&d, &y)| if y > 0.0 && d > 0.0 { d } else { 0.0 })
                .collect::<Vec<f64>>()
        };
        let a1 = conv(&layers[L_CONV1], belief);
        let a2 = conv(&layers[L_CONV2], &a1);
        let hb = lin(&layers[L_BELIEF], &a2);
        let hs = lin(&layers[L_SIDE], side);
        let cat: Vec<f64> = hb.iter().chain(&hs).copied().collect();
        let hj = lin(&layers[L_JOINT], &cat);
        let mut dl = [0.0; 3];
        dl[action] = 1.0;
        let dhj = guide(lin_back(&layers[L_ACTOR], &dl, HIDDEN), &hj);
        let dcat = guide(lin_back(&layers[L_JOINT], &dhj, 2 * HIDDEN), &cat);
        let dside = lin_back(&layers[L_SIDE], &dcat[HIDDEN..], side.len());
        let da2 = guide(lin_back(&layers[L_BELIEF], &dcat[..HIDDEN], FLAT), &a2);
        let da1 = guide(conv_back(&layers[L_CONV2], &da2, A1), &a1);
        let dbelief = conv_back(&layers[L_CONV1], &da1, belief.len());
        (dbelief, dside)
    }

    #[test]
    fn guided_backprop_matches_f64_reference_on_the_real_shape() {
        let net = lively_net(REAL, 61);
        let (belief, side) = random_inputs(REAL, 1, 62);
        let p = to64(&net.params);
        for action in 0..N_ACTIONS {
            let (gb, gs) = net.guided_backprop(&belief, &side, action);
            let (rb, rs) = reference_guided(&REAL, &p, &to64(&belief), &to64(&side), action);
            let scale = rb.iter().chain(&rs).fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(scale > 1e-3, "degenerate guided map for action {action}");
            for (i, (a, r)) in gb.iter().zip(&rb).chain(gs.iter().zip(&rs)).enumerate() {
                assert!(
                    (f64::from(*a) - r).abs() <= 1e-4 * scale,
                    "action {action} input {i}: {a} vs {r}"
                );
            }
            // Guided is not plain backprop here: some negative gradient was stopped.
            let (pb, _) = net.input_gradient(&belief, &side, dl_onehot(action), 0.0);
            let differ = gb
                .iter()
                .zip(&pb)
                .filter(|(g, p)| (*g - *p).abs() > 1e-6)
                .count();
            assert!(
                differ > 100,
                "action {action}: guided equals plain on all but {differ}"
            );
        }
    }

    fn dl_onehot(action: usize) -> [f32; N_ACTIONS] {
        let mut d = [0.0; N_ACTIONS];
        d[action] = 1.0;
        d
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        let shape = SMALL;
        let net = lively_net(shape, 21);
        let (belief, side) = random_inputs(shape, 1, 22);
        let c = [0.7f32, -1.3, 0.4];
        let d = -0.8f32;
        let (gb, gs) = net.input_gradient(&belief, &side, c, d);
        let p = to64(&net.params);
        let loss = |bel: &[f64], sd: &[f64]| {
            let (l, v) = reference(&shape, &p, bel, sd);
            (0..3).map(|a| f64::from(c[a]) * l[a]).sum::<f64>() + f64::from(d) * v
        };
        let (mut bel, mut sd) = (to64(&belief), to64(&side));
        let eps = 1e-4;
        let mut rng = Pcg64::seed_from_u64(23);
        let mut nonzero = 0;
        for _ in 0..30 {
            let j = rng.gen_range(0..bel.len());
            let o = bel[j];
            bel[j] = o + eps;
            let up = loss(&bel, &sd);
            bel[j] = o - eps;
            let n = (up - loss(&bel, &sd)) / (2.0 * eps);
            bel[j] = o;
            let a = f64::from(gb[j]);
            assert!(
                (a - n).abs() <= 1e-4 + 2e-3 * n.abs(),
                "belief {j}: {a} vs {n}"
            );
            nonzero += usize::from(n.abs() > 1e-4);
        }
        assert!(nonzero >= 10, "belief gradient check nearly vacuous");
        for j in 0..sd.len() {
            let o = sd[j];
            sd[j] = o + eps;
            let up = loss(&bel, &sd);
            sd[j] = o - eps;
            let n = (up - loss(&bel, &sd)) / (2.0 * eps);
            sd[j] = o;
            let a = f64::from(gs[j]);
            assert!(
                (a - n).abs() <= 1e-4 + 2e-3 * n.abs(),
                "side {j}: {a} vs {n}"
            );
        }
    }

    fn grad_in_pool(
        threads: usize,
        net: &PolicyNet,
        belief: &[f32],
        side: &[f32],
        b: usize,
    ) -> Vec<u32> {
        let dl = random_vec(b * N_ACTIONS, 31);
        let dv = random_vec(b, 32);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut cache = BatchCache::new();
            net.forward_batch(belief, side, b, &mut cache);
            let mut grad = vec![0.0; net.shape.param_count()];
            net.backward_batch(&mut cache, &dl, &dv, &mut grad);
            grad.iter().map(|g| g.to_bits()).collect()
        })
    }

    #[test]
    fn gradients_are_bit_identical_for_any_thread_count() {
        let net = lively_net(REAL, 41);
        let b = 37;
        let (belief, side) = random_inputs(REAL, b, 42);
        let one = grad_in_pool(1, &net, &belief, &side, b);
        let three = grad_in_pool(3, &net, &belief, &side, b);
        let two = grad_in_pool(2, &net, &belief, &side, b);
        assert!(one.iter().any(|&g| g != 0));
        assert!(one == three, "1 vs 3 threads differ");
        assert!(one == two, "1 vs 2 threads differ");
    }

    #[test]
    fn backward_adds_to_grad() {
        let net = lively_net(SMALL, 51);
        let b = 2;
        let (belief, side) = random_inputs(SMALL, b, 52);
        let (dl, dv) = (random_vec(b * 3, 53), random_vec(b, 54));
        let mut cache = BatchCache::new();
        net.forward_batch(&belief, &side, b, &mut cache);
        let mut once = vec![0.0; SMALL.param_count()];
        net.backward_batch(&mut cache, &dl, &dv, &mut once);
        let mut twice = once.clone();
        net.backward_batch(&mut cache, &dl, &dv, &mut twice);
        for (o, t) in once.iter().zip(&twice) {
            assert_eq!(2.0 * o, *t);
        }
    }

    #[test]
    fn loss_helpers() {
        let z = [0.0f32; 3];
        assert!((entropy(&z) - 3f32.ln()).abs() < 1e-6);
        assert!((softmax(&[1.0, 2.0, 3.0]).iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let big = log_softmax(&[1000.0, 0.0, -1000.0]);
        assert!(big.iter().all(|x| !x.is_nan()) && big[0].abs() < 1e-6);
        // Analytic logit gradients against central differences.
        let l = [0.3f32, -0.8, 1.1];
        let eps = 1e-3;
        let (ge, gl) = (entropy_grad(&l), log_prob_grad(&l, 1));
        for k in 0..3 {
            let (mut up, mut down) = (l, l);
            up[k] += eps;
            down[k] -= eps;
            let ne = (entropy(&up) - entropy(&down)) / (2.0 * eps);
            let nl = (log_softmax(&up)[1] - log_softmax(&down)[1]) / (2.0 * eps);
            assert!(
                (ge[k] - ne).abs() < 1e-3,
                "entropy grad {k}: {} vs {ne}",
                ge[k]
            );
            assert!(
                (gl[k] - nl).abs() < 1e-3,
                "log-prob grad {k}: {} vs {nl}",
                gl[k]
            );
        }
    }

    #[test]
    fn adam_and_clipping() {
        // First Adam step moves each parameter by about lr against its gradient's sign
        // (bias correction makes m̂/√v̂ = ±1), and not at all for a zero gradient.
        let mut p = vec![1.0f32, 1.0, 1.0];
        let mut adam = Adam::new(3, 0.01);
        adam.step(&mut p, &[0.5, -2.0, 0.0]);
        assert!(
            (p[0] - 0.99).abs() < 1e-4 && (p[1] - 1.01).abs() < 1e-4 && p[2] == 1.0,
            "{p:?}"
        );
        assert_eq!(adam.t, 1);

        let mut g = vec![3.0f32, 4.0];
        assert_eq!(clip_global_norm(&mut g, 1.0), 5.0);
        assert!((g[0].hypot(g[1]) - 1.0).abs() < 1e-5);
        let mut small = vec![0.3f32, 0.4];
        assert!((clip_global_norm(&mut small, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(small, [0.3, 0.4]);
    }

    /// Timings for the report: `cargo test --release --lib learn::net::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing() {
        use std::time::Instant;
        for k in [1, 10] {
            let shape = NetShape {
                rot_bins: k,
                side: 108,
            };
            let net = PolicyNet::new(shape, 1);
            let (belief, side) = random_inputs(shape, 1, 2);
            let mut s = Scratch::new(shape);
            let mut acc = 0.0;
            for _ in 0..200 {
                acc += net.forward_with(&belief, &side, &mut s).value;
            }
            let n = 5000;
            let t = Instant::now();
            for _ in 0..n {
                acc += net.forward_with(&belief, &side, &mut s).value;
            }
            let us = t.elapsed().as_secs_f64() * 1e6 / n as f64;
            println!("batch-1 forward K={k}: {us:.1} us ({acc:.1})");
        }
        let b = 256;
        let net = lively_net(REAL, 3);
        let (belief, side) = random_inputs(REAL, b, 4);
        let (dl, dv) = (random_vec(b * 3, 5), random_vec(b, 6));
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut cache = BatchCache::new();
                let mut grad = vec![0.0; REAL.param_count()];
                let reps = 10;
                let (mut tf, mut tb) = (0.0, 0.0);
                for rep in 0..reps + 2 {
                    let t = Instant::now();
                    net.forward_batch(&belief, &side, b, &mut cache);
                    let t1 = Instant::now();
                    net.backward_batch(&mut cache, &dl, &dv, &mut grad);
                    if rep >= 2 {
                        tf += (t1 - t).as_secs_f64();
                        tb += t1.elapsed().as_secs_f64();
                    }
                }
                let ms = |x: f64| x * 1e3 / reps as f64;
                println!(
                    "batch-256 K=10, {threads} thread(s): forward {:.1} ms + backward {:.1} ms = {:.1} ms",
                    ms(tf),
                    ms(tb),
                    ms(tf + tb)
                );
            });
        }
    }
}
