use super::kernels::relu_mask;
use super::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const SMALL: NetShape = NetShape {
    rot_bins: 2,
    side: 5,
};
const REAL: NetShape = NetShape {
    rot_bins: 10,
    side: 108,
};

/// A network with every parameter (biases and the actor head included) at a healthy
/// random scale, so every layer has gradient and the ReLUs are a mix of on and off.
fn lively_net(shape: NetShape, seed: u64) -> PolicyNet {
    let mut net = PolicyNet::new(shape, seed);
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xabcd);
    for layer in shape.layers() {
        let bound = (6.0 / layer.fan_in() as f32).sqrt();
        for w in &mut net.params[layer.weights()] {
            *w = rng.gen_range(-bound..bound);
        }
        for b in &mut net.params[layer.bias()] {
            *b = rng.gen_range(-0.1..0.1);
        }
    }
    net
}

fn random_inputs(shape: NetShape, b: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let belief = (0..b * shape.belief_len())
        .map(|_| rng.gen::<f32>())
        .collect();
    let side = (0..b * shape.side)
        .map(|_| rng.gen_range(-1.0..1.0))
        .collect();
    (belief, side)
}

fn random_vec(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

/// f64 reference of a fully-connected layer (with its ReLU when it has one).
fn ref_linear(layer: &Layer, p: &[f64], x: &[f64]) -> Vec<f64> {
    let (w, b) = (&p[layer.weights()], &p[layer.bias()]);
    (0..layer.bias_len)
        .map(|o| {
            let s = b[o] + (0..x.len()).map(|i| w[o * x.len() + i] * x[i]).sum::<f64>();
            if layer.relu {
                s.max(0.0)
            } else {
                s
            }
        })
        .collect()
}

/// Calls `f(out_index, in_index, weight)` for every tap of the conv `layer` that falls
/// inside its input: a direct (not im2col) convolution straight from the documented
/// parameter layout.
fn ref_conv_taps(layer: &Layer, p: &[f64], f: &mut dyn FnMut(usize, usize, f64)) {
    let LayerKind::Conv {
        in_ch,
        out_ch,
        in_size,
        out_size,
    } = layer.kind
    else {
        panic!("not a conv")
    };
    let w = &p[layer.weights()];
    for o in 0..out_ch {
        for oy in 0..out_size {
            for ox in 0..out_size {
                for c in 0..in_ch {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let iy = (2 * oy + ky) as isize - 1;
                            let ix = (2 * ox + kx) as isize - 1;
                            if iy < 0 || ix < 0 || iy >= in_size as isize || ix >= in_size as isize
                            {
                                continue;
                            }
                            let oi = (o * out_size + oy) * out_size + ox;
                            let ii = (c * in_size + iy as usize) * in_size + ix as usize;
                            f(oi, ii, w[((o * in_ch + c) * 3 + ky) * 3 + kx]);
                        }
                    }
                }
            }
        }
    }
}

/// f64 reference of a conv layer and its ReLU.
fn ref_conv(layer: &Layer, p: &[f64], x: &[f64]) -> Vec<f64> {
    let LayerKind::Conv { out_size, .. } = layer.kind else {
        panic!("not a conv")
    };
    let b = &p[layer.bias()];
    let per = out_size * out_size;
    let mut y: Vec<f64> = (0..b.len() * per).map(|i| b[i / per]).collect();
    ref_conv_taps(layer, p, &mut |oi, ii, w| y[oi] += w * x[ii]);
    y.iter().map(|v| v.max(0.0)).collect()
}

/// Every tensor of the independent f64 forward pass.
struct RefActs {
    a1: Vec<f64>,
    a2: Vec<f64>,
    hb: Vec<f64>,
    hs: Vec<f64>,
    hj: Vec<f64>,
    logits: [f64; 3],
    value: f64,
}

fn reference_acts(shape: &NetShape, p: &[f64], belief: &[f64], side: &[f64]) -> RefActs {
    let layers = shape.layers();
    let a1 = ref_conv(&layers[L_CONV1], p, belief);
    let a2 = ref_conv(&layers[L_CONV2], p, &a1);
    let hb = ref_linear(&layers[L_BELIEF], p, &a2);
    let hs = ref_linear(&layers[L_SIDE], p, side);
    let cat: Vec<f64> = hb.iter().chain(&hs).copied().collect();
    let hj = ref_linear(&layers[L_JOINT], p, &cat);
    let l = ref_linear(&layers[L_ACTOR], p, &hj);
    let v = ref_linear(&layers[L_CRITIC], p, &hj);
    RefActs {
        a1,
        a2,
        hb,
        hs,
        hj,
        logits: [l[0], l[1], l[2]],
        value: v[0],
    }
}

fn reference(shape: &NetShape, p: &[f64], belief: &[f64], side: &[f64]) -> ([f64; 3], f64) {
    let r = reference_acts(shape, p, belief, side);
    (r.logits, r.value)
}

fn to64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

#[test]
fn layout_sizes_and_macs() {
    let k1 = NetShape {
        rot_bins: 1,
        side: 108,
    };
    assert_eq!(k1.param_count(), 14_296);
    assert_eq!(REAL.param_count(), 14_944);
    assert_eq!(k1.macs(), 48_456);
    assert_eq!(REAL.macs(), 194_256);
    let names: Vec<_> = REAL.layers().iter().map(|l| l.name).collect();
    assert_eq!(
        names,
        [
            "conv1",
            "conv2",
            "fc_belief",
            "fc_side",
            "fc_joint",
            "actor",
            "critic"
        ]
    );
    let mut next = 0;
    for l in REAL.layers() {
        assert_eq!(l.offset, next, "{} not contiguous", l.name);
        next = l.bias().end;
    }
    assert_eq!(next, REAL.param_count());
}

#[test]
fn same_seed_same_params_other_seed_other_params() {
    let a = PolicyNet::new(REAL, 7);
    let b = PolicyNet::new(REAL, 7);
    let c = PolicyNet::new(REAL, 8);
    assert_eq!(a.params, b.params);
    assert_ne!(a.params, c.params);
    // Biases start at 0, the actor head small, the critic head not.
    let layers = REAL.layers();
    assert!(layers
        .iter()
        .all(|l| a.params[l.bias()].iter().all(|&x| x == 0.0)));
    let max_abs = |l: &Layer| {
        a.params[l.weights()]
            .iter()
            .fold(0.0f32, |m, x| m.max(x.abs()))
    };
    assert!(max_abs(&layers[L_ACTOR]) < 0.01 * (3.0f32 / HIDDEN as f32).sqrt());
    assert!(max_abs(&layers[L_CRITIC]) > 0.1);
}

#[test]
fn forward_matches_f64_reference() {
    let net = lively_net(SMALL, 3);
    let (belief, side) = random_inputs(SMALL, 1, 4);
    let out = net.forward(&belief, &side);
    let (l, v) = reference(&SMALL, &to64(&net.params), &to64(&belief), &to64(&side));
    for (a, b) in out
        .logits
        .iter()
        .chain([&out.value])
        .zip(l.iter().chain([&v]))
    {
        assert!(
            (f64::from(*a) - b).abs() <= 1e-4 * (1.0 + b.abs()),
            "{a} vs {b}"
        );
    }
    assert!(
        l.iter().any(|x| x.abs() > 1e-2),
        "degenerate test network: {l:?}"
    );
}

#[test]
fn single_forward_equals_batch_rows_bitwise() {
    let net = lively_net(REAL, 5);
    let b = 11; // not a multiple of GRAD_CHUNK
    let (belief, side) = random_inputs(REAL, b, 6);
    let (logits, values) = net.forward_batch(&belief, &side, b, &mut BatchCache::new());
    let mut s = Scratch::new(REAL);
    let (bl, sl) = (REAL.belief_len(), REAL.side);
    for i in 0..b {
        let one = net.forward_with(
            &belief[i * bl..(i + 1) * bl],
            &side[i * sl..(i + 1) * sl],
            &mut s,
        );
        assert_eq!(
            one.logits.map(f32::to_bits),
            logits[i].map(f32::to_bits),
            "row {i}"
        );
        assert_eq!(one.value.to_bits(), values[i].to_bits(), "row {i}");
    }
}

/// The activations the quantiser calibrates on come from the forward pass itself: the
/// output bit for bit, every layer against the independent f64 reference.
#[test]
fn forward_activations_are_the_forward_pass() {
    for shape in [SMALL, REAL] {
        let net = lively_net(shape, 21);
        let (belief, side) = random_inputs(shape, 1, 22);
        let out = net.forward(&belief, &side);
        let mut s = Scratch::new(shape);
        let a = net.forward_activations(&belief, &side, &mut s);
        assert_eq!(
            a.output.logits.map(f32::to_bits),
            out.logits.map(f32::to_bits)
        );
        assert_eq!(a.output.value.to_bits(), out.value.to_bits());
        let r = reference_acts(&shape, &to64(&net.params), &to64(&belief), &to64(&side));
        for (name, got, want) in [
            ("conv1", a.conv1, &r.a1),
            ("conv2", a.conv2, &r.a2),
            ("fc_belief", a.belief, &r.hb),
            ("fc_side", a.side, &r.hs),
            ("fc_joint", a.joint, &r.hj),
        ] {
            assert_eq!(got.len(), want.len(), "{name} length");
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for (x, y) in got.iter().zip(want) {
                assert!(
                    (f64::from(*x) - y).abs() <= 1e-4 * scale,
                    "{name}: {x} vs {y}"
                );
            }
            assert!(want.iter().any(|&y| y > 0.0), "{name}: all zero");
        }
    }
}

/// Analytic gradients of `L = Σ_samples Σ_i c_i·logit_i + d·value` against central
/// differences of the independent f64 reference, for weights and biases of every layer.
/// An entry is skipped only if its finite difference is inconsistent at two step sizes
/// (a ReLU kink between them); skips must stay rare.
#[test]
fn parameter_gradients_match_finite_differences() {
    let shape = SMALL;
    let b = 3;
    let net = lively_net(shape, 11);
    let (belief, side) = random_inputs(shape, b, 12);
    let c = random_vec(b * N_ACTIONS, 13);
    let d = random_vec(b, 14);

    let mut cache = BatchCache::new();
    net.forward_batch(&belief, &side, b, &mut cache);
    let mut grad = vec![0.0; shape.param_count()];
    net.backward_batch(&mut cache, &c, &d, &mut grad);

    let (bl, sl) = (shape.belief_len(), shape.side);
    let (bel64, side64) = (to64(&belief), to64(&side));
    let loss = |p: &[f64]| {
        (0..b)
            .map(|i| {
                let (l, v) = reference(
                    &shape,
                    p,
                    &bel64[i * bl..(i + 1) * bl],
                    &side64[i * sl..(i + 1) * sl],
                );
                (0..3).map(|a| f64::from(c[i * 3 + a]) * l[a]).sum::<f64>() + f64::from(d[i]) * v
            })
            .sum::<f64>()
    };
    let mut p = to64(&net.params);
    let mut fd = |j: usize, eps: f64| {
        let orig = p[j];
        p[j] = orig + eps;
        let up = loss(&p);
        p[j] = orig - eps;
        let down = loss(&p);
        p[j] = orig;
        (up - down) / (2.0 * eps)
    };

    let mut rng = Pcg64::seed_from_u64(15);
    let (mut checked, mut skipped) = (0, 0);
    for layer in shape.layers() {
        for (range, n) in [(layer.weights(), 12), (layer.bias(), 6)] {
            let mut nonzero = 0;
            // Half uniformly at random, half among entries with a nonzero analytic
            // gradient (dead ReLUs zero many weight gradients; both kinds are checked).
            let live: Vec<usize> = range.clone().filter(|&j| grad[j] != 0.0).collect();
            let picks: Vec<usize> = if range.len() <= n {
                range.clone().collect()
            } else {
                let mut v: Vec<usize> = (0..n / 2).map(|_| rng.gen_range(range.clone())).collect();
                v.extend((0..n / 2).filter_map(|_| live.get(rng.gen_range(0..live.len().max(1)))));
                v
            };
            for &j in &picks {
                let (n1, n2) = (fd(j, 1e-4), fd(j, 3e-5));
                if (n1 - n2).abs() > 1e-6 * (1.0 + n1.abs()) {
                    skipped += 1;
                    continue;
                }
                checked += 1;
                let a = f64::from(grad[j]);
                assert!(
                    (a - n1).abs() <= 1e-4 + 2e-3 * n1.abs(),
                    "{} param {j}: analytic {a}, numeric {n1}",
                    layer.name
                );
                if n1.abs() > 1e-4 {
                    nonzero += 1;
                }
            }
            assert!(
                nonzero * 2 >= picks.len(),
                "{}: gradient check nearly vacuous",
                layer.name
            );
        }
    }
    assert!(
        skipped * 10 <= checked,
        "{skipped} kinks vs {checked} checked"
    );
}

#[test]
fn guided_relu_mask_hand_set_masks() {
    // Output y > 0 and gradient d > 0: passes; any other combination: blocked. Plain
    // ReLU backprop (relu_mask) passes the negative gradient of an active unit.
    let y = [1.0f32, 1.0, 0.0, 0.0, 2.5, 0.0];
    let d = [0.5f32, -0.5, 0.5, -0.5, 3.0, 0.0];
    let mut g = d;
    guided_relu_mask(&mut g, &y);
    assert_eq!(g, [0.5, 0.0, 0.0, 0.0, 3.0, 0.0]);
    let mut p = d;
    relu_mask(&mut p, &y);
    assert_eq!(p, [0.5, -0.5, 0.0, 0.0, 3.0, 0.0]);
}

/// A network with a handful of nonzero weights, small enough to back-propagate by hand:
///
/// ```text
/// conv1: a1₀(y,x) = relu(b(2y,2x)),  a1₁(y,x) = relu(2·b(2y,2x))   (kernel centres 1, 2)
/// conv2: a2₀(y,x) = relu(a1₀(2y,2x)), a2₁(y,x) = relu(a1₁(2y,2x))  (so a2ᵢ(y,x) ∝ b(4y,4x))
/// fc_belief: hb₀ = relu(a2₀(0,1) + a2₁(0,2)) = b(0,4) + 2·b(0,8),  hb₁ = relu(a2₀(0,1)) = b(0,4)
/// fc_side:   hs₀ = relu(side₀),  hs₁ = relu(side₁)
/// fc_joint:  hj₀ = relu(hb₀ + hs₀),  hj₁ = relu(hb₁ + hs₁)
/// actor:     logit₂ (measure) = hj₀ − hj₁,  logit₀ = hj₁;  critic: v = hj₀
/// ```
///
/// With b(0,4) = 0.5, b(0,8) = 0.25, side = (1, −1): hb = (1, 0.5), hs = (1, 0),
/// hj = (2, 0.5), logit₂ = 1.5. For the measure logit the gradient at hj is (1, −1):
/// plain backprop carries the −1 down hj₁ → hb₁ → b(0,4), where it cancels the +1 from
/// hb₀, so ∂logit₂/∂b(0,4) = 0 and ∂/∂b(0,8) = 2; guided backprop stops the −1 at hj₁,
/// so its map is b(0,4): 1, b(0,8): 2, and side: (1, 0) (hs₁ is off in both).
fn hand_net() -> PolicyNet {
    let shape = NetShape {
        rot_bins: 1,
        side: 2,
    };
    let mut p = vec![0.0f32; shape.param_count()];
    let l = shape.layers();
    let centre = 4; // [ky=1][kx=1]
                    // conv1 weights [out][in=1][3][3]
    p[l[L_CONV1].offset + centre] = 1.0;
    p[l[L_CONV1].offset + KK + centre] = 2.0;
    // conv2 weights [out][in=8][3][3]: out 0 ← in 0, out 1 ← in 1
    p[l[L_CONV2].offset + centre] = 1.0;
    p[l[L_CONV2].offset + (C1 + 1) * KK + centre] = 1.0;
    // fc_belief [32][256]; a2 flat index = c·64 + y·8 + x
    let fb = l[L_BELIEF].offset;
    p[fb + 1] = 1.0; // hb0 ← a2₀(0,1)
    p[fb + 64 + 2] = 1.0; // hb0 ← a2₁(0,2)
    p[fb + FLAT + 1] = 1.0; // hb1 ← a2₀(0,1)
                            // fc_side [32][2]
    let fs = l[L_SIDE].offset;
    p[fs] = 1.0;
    p[fs + 2 + 1] = 1.0;
    // fc_joint [32][64]: input = hb (0..32) | hs (32..64)
    let fj = l[L_JOINT].offset;
    p[fj] = 1.0;
    p[fj + HIDDEN] = 1.0;
    p[fj + 64 + 1] = 1.0;
    p[fj + 64 + HIDDEN + 1] = 1.0;
    // actor [3][32], critic [1][32]
    let fa = l[L_ACTOR].offset;
    p[fa + 2 * HIDDEN] = 1.0;
    p[fa + 2 * HIDDEN + 1] = -1.0;
    p[fa + 1] = 1.0;
    p[l[L_CRITIC].offset] = 1.0;
    PolicyNet::from_params(shape, p).unwrap()
}

#[test]
fn guided_backprop_hand_computed_tiny_net() {
    let net = hand_net();
    let mut belief = vec![0.0f32; GRID * GRID];
    belief[4] = 0.5; // b(0,4)
    belief[8] = 0.25; // b(0,8)
    let side = [1.0f32, -1.0];
    let out = net.forward(&belief, &side);
    assert_eq!(out.logits, [0.5, 0.0, 1.5]);
    assert_eq!(out.value, 2.0);

    let (gb, gs) = net.guided_backprop(&belief, &side, 2);
    let mut want = vec![0.0f32; GRID * GRID];
    want[4] = 1.0;
    want[8] = 2.0;
    assert_eq!(gb, want, "guided map over the belief");
    assert_eq!(gs, [1.0, 0.0], "guided map over the side features");

    // Plain backprop of the same logit: the −1 through hj₁ cancels at b(0,4).
    let (pb, ps) = net.input_gradient(&belief, &side, [0.0, 0.0, 1.0], 0.0);
    let mut plain = vec![0.0f32; GRID * GRID];
    plain[8] = 2.0;
    assert_eq!(pb, plain);
    assert_eq!(ps, [1.0, 0.0]);

    // The rotate-left logit (= hj₁): only positive gradients on its path, so guided
    // and plain agree, b(0,4): 1, side: (0, 0) since hs₁ is off.
    let (gb0, gs0) = net.guided_backprop(&belief, &side, 0);
    let mut want0 = vec![0.0f32; GRID * GRID];
    want0[4] = 1.0;
    assert_eq!(gb0, want0);
    assert_eq!(gs0, [0.0, 0.0]);
    // rotate-right's logit is constant 0: nothing lights up.
    let (gb1, gs1) = net.guided_backprop(&belief, &side, 1);
    assert!(gb1.iter().chain(&gs1).all(|&g| g == 0.0));
}

/// Independent f64 guided back-propagation: direct convolutions (no im2col), the
/// transposed convolution written out, the guided rule applied at every ReLU.
fn reference_guided(
    shape: &NetShape,
    p: &[f64],
    belief: &[f64],
    side: &[f64],
    action: usize,
) -> (Vec<f64>, Vec<f64>) {
    let layers = shape.layers();
    let conv_back = |l: &Layer, dy: &[f64], n_in: usize| {
        let mut dx = vec![0.0; n_in];
        ref_conv_taps(l, p, &mut |oi, ii, w| dx[ii] += w * dy[oi]);
        dx
    };
    let lin_back = |l: &Layer, dy: &[f64], n_in: usize| {
        let w = &p[l.weights()];
        (0..n_in)
            .map(|i| (0..dy.len()).map(|o| w[o * n_in + i] * dy[o]).sum::<f64>())
            .collect::<Vec<f64>>()
    };
    let guide = |d: Vec<f64>, y: &[f64]| {
        d.iter()
            .zip(y)
            .map(|(&d, &y)| if y > 0.0 && d > 0.0 { d } else { 0.0 })
            .collect::<Vec<f64>>()
    };
    let RefActs {
        a1, a2, hb, hs, hj, ..
    } = reference_acts(shape, p, belief, side);
    let cat: Vec<f64> = hb.iter().chain(&hs).copied().collect();
    let mut dl = [0.0; 3];
    dl[action] = 1.0;
    let dhj = guide(lin_back(&layers[L_ACTOR], &dl, HIDDEN), &hj);
    let dcat = guide(lin_back(&layers[L_JOINT], &dhj, 2 * HIDDEN), &cat);
    let dside = lin_back(&layers[L_SIDE], &dcat[HIDDEN..], side.len());
    let da2 = guide(lin_back(&layers[L_BELIEF], &dcat[..HIDDEN], FLAT), &a2);
    let da1 = guide(conv_back(&layers[L_CONV2], &da2, A1), &a1);
    let dbelief = conv_back(&layers[L_CONV1], &da1, belief.len());
    (dbelief, dside)
}

#[test]
fn guided_backprop_matches_f64_reference_on_the_real_shape() {
    let net = lively_net(REAL, 61);
    let (belief, side) = random_inputs(REAL, 1, 62);
    let p = to64(&net.params);
    for action in 0..N_ACTIONS {
        let (gb, gs) = net.guided_backprop(&belief, &side, action);
        let (rb, rs) = reference_guided(&REAL, &p, &to64(&belief), &to64(&side), action);
        let scale = rb.iter().chain(&rs).fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 1e-3, "degenerate guided map for action {action}");
        for (i, (a, r)) in gb.iter().zip(&rb).chain(gs.iter().zip(&rs)).enumerate() {
            assert!(
                (f64::from(*a) - r).abs() <= 1e-4 * scale,
                "action {action} input {i}: {a} vs {r}"
            );
        }
        // Guided is not plain backprop here: some negative gradient was stopped.
        let (pb, _) = net.input_gradient(&belief, &side, dl_onehot(action), 0.0);
        let differ = gb
            .iter()
            .zip(&pb)
            .filter(|(g, p)| (*g - *p).abs() > 1e-6)
            .count();
        assert!(
            differ > 100,
            "action {action}: guided equals plain on all but {differ}"
        );
    }
}

fn dl_onehot(action: usize) -> [f32; N_ACTIONS] {
    let mut d = [0.0; N_ACTIONS];
    d[action] = 1.0;
    d
}

#[test]
fn input_gradient_matches_finite_differences() {
    let shape = SMALL;
    let net = lively_net(shape, 21);
    let (belief, side) = random_inputs(shape, 1, 22);
    let c = [0.7f32, -1.3, 0.4];
    let d = -0.8f32;
    let (gb, gs) = net.input_gradient(&belief, &side, c, d);
    let p = to64(&net.params);
    let loss = |bel: &[f64], sd: &[f64]| {
        let (l, v) = reference(&shape, &p, bel, sd);
        (0..3).map(|a| f64::from(c[a]) * l[a]).sum::<f64>() + f64::from(d) * v
    };
    let (mut bel, mut sd) = (to64(&belief), to64(&side));
    let eps = 1e-4;
    let mut rng = Pcg64::seed_from_u64(23);
    let mut nonzero = 0;
    for _ in 0..30 {
        let j = rng.gen_range(0..bel.len());
        let o = bel[j];
        bel[j] = o + eps;
        let up = loss(&bel, &sd);
        bel[j] = o - eps;
        let n = (up - loss(&bel, &sd)) / (2.0 * eps);
        bel[j] = o;
        let a = f64::from(gb[j]);
        assert!(
            (a - n).abs() <= 1e-4 + 2e-3 * n.abs(),
            "belief {j}: {a} vs {n}"
        );
        nonzero += usize::from(n.abs() > 1e-4);
    }
    assert!(nonzero >= 10, "belief gradient check nearly vacuous");
    for j in 0..sd.len() {
        let o = sd[j];
        sd[j] = o + eps;
        let up = loss(&bel, &sd);
        sd[j] = o - eps;
        let n = (up - loss(&bel, &sd)) / (2.0 * eps);
        sd[j] = o;
        let a = f64::from(gs[j]);
        assert!(
            (a - n).abs() <= 1e-4 + 2e-3 * n.abs(),
            "side {j}: {a} vs {n}"
        );
    }
}

fn grad_in_pool(
    threads: usize,
    net: &PolicyNet,
    belief: &[f32],
    side: &[f32],
    b: usize,
) -> Vec<u32> {
    let dl = random_vec(b * N_ACTIONS, 31);
    let dv = random_vec(b, 32);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut cache = BatchCache::new();
        net.forward_batch(belief, side, b, &mut cache);
        let mut grad = vec![0.0; net.shape.param_count()];
        net.backward_batch(&mut cache, &dl, &dv, &mut grad);
        grad.iter().map(|g| g.to_bits()).collect()
    })
}

#[test]
fn gradients_are_bit_identical_for_any_thread_count() {
    let net = lively_net(REAL, 41);
    let b = 37;
    let (belief, side) = random_inputs(REAL, b, 42);
    let one = grad_in_pool(1, &net, &belief, &side, b);
    let three = grad_in_pool(3, &net, &belief, &side, b);
    let two = grad_in_pool(2, &net, &belief, &side, b);
    assert!(one.iter().any(|&g| g != 0));
    assert!(one == three, "1 vs 3 threads differ");
    assert!(one == two, "1 vs 2 threads differ");
}

#[test]
fn backward_adds_to_grad() {
    let net = lively_net(SMALL, 51);
    let b = 2;
    let (belief, side) = random_inputs(SMALL, b, 52);
    let (dl, dv) = (random_vec(b * 3, 53), random_vec(b, 54));
    let mut cache = BatchCache::new();
    net.forward_batch(&belief, &side, b, &mut cache);
    let mut once = vec![0.0; SMALL.param_count()];
    net.backward_batch(&mut cache, &dl, &dv, &mut once);
    let mut twice = once.clone();
    net.backward_batch(&mut cache, &dl, &dv, &mut twice);
    for (o, t) in once.iter().zip(&twice) {
        assert_eq!(2.0 * o, *t);
    }
}

#[test]
fn loss_helpers() {
    let z = [0.0f32; 3];
    assert!((entropy(&z) - 3f32.ln()).abs() < 1e-6);
    assert!((softmax(&[1.0, 2.0, 3.0]).iter().sum::<f32>() - 1.0).abs() < 1e-6);
    let big = log_softmax(&[1000.0, 0.0, -1000.0]);
    assert!(big.iter().all(|x| !x.is_nan()) && big[0].abs() < 1e-6);
    // Analytic logit gradients against central differences.
    let l = [0.3f32, -0.8, 1.1];
    let eps = 1e-3;
    let (ge, gl) = (entropy_grad(&l), log_prob_grad(&l, 1));
    for k in 0..3 {
        let (mut up, mut down) = (l, l);
        up[k] += eps;
        down[k] -= eps;
        let ne = (entropy(&up) - entropy(&down)) / (2.0 * eps);
        let nl = (log_softmax(&up)[1] - log_softmax(&down)[1]) / (2.0 * eps);
        assert!(
            (ge[k] - ne).abs() < 1e-3,
            "entropy grad {k}: {} vs {ne}",
            ge[k]
        );
        assert!(
            (gl[k] - nl).abs() < 1e-3,
            "log-prob grad {k}: {} vs {nl}",
            gl[k]
        );
    }
}

#[test]
fn adam_and_clipping() {
    // First Adam step moves each parameter by about lr against its gradient's sign
    // (bias correction makes m̂/√v̂ = ±1), and not at all for a zero gradient.
    let mut p = vec![1.0f32, 1.0, 1.0];
    let mut adam = Adam::new(3, 0.01);
    adam.step(&mut p, &[0.5, -2.0, 0.0]);
    assert!(
        (p[0] - 0.99).abs() < 1e-4 && (p[1] - 1.01).abs() < 1e-4 && p[2] == 1.0,
        "{p:?}"
    );
    assert_eq!(adam.t, 1);

    let mut g = vec![3.0f32, 4.0];
    assert_eq!(clip_global_norm(&mut g, 1.0), 5.0);
    assert!((g[0].hypot(g[1]) - 1.0).abs() < 1e-5);
    let mut small = vec![0.3f32, 0.4];
    assert!((clip_global_norm(&mut small, 1.0) - 0.5).abs() < 1e-6);
    assert_eq!(small, [0.3, 0.4]);
}

/// Timings for the report: `cargo test --release --lib learn::net::tests::timing -- --ignored --nocapture`.
#[test]
#[ignore]
fn timing() {
    use std::time::Instant;
    for k in [1, 10] {
        let shape = NetShape {
            rot_bins: k,
            side: 108,
        };
        let net = PolicyNet::new(shape, 1);
        let (belief, side) = random_inputs(shape, 1, 2);
        let mut s = Scratch::new(shape);
        let mut acc = 0.0;
        for _ in 0..200 {
            acc += net.forward_with(&belief, &side, &mut s).value;
        }
        let n = 5000;
        let t = Instant::now();
        for _ in 0..n {
            acc += net.forward_with(&belief, &side, &mut s).value;
        }
        let us = t.elapsed().as_secs_f64() * 1e6 / n as f64;
        println!("batch-1 forward K={k}: {us:.1} us ({acc:.1})");
    }
    let b = 256;
    let net = lively_net(REAL, 3);
    let (belief, side) = random_inputs(REAL, b, 4);
    let (dl, dv) = (random_vec(b * 3, 5), random_vec(b, 6));
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut cache = BatchCache::new();
            let mut grad = vec![0.0; REAL.param_count()];
            let reps = 10;
            let (mut tf, mut tb) = (0.0, 0.0);
            for rep in 0..reps + 2 {
                let t = Instant::now();
                net.forward_batch(&belief, &side, b, &mut cache);
                let t1 = Instant::now();
                net.backward_batch(&mut cache, &dl, &dv, &mut grad);
                if rep >= 2 {
                    tf += (t1 - t).as_secs_f64();
                    tb += t1.elapsed().as_secs_f64();
                }
            }
            let ms = |x: f64| x * 1e3 / reps as f64;
            println!(
                "batch-256 K=10, {threads} thread(s): forward {:.1} ms + backward {:.1} ms = {:.1} ms",
                ms(tf),
                ms(tb),
                ms(tf + tb)
            );
        });
    }
}
