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

use crate::episode::Action;

pub mod agent;
pub mod dot;
#[cfg(target_arch = "arm")]
#[allow(unsafe_code)]
pub mod dsp;
pub mod error;
mod fast;
pub mod kernels;
pub mod selftest;
pub mod write;

use crate::checksum::crc32;
use crate::localization::MAX_ROT_BINS;
use crate::policy::{PolicyInput, BELIEF_PLANE, BELIEF_SIDE, SIDE_FEATURES};
pub use agent::{QuantizedAgent, ScratchAgent};
use dot::{Dot, Fast};
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
    belief_input: QuantParams,
    side_input: QuantParams,
    layers: [LayerView<'a>; N_LAYERS],
}

fn le_i32(c: &[u8]) -> i32 {
    c.try_into().map(i32::from_le_bytes).unwrap_or(0)
}

fn field<const N: usize>(b: &[u8], at: usize) -> Result<[u8; N], BlobError> {
    let end = at.checked_add(N).ok_or(BlobError::Truncated)?;
    b.get(at..end)
        .and_then(|s| s.try_into().ok())
        .ok_or(BlobError::Truncated)
}

fn rd_u16(b: &[u8], at: usize) -> Result<u16, BlobError> {
    field::<2>(b, at).map(u16::from_le_bytes)
}

fn rd_u32(b: &[u8], at: usize) -> Result<u32, BlobError> {
    field::<4>(b, at).map(u32::from_le_bytes)
}

fn rd_i32(b: &[u8], at: usize) -> Result<i32, BlobError> {
    field::<4>(b, at).map(i32::from_le_bytes)
}

fn rd_f32(b: &[u8], at: usize) -> Result<f32, BlobError> {
    field::<4>(b, at).map(f32::from_le_bytes)
}

fn rd_quant(b: &[u8], scale_at: usize, zp_at: usize) -> Result<QuantParams, BlobError> {
    let p = QuantParams {
        scale: rd_f32(b, scale_at)?,
        zero_point: rd_i32(b, zp_at)?,
    };
    if p.scale.is_normal() && p.scale > 0.0 {
        Ok(p)
    } else {
        Err(BlobError::BadQuantization)
    }
}

fn int8_zero_point(p: &QuantParams) -> Result<(), BlobError> {
    if (-128..=127).contains(&p.zero_point) {
        Ok(())
    } else {
        Err(BlobError::BadQuantization)
    }
}

/// Bit-equality of two tensors' quantisation (they are written by one quantiser).
fn same(a: &QuantParams, b: &QuantParams) -> bool {
    a.scale.to_bits() == b.scale.to_bits() && a.zero_point == b.zero_point
}

/// The `len` bytes at `off`, which must lie in `data` (`TABLE_END..total − 4`).
fn section(b: &[u8], off: u32, len: usize, data_end: usize) -> Result<&[u8], BlobError> {
    let off = off as usize;
    let end = off.checked_add(len).ok_or(BlobError::BadTensorTable)?;
    if off < TABLE_END || end > data_end {
        return Err(BlobError::BadTensorTable);
    }
    b.get(off..end).ok_or(BlobError::BadTensorTable)
}

impl<'a> QuantizedPolicy<'a> {
    /// Validates `bytes` (layout in `docs/policy-blob.md`) and returns a view that reads the
    /// tensors in place. Never panics.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse_inner(bytes, true)
    }

    /// [`QuantizedPolicy::parse`] without the CRC-32 pass (every structural check stays, so
    /// it still never panics): for bytes `parse` accepted before and that cannot have
    /// changed since, such as the device's installed policy slot, re-viewed at every
    /// decision. The CRC over a 16 KB blob costs about as much as a decision.
    pub fn parse_verified(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse_inner(bytes, false)
    }

    fn parse_inner(bytes: &'a [u8], check_crc: bool) -> Result<Self, BlobError> {
        let b = bytes;
        if b.len() < HEADER_LEN {
            return Err(BlobError::Truncated);
        }
        if field::<8>(b, 0)? != MAGIC {
            return Err(BlobError::BadMagic);
        }
        let version = rd_u16(b, 8)?;
        if version != FORMAT_VERSION {
            return Err(BlobError::UnsupportedVersion(version));
        }
        let total = rd_u32(b, 20)? as usize;
        if b.len() < total {
            return Err(BlobError::Truncated);
        }
        if b.len() > total {
            return Err(BlobError::TrailingBytes);
        }
        let data_end = total
            .checked_sub(CRC_LEN)
            .filter(|&e| e >= TABLE_END)
            .ok_or(BlobError::Truncated)?;
        let body = b.get(..data_end).ok_or(BlobError::Truncated)?;
        if check_crc && crc32(body) != rd_u32(b, data_end)? {
            return Err(BlobError::BadChecksum);
        }
        let arch = rd_u16(b, 10)?;
        let Some(dims) = layer_dims(arch, 1) else {
            return Err(BlobError::UnknownArchitecture(arch));
        };
        let rot_bins = field::<1>(b, 12)?[0];
        let n_layers = field::<1>(b, 13)?[0] as usize;
        let side_len = rd_u16(b, 14)? as usize;
        let side_features = rd_u16(b, 16)? as usize;
        if !(1..=MAX_ROT_BINS).contains(&(rot_bins as usize))
            || n_layers != N_LAYERS
            || side_len != BELIEF_SIDE
            || side_features != SIDE_FEATURES
        {
            return Err(BlobError::ShapeMismatch);
        }
        if rd_u16(b, 18)? != 0 {
            return Err(BlobError::BadTensorTable);
        }
        let belief_input = rd_quant(b, 24, 28)?;
        let side_input = rd_quant(b, 32, 36)?;
        int8_zero_point(&belief_input)?;
        int8_zero_point(&side_input)?;

        let dims = layer_dims(arch, rot_bins as usize).unwrap_or(dims);
        let mut layers = [LayerView {
            dims: dims[0],
            input: belief_input,
            output: belief_input,
            weights: &[],
            bias: &[],
            multiplier: &[],
            shift: &[],
        }; N_LAYERS];
        for (i, (view, want)) in layers.iter_mut().zip(dims.iter()).enumerate() {
            let e = HEADER_LEN + i * ENTRY_LEN;
            let kind = match field::<1>(b, e)?[0] {
                KIND_CONV3X3_S2_P1 => LayerKind::Conv,
                KIND_FULLY_CONNECTED => LayerKind::FullyConnected,
                _ => return Err(BlobError::BadTensorTable),
            };
            let relu = match field::<1>(b, e + 1)?[0] {
                ACT_RELU_I8 => true,
                ACT_NONE_I32 => false,
                _ => return Err(BlobError::BadTensorTable),
            };
            if field::<2>(b, e + 2)? != [0, 0] {
                return Err(BlobError::BadTensorTable);
            }
            let got = LayerDims {
                kind,
                relu,
                inputs: rd_u16(b, e + 4)? as usize,
                outputs: rd_u16(b, e + 6)? as usize,
                in_size: rd_u16(b, e + 8)? as usize,
                out_size: rd_u16(b, e + 10)? as usize,
            };
            if got != *want {
                return Err(BlobError::ShapeMismatch);
            }
            let input = rd_quant(b, e + 20, e + 12)?;
            let output = rd_quant(b, e + 24, e + 16)?;
            int8_zero_point(&input)?;
            if relu {
                int8_zero_point(&output)?;
            } else if output.zero_point != 0 {
                return Err(BlobError::BadQuantization);
            }
            let w_len = rd_u32(b, e + 32)? as usize;
            if w_len != want.weight_len() {
                return Err(BlobError::ShapeMismatch);
            }
            let n = want.outputs;
            let weights = section(b, rd_u32(b, e + 28)?, w_len, data_end)?;
            let bias = section(b, rd_u32(b, e + 36)?, 4 * n, data_end)?;
            let multiplier = section(b, rd_u32(b, e + 40)?, 4 * n, data_end)?;
            let shift = section(b, rd_u32(b, e + 44)?, n, data_end)?;
            // Symmetric weights: −128 never occurs (CMSIS-NN's range), which also bounds
            // every accumulator well inside i32 (see `docs/policy-blob.md`).
            // (The weight scan is the costly part of a parse; a re-view of a verified blob
            // skips it: the bytes are the ones checked then.)
            if (check_crc && weights.iter().any(|&w| w as i8 == i8::MIN))
                || multiplier.chunks_exact(4).any(|m| le_i32(m) < 0)
                || shift
                    .iter()
                    .any(|&s| !(-31..=30).contains(&(s as i8 as i32)))
            {
                return Err(BlobError::BadQuantization);
            }
            *view = LayerView {
                dims: *want,
                input,
                output,
                weights,
                bias,
                multiplier,
                shift,
            };
        }
        // The chain: each layer reads what the previous one wrote; fc_belief and fc_side
        // write the two halves of fc_joint's input, so all three share one quantisation.
        let l = &layers;
        let chained = same(&l[L_CONV1].input, &belief_input)
            && same(&l[L_CONV2].input, &l[L_CONV1].output)
            && same(&l[L_BELIEF].input, &l[L_CONV2].output)
            && same(&l[L_SIDE].input, &side_input)
            && same(&l[L_BELIEF].output, &l[L_JOINT].input)
            && same(&l[L_SIDE].output, &l[L_JOINT].input)
            && same(&l[L_ACTOR].input, &l[L_JOINT].output)
            && same(&l[L_CRITIC].input, &l[L_JOINT].output);
        if !chained {
            return Err(BlobError::BadQuantization);
        }
        Ok(QuantizedPolicy {
            bytes,
            arch,
            rot_bins,
            belief_input,
            side_input,
            layers,
        })
    }

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

    /// Quantises the side features of `input` (via a 432-byte `f32` buffer on the stack).
    pub fn quantize_side(&self, input: &PolicyInput<'_>, out: &mut [i8; SIDE_FEATURES]) {
        let mut f = [0.0f32; SIDE_FEATURES];
        input.write_side(&mut f);
        for (q, &v) in out.iter_mut().zip(f.iter()) {
            *q = quantize_value(v, self.side_input);
        }
    }

    /// One decision from what the instrument knows: quantise the inputs, run the network.
    pub fn decide(
        &self,
        input: &PolicyInput<'_>,
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        let got = input.belief_planes();
        if got != self.rot_bins as usize {
            return Err(RunError::WrongRotBins {
                expected: self.rot_bins,
                got: got.min(255) as u8,
            });
        }
        let Scratch { belief, side, acts } = scratch;
        let p = self.belief_input;
        let k = self.rot_bins as usize;
        let x1 = &mut belief[..fast::padded_side(S1) * fast::padded_side(S1) * k];
        // The padding and any cell the grid lacks are real 0: the zero point.
        x1.fill(p.zero_point as i8);
        if input.write_belief_q_hwc(x1, p.scale, p.zero_point, fast::padded_side(S1)) == 0 {
            return Err(RunError::NotReady);
        }
        self.quantize_side(input, side);
        self.run::<Fast>(belief, side, acts)
    }

    /// One decision from already quantised inputs (`belief`: `K × 900`, `[plane][y][x]`).
    pub fn infer(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        self.infer_with::<Fast>(belief, side, scratch)
    }

    /// [`QuantizedPolicy::infer`] on the inner products of backend `D` ([`dot::Portable`],
    /// or `dsp::Dsp` on the M4): what the self-test compares.
    pub fn infer_with<D: Dot>(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        if belief.len() != self.belief_len() {
            return Err(RunError::BadInput);
        }
        let k = self.rot_bins as usize;
        let s = fast::padded_side(S1);
        let x1 = &mut scratch.belief[..s * s * k];
        x1.fill(self.belief_input.zero_point as i8);
        for (c, plane) in belief.chunks_exact(BELIEF_PLANE).enumerate() {
            for (y, row) in plane.chunks_exact(BELIEF_SIDE).enumerate() {
                for (x, &v) in row.iter().enumerate() {
                    x1[((y + 1) * s + x + 1) * k + c] = v;
                }
            }
        }
        self.run::<D>(&scratch.belief, side, &mut scratch.acts)
    }

    /// One decision from the inputs `scratch` already holds (the padded belief map and
    /// the side features), on backend `D`: for the self-test.
    fn run_in<D: Dot>(&self, scratch: &mut Scratch) -> Result<Decision, RunError> {
        let Scratch { belief, side, acts } = scratch;
        self.run::<D>(belief, side, acts)
    }

    fn run<D: Dot>(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        acts: &mut Activations,
    ) -> Result<Decision, RunError> {
        let l = &self.layers;
        let Activations { a2, cat, joint } = acts;
        let mut a1 = [0i8; fast::X2_LEN];
        let mut work = fast::ConvWork::new();
        let work = &mut work;
        // Architecture 2 uses a prefix of each buffer (sized for architecture 1).
        let len = |i: usize| l[i].dims.output_len();
        let a2 = a2.get_mut(..len(L_CONV2)).ok_or(RunError::BadInput)?;
        let h = len(L_BELIEF);
        let cat = cat.get_mut(..2 * h).ok_or(RunError::BadInput)?;
        let joint = joint.get_mut(..len(L_JOINT)).ok_or(RunError::BadInput)?;
        let s2 = fast::padded_side(S2);
        let a1p = a1.get_mut(..s2 * s2 * C1).ok_or(RunError::BadInput)?;
        fast::conv::<D>(&l[L_CONV1], belief, work, fast::ConvOut::Padded(a1p, s2));
        fast::conv::<D>(&l[L_CONV2], &a1[..], work, fast::ConvOut::Planar(a2));
        let (hb, hs) = cat.split_at_mut(h);
        fast::fully_connected_i8::<D>(&l[L_BELIEF], a2, hb);
        fast::fully_connected_i8::<D>(&l[L_SIDE], side, hs);
        fast::fully_connected_i8::<D>(&l[L_JOINT], cat, joint);
        let mut logits = [0i32; 3];
        fast::fully_connected_i32::<D>(&l[L_ACTOR], joint, &mut logits);
        let mut value = [0i32; 1];
        fast::fully_connected_i32::<D>(&l[L_CRITIC], joint, &mut value);
        Ok(Decision {
            action: ACTIONS[argmax(&logits)],
            logits,
            value: value[0],
        })
    }

    /// One decision by the reference kernels of [`kernels`] (planar layout, one product at
    /// a time, activations on the stack): what the fast path is tested against.
    #[inline(never)]
    pub fn infer_reference(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
    ) -> Result<Decision, RunError> {
        if belief.len() != self.belief_len() {
            return Err(RunError::BadInput);
        }
        let l = &self.layers;
        let len = |i: usize| l[i].dims.output_len();
        let mut a1 = [0i8; C1 * S1 * S1];
        let mut a2 = [0i8; FLAT];
        let mut cat = [0i8; 2 * HIDDEN];
        let mut joint = [0i8; HIDDEN];
        let a1 = a1.get_mut(..len(L_CONV1)).ok_or(RunError::BadInput)?;
        let a2 = a2.get_mut(..len(L_CONV2)).ok_or(RunError::BadInput)?;
        let h = len(L_BELIEF);
        let cat = cat.get_mut(..2 * h).ok_or(RunError::BadInput)?;
        let joint = joint.get_mut(..len(L_JOINT)).ok_or(RunError::BadInput)?;
        conv3x3_s2_p1(&l[L_CONV1], belief, a1);
        conv3x3_s2_p1(&l[L_CONV2], a1, a2);
        let (hb, hs) = cat.split_at_mut(h);
        fully_connected_i8(&l[L_BELIEF], a2, hb);
        fully_connected_i8(&l[L_SIDE], side, hs);
        fully_connected_i8(&l[L_JOINT], cat, joint);
        let mut logits = [0i32; 3];
        fully_connected_i32(&l[L_ACTOR], joint, &mut logits);
        let mut value = [0i32; 1];
        fully_connected_i32(&l[L_CRITIC], joint, &mut value);
        Ok(Decision {
            action: ACTIONS[argmax(&logits)],
            logits,
            value: value[0],
        })
    }
}

/// The CRC-32 a blob carries in its last 4 bytes (over everything before them): the
/// blob's identity in reports and the value a policy upload announces. (The CRC of a whole
/// valid blob, its own CRC included, is the same constant for every blob.)
pub fn stored_crc(blob: &[u8]) -> Option<u32> {
    let t = blob.get(blob.len().checked_sub(CRC_LEN)?..)?;
    Some(u32::from_le_bytes([t[0], t[1], t[2], t[3]]))
}

/// The one-channel-at-a-time kernel the paired one replaced: the reference its test
/// compares against.
#[cfg(test)]
fn conv3x3_s2_p1_one_channel(layer: &LayerView<'_>, input: &[i8], out: &mut [i8]) {
    let d = layer.dims;
    let (n_in, n_out) = (d.in_size, d.out_size);
    let (c_in, in_plane, out_plane) = (d.inputs, n_in * n_in, n_out * n_out);
    let fan_in = d.fan_in();
    // Validated by `parse`; checked once here so nothing below can index out of bounds.
    if input.len() < c_in * in_plane
        || out.len() < d.outputs * out_plane
        || layer.weights.len() < d.outputs * fan_in
        || out_plane > MAX_CONV_OUT
    {
        return;
    }
    let zp_in = layer.input.zero_point;
    let zp_out = layer.output.zero_point;
    // Σ (x − zp)·w = Σ x·w − zp · Σ w over the taps inside the input: the inner loop
    // multiplies raw int8 values, and the zero point is paid once per output with the
    // summed weights of its valid taps. Weights stay in registers across a whole plane.
    let mut acc = [0i32; MAX_CONV_OUT];
    for (co, (bias, mult, shift)) in layer.channels().enumerate() {
        let acc = &mut acc[..out_plane];
        acc.fill(0);
        let mut wsum = [0i32; KK];
        let kernel = &layer.weights[co * fan_in..(co + 1) * fan_in];
        for (plane, wc) in input.chunks_exact(in_plane).zip(kernel.chunks_exact(KK)) {
            let mut w = [0i32; KK];
            for (k, (wk, &b)) in w.iter_mut().zip(wc).enumerate() {
                *wk = b as i8 as i32;
                wsum[k] += *wk;
            }
            for (oy, acc_row) in acc.chunks_exact_mut(n_out).enumerate() {
                let r = 2 * oy; // input row of the kernel's middle row
                for (ky, wr) in [(0usize, 0usize), (1, 3), (2, 6)] {
                    let Some(row) = (r + ky)
                        .checked_sub(1)
                        .and_then(|y| plane.get(y * n_in..(y + 1) * n_in))
                    else {
                        continue;
                    };
                    let (w0, w1, w2) = (w[wr], w[wr + 1], w[wr + 2]);
                    // Output column 0 has no left tap (padding); columns 1.. read the
                    // windows row[2·ox − 1 ..= 2·ox + 1], stepping by 2.
                    if let (Some(a), Some(&x1), Some(&x2)) =
                        (acc_row.first_mut(), row.first(), row.get(1))
                    {
                        *a += x1 as i32 * w1 + x2 as i32 * w2;
                    }
                    let rest = acc_row.get_mut(1..).unwrap_or(&mut []);
                    let windows = row.get(1..).unwrap_or(&[]).windows(3).step_by(2);
                    let full = windows.len();
                    for (a, win) in rest.iter_mut().zip(windows) {
                        *a += win[0] as i32 * w0 + win[1] as i32 * w1 + win[2] as i32 * w2;
                    }
                    // A last column whose right tap falls in the padding (odd n_in).
                    if let Some(a) = rest.get_mut(full) {
                        let c = 2 * (full + 1);
                        if let (Some(&x0), Some(&x1)) = (row.get(c - 1), row.get(c)) {
                            *a += x0 as i32 * w0 + x1 as i32 * w1;
                        }
                    }
                }
            }
        }
        // A tap (o, k) reads input index 2·o + k − 1, valid inside 0..n_in.
        let valid = |o: usize, k: usize| (2 * o + k).checked_sub(1).is_some_and(|i| i < n_in);
        for (oy, acc_row) in acc.chunks_exact(n_out).enumerate() {
            // Weight sums of this output row's valid kernel rows, per kernel column.
            let mut col = [0i32; 3];
            for ky in 0..3 {
                if valid(oy, ky) {
                    for (kx, c) in col.iter_mut().enumerate() {
                        *c += wsum[ky * 3 + kx];
                    }
                }
            }
            let all = col[0] + col[1] + col[2];
            for (ox, &a) in acc_row.iter().enumerate() {
                let ws = if ox > 0 && 2 * ox + 1 < n_in {
                    all
                } else {
                    (0..3).filter(|&kx| valid(ox, kx)).map(|kx| col[kx]).sum()
                };
                let v = a.wrapping_sub(zp_in.wrapping_mul(ws));
                if let Some(o) = out.get_mut(co * out_plane + oy * n_out + ox) {
                    *o = requantize_i8(v.saturating_add(bias), mult, shift, zp_out, d.relu);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use rand_core::{RngCore, SeedableRng};
    use rand_pcg::Pcg32;
    use std::vec;
    use std::vec::Vec;

    /// Owned tensors of one layer, for building test blobs.
    #[derive(Clone)]
    struct Owned {
        weights: Vec<i8>,
        bias: Vec<i32>,
        multiplier: Vec<i32>,
        shift: Vec<i8>,
        input: QuantParams,
        output: QuantParams,
    }

    fn build(k: u8, belief: QuantParams, side: QuantParams, layers: &[Owned]) -> Vec<u8> {
        build_arch(ARCH_CONV8_16_FC64, k, belief, side, layers)
    }

    fn build_arch(
        arch: u16,
        k: u8,
        belief: QuantParams,
        side: QuantParams,
        layers: &[Owned],
    ) -> Vec<u8> {
        let t: Vec<LayerTensors<'_>> = layers
            .iter()
            .map(|l| LayerTensors {
                weights: &l.weights,
                bias: &l.bias,
                multiplier: &l.multiplier,
                shift: &l.shift,
                input: l.input,
                output: l.output,
            })
            .collect();
        let t: [LayerTensors<'_>; N_LAYERS] = t.try_into().ok().unwrap();
        let mut out = vec![0u8; blob_len(arch, k as usize)];
        let n = write_blob(&mut out, arch, k, belief, side, &t).unwrap();
        assert_eq!(n, out.len());
        out
    }

    const UNIT: QuantParams = QuantParams {
        scale: 1.0,
        zero_point: 0,
    };

    /// All-zero layers with multiplier 1.0 (Q31 2^30, shift 1) and unit quantisation.
    fn zero_layers(k: u8) -> Vec<Owned> {
        zero_layers_arch(ARCH_CONV8_16_FC64, k)
    }

    fn zero_layers_arch(arch: u16, k: u8) -> Vec<Owned> {
        layer_dims(arch, k as usize)
            .unwrap()
            .iter()
            .map(|d| Owned {
                weights: vec![0; d.weight_len()],
                bias: vec![0; d.outputs],
                multiplier: vec![1 << 30; d.outputs],
                shift: vec![1; d.outputs],
                input: UNIT,
                output: UNIT,
            })
            .collect()
    }

    /// A random, valid K = 1 blob (asymmetric activations, per-channel multipliers).
    fn random_blob(seed: u64) -> Vec<u8> {
        let mut rng = Pcg32::seed_from_u64(seed);
        let act = QuantParams {
            scale: 0.05,
            zero_point: -128,
        };
        let belief = QuantParams {
            scale: 1.0 / 255.0,
            zero_point: -128,
        };
        let side = QuantParams {
            scale: 0.02,
            zero_point: -20,
        };
        let mut layers = zero_layers(1);
        for (i, l) in layers.iter_mut().enumerate() {
            for w in &mut l.weights {
                *w = ((rng.next_u32() % 255) as i32 - 127) as i8; // −127..=127
            }
            for (b, m) in l.bias.iter_mut().zip(&mut l.multiplier) {
                *b = (rng.next_u32() % 2001) as i32 - 1000;
                *m = (1 << 30) + (rng.next_u32() >> 2) as i32;
            }
            l.shift.iter_mut().for_each(|s| *s = -9);
            l.input = match i {
                L_CONV1 => belief,
                L_SIDE => side,
                _ => act,
            };
            l.output = if i >= L_ACTOR {
                QuantParams {
                    scale: 0.001,
                    zero_point: 0,
                }
            } else {
                act
            };
        }
        build(1, belief, side, &layers)
    }

    /// Independent reference of `MultiplyByQuantizedMultiplier` in i128: floor-rounded
    /// (half up) high product, then a half-away-from-zero division by 2^right.
    fn reference(x: i32, q: i32, shift: i32) -> i64 {
        let left = shift.max(0);
        let right = (-shift).max(0);
        let x = (x as i64 * (1i64 << left)).clamp(i32::MIN as i64, i32::MAX as i64) as i128;
        let p = x * q as i128;
        let r1 = if x == i32::MIN as i128 && q == i32::MIN {
            i32::MAX as i128
        } else {
            (p + (1i128 << 30)).div_euclid(1i128 << 31)
        };
        if right == 0 {
            return r1 as i64;
        }
        let half = 1i128 << (right - 1);
        let mag = (r1.abs() + half) >> right;
        (if r1 < 0 { -mag } else { mag }) as i64
    }

    /// The 32-bit / one-floor forms of the two gemmlowp helpers equal gemmlowp's own
    /// formulation (nudge, truncating division; 64-bit remainder arithmetic) for every sign.
    #[test]
    fn gemmlowp_helpers_equal_their_literal_forms() {
        fn srdhm(a: i32, b: i32) -> i32 {
            if a == i32::MIN && b == i32::MIN {
                return i32::MAX;
            }
            let ab = a as i64 * b as i64;
            let nudge: i64 = if ab >= 0 { 1 << 30 } else { 1 - (1 << 30) };
            ((ab + nudge) / (1i64 << 31)) as i32
        }
        fn rdbp(x: i32, e: i32) -> i32 {
            let e = e.clamp(0, 31);
            let mask = (1i64 << e) - 1;
            let x = x as i64;
            let threshold = (mask >> 1) + i64::from(x < 0);
            ((x >> e) + i64::from((x & mask) > threshold)) as i32
        }
        let mut rng = Pcg32::seed_from_u64(3);
        let edge = [
            0,
            1,
            -1,
            i32::MIN,
            i32::MAX,
            i32::MIN + 1,
            1 << 30,
            -(1 << 30),
            3,
            -3,
        ];
        for i in 0..300_000u32 {
            let pick = |rng: &mut Pcg32| match rng.next_u32() % 3 {
                0 => edge[rng.next_u32() as usize % edge.len()],
                1 => rng.next_u32() as i32 >> (rng.next_u32() % 32),
                _ => rng.next_u32() as i32,
            };
            let (a, b) = (pick(&mut rng), pick(&mut rng));
            assert_eq!(
                saturating_rounding_doubling_high_mul(a, b),
                srdhm(a, b),
                "{a} {b}"
            );
            let e = (i % 40) as i32 - 4;
            assert_eq!(rounding_divide_by_pot(a, e), rdbp(a, e), "{a} {e}");
        }
    }

    #[test]
    fn requantisation_matches_an_i128_reference() {
        let mut rng = Pcg32::seed_from_u64(7);
        let mut edge = vec![
            0,
            1,
            -1,
            2,
            -2,
            127,
            -128,
            1 << 20,
            -(1 << 20),
            i32::MAX,
            i32::MIN,
            i32::MAX - 1,
            i32::MIN + 1,
        ];
        // Exact halves after the shift.
        for e in 1..8 {
            edge.push(3 << (e - 1));
            edge.push(-(3 << (e - 1)));
        }
        let mults = [0, 1, 1 << 30, (1 << 30) + 1, i32::MAX, 1_518_500_250];
        let mut checked = 0;
        for _ in 0..200_000 {
            let x = match rng.next_u32() % 4 {
                0 => edge[rng.next_u32() as usize % edge.len()],
                1 => (rng.next_u32() % 100_000) as i32 - 50_000,
                _ => rng.next_u32() as i32 >> (rng.next_u32() % 31),
            };
            let q = if rng.next_u32() % 3 == 0 {
                mults[rng.next_u32() as usize % mults.len()]
            } else {
                (rng.next_u32() >> 1) as i32
            };
            let shift = (rng.next_u32() % 62) as i32 - 31;
            let got = multiply_by_quantized_multiplier(x, q, shift.min(30));
            assert_eq!(
                got as i64,
                reference(x, q, shift.min(30)),
                "x {x} q {q} shift {shift}"
            );
            // Within one unit of the exact real product (when it is representable).
            let exact = x as f64 * q as f64 * 2f64.powi(shift.min(30) - 31);
            if exact.abs() < 2e9 && shift <= 0 {
                assert!(
                    (got as f64 - exact).abs() <= 1.0,
                    "x {x} q {q} shift {shift}"
                );
                checked += 1;
            }
        }
        assert!(checked > 50_000);
        // The documented corner cases.
        assert_eq!(
            saturating_rounding_doubling_high_mul(i32::MIN, i32::MIN),
            i32::MAX
        );
        assert_eq!(rounding_divide_by_pot(5, 1), 3);
        assert_eq!(rounding_divide_by_pot(-5, 1), -3);
        assert_eq!(rounding_divide_by_pot(-3, 1), -2);
        assert_eq!(rounding_divide_by_pot(3, 1), 2);
        assert_eq!(multiply_by_quantized_multiplier(103, 1 << 30, 0), 52);
        assert_eq!(multiply_by_quantized_multiplier(-103, 1 << 30, 0), -51);
        // A left shift saturates x first (CMSIS-NN would wrap, TFLite is undefined).
        assert_eq!(
            multiply_by_quantized_multiplier(i32::MAX, i32::MAX, 30),
            i32::MAX - 1
        );
        assert_eq!(
            multiply_by_quantized_multiplier(-5, 1 << 30, 30),
            i32::MIN / 2
        );
    }

    #[test]
    fn quantize_value_rounds_half_away_and_saturates() {
        let p = QuantParams {
            scale: 0.5,
            zero_point: -10,
        };
        assert_eq!(quantize_value(0.0, p), -10);
        assert_eq!(quantize_value(0.25, p), -9);
        assert_eq!(quantize_value(-0.25, p), -11);
        assert_eq!(quantize_value(1e9, p), 127);
        assert_eq!(quantize_value(-1e9, p), -128);
        assert_eq!(quantize_value(f32::NAN, p), -10);
    }

    #[test]
    fn hand_computed_network() {
        // K = 1, unit scales, zero points 0, all weights 0 but a few:
        // conv1 ch0 and conv2 ch0 pass their centre tap (input (2y, 2x)); fc_belief out 0
        // reads conv2 ch0 (1, 2); fc_side out 0 = −side[0] (cut by the ReLU);
        // fc_joint: out 0 = 0.5·hb0, out 1 = 0.5·(hb0 + 3); actor: 2·j0, 2·j1, bias 104;
        // critic: j0 − j1.
        let mut l = zero_layers(1);
        l[L_CONV1].weights[4] = 1;
        l[L_CONV2].weights[4] = 1;
        l[L_BELIEF].weights[8 + 2] = 1;
        l[L_SIDE].weights[0] = -1;
        l[L_JOINT].weights[0] = 1;
        l[L_JOINT].weights[128] = 1;
        l[L_JOINT].bias[1] = 3;
        l[L_JOINT].multiplier.fill(1 << 30);
        l[L_JOINT].shift.fill(0);
        l[L_ACTOR].weights[0] = 2;
        l[L_ACTOR].weights[64 + 1] = 2;
        l[L_ACTOR].bias[2] = 104;
        l[L_CRITIC].weights[0] = 1;
        l[L_CRITIC].weights[1] = -1;
        let blob = build(1, UNIT, UNIT, &l);
        let p = QuantizedPolicy::parse(&blob).unwrap();
        let mut belief = [0i8; 900];
        belief[4 * 30 + 8] = 100; // conv1 (2, 4) → conv2 (1, 2)
        belief[5 * 30 + 9] = 77; // odd coordinates: no centre tap reads it
        let mut side = [0i8; SIDE_FEATURES];
        side[0] = 50;
        let mut s = Scratch::new();
        let d = p.infer(&belief, &side, &mut s).unwrap();
        // j0 = 0.5·100 = 50; j1 = 0.5·103 = 51.5 → 52 (half up); logits 100, 104, 104.
        assert_eq!(d.logits, [100, 104, 104]);
        assert_eq!(d.action, Action::RotateRight, "first of the tied maxima");
        assert_eq!(d.value, -2);
        assert_eq!(s.acts.cat[HIDDEN], 0, "ReLU cut fc_side's −50");
        // Padding: a pixel on the border is read by the tap of the first output.
        let mut belief = [0i8; 900];
        belief[0] = 10;
        l[L_CONV1].weights.fill(0);
        l[L_CONV1].weights[8] = 1; // (ky, kx) = (2, 2) reads input (1, 1) at output (0, 0)
        l[L_CONV1].weights[0] = 1; // (0, 0): input (−1, −1), padding
        let blob = build(1, UNIT, UNIT, &l);
        let p = QuantizedPolicy::parse(&blob).unwrap();
        belief[31] = 9;
        p.infer(&belief, &side, &mut s).unwrap();
        // conv1's output (0, 0) = 9, which conv2's centre tap passes to its output (0, 0).
        assert_eq!(s.acts.a2[0], 9);
        assert_eq!(
            p.infer(&belief[..899], &side, &mut s),
            Err(RunError::BadInput)
        );
    }

    #[test]
    fn paired_conv_equals_the_one_channel_kernel() {
        // Both convolutions of random blobs, on random inputs: the kernel that computes
        // two output channels per input load gives the reference's outputs bit for bit.
        for seed in [1u64, 2, 3] {
            let blob = random_blob(seed);
            let p = QuantizedPolicy::parse(&blob).unwrap();
            let mut rng = Pcg32::seed_from_u64(seed);
            for li in [L_CONV1, L_CONV2] {
                let l = p.layer(li).unwrap();
                let n_in = l.dims.inputs * l.dims.in_size * l.dims.in_size;
                let input: Vec<i8> = (0..n_in).map(|_| rng.next_u32() as i8).collect();
                let n = l.dims.output_len();
                let (mut a, mut b) = (vec![0i8; n], vec![0i8; n]);
                conv3x3_s2_p1(l, &input, &mut a);
                conv3x3_s2_p1_one_channel(l, &input, &mut b);
                assert_eq!(a, b, "seed {seed} layer {li}");
            }
        }
    }

    /// The fast layers (padded layout, widened weights; the DSP kernels on the M4, where the
    /// firmware's `dsp-selftest` runs this same check) equal the reference kernels on random
    /// tensors, on the committed blobs and on random blobs of architecture 1.
    #[test]
    fn fast_kernels_equal_the_reference() {
        use crate::policy::builtin::{K1, K10};
        let r = super::selftest::run(7, &[K1, K10], None).unwrap();
        assert!(r.cases > 140, "{r:?}");
        let blobs: Vec<Vec<u8>> = (0..4).map(random_blob).collect();
        let views: Vec<&[u8]> = blobs.iter().map(|b| &b[..]).collect();
        super::selftest::run(11, &views, None).unwrap();
    }

    #[test]
    fn random_blob_parses_and_runs() {
        let blob = random_blob(1);
        let p = QuantizedPolicy::parse(&blob).unwrap();
        assert_eq!(p.rot_bins(), 1);
        assert_eq!(blob.len(), blob_len(ARCH_CONV8_16_FC64, 1));
        // Architecture 2 (the smaller graph) runs in a prefix of the same scratch.
        let mut l = zero_layers_arch(ARCH_CONV8_4_FC32, 10);
        l[L_ACTOR].bias[2] = 1;
        let small = build_arch(ARCH_CONV8_4_FC32, 10, UNIT, UNIT, &l);
        let p2 = QuantizedPolicy::parse(&small).unwrap();
        assert_eq!((p2.arch(), p2.rot_bins()), (ARCH_CONV8_4_FC32, 10));
        let d = p2.infer(&[0; 9000], &[0; SIDE_FEATURES], &mut Scratch::new());
        assert_eq!(d.unwrap().action, Action::Measure);
        assert_eq!(
            QuantizedPolicy::parse(&small[..small.len() - 1]).err(),
            Some(BlobError::Truncated)
        );
        let mut s = Scratch::new();
        let belief = [-128i8; 900];
        let side = [3i8; SIDE_FEATURES];
        let a = p.infer(&belief, &side, &mut s).unwrap();
        let b = p.infer(&belief, &side, &mut s).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn every_truncation_is_rejected() {
        let blob = random_blob(2);
        for n in 0..blob.len() {
            assert_eq!(
                QuantizedPolicy::parse(&blob[..n]).err(),
                Some(BlobError::Truncated),
                "{n}"
            );
        }
        let mut long = blob.clone();
        long.push(0);
        assert_eq!(
            QuantizedPolicy::parse(&long).err(),
            Some(BlobError::TrailingBytes)
        );
    }

    #[test]
    fn single_bit_flips_are_rejected() {
        // Every bit of the header, the table and the CRC, and every bit of every 61st data
        // byte (a full sweep of the 82 KB takes minutes: the CRC is re-run per flip).
        let mut blob = random_blob(3);
        let n = blob.len();
        let bytes = (0..TABLE_END)
            .chain((TABLE_END..n - 4).step_by(61))
            .chain(n - 4..n);
        let mut tried = 0;
        for i in bytes {
            for bit in 0..8 {
                blob[i] ^= 1 << bit;
                assert!(QuantizedPolicy::parse(&blob).is_err(), "byte {i} bit {bit}");
                blob[i] ^= 1 << bit;
                tried += 1;
            }
        }
        assert!(tried > 10_000);
        assert!(QuantizedPolicy::parse(&blob).is_ok());
    }

    #[test]
    fn header_errors_are_specific() {
        let blob = random_blob(4);
        let with = |at: usize, bytes: &[u8]| {
            let mut b = blob.clone();
            b[at..at + bytes.len()].copy_from_slice(bytes);
            // Re-seal, so the specific check (not the CRC) is what refuses it.
            let n = b.len() - 4;
            let crc = crc32(&b[..n]);
            b[n..].copy_from_slice(&crc.to_le_bytes());
            QuantizedPolicy::parse(&b).err()
        };
        assert_eq!(with(0, b"X"), Some(BlobError::BadMagic));
        assert_eq!(with(8, &[2, 0]), Some(BlobError::UnsupportedVersion(2)));
        assert_eq!(with(10, &[9, 0]), Some(BlobError::UnknownArchitecture(9)));
        assert_eq!(with(12, &[11]), Some(BlobError::ShapeMismatch));
        assert_eq!(with(12, &[2]), Some(BlobError::ShapeMismatch));
        assert_eq!(with(14, &[31, 0]), Some(BlobError::ShapeMismatch));
        assert_eq!(with(16, &[107, 0]), Some(BlobError::ShapeMismatch));
        // Belief input scale 0.0, zero point 200.
        assert_eq!(with(24, &[0; 4]), Some(BlobError::BadQuantization));
        assert_eq!(with(28, &[200, 0, 0, 0]), Some(BlobError::BadQuantization));
        // conv1's kind, its weights' offset far outside, a shift of 40, a weight of −128.
        assert_eq!(with(HEADER_LEN, &[7]), Some(BlobError::BadTensorTable));
        assert_eq!(
            with(HEADER_LEN + 28, &[0xff, 0xff, 0xff, 0x7f]),
            Some(BlobError::BadTensorTable)
        );
        assert_eq!(
            with(HEADER_LEN + 28, &[0xff, 0xff, 0xff, 0xff]),
            Some(BlobError::BadTensorTable)
        );
        let s_at = u32::from_le_bytes(blob[HEADER_LEN + 44..HEADER_LEN + 48].try_into().unwrap());
        assert_eq!(with(s_at as usize, &[40]), Some(BlobError::BadQuantization));
        assert_eq!(with(TABLE_END, &[0x80]), Some(BlobError::BadQuantization));
        // A layer's input zero point that is not its predecessor's output zero point.
        let e = HEADER_LEN + L_CONV2 * ENTRY_LEN;
        assert_eq!(
            with(e + 12, &[5, 0, 0, 0]),
            Some(BlobError::BadQuantization)
        );
        let mut bad = blob.clone();
        let n = bad.len() - 1;
        bad[n] ^= 1;
        assert_eq!(
            QuantizedPolicy::parse(&bad).err(),
            Some(BlobError::BadChecksum)
        );
    }

    #[test]
    fn garbage_never_panics() {
        let mut rng = Pcg32::seed_from_u64(9);
        let blob = random_blob(5);
        let mut buf = vec![0u8; 4096];
        for round in 0..20_000 {
            let n = (rng.next_u32() % 4096) as usize;
            rng.fill_bytes(&mut buf[..n]);
            if round % 2 == 0 && n >= 24 {
                // A real header, with the declared length made to fit: reaches the CRC.
                buf[..24].copy_from_slice(&blob[..24]);
                buf[20..24].copy_from_slice(&(n as u32).to_le_bytes());
            }
            assert!(QuantizedPolicy::parse(&buf[..n]).is_err());
        }
        // Structurally random but sealed with a valid CRC: must still never panic.
        for _ in 0..2_000 {
            let mut b = blob.clone();
            for _ in 0..4 {
                let i = rng.next_u32() as usize % TABLE_END;
                b[i] = rng.next_u32() as u8;
            }
            let n = b.len() - 4;
            let crc = crc32(&b[..n]);
            b[n..].copy_from_slice(&crc.to_le_bytes());
            if let Ok(p) = QuantizedPolicy::parse(&b) {
                let _ = p.infer(&[0; 900], &[0; SIDE_FEATURES], &mut Scratch::new());
            }
        }
    }
}
