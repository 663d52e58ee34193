//! Unit tests of the int8 policy: blob parsing and its refusals, the requantisation
//! helpers against independent references, hand-computed and random networks, and the
//! fast layers against the reference kernels.

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
    let n = write_blob(
        &mut out,
        arch,
        k,
        InstrumentProfile::EdmScan,
        belief,
        side,
        &t,
    )
    .unwrap();
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

/// The one-channel-at-a-time kernel the paired one replaced: the reference its test
/// compares against.
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
