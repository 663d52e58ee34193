//! The int8 kernels checked against each other where they run: the fast layers on the
//! backend the target uses ([`Fast`]: the DSP `asm!` kernels on the Cortex-M4) against the
//! same layers on [`Portable`], and both against the reference kernels of [`super::kernels`]
//! (planar layout, one product at a time), on random tensors and on the policies a caller
//! passes (the committed blobs). The firmware runs it in its `dsp-selftest` mode under
//! QEMU (`tests/tests/qemu_hil.rs`); the host's unit tests run it too (there `Fast` is
//! `Portable`, so only the comparison with the reference kernels has teeth on the host).
//!
//! Everything lives on the stack (about 25 KB at its deepest: a [`Scratch`] and the
//! reference's activations; each check has its own frame); nothing panics: a difference is a [`Mismatch`].

use super::dot::{Dot, Portable};
use super::fast::{self, ConvOut, ConvWork};
use super::kernels::{conv3x3_s2_p1, fully_connected_i8};
use super::*;

/// What differed first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mismatch {
    /// [`Dot::conv4`] on random vectors (case number).
    Conv4(u32),
    /// [`Dot::fc2`] on random vectors.
    Fc2(u32),
    /// A random convolution layer: fast (backend) vs fast (portable) vs reference.
    ConvLayer(u32),
    /// A random fully connected layer.
    FcLayer(u32),
    /// A whole decision on blob `blob`, random input `case`.
    Network {
        /// Index into the blobs passed.
        blob: u8,
        /// Input number.
        case: u32,
    },
    /// A blob passed does not parse.
    BadBlob(u8),
    /// [`Dot::max_u8x4`] on random words.
    Max4(u32),
    /// [`crate::world::math::sqrt`] (the FPU's `VSQRT.F32` on the M4F) against libm's
    /// `sqrtf` (the host's): the input's bits.
    Sqrt(u32),
}

/// What ran, and the network's cost on the last blob (in `clock` ticks, 0 without a clock).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Comparisons made, all equal.
    pub cases: u32,
    /// One decision (`infer`, inputs already int8) on the [`Fast`] backend.
    pub fast_ticks: u32,
    /// The same on [`Portable`] (the fast layout, plain Rust loops).
    pub portable_ticks: u32,
    /// The same by the reference kernels.
    pub reference_ticks: u32,
    /// The [`Fast`] pass layer by layer (table order: conv1, conv2, fc_belief, fc_side,
    /// fc_joint, actor, critic).
    pub layer_ticks: [u32; N_LAYERS],
}

/// xorshift32: deterministic random bytes without a dependency.
struct Rng(u32);

impl Rng {
    fn next(&mut self) -> u32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        x
    }
    /// An int8, with the extremes over-represented (saturation paths).
    fn i8(&mut self) -> i8 {
        match self.next() % 16 {
            0 => -128,
            1 => 127,
            _ => self.next() as i8,
        }
    }
    /// A weight in `[-127, 127]` (the blob's range).
    fn weight(&mut self) -> i8 {
        self.i8().max(-127)
    }
    fn range(&mut self, lo: i32, hi: i32) -> i32 {
        lo + (self.next() % (hi - lo + 1) as u32) as i32
    }
}

/// Runs every comparison: `seed` picks the random tensors, `blobs` are whole policies to
/// decide with on random inputs, `clock` (the device's cycle counter) times one decision.
pub fn run(seed: u32, blobs: &[&[u8]], clock: Option<fn() -> u32>) -> Result<Report, Mismatch> {
    let mut rng = Rng(seed | 1);
    let mut report = Report::default();
    primitives(&mut rng, &mut report)?;
    conv_layers(&mut rng, &mut report)?;
    fc_layers(&mut rng, &mut report)?;
    decisions(blobs, &mut rng, clock, &mut report)?;
    Ok(report)
}

#[inline(never)]
fn decisions(
    blobs: &[&[u8]],
    rng: &mut Rng,
    clock: Option<fn() -> u32>,
    report: &mut Report,
) -> Result<(), Mismatch> {
    let mut scratch = Scratch::new();
    for (b, blob) in blobs.iter().enumerate() {
        let policy = QuantizedPolicy::parse(blob).map_err(|_| Mismatch::BadBlob(b as u8))?;
        network(&policy, b as u8, rng, &mut scratch, clock, report)?;
    }
    Ok(())
}

// Its own stack frame: the buffers of each check are large, the device's stack ~40 KB.
#[inline(never)]
fn primitives(rng: &mut Rng, report: &mut Report) -> Result<(), Mismatch> {
    for case in 0..64u32 {
        let n = 4 * (1 + rng.next() as usize % 32);
        let mut x = [0i8; 128];
        let mut w = [0u32; 256];
        x.iter_mut().for_each(|v| *v = rng.i8());
        w.iter_mut().for_each(|v| {
            let (a, b) = (
                rng.weight() as i16 as u16 as u32,
                rng.weight() as i16 as u16 as u32,
            );
            *v = a | (b << 16);
        });
        // A window of three runs of `seg` bytes, `row` apart, inside `x`.
        let seg = 4 * (1 + rng.next() as usize % 10);
        let row = seg + rng.next() as usize % (1 + (128 - 3 * seg) / 2);
        let init = [rng.next() as i32 >> 8, 0, -1, rng.next() as i32 >> 4];
        let (mut a, mut b) = (init, init);
        Fast::conv4(&x, row, seg, &w[..6 * seg], &mut a);
        Portable::conv4(&x, row, seg, &w[..6 * seg], &mut b);
        if a != b {
            return Err(Mismatch::Conv4(case));
        }
        let mut w0 = [0u8; 128];
        let mut w1 = [0u8; 128];
        w0.iter_mut().for_each(|v| *v = rng.weight() as u8);
        w1.iter_mut().for_each(|v| *v = rng.weight() as u8);
        let off = rng.range(-127, 128);
        if Fast::fc2(&x[..n], off, &w0[..n], &w1[..n])
            != Portable::fc2(&x[..n], off, &w0[..n], &w1[..n])
        {
            return Err(Mismatch::Fc2(case));
        }
        // Random words, and words with some lanes equal.
        let (a, b) = (rng.next(), rng.next());
        let b2 = (a & 0x00FF_00FF) | (b & 0xFF00_FF00);
        for (p, q) in [(a, b), (b, a), (a, b2), (b2, a), (a, a)] {
            if Fast::max_u8x4(p, q) != Portable::max_u8x4(p, q) {
                return Err(Mismatch::Max4(case));
            }
        }
        report.cases += 3;
    }
    sqrt_bits(rng, report)
}

/// The target's square root against libm's, bit for bit: random bit patterns over every
/// exponent (subnormals included), exact squares, and the edges. Not a kernel, but it sits
/// on the same path (the registration's correspondences) and differs by target the same way.
fn sqrt_bits(rng: &mut Rng, report: &mut Report) -> Result<(), Mismatch> {
    let edges = [
        0.0f32,
        -0.0,
        f32::MIN_POSITIVE,
        f32::from_bits(1),
        f32::MAX,
        f32::INFINITY,
        1.0,
        2.0,
        0.25,
        -1.0,
        f32::NEG_INFINITY,
    ];
    let random = (0..2048u32).map(|k| {
        let r = rng.next();
        if k % 4 == 0 {
            // An exact square: the root is exact, a rounding slip would show.
            let m = (r >> 20) as f32 + 1.0;
            m * m
        } else {
            f32::from_bits(r & 0x7FFF_FFFF)
        }
    });
    for x in edges.into_iter().chain(random) {
        let (a, b) = (crate::world::math::sqrt(x), libm::sqrtf(x));
        if a.to_bits() != b.to_bits() && !(a.is_nan() && b.is_nan()) {
            return Err(Mismatch::Sqrt(x.to_bits()));
        }
        report.cases += 1;
    }
    Ok(())
}

/// Random per-channel quantisation bytes: biases, Q31 multipliers in `[2³⁰, 2³¹)`, shifts.
fn channels(rng: &mut Rng, n: usize, bias: &mut [u8], mult: &mut [u8], shift: &mut [u8]) {
    for c in 0..n {
        let b = rng.range(-20_000, 20_000);
        let m = (1u32 << 30 | rng.next() >> 2) as i32;
        bias[4 * c..4 * c + 4].copy_from_slice(&b.to_le_bytes());
        mult[4 * c..4 * c + 4].copy_from_slice(&m.to_le_bytes());
        shift[c] = rng.range(-12, 1) as i8 as u8;
    }
}

fn quant(rng: &mut Rng) -> QuantParams {
    QuantParams {
        scale: 1.0,
        zero_point: rng.range(-128, 127),
    }
}

// Its own stack frame: the buffers of each check are large, the device's stack ~40 KB.
#[inline(never)]
fn conv_layers(rng: &mut Rng, report: &mut Report) -> Result<(), Mismatch> {
    let mut input = [0i8; MAX_BELIEF_LEN];
    let mut padded = [0i8; fast::X1_LEN];
    let mut weights = [0u8; C1 * MAX_ROT_BINS * KK];
    let (mut bias, mut mult, mut shift) = ([0u8; 4 * C1], [0u8; 4 * C1], [0u8; C1]);
    let mut work = ConvWork::new();
    for case in 0..6u32 {
        // conv1's shape with a random K (conv2's runs in every whole decision).
        let k = 1 + rng.next() as usize % MAX_ROT_BINS;
        let dims = layer_dims(ARCH_CONV8_4_FC32, k).map(|d| d[L_CONV1]);
        let Some(dims) = dims else {
            return Err(Mismatch::ConvLayer(case));
        };
        let w = &mut weights[..dims.weight_len()];
        w.iter_mut().for_each(|v| *v = rng.weight() as u8);
        channels(rng, C1, &mut bias, &mut mult, &mut shift);
        let layer = LayerView {
            dims,
            input: quant(rng),
            output: quant(rng),
            weights: w,
            bias: &bias,
            multiplier: &mult,
            shift: &shift,
        };
        let x = &mut input[..k * BELIEF_PLANE];
        x.iter_mut().for_each(|v| *v = rng.i8());
        let side = fast::padded_side(S1);
        let p = &mut padded[..side * side * k + 4];
        p.fill(layer.input.zero_point as i8);
        for (c, plane) in x.chunks_exact(BELIEF_PLANE).enumerate() {
            for (i, &v) in plane.iter().enumerate() {
                let (y, xx) = (i / BELIEF_SIDE, i % BELIEF_SIDE);
                p[((y + 1) * side + xx + 1) * k + c] = v;
            }
        }
        let mut reference = [0i8; C1 * S1 * S1];
        conv3x3_s2_p1(&layer, x, &mut reference);
        let mut out = [0i8; C1 * S1 * S1];
        fast::conv::<Fast>(&layer, p, &mut work, ConvOut::Planar(&mut out));
        let same = out == reference;
        fast::conv::<Portable>(&layer, p, &mut work, ConvOut::Planar(&mut out));
        if !same || out != reference {
            return Err(Mismatch::ConvLayer(case));
        }
        report.cases += 1;
    }
    Ok(())
}

// Its own stack frame: the buffers of each check are large, the device's stack ~40 KB.
#[inline(never)]
fn fc_layers(rng: &mut Rng, report: &mut Report) -> Result<(), Mismatch> {
    const N: usize = 16;
    let mut weights = [0u8; N * 260];
    let (mut bias, mut mult, mut shift) = ([0u8; 4 * N], [0u8; 4 * N], [0u8; N]);
    let mut x = [0i8; 260];
    for case in 0..12u32 {
        // Fan-ins of every shape, multiples of 4 or not, and an odd output count.
        let fan = 1 + rng.next() as usize % 259;
        let outs = 1 + rng.next() as usize % N;
        let dims = LayerDims {
            kind: LayerKind::FullyConnected,
            relu: rng.next() % 2 == 0,
            inputs: fan,
            outputs: outs,
            in_size: 1,
            out_size: 1,
        };
        let w = &mut weights[..fan * outs];
        w.iter_mut().for_each(|v| *v = rng.weight() as u8);
        channels(rng, outs, &mut bias, &mut mult, &mut shift);
        let mut output = quant(rng);
        if !dims.relu {
            output.zero_point = 0;
        }
        let layer = LayerView {
            dims,
            input: quant(rng),
            output,
            weights: w,
            bias: &bias[..4 * outs],
            multiplier: &mult[..4 * outs],
            shift: &shift[..outs],
        };
        x.iter_mut().for_each(|v| *v = rng.i8());
        let (mut r, mut a, mut b) = ([0i8; N], [0i8; N], [0i8; N]);
        fully_connected_i8(&layer, &x[..fan], &mut r[..outs]);
        fast::fully_connected_i8::<Fast>(&layer, &x[..fan], &mut a[..outs]);
        fast::fully_connected_i8::<Portable>(&layer, &x[..fan], &mut b[..outs]);
        let (mut ri, mut ai) = ([0i32; N], [0i32; N]);
        super::kernels::fully_connected_i32(&layer, &x[..fan], &mut ri[..outs]);
        fast::fully_connected_i32::<Fast>(&layer, &x[..fan], &mut ai[..outs]);
        if a != r || b != r || ai != ri {
            return Err(Mismatch::FcLayer(case));
        }
        report.cases += 1;
    }
    Ok(())
}

// Its own stack frame: the buffers of each check are large, the device's stack ~40 KB.
#[inline(never)]
fn network(
    policy: &QuantizedPolicy<'_>,
    blob: u8,
    rng: &mut Rng,
    scratch: &mut Scratch,
    clock: Option<fn() -> u32>,
    report: &mut Report,
) -> Result<(), Mismatch> {
    let now = || clock.map_or(0, |c| c());
    let n = policy.belief_len();
    let k = policy.rot_bins() as usize;
    let s = fast::padded_side(S1);
    let zb = policy.belief_input().zero_point as i8;
    let zs = policy.side_input().zero_point as i8;
    for case in 0..4u32 {
        let bad = Mismatch::Network { blob, case };
        // Case 0: the zero point everywhere (an empty map); then random maps. The map is
        // drawn twice from the same state: into the padded layout for the fast passes, then
        // planar (into the same buffer) for the reference, so no second K × 900 buffer.
        let draw = rng.0;
        let value = |rng: &mut Rng, zero: i8| if case == 0 { zero } else { rng.i8() };
        scratch.belief[..s * s * k].fill(zb);
        for i in 0..n {
            let (c, y, x) = (
                i / BELIEF_PLANE,
                i % BELIEF_PLANE / BELIEF_SIDE,
                i % BELIEF_SIDE,
            );
            scratch.belief[((y + 1) * s + x + 1) * k + c] = value(rng, zb);
        }
        let side_draw = rng.0;
        scratch.side.iter_mut().for_each(|v| *v = value(rng, zs));
        let t0 = now();
        let d_fast = policy.run_in::<Fast>(scratch);
        let t1 = now();
        let acts = (scratch.acts.a2, scratch.acts.cat, scratch.acts.joint);
        let d_port = policy.run_in::<Portable>(scratch);
        let t2 = now();
        let same_acts = acts == (scratch.acts.a2, scratch.acts.cat, scratch.acts.joint);
        if case == 3 {
            report.layer_ticks = layer_ticks(policy, scratch, now);
        }
        rng.0 = draw;
        for v in &mut scratch.belief[..n] {
            *v = value(rng, zb);
        }
        rng.0 = side_draw;
        let mut side = [0i8; SIDE_FEATURES];
        side.iter_mut().for_each(|v| *v = value(rng, zs));
        let t3 = now();
        let d_ref = policy.infer_reference(&scratch.belief[..n], &side);
        let t4 = now();
        if d_fast.is_err() || d_fast != d_port || d_fast != d_ref || !same_acts {
            return Err(bad);
        }
        report.fast_ticks = t1.wrapping_sub(t0);
        report.portable_ticks = t2.wrapping_sub(t1);
        report.reference_ticks = t4.wrapping_sub(t3);
        report.cases += 1;
    }
    Ok(())
}

/// Times each layer of one [`Fast`] pass over the activations `scratch` holds (after an
/// `infer_with`), in clock ticks.
fn layer_ticks(
    policy: &QuantizedPolicy<'_>,
    scratch: &mut Scratch,
    now: impl Fn() -> u32,
) -> [u32; N_LAYERS] {
    let l = &policy.layers;
    let Activations { a2, cat, joint } = &mut scratch.acts;
    let mut a1 = [0i8; fast::X2_LEN];
    let mut work = ConvWork::new();
    let work = &mut work;
    let mut t = [0u32; N_LAYERS];
    let s2 = fast::padded_side(S2);
    let h = l[L_BELIEF].dims.outputs;
    let mut logits = [0i32; 3];
    let mut value = [0i32; 1];
    let mut c = now();
    let mut lap = |i: usize, c: &mut u32| {
        let n = now();
        t[i] = n.wrapping_sub(*c);
        *c = now();
    };
    fast::conv::<Fast>(
        &l[L_CONV1],
        &scratch.belief,
        work,
        ConvOut::Padded(&mut a1[..s2 * s2 * C1], s2),
    );
    lap(L_CONV1, &mut c);
    let a2 = &mut a2[..l[L_CONV2].dims.output_len()];
    fast::conv::<Fast>(&l[L_CONV2], &a1[..], work, ConvOut::Planar(a2));
    lap(L_CONV2, &mut c);
    let (hb, hs) = cat[..2 * h].split_at_mut(h);
    fast::fully_connected_i8::<Fast>(&l[L_BELIEF], a2, hb);
    lap(L_BELIEF, &mut c);
    fast::fully_connected_i8::<Fast>(&l[L_SIDE], &scratch.side, hs);
    lap(L_SIDE, &mut c);
    let joint = &mut joint[..l[L_JOINT].dims.outputs];
    fast::fully_connected_i8::<Fast>(&l[L_JOINT], &cat[..2 * h], joint);
    lap(L_JOINT, &mut c);
    fast::fully_connected_i32::<Fast>(&l[L_ACTOR], joint, &mut logits);
    lap(L_ACTOR, &mut c);
    fast::fully_connected_i32::<Fast>(&l[L_CRITIC], joint, &mut value);
    lap(L_CRITIC, &mut c);
    t
}
