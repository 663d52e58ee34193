//! The int8 network's layers as the instrument runs them: the same integers as the
//! reference kernels of [`super::kernels`] (bit for bit, tested), laid out so the inner loops
//! are long runs of [`Dot`] products with no im2col copies.
//!
//! - **Convolutions read a padded channel-interleaved map.** A conv input lives in a
//!   `side × side × C` buffer (`side = 2·n_out + 1`, pixel `(y, x)` at row `y + 1`, column
//!   `x + 1`, its `C` channels adjacent) whose border holds the input zero point, i.e. real 0,
//!   the convolution's zero padding. One output pixel's 3 × 3 × C window is then 3 runs of
//!   `3·C` adjacent bytes (one per kernel row), read in place: the belief map is written
//!   this way by [`PolicyInput::write_belief_q_hwc`](crate::policy::PolicyInput::write_belief_q_hwc), conv1 writes its output
//!   this way for conv2. The blob keeps its `[out][in][ky][kx]` weights
//!   (`docs/policy-blob.md`, format unchanged).
//! - **Conv weights are widened per decision**, 4 output channels at a time, into
//!   [`ConvWork`] (768 bytes): reordered to the window's `[ky][kx][c]` order, each kernel
//!   row zero-padded to a multiple of 4 bytes ([`seg_len`]), sign-extended to int16 pairs in
//!   SMLAD order, the 4 channels side by side ([`Dot::conv4`]). About 1 000 weights for the committed K = 10 policy, a few
//!   thousand instructions, against ~160 000 multiply-accumulates that then need no
//!   sign extension of their weights.
//! - **Zero points.** `Σ (x − zp)·w = Σ x·w − zp·Σ w`: with the padding at `zp`, every
//!   window sums over all 9·C taps, so the correction `−zp·Σ w` is one constant per output
//!   channel ([`ConvWork`], computed while widening). Fully connected layers subtract the
//!   zero point in the lanes instead ([`Dot::fc2`], SXTAB16).
//! - **Requantisation** is [`Requant`]: [`requantize_i8`](super::kernels::requantize_i8) /
//!   [`multiply_by_quantized_multiplier`] with the per-channel constants worked out once.

use super::dot::Dot;
use super::kernels::multiply_by_quantized_multiplier;
use super::{LayerKind, LayerView, C1, C2, KK, S1, S2};
use crate::localization::MAX_ROT_BINS;

/// Bytes of one kernel row's window run for `c` channels (`3·c`), rounded up to a whole
/// word; the extra weights are 0, so the extra bytes read (the next pixel's) add nothing.
pub const fn seg_len(c: usize) -> usize {
    (3 * c).div_ceil(4) * 4
}

/// Side of the padded map a convolution with `n_out × n_out` outputs reads.
pub const fn padded_side(n_out: usize) -> usize {
    2 * n_out + 1
}

/// Bytes after a padded map that the last window's rounded-up run may read.
const SLACK: usize = 4;
/// Padded belief map (conv1's input) for the largest `K`.
pub(super) const X1_LEN: usize = padded_side(S1) * padded_side(S1) * MAX_ROT_BINS + SLACK;
/// Padded conv1 output (conv2's input).
pub(super) const X2_LEN: usize = padded_side(S2) * padded_side(S2) * C1 + SLACK;
/// Widened weights of one group of 4 output channels (three runs of `seg_len(c_in)`).
const fn wide_len(c_in: usize) -> usize {
    3 * (seg_len(c_in) / 4) * 8
}
const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}
/// Widened weights of the larger group (one buffer, reused group by group: 768 bytes).
const WIDE_LEN: usize = max(wide_len(MAX_ROT_BINS), wide_len(C1));
const _: () = assert!(C1 % 4 == 0 && C2 % 4 == 0);

/// One output channel's requantisation with its constants worked out once per layer:
/// exactly [`requantize_i8`] / [`multiply_by_quantized_multiplier`] (tested), in a third
/// of the instructions.
#[derive(Clone, Copy, Debug)]
pub(super) struct Requant {
    bias: i32,
    mult: i32,
    left: u32,
    right: u32,
    /// `2^right − 1`.
    mask: i32,
    zp: i32,
    lo: i32,
}

impl Requant {
    const ZERO: Requant = Requant {
        bias: 0,
        mult: 0,
        left: 0,
        right: 0,
        mask: 0,
        zp: 0,
        lo: -128,
    };

    /// The constants of a channel `(bias, multiplier, shift)` into a layer with output
    /// zero point `zp` (ReLU: the clamp's lower end is `zp`).
    pub(super) fn new((bias, mult, shift): (i32, i32, i32), zp: i32, relu: bool) -> Self {
        let s = shift.clamp(-31, 30);
        let right = (-s).max(0) as u32;
        Requant {
            bias,
            mult,
            left: s.max(0) as u32,
            right,
            mask: ((1u32 << right) - 1) as i32,
            zp,
            lo: if relu { zp.max(-128) } else { -128 },
        }
    }

    /// [`multiply_by_quantized_multiplier`]`(acc + bias, …)`.
    #[inline(always)]
    pub(super) fn scale(&self, acc: i32) -> i32 {
        let x = acc.saturating_add(self.bias);
        if self.left != 0 || self.mult < 0 {
            return self.scale_general(x);
        }
        // The doubling high product: (x·m + 2³⁰) >> 31 (only x = m = i32::MIN would
        // saturate, and m ≥ 0 here), then the rounding division by 2^right, half away
        // from zero.
        let h = ((x as i64 * self.mult as i64 + (1 << 30)) >> 31) as i32;
        let threshold = (self.mask >> 1) + i32::from(h < 0);
        (h >> self.right) + i32::from((h & self.mask) > threshold)
    }

    /// A left shift or a negative multiplier (neither in a calibrated blob).
    #[cold]
    #[inline(never)]
    fn scale_general(&self, x: i32) -> i32 {
        let x = x.saturating_mul(1 << self.left);
        let h = super::kernels::saturating_rounding_doubling_high_mul(x, self.mult);
        super::kernels::rounding_divide_by_pot(h, self.right as i32)
    }

    /// [`requantize_i8`]`(acc + bias, …)` (`lo ≤ 127`: a valid zero point).
    #[inline(always)]
    pub(super) fn apply_i8(&self, acc: i32) -> i8 {
        self.scale(acc)
            .saturating_add(self.zp)
            .max(self.lo)
            .min(127) as i8
    }
}

/// One group of 4 output channels of a convolution prepared for [`Dot::conv4`], and their
/// per-channel constants.
#[derive(Clone, Debug)]
pub(super) struct ConvWork {
    wide: [u32; WIDE_LEN],
    /// `−zp_in · Σ w` per output channel.
    zc: [i32; 4],
    /// Requantisation per output channel.
    ch: [Requant; 4],
}

impl ConvWork {
    pub(super) const fn new() -> Self {
        ConvWork {
            wide: [0; WIDE_LEN],
            zc: [0; 4],
            ch: [Requant::ZERO; 4],
        }
    }
}

/// Fills `work` with output channels `4g .. 4g + 4` of `layer` (a conv; channels past its
/// last have weights 0): widened weights and channel constants. False when the layer does
/// not fit the buffers (not for any architecture [`super::layer_dims`] knows).
fn widen(layer: &LayerView<'_>, g: usize, work: &mut ConvWork) -> bool {
    let d = layer.dims;
    let (c_in, c_out, fan) = (d.inputs, d.outputs, d.fan_in());
    let words = seg_len(c_in) / 4;
    let len = wide_len(c_in);
    if d.kind != LayerKind::Conv || c_in == 0 || len > WIDE_LEN || layer.weights.len() < c_out * fan
    {
        return false;
    }
    let zp = layer.input.zero_point;
    work.wide[..len].fill(0);
    work.zc = [0; 4];
    work.ch = [Requant::ZERO; 4];
    let first = 4 * g;
    let rows = layer.weights.chunks_exact(fan).skip(first);
    for (r, ((wo, zc), (ch, c))) in rows
        .zip(work.zc.iter_mut())
        .zip(work.ch.iter_mut().zip(layer.channels().skip(first)))
        .enumerate()
    {
        *ch = Requant::new(c, layer.output.zero_point, d.relu);
        let mut sum = 0i32;
        // Scatter the weights (read in blob order, `[c][ky][kx]`) to their lanes: output
        // `r` of the group; tap `(ky, kx)` of channel `c` is byte `t = kx·C + c` of run
        // `ky`, i.e. half `t mod 4 ≥ 2` of word `2·r + t mod 2` in the run's word `t / 4`.
        for (c, wc) in wo.chunks_exact(KK).enumerate() {
            for (k, &b) in wc.iter().enumerate() {
                let (ky, kx) = (k / 3, k % 3);
                let t = kx * c_in + c;
                let i = (ky * words + t / 4) * 8 + 2 * r + (t & 1);
                let v = b as i8 as i32;
                sum += v;
                if let Some(p) = work.wide.get_mut(i) {
                    *p |= (v as i16 as u16 as u32) << (16 * ((t >> 1) & 1));
                }
            }
        }
        *zc = zp.wrapping_mul(sum).wrapping_neg();
    }
    true
}

/// Where a convolution writes.
pub(super) enum ConvOut<'o> {
    /// A padded channel-interleaved map of side `side` for the next convolution (its
    /// border set to the output zero point here).
    Padded(&'o mut [i8], usize),
    /// `[o][y][x]`, the flattening fc_belief reads.
    Planar(&'o mut [i8]),
}

/// 3×3 convolution, stride 2, zero padding 1, from a padded map `x` (module doc).
pub(super) fn conv<D: Dot>(layer: &LayerView<'_>, x: &[i8], work: &mut ConvWork, out: ConvOut<'_>) {
    let d = layer.dims;
    let (c_in, c_out, n_out) = (d.inputs, d.outputs, d.out_size);
    let side = padded_side(n_out);
    let seg = seg_len(c_in);
    if c_in == 0 || n_out == 0 || x.len() < side * side * c_in + (seg - 3 * c_in) {
        return;
    }
    // Output `o` of pixel (oy, ox) goes to `pixel(oy, ox) + o · o_stride`.
    let (out, o_stride, o_side) = match out {
        ConvOut::Padded(buf, s) => {
            if s < n_out + 2 || buf.len() < s * s * c_out {
                return;
            }
            buf.fill(layer.output.zero_point as i8);
            (buf, 1, s)
        }
        ConvOut::Planar(buf) => (buf, n_out * n_out, 0),
    };
    let pixel = |oy: usize, ox: usize| {
        if o_stride == 1 {
            ((oy + 1) * o_side + ox + 1) * c_out
        } else {
            oy * n_out + ox
        }
    };
    let row = side * c_in;
    let window = 2 * row + seg;
    let wlen = wide_len(c_in);
    for g in 0..c_out.div_ceil(4) {
        if !widen(layer, g, work) {
            return;
        }
        let wide = &work.wide[..wlen];
        let lanes = (c_out - 4 * g).min(4);
        let ch = &work.ch[..lanes];
        for oy in 0..n_out {
            for ox in 0..n_out {
                // The window's top-left tap: padded row 2·oy, column 2·ox.
                let base = 2 * oy * row + 2 * ox * c_in;
                let mut acc = work.zc;
                if let Some(win) = x.get(base..base + window) {
                    D::conv4(win, row, seg, wide, &mut acc);
                }
                let mut i = pixel(oy, ox) + 4 * g * o_stride;
                for (&a, q) in acc.iter().zip(ch) {
                    if let Some(v) = out.get_mut(i) {
                        *v = q.apply_i8(a);
                    }
                    i += o_stride;
                }
            }
        }
    }
}

/// `Σ (x − zp)·w + bias` of every output of a fully connected layer, passed to `emit` with
/// the output's multiplier and shift.
fn fc<D: Dot>(layer: &LayerView<'_>, input: &[i8], mut emit: impl FnMut(usize, i32, i32, i32)) {
    let fan = layer.dims.fan_in();
    let Some(x) = input.get(..fan) else {
        return;
    };
    let off = layer.input.zero_point.wrapping_neg();
    let body = fan - fan % 4;
    let (xb, xt) = x.split_at(body);
    let dot2 = |w0: &[u8], w1: &[u8]| -> [i32; 2] {
        let [a, b] = D::fc2(xb, off, &w0[..body], &w1[..body]);
        let [ta, tb] = <super::dot::Portable as Dot>::fc2(xt, off, &w0[body..], &w1[body..]);
        [a.wrapping_add(ta), b.wrapping_add(tb)]
    };
    let mut ch = layer.channels();
    let mut rows = layer.weights.chunks_exact(fan).enumerate();
    while let Some((o, w0)) = rows.next() {
        let next = rows.next();
        let w1 = next.map_or(w0, |(_, w)| w);
        let [a, b] = dot2(w0, w1);
        if let Some((bias, mult, shift)) = ch.next() {
            emit(o, a.saturating_add(bias), mult, shift);
        }
        if let (Some((o1, _)), Some((bias, mult, shift))) = (next, ch.next()) {
            emit(o1, b.saturating_add(bias), mult, shift);
        }
    }
}

/// Fully connected layer with int8 output (ReLU folded into the clamp).
pub(super) fn fully_connected_i8<D: Dot>(layer: &LayerView<'_>, input: &[i8], out: &mut [i8]) {
    let (zp, relu) = (layer.output.zero_point, layer.dims.relu);
    fc::<D>(layer, input, |o, acc, mult, shift| {
        if let Some(v) = out.get_mut(o) {
            *v = Requant::new((0, mult, shift), zp, relu).apply_i8(acc);
        }
    });
}

/// Fully connected head with int32 output.
pub(super) fn fully_connected_i32<D: Dot>(layer: &LayerView<'_>, input: &[i8], out: &mut [i32]) {
    fc::<D>(layer, input, |o, acc, mult, shift| {
        if let Some(v) = out.get_mut(o) {
            *v = multiply_by_quantized_multiplier(acc, mult, shift);
        }
    });
}
