//! Reading a policy blob: [`QuantizedPolicy::parse`] validates the header, the tensor table,
//! the quantisation parameters and the CRC once (`docs/policy-blob.md`), and the view it
//! returns reads the tensors in place. Every defect is a typed [`BlobError`]; no input bytes
//! can make it panic.

use super::*;

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
        let [code, reserved] = field::<2>(b, 18)?;
        let instrument =
            InstrumentProfile::from_code(code).ok_or(BlobError::UnknownInstrument(code))?;
        if reserved != 0 {
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
            instrument,
            belief_input,
            side_input,
            layers,
        })
    }
}
