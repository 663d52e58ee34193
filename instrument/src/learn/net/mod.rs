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
//!
//! **Files.** This one: the architecture's constants; `layout.rs`: [`NetShape`] and the
//! [`Layer`] table (where each layer's parameters sit); `network.rs`: [`PolicyNet`]
//! (initialisation, single and batched forward, backward, input gradients, guided
//! back-propagation, the per-layer [`Activations`] the int8 quantiser calibrates on) and its
//! buffers; `sample.rs`: the forward and backward of one sample, which every path runs;
//! `kernels.rs`: the layer kernels (dot products, im2col convolution, linear, ReLU);
//! `loss.rs`: the categorical's log-softmax, entropy and their gradients; `adam.rs`: Adam
//! and global-norm clipping; `tests.rs`: the f64 references and finite-difference checks.

mod adam;
mod kernels;
mod layout;
mod loss;
mod network;
mod sample;

use activesense_core::policy::int8;
pub use adam::{clip_global_norm, Adam};
pub use kernels::guided_relu_mask;
pub use layout::{Layer, LayerKind, NetShape};
pub use loss::{entropy, entropy_grad, log_prob_grad, log_softmax, softmax};
pub use network::{Activations, BatchCache, Output, PolicyNet, Scratch};

/// Architecture id written in policy files: the core's `conv8-4-fc32`, whose graph
/// ([`int8::layer_dims`]) this network's layers are derived from, so the float network the
/// host trains and the int8 one the instrument runs have one definition.
pub const ARCH_ID: u16 = int8::ARCH_CONV8_4_FC32;
/// Human-readable architecture name.
pub const ARCH_NAME: &str = "conv8-4-fc32";
/// Side of the square belief map (cells).
pub const GRID: usize = activesense_core::policy::BELIEF_SIDE;
/// Largest supported number of rotation bins `K` (belief planes).
pub const MAX_ROT_BINS: usize = activesense_core::limits::MAX_ROT_BINS;
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

/// The core's graph for this architecture (K = 1; K only changes conv1's inputs).
const GRAPH: [int8::LayerDims; N_LAYERS] = match int8::layer_dims(ARCH_ID, 1) {
    Some(g) => g,
    None => panic!("the core knows this architecture"),
};
const C1: usize = GRAPH[L_CONV1].outputs;
const C2: usize = GRAPH[L_CONV2].outputs;
const S1: usize = GRAPH[L_CONV1].out_size;
const S2: usize = GRAPH[L_CONV2].out_size;
const P0: usize = GRID * GRID;
const P1: usize = S1 * S1;
const P2: usize = S2 * S2;
const FLAT: usize = C2 * P2;
const HIDDEN: usize = GRAPH[L_BELIEF].outputs;
const KK: usize = CONV_KERNEL * CONV_KERNEL;

// One sample's kept activations (all post-ReLU), back to back: conv1 | conv2 | fc_belief |
// fc_side | fc_joint. fc_belief and fc_side are adjacent so they *are* the concat.
const A1: usize = C1 * P1;
const OFF_HB: usize = A1 + FLAT;
const OFF_HJ: usize = OFF_HB + 2 * HIDDEN;
const ACTS: usize = OFF_HJ + HIDDEN;

/// Index of each layer in [`NetShape::layers`].
const L_CONV1: usize = 0;
const L_CONV2: usize = 1;
const L_BELIEF: usize = 2;
const L_SIDE: usize = 3;
const L_JOINT: usize = 4;
const L_ACTOR: usize = 5;
const L_CRITIC: usize = 6;
/// Number of layers.
pub const N_LAYERS: usize = int8::N_LAYERS;

const _: () = assert!(GRAPH[L_BELIEF].inputs == FLAT && GRAPH[L_CONV1].in_size == GRID);
const _: () = assert!(GRAPH[L_ACTOR].outputs == N_ACTIONS && GRAPH[L_CRITIC].outputs == 1);

#[cfg(test)]
mod tests;
