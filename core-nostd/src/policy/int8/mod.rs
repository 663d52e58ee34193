//! The int8 policy (paper §3.1 on the instrument): integer-only inference of the
//! `conv8-16-fc64` actor-critic network from a quantised *policy blob*, following the
//! TFLite-Micro / CMSIS-NN conventions, so the Cortex-M4F chooses its actions without floats
//! in the network and without a heap.
//!
//! - **Blob** (`docs/policy-blob.md`): a versioned, little-endian, CRC-32-terminated byte
//!   string written by the host quantiser (`host-sim/src/learn/quantize.rs`).
//!   [`QuantizedPolicy::parse`] validates it once (magic, version, architecture, `K`,
//!   shapes, tensor table, quantisation parameters, every weight in `[-127, 127]`, CRC) and
//!   then reads the weights straight from the slice: a `static` blob in flash is used in
//!   place. No input bytes can make it panic; every defect is a typed [`BlobError`].
//! - **Arithmetic**: int8 activations (asymmetric, one zero point per tensor), int8 weights
//!   (symmetric per output channel), int32 accumulators and biases, requantisation by a Q31
//!   multiplier and a shift exactly as `arm_nn_requantize` / `MultiplyByQuantizedMultiplier`
//!   ([`multiply_by_quantized_multiplier`]), ReLU folded into the clamp. The two heads keep
//!   int32 outputs (one common scale per head), so the argmax of the actor is not blurred
//!   by an 8-bit grid.
//! - **The only float step** is the quantisation of the network inputs: the belief map is
//!   quantised as it is extracted ([`PolicyInput::write_belief_q`], no `K × 900` float
//!   buffer), the 108 side features through one small `f32` buffer on the stack
//!   ([`QuantizedPolicy::quantize_side`]). Both use [`quantize_value`].
//! - **Memory**: [`Scratch`] holds every activation for the largest `K` = 10 in
//!   [`SCRATCH_BYTES`] bytes (≈ 12 KiB); keep it in a `static` next to the blob.
//!
//! Embedding: `static BLOB: &[u8] = include_bytes!("policy.int8");` parsed at boot with
//! [`QuantizedPolicy::parse`], then a [`QuantizedAgent`] (it owns its [`Scratch`]) plays
//! behind the [`Policy`](crate::policy::Policy) seam like any baseline. The host runs this very code, so its
//! integer results are the reference for the device, bit for bit.
//!
//! This file holds the blob's layout (constants, layer dimensions, the validated view) and
//! the inference scratch; `parse` validates a blob, `infer` runs the network on the
//! [`Fast`] backend, [`kernels`] and `fast` are the layers, [`dot`] the inner products.

use crate::episode::Action;
pub use crate::episode::InstrumentProfile;

pub mod agent;
pub mod dot;
#[cfg(target_arch = "arm")]
#[allow(unsafe_code)]
pub mod dsp;
pub mod error;
mod fast;
mod infer;
pub mod kernels;
mod parse;
pub mod selftest;
pub mod write;

#[cfg(test)]
mod tests;

use crate::checksum::crc32;
use crate::localization::MAX_ROT_BINS;
use crate::policy::{PolicyInput, BELIEF_PLANE, BELIEF_SIDE, SIDE_FEATURES};
pub use agent::{QuantizedAgent, ScratchAgent};
use dot::Dot;
pub use error::BlobError;
pub use kernels::*;
pub use write::{blob_len, write_blob, LayerTensors};

/// First eight bytes of every blob.
pub const MAGIC: [u8; 8] = *b"ASQPOLCY";
/// The blob format version this code reads.
pub const FORMAT_VERSION: u16 = 1;
/// Architecture id of `conv8-16-fc64` (the float policy file's id too).
pub const ARCH_CONV8_16_FC64: u16 = 1;
/// Architecture id of `conv8-4-fc32` (the same graph, conv2 with 4 channels, 32 hidden).
pub const ARCH_CONV8_4_FC32: u16 = 2;
/// Layers in the architecture: conv1, conv2, fc_belief, fc_side, fc_joint, actor, critic.
pub const N_LAYERS: usize = 7;
/// Bytes of the fixed header.
pub const HEADER_LEN: usize = 40;
/// Bytes of one tensor-table entry.
pub const ENTRY_LEN: usize = 48;
/// Offset of the first byte after the tensor table (where tensor data may start).
pub const TABLE_END: usize = HEADER_LEN + N_LAYERS * ENTRY_LEN;
/// Bytes of the trailing CRC-32.
pub const CRC_LEN: usize = 4;
/// Layer kind code: 3×3 convolution, stride 2, zero padding 1.
pub const KIND_CONV3X3_S2_P1: u8 = 1;
/// Layer kind code: fully connected.
pub const KIND_FULLY_CONNECTED: u8 = 2;
/// Activation code: none, int32 output (the two heads).
pub const ACT_NONE_I32: u8 = 0;
/// Activation code: ReLU folded into the int8 clamp.
pub const ACT_RELU_I8: u8 = 1;

/// Index of each layer in the tensor table.
pub const L_CONV1: usize = 0;
/// conv2.
pub const L_CONV2: usize = 1;
/// fc_belief.
pub const L_BELIEF: usize = 2;
/// fc_side.
pub const L_SIDE: usize = 3;
/// fc_joint.
pub const L_JOINT: usize = 4;
/// actor head (3 logits).
pub const L_ACTOR: usize = 5;
/// critic head (1 value).
pub const L_CRITIC: usize = 6;

const C1: usize = 8;
const C2: usize = 16;
const S1: usize = 15;
const S2: usize = 8;
const HIDDEN: usize = 64;
const FLAT: usize = C2 * S2 * S2;
const KK: usize = 9;
/// Largest convolution output plane (conv1: 15 × 15).
const MAX_CONV_OUT: usize = S1 * S1;
/// Largest belief input: `MAX_ROT_BINS × 900` int8.
pub const MAX_BELIEF_LEN: usize = MAX_ROT_BINS * BELIEF_PLANE;

const _: () = assert!(BELIEF_SIDE == 30 && (BELIEF_SIDE + 2 - 3) / 2 + 1 == S1);
const _: () = assert!((S1 + 2 - 3) / 2 + 1 == S2);
const _: () = assert!(TABLE_END == 376);

/// Why one inference could not run (the blob itself is always valid here).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunError {
    /// The localizer's `K` is not the blob's.
    WrongRotBins {
        /// The blob's `K`.
        expected: u8,
        /// The localizer's.
        got: u8,
    },
    /// The localizer holds no plan yet.
    NotReady,
    /// An input slice has the wrong length.
    BadInput,
}

/// Affine quantisation of a tensor: `real = scale · (q − zero_point)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantParams {
    /// Real value of one step.
    pub scale: f32,
    /// The integer that represents 0.0 (exactly).
    pub zero_point: i32,
}

/// What a layer computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerKind {
    /// 3×3 convolution, stride 2, zero padding 1, square maps.
    Conv,
    /// Fully connected.
    FullyConnected,
}

/// The dimensions the architecture fixes for one layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerDims {
    /// Kind.
    pub kind: LayerKind,
    /// ReLU + int8 output (true) or int32 output without activation (the heads).
    pub relu: bool,
    /// Input channels (conv) or inputs (fully connected).
    pub inputs: usize,
    /// Output channels or outputs.
    pub outputs: usize,
    /// Input map side (conv), 1 for fully connected.
    pub in_size: usize,
    /// Output map side (conv), 1 for fully connected.
    pub out_size: usize,
}

impl LayerDims {
    /// Weights per output channel (the fan-in).
    pub const fn fan_in(&self) -> usize {
        match self.kind {
            LayerKind::Conv => self.inputs * KK,
            LayerKind::FullyConnected => self.inputs,
        }
    }
    /// Number of int8 weights.
    pub const fn weight_len(&self) -> usize {
        self.outputs * self.fan_in()
    }
    /// Input values (int8).
    pub const fn input_len(&self) -> usize {
        self.inputs * self.in_size * self.in_size
    }
    /// Output values.
    pub const fn output_len(&self) -> usize {
        self.outputs * self.out_size * self.out_size
    }
}

/// The layer dimensions of architecture `arch` for `K` belief planes, in table order;
/// `None` for an unknown architecture.
pub const fn layer_dims(arch: u16, rot_bins: usize) -> Option<[LayerDims; N_LAYERS]> {
    match arch {
        ARCH_CONV8_16_FC64 => Some(graph(rot_bins, C2, HIDDEN)),
        ARCH_CONV8_4_FC32 => Some(graph(rot_bins, 4, 32)),
        _ => None,
    }
}

/// The shared graph with `c2` conv2 channels and `hidden` units per hidden layer (the
/// largest, architecture 1, sizes [`Scratch`]).
const fn graph(rot_bins: usize, c2: usize, hidden: usize) -> [LayerDims; N_LAYERS] {
    const fn conv(inputs: usize, outputs: usize, in_size: usize, out_size: usize) -> LayerDims {
        LayerDims {
            kind: LayerKind::Conv,
            relu: true,
            inputs,
            outputs,
            in_size,
            out_size,
        }
    }
    const fn fc(inputs: usize, outputs: usize, relu: bool) -> LayerDims {
        LayerDims {
            kind: LayerKind::FullyConnected,
            relu,
            inputs,
            outputs,
            in_size: 1,
            out_size: 1,
        }
    }
    [
        conv(rot_bins, C1, BELIEF_SIDE, S1),
        conv(C1, c2, S1, S2),
        fc(c2 * S2 * S2, hidden, true),
        fc(SIDE_FEATURES, hidden, true),
        fc(2 * hidden, hidden, true),
        fc(hidden, 3, false),
        fc(hidden, 1, false),
    ]
}

/// One validated layer: dimensions, quantisation and its tensors, borrowed from the blob.
#[derive(Clone, Copy, Debug)]
pub struct LayerView<'a> {
    /// Dimensions (those of [`layer_dims`]).
    pub dims: LayerDims,
    /// Quantisation of the layer's input.
    pub input: QuantParams,
    /// Quantisation of the output (int32 heads: zero point 0).
    pub output: QuantParams,
    /// int8 weights, `[out][in][ky][kx]` or `[out][in]`.
    weights: &'a [u8],
    /// int32 LE biases, one per output channel.
    bias: &'a [u8],
    /// Q31 multipliers, int32 LE, one per output channel.
    multiplier: &'a [u8],
    /// Shifts, int8, one per output channel (positive = left).
    shift: &'a [u8],
}

impl<'a> LayerView<'a> {
    /// The int8 weights.
    pub fn weights(&self) -> impl Iterator<Item = i8> + 'a {
        self.weights.iter().map(|&b| b as i8)
    }
    /// Per-output-channel (bias, multiplier, shift).
    pub fn channels(&self) -> impl Iterator<Item = (i32, i32, i32)> + 'a {
        self.bias
            .chunks_exact(4)
            .zip(self.multiplier.chunks_exact(4))
            .zip(self.shift.iter())
            .map(|((b, m), &s)| (le_i32(b), le_i32(m), s as i8 as i32))
    }
}

/// One decision of the int8 network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decision {
    /// The argmax of the logits (first on ties), in the order left, right, measure.
    pub action: Action,
    /// Actor logits in units of the actor's output scale ([`QuantizedPolicy::logit_scale`]).
    pub logits: [i32; 3],
    /// Critic value in units of [`QuantizedPolicy::value_scale`].
    pub value: i32,
}

/// The activations of one inference (the int8 inputs and every hidden layer's output), all
/// sized for the largest `K`, and the convolution weights widened for the DSP kernels
/// (`fast`, on the stack during a decision). About 11 KiB; keep it in a `static` on the device.
#[derive(Clone, Debug)]
pub struct Scratch {
    /// The belief map in the convolutions' padded, channel-interleaved layout.
    belief: [i8; fast::X1_LEN],
    side: [i8; SIDE_FEATURES],
    acts: Activations,
}

/// The activations kept after a decision (for logs and tests). conv1's padded output and
/// the widened conv weights (3.2 KB) live on the stack during the decision instead: the
/// decision's call chain is shallow, while the firmware's deepest one (the refinement)
/// needs every byte of stack the statics leave.
#[derive(Clone, Debug)]
struct Activations {
    a2: [i8; FLAT],
    cat: [i8; 2 * HIDDEN],
    joint: [i8; HIDDEN],
}

/// RAM of a [`Scratch`]: every activation and the int8 inputs for `K` = 10.
pub const SCRATCH_BYTES: usize = core::mem::size_of::<Scratch>();

// The device's RAM budget for activations and scratch: 24 KiB (10 938 bytes used).
const _: () = assert!(SCRATCH_BYTES <= 24 * 1024);

impl Scratch {
    /// Zeroed scratch (`const`, for a `static`).
    pub const fn new() -> Self {
        Scratch {
            belief: [0; fast::X1_LEN],
            side: [0; SIDE_FEATURES],
            acts: Activations {
                a2: [0; FLAT],
                cat: [0; 2 * HIDDEN],
                joint: [0; HIDDEN],
            },
        }
    }
}

impl Default for Scratch {
    fn default() -> Self {
        Self::new()
    }
}

/// A validated, zero-copy view of a policy blob.
#[derive(Clone, Copy, Debug)]
pub struct QuantizedPolicy<'a> {
    bytes: &'a [u8],
    arch: u16,
    rot_bins: u8,
    instrument: InstrumentProfile,
    belief_input: QuantParams,
    side_input: QuantParams,
    layers: [LayerView<'a>; N_LAYERS],
}

fn le_i32(c: &[u8]) -> i32 {
    c.try_into().map(i32::from_le_bytes).unwrap_or(0)
}

impl<'a> QuantizedPolicy<'a> {
    /// The blob this view reads.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Architecture id.
    pub fn arch(&self) -> u16 {
        self.arch
    }

    /// Belief planes `K` the network was trained for.
    pub fn rot_bins(&self) -> u8 {
        self.rot_bins
    }

    /// The instrument the network was trained for (blob byte 18): an EDM-only network never
    /// saw a scan, and a scan network expects one.
    pub fn instrument(&self) -> InstrumentProfile {
        self.instrument
    }

    /// Belief values a decision reads: `K × 900`.
    pub fn belief_len(&self) -> usize {
        self.rot_bins as usize * BELIEF_PLANE
    }

    /// Quantisation of the belief input.
    pub fn belief_input(&self) -> QuantParams {
        self.belief_input
    }

    /// Quantisation of the side-feature input.
    pub fn side_input(&self) -> QuantParams {
        self.side_input
    }

    /// Layer `i` in table order (`L_CONV1` … `L_CRITIC`).
    pub fn layer(&self, i: usize) -> Option<&LayerView<'a>> {
        self.layers.get(i)
    }

    /// Real value of one unit of [`Decision::logits`].
    pub fn logit_scale(&self) -> f32 {
        self.layers[L_ACTOR].output.scale
    }

    /// Real value of one unit of [`Decision::value`].
    pub fn value_scale(&self) -> f32 {
        self.layers[L_CRITIC].output.scale
    }
}

/// The CRC-32 a blob carries in its last 4 bytes (over everything before them): the
/// blob's identity in reports and the value a policy upload announces. (The CRC of a whole
/// valid blob, its own CRC included, is the same constant for every blob.)
pub fn stored_crc(blob: &[u8]) -> Option<u32> {
    let t = blob.get(blob.len().checked_sub(CRC_LEN)?..)?;
    Some(u32::from_le_bytes([t[0], t[1], t[2], t[3]]))
}

/// The backend the network runs: the DSP kernels on the Cortex-M4, [`dot::Portable`]
/// elsewhere. The choice belongs here, above both: [`dot`] defines the interface and the
/// portable reference, `dsp` implements it for the M4, and neither names the other's place.
#[cfg(target_arch = "arm")]
pub type Fast = dsp::Dsp;
/// The backend the network runs: the DSP kernels on the Cortex-M4, [`dot::Portable`]
/// elsewhere.
#[cfg(not(target_arch = "arm"))]
pub type Fast = dot::Portable;
