//! The blob writer: lays out a quantised network as a policy blob (`docs/policy-blob.md`),
//! the exact inverse of [`super::QuantizedPolicy::parse`]. The host quantiser and the tests
//! use it; the device only reads blobs.

use super::*;
use crate::checksum::crc32;

/// One layer's tensors and quantisation, as [`write_blob`] lays them out.
#[derive(Clone, Copy, Debug)]
pub struct LayerTensors<'t> {
    /// int8 weights in `[-127, 127]`, `[out][in][ky][kx]` or `[out][in]`.
    pub weights: &'t [i8],
    /// int32 biases at scale `input.scale × weight_scale[c]`.
    pub bias: &'t [i32],
    /// Q31 multipliers (≥ 0).
    pub multiplier: &'t [i32],
    /// Shifts in `−31..=30` (positive = left).
    pub shift: &'t [i8],
    /// Input quantisation.
    pub input: QuantParams,
    /// Output quantisation (heads: zero point 0).
    pub output: QuantParams,
}

/// Bytes of the blob of architecture `arch` for `K` belief planes (0 for an unknown one).
pub const fn blob_len(arch: u16, rot_bins: usize) -> usize {
    let Some(dims) = layer_dims(arch, rot_bins) else {
        return 0;
    };
    let mut n = TABLE_END + CRC_LEN;
    let mut i = 0;
    while i < N_LAYERS {
        n += dims[i].weight_len() + 9 * dims[i].outputs;
        i += 1;
    }
    n
}

/// Writes a blob (layout in `docs/policy-blob.md`) into `out` and returns its length. The
/// tensors follow the table layer by layer: weights, biases, multipliers, shifts. Refuses
/// tensors whose lengths do not fit the architecture ([`BlobError::ShapeMismatch`]) and an
/// `out` shorter than [`blob_len`] ([`BlobError::Truncated`]); the values themselves are
/// checked when the result is parsed.
pub fn write_blob(
    out: &mut [u8],
    arch: u16,
    rot_bins: u8,
    instrument: InstrumentProfile,
    belief_input: QuantParams,
    side_input: QuantParams,
    layers: &[LayerTensors<'_>; N_LAYERS],
) -> Result<usize, BlobError> {
    if !(1..=MAX_ROT_BINS).contains(&(rot_bins as usize)) {
        return Err(BlobError::ShapeMismatch);
    }
    let dims = layer_dims(arch, rot_bins as usize).ok_or(BlobError::UnknownArchitecture(arch))?;
    let total = blob_len(arch, rot_bins as usize);
    let out = out.get_mut(..total).ok_or(BlobError::Truncated)?;
    out.fill(0);
    put(out, 0, &MAGIC);
    put(out, 8, &FORMAT_VERSION.to_le_bytes());
    put(out, 10, &arch.to_le_bytes());
    put(out, 12, &[rot_bins, N_LAYERS as u8]);
    put(out, 14, &(BELIEF_SIDE as u16).to_le_bytes());
    put(out, 16, &(SIDE_FEATURES as u16).to_le_bytes());
    put(out, 18, &[instrument.code(), 0]);
    put(out, 20, &(total as u32).to_le_bytes());
    put(out, 24, &belief_input.scale.to_le_bytes());
    put(out, 28, &belief_input.zero_point.to_le_bytes());
    put(out, 32, &side_input.scale.to_le_bytes());
    put(out, 36, &side_input.zero_point.to_le_bytes());
    let mut at = TABLE_END;
    for (i, (t, d)) in layers.iter().zip(dims.iter()).enumerate() {
        let n = d.outputs;
        if t.weights.len() != d.weight_len()
            || t.bias.len() != n
            || t.multiplier.len() != n
            || t.shift.len() != n
        {
            return Err(BlobError::ShapeMismatch);
        }
        let e = HEADER_LEN + i * ENTRY_LEN;
        let kind = match d.kind {
            LayerKind::Conv => KIND_CONV3X3_S2_P1,
            LayerKind::FullyConnected => KIND_FULLY_CONNECTED,
        };
        let act = if d.relu { ACT_RELU_I8 } else { ACT_NONE_I32 };
        put(out, e, &[kind, act]);
        for (j, v) in [d.inputs, d.outputs, d.in_size, d.out_size]
            .iter()
            .enumerate()
        {
            put(out, e + 4 + 2 * j, &(*v as u16).to_le_bytes());
        }
        put(out, e + 12, &t.input.zero_point.to_le_bytes());
        put(out, e + 16, &t.output.zero_point.to_le_bytes());
        put(out, e + 20, &t.input.scale.to_le_bytes());
        put(out, e + 24, &t.output.scale.to_le_bytes());
        let w_at = at;
        let b_at = w_at + t.weights.len();
        let m_at = b_at + 4 * n;
        let s_at = m_at + 4 * n;
        at = s_at + n;
        for (j, v) in [w_at, t.weights.len(), b_at, m_at, s_at].iter().enumerate() {
            put(out, e + 28 + 4 * j, &(*v as u32).to_le_bytes());
        }
        for (j, &w) in t.weights.iter().enumerate() {
            put(out, w_at + j, &[w as u8]);
        }
        for (j, (&b, &m)) in t.bias.iter().zip(t.multiplier).enumerate() {
            put(out, b_at + 4 * j, &b.to_le_bytes());
            put(out, m_at + 4 * j, &m.to_le_bytes());
        }
        for (j, &sh) in t.shift.iter().enumerate() {
            put(out, s_at + j, &[sh as u8]);
        }
    }
    let crc = crc32(out.get(..at).unwrap_or(&[]));
    put(out, at, &crc.to_le_bytes());
    Ok(total)
}

/// Copies `bytes` to `out[at..]` (a no-op where it does not fit: `write_blob` sized `out`).
fn put(out: &mut [u8], at: usize, bytes: &[u8]) {
    if let Some(dst) = out.get_mut(at..at + bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}
