//! [`PolicyNet`]: the flat parameters and every pass over them (initialisation, the single
//! and batched forward, the batched backward, input gradients and guided back-propagation),
//! the per-sample buffers ([`Scratch`]), what a batch keeps for its backward ([`BatchCache`])
//! and the per-layer [`Activations`] of one forward pass.

use super::sample::{backward_sample, forward_sample};
use super::{
    NetShape, A1, ACTS, C1, FLAT, GRAD_CHUNK, HIDDEN, KK, L_ACTOR, L_CRITIC, MAX_ROT_BINS,
    N_ACTIONS, P1, P2,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

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

    /// One decision with every layer's output: [`PolicyNet::forward_with`] itself (the same
    /// call, so `output` is bit-identical to it), then a view of the activations it kept in
    /// `scratch`. The int8 quantiser calibrates its activation ranges on these.
    pub fn forward_activations<'s>(
        &self,
        belief: &[f32],
        side: &[f32],
        scratch: &'s mut Scratch,
    ) -> Activations<'s> {
        let output = self.forward_with(belief, side, scratch);
        Activations::of(&scratch.acts, output)
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
        self.input_maps(belief, side, dlogits, dvalue, false)
    }

    /// Guided back-propagation (Springenberg et al. 2014) of the logit of `action` to the
    /// inputs, for one sample: the backward pass of `logits[action]` in which every ReLU
    /// passes the gradient only where its forward output was positive *and* the incoming
    /// gradient is positive ([`guided_relu_mask`](super::guided_relu_mask)). Returns the maps
    /// over the belief (`K·900`, layout of the input) and over the side features. The inputs
    /// themselves are not behind a ReLU, so the maps can hold negative values (a negative
    /// first-layer weight); the inspection tool shows their positive part. Allocates.
    pub fn guided_backprop(
        &self,
        belief: &[f32],
        side: &[f32],
        action: usize,
    ) -> (Vec<f32>, Vec<f32>) {
        assert!(action < N_ACTIONS, "action {action} out of range");
        let mut dlogits = [0.0; N_ACTIONS];
        dlogits[action] = 1.0;
        self.input_maps(belief, side, dlogits, 0.0, true)
    }

    /// One sample's forward, then its backward from the output gradients down to the
    /// inputs (no parameter gradient), plain or guided at the ReLUs.
    fn input_maps(
        &self,
        belief: &[f32],
        side: &[f32],
        dlogits: [f32; N_ACTIONS],
        dvalue: f32,
        guided: bool,
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
            guided,
        );
        (dbelief, dside)
    }

    fn check_inputs(&self, belief: &[f32], side: &[f32], b: usize) {
        assert_eq!(belief.len(), b * self.shape.belief_len(), "belief length");
        assert_eq!(side.len(), b * self.shape.side, "side length");
    }
}

/// Every tensor of one forward pass (the hidden layers after their ReLU), borrowed from the
/// [`Scratch`] that computed it: see [`PolicyNet::forward_activations`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Activations<'s> {
    /// conv1 output, `8 × 15 × 15`, `[c][y][x]`.
    pub conv1: &'s [f32],
    /// conv2 output, `4 × 8 × 8` (= fc_belief's input).
    pub conv2: &'s [f32],
    /// fc_belief output (first half of fc_joint's input).
    pub belief: &'s [f32],
    /// fc_side output (second half).
    pub side: &'s [f32],
    /// fc_joint output (the heads' input).
    pub joint: &'s [f32],
    /// The heads: logits and value.
    pub output: Output,
}

impl<'s> Activations<'s> {
    /// Splits one sample's kept activations, `conv1 | conv2 | fc_belief | fc_side | fc_joint`.
    fn of(acts: &'s [f32], output: Output) -> Self {
        let (conv1, rest) = acts.split_at(A1);
        let (conv2, rest) = rest.split_at(FLAT);
        let (belief, rest) = rest.split_at(HIDDEN);
        let (side, joint) = rest.split_at(HIDDEN);
        Activations {
            conv1,
            conv2,
            belief,
            side,
            joint,
            output,
        }
    }
}

/// Reusable per-sample buffers: activations, im2col matrices and backward temporaries.
#[derive(Clone, Debug)]
pub struct Scratch {
    pub(super) shape: NetShape,
    pub(super) acts: Vec<f32>,
    pub(super) col1: Vec<f32>,
    pub(super) col2: Vec<f32>,
    pub(super) dcol: Vec<f32>,
    pub(super) da1: Vec<f32>,
    pub(super) da2: Vec<f32>,
    pub(super) dhj: Vec<f32>,
    pub(super) dcat: Vec<f32>,
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
