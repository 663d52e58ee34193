//! The integer kernels of the int8 policy (TFLite-Micro / CMSIS-NN conventions): input
//! quantisation, gemmlowp's fixed-point requantisation, the 3×3 stride-2 convolution and
//! the fully connected layers, and the actor's argmax. Bit-exact on every target.

use super::{LayerView, QuantParams, KK, MAX_CONV_OUT};
use crate::episode::Action;

/// Actor output index → action (the network's order: left, right, measure).
pub const ACTIONS: [Action; 3] = [Action::RotateLeft, Action::RotateRight, Action::Measure];

/// Index of the largest value, the first on ties (as the float agent decides).
pub fn argmax(v: &[i32; 3]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate().skip(1) {
        if x > v[best] {
            best = i;
        }
    }
    best
}

/// Quantises one real value: `clamp(round(v / scale) + zero_point, −128, 127)`, rounding
/// half away from zero (TFLite's `Quantize`). NaN maps to the zero point.
pub fn quantize_value(v: f32, p: QuantParams) -> i8 {
    // `as` saturates and maps NaN to 0.
    let q = libm::roundf(v / p.scale) as i32;
    q.saturating_add(p.zero_point).clamp(-128, 127) as i8
}

/// gemmlowp's `SaturatingRoundingDoublingHighMul`: `round(a · b / 2³¹)`, halves rounded
/// up, saturating the single overflow case `a = b = i32::MIN`.
pub fn saturating_rounding_doubling_high_mul(a: i32, b: i32) -> i32 {
    if a == i32::MIN && b == i32::MIN {
        return i32::MAX;
    }
    // gemmlowp adds 2³⁰ (or 1 − 2³⁰ below 0) and divides by 2³¹ truncating toward zero;
    // for a negative sum that truncation is the floor of (sum + 2³¹ − 1) / 2³¹, so both
    // cases are one floor: (a·b + 2³⁰) >> 31, a multiply-accumulate and a shift on the
    // Cortex-M4 (a 64-bit division would be a library call of hundreds of instructions).
    // Outside a = b = i32::MIN the result fits an i32.
    ((a as i64 * b as i64 + (1 << 30)) >> 31) as i32
}

/// gemmlowp's `RoundingDivideByPOT`: `x / 2^exponent` rounded half away from zero
/// (`exponent` is clamped to `0..=31`). All in 32 bits: the mask, the remainder and the
/// threshold stay below 2³¹.
pub fn rounding_divide_by_pot(x: i32, exponent: i32) -> i32 {
    let e = exponent.clamp(0, 31) as u32;
    let mask = ((1u32 << e) - 1) as i32;
    let remainder = x & mask;
    let threshold = (mask >> 1) + i32::from(x < 0);
    (x >> e) + i32::from(remainder > threshold)
}

/// `arm_nn_requantize` / TFLite `MultiplyByQuantizedMultiplier`: `x · multiplier · 2^shift
/// / 2³¹` with the multiplier in Q31 and `shift` in `−31..=30` (clamped). A positive shift
/// is applied to `x` first, saturating where the reference implementations would overflow
/// (never, for a calibrated network); a negative shift is a rounding division afterwards.
pub fn multiply_by_quantized_multiplier(x: i32, multiplier: i32, shift: i32) -> i32 {
    let s = shift.clamp(-31, 30);
    let left = s.max(0);
    let right = (-s).max(0);
    let x = x.saturating_mul(1i32 << left);
    rounding_divide_by_pot(saturating_rounding_doubling_high_mul(x, multiplier), right)
}

/// Requantises an accumulator (bias included) to int8 with the layer's output zero point;
/// the clamp's lower end is the zero point when a ReLU follows (real 0).
pub(super) fn requantize_i8(
    acc: i32,
    multiplier: i32,
    shift: i32,
    zero_point: i32,
    relu: bool,
) -> i8 {
    let lo = if relu { zero_point } else { -128 };
    multiply_by_quantized_multiplier(acc, multiplier, shift)
        .saturating_add(zero_point)
        .clamp(lo.max(-128), 127) as i8
}

/// 3×3 convolution, stride 2, zero padding 1 (padding contributes real 0, i.e. nothing
/// after the input zero point is subtracted). `input`: `[c][y][x]`; `out`: `[o][y][x]`.
pub(super) fn conv3x3_s2_p1(layer: &LayerView<'_>, input: &[i8], out: &mut [i8]) {
    let d = layer.dims;
    let (n_in, n_out) = (d.in_size, d.out_size);
    let (c_in, in_plane, out_plane) = (d.inputs, n_in * n_in, n_out * n_out);
    let fan_in = d.fan_in();
    // Validated by `parse`; checked once here so nothing below can index out of bounds.
    if input.len() < c_in * in_plane
        || out.len() < d.outputs * out_plane
        || layer.weights.len() < d.outputs * fan_in
        || out_plane > MAX_CONV_OUT
        || n_in < 2
    {
        return;
    }
    let zp_in = layer.input.zero_point;
    let zp_out = layer.output.zero_point;
    // Σ (x − zp)·w = Σ x·w − zp · Σ w over the taps inside the input: the inner loop
    // multiplies raw int8 values, and the zero point is paid once per output with the
    // summed weights of its valid taps. Two output channels share every input load, and
    // their weights stay in registers across a whole plane.
    let mut acc = [[0i32; MAX_CONV_OUT]; 2];
    let mut co = 0;
    while co < d.outputs {
        let width = (d.outputs - co).min(2);
        let (acc_a, acc_b) = acc.split_at_mut(1);
        let (acc_a, acc_b) = (&mut acc_a[0][..out_plane], &mut acc_b[0][..out_plane]);
        acc_a.fill(0);
        acc_b.fill(0);
        let mut wsum = [[0i32; KK]; 2];
        for (ci, plane) in input.chunks_exact(in_plane).take(c_in).enumerate() {
            let mut w = [[0i32; KK]; 2];
            for j in 0..width {
                let base = (co + j) * fan_in + ci * KK;
                for (k, &b) in layer.weights[base..base + KK].iter().enumerate() {
                    w[j][k] = b as i8 as i32;
                    wsum[j][k] += w[j][k];
                }
            }
            for (oy, (ra, rb)) in acc_a
                .chunks_exact_mut(n_out)
                .zip(acc_b.chunks_exact_mut(n_out))
                .enumerate()
            {
                let r = 2 * oy; // input row of the kernel's middle row
                for wr in [0usize, 3, 6] {
                    let Some(row) = (r + wr / 3)
                        .checked_sub(1)
                        .and_then(|y| plane.get(y * n_in..(y + 1) * n_in))
                    else {
                        continue;
                    };
                    let (a0, a1, a2) = (w[0][wr], w[0][wr + 1], w[0][wr + 2]);
                    let (b0, b1, b2) = (w[1][wr], w[1][wr + 1], w[1][wr + 2]);
                    // Output column 0 has no left tap (padding); columns 1.. read the
                    // windows row[2·ox − 1 ..= 2·ox + 1], stepping by 2.
                    let (x1, x2) = (row[0] as i32, row[1] as i32);
                    ra[0] += x1 * a1 + x2 * a2;
                    rb[0] += x1 * b1 + x2 * b2;
                    let windows = row[1..].windows(3).step_by(2);
                    let full = windows.len();
                    for ((pa, pb), win) in ra[1..].iter_mut().zip(rb[1..].iter_mut()).zip(windows) {
                        let (x0, x1, x2) = (win[0] as i32, win[1] as i32, win[2] as i32);
                        *pa += x0 * a0 + x1 * a1 + x2 * a2;
                        *pb += x0 * b0 + x1 * b1 + x2 * b2;
                    }
                    // A last column whose right tap falls in the padding (odd n_in).
                    if full + 1 < n_out {
                        let c = 2 * (full + 1);
                        if let (Some(&x0), Some(&x1)) = (row.get(c - 1), row.get(c)) {
                            let (x0, x1) = (x0 as i32, x1 as i32);
                            ra[full + 1] += x0 * a0 + x1 * a1;
                            rb[full + 1] += x0 * b0 + x1 * b1;
                        }
                    }
                }
            }
        }
        // A tap (o, k) reads input index 2·o + k − 1, valid inside 0..n_in.
        let valid = |o: usize, k: usize| (2 * o + k).checked_sub(1).is_some_and(|i| i < n_in);
        for ((j, accj), (bias, mult, shift)) in [&*acc_a, &*acc_b]
            .into_iter()
            .enumerate()
            .take(width)
            .zip(layer.channels().skip(co))
        {
            for (oy, acc_row) in accj.chunks_exact(n_out).enumerate() {
                // Weight sums of this output row's valid kernel rows, per kernel column.
                let mut col = [0i32; 3];
                for ky in 0..3 {
                    if valid(oy, ky) {
                        for (kx, c) in col.iter_mut().enumerate() {
                            *c += wsum[j][ky * 3 + kx];
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
                    if let Some(o) = out.get_mut((co + j) * out_plane + oy * n_out + ox) {
                        *o = requantize_i8(v.saturating_add(bias), mult, shift, zp_out, d.relu);
                    }
                }
            }
        }
        co += width;
    }
}

/// Dot products of each weight row with `(input − zero point)`, plus the bias.
pub(super) fn fc_accumulators<'b>(
    layer: &'b LayerView<'_>,
    input: &'b [i8],
) -> impl Iterator<Item = (i32, i32, i32)> + 'b {
    let zp_in = layer.input.zero_point;
    layer
        .weights
        .chunks_exact(layer.dims.fan_in())
        .zip(layer.channels())
        .map(move |(row, (bias, mult, shift))| {
            let acc: i32 = row
                .iter()
                .zip(input)
                .map(|(&w, &x)| (x as i32 - zp_in) * (w as i8 as i32))
                .sum();
            (acc.saturating_add(bias), mult, shift)
        })
}

/// Fully connected layer with int8 output (ReLU folded into the clamp).
pub(super) fn fully_connected_i8(layer: &LayerView<'_>, input: &[i8], out: &mut [i8]) {
    let (zp, relu) = (layer.output.zero_point, layer.dims.relu);
    for (o, (acc, mult, shift)) in out.iter_mut().zip(fc_accumulators(layer, input)) {
        *o = requantize_i8(acc, mult, shift, zp, relu);
    }
}

/// Fully connected head with int32 output (one scale for all outputs, zero point 0).
pub(super) fn fully_connected_i32(layer: &LayerView<'_>, input: &[i8], out: &mut [i32]) {
    for (o, (acc, mult, shift)) in out.iter_mut().zip(fc_accumulators(layer, input)) {
        *o = multiply_by_quantized_multiplier(acc, mult, shift);
    }
}
