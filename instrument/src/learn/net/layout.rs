//! The network's shape: [`NetShape`] (the two input sizes) and the [`Layer`] table that
//! places every layer's weights and biases in the flat parameter vector (the layout the
//! module doc of [`super`] describes; the policy file and the int8 quantiser read it too),
//! derived from the core's graph of the architecture (`int8::layer_dims`).

use super::{ARCH_ID, KK, L_SIDE, MAX_ROT_BINS, N_LAYERS, P0};
use activesense_core::policy::int8;
use std::ops::Range;

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

impl NetShape {
    /// Floats in one belief map: `K·30·30`.
    pub fn belief_len(&self) -> usize {
        self.rot_bins * P0
    }

    /// The layers in parameter order (an array, so the hot paths can call it freely).
    pub fn layers(&self) -> [Layer; N_LAYERS] {
        const NAMES: [&str; N_LAYERS] = [
            "conv1",
            "conv2",
            "fc_belief",
            "fc_side",
            "fc_joint",
            "actor",
            "critic",
        ];
        // The core's graph for K planes; the side input's length is the shape's (the
        // tests vary it).
        let graph = int8::layer_dims(ARCH_ID, self.rot_bins).expect("the core knows ARCH_ID");
        let mut i = 0;
        let specs = graph.map(|d| {
            let inputs = if i == L_SIDE { self.side } else { d.inputs };
            let kind = match d.kind {
                int8::LayerKind::Conv => LayerKind::Conv {
                    in_ch: inputs,
                    out_ch: d.outputs,
                    in_size: d.in_size,
                    out_size: d.out_size,
                },
                int8::LayerKind::FullyConnected => LayerKind::Linear {
                    inputs,
                    outputs: d.outputs,
                },
            };
            i += 1;
            (NAMES[i - 1], kind, d.relu)
        });
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

    pub(super) fn assert_valid(&self) {
        assert!(
            (1..=MAX_ROT_BINS).contains(&self.rot_bins),
            "rot_bins must be 1..={MAX_ROT_BINS}, got {}",
            self.rot_bins
        );
    }
}
