//! The forward and backward pass of one sample. [`PolicyNet::forward_with`], the batched
//! forward and backward and the input-gradient maps all run exactly these two functions, so
//! a single decision is bit-identical to its row of a batch.
//!
//! [`PolicyNet::forward_with`]: super::PolicyNet::forward_with

use super::kernels::{
    col2im_add, conv_backward, conv_forward, guided_relu_mask, im2col, linear, linear_backward,
    relu, relu_mask,
};
use super::{
    Layer, NetShape, Output, Scratch, A1, C1, C2, FLAT, GRID, HIDDEN, KK, L_ACTOR, L_BELIEF,
    L_CONV1, L_CONV2, L_CRITIC, L_JOINT, L_SIDE, N_ACTIONS, P1, P2, S1, S2,
};

fn split_wb<'a>(params: &'a [f32], layer: &Layer) -> (&'a [f32], &'a [f32]) {
    (&params[layer.weights()], &params[layer.bias()])
}

pub(super) fn forward_sample(
    shape: &NetShape,
    params: &[f32],
    belief: &[f32],
    side: &[f32],
    acts: &mut [f32],
    col1: &mut [f32],
    col2: &mut [f32],
) -> Output {
    let layers = shape.layers();
    let (a1, rest) = acts.split_at_mut(A1);
    let (a2, rest) = rest.split_at_mut(FLAT);
    let (hcat, hj) = rest.split_at_mut(2 * HIDDEN);

    let (w, b) = split_wb(params, &layers[L_CONV1]);
    im2col(shape.rot_bins, GRID, S1, belief, col1);
    conv_forward(w, b, col1, a1);
    relu(a1);

    let (w, b) = split_wb(params, &layers[L_CONV2]);
    im2col(C1, S1, S2, a1, col2);
    conv_forward(w, b, col2, a2);
    relu(a2);

    let (hb, hs) = hcat.split_at_mut(HIDDEN);
    let (w, b) = split_wb(params, &layers[L_BELIEF]);
    linear(w, b, a2, hb);
    relu(hb);
    let (w, b) = split_wb(params, &layers[L_SIDE]);
    linear(w, b, side, hs);
    relu(hs);

    let (w, b) = split_wb(params, &layers[L_JOINT]);
    linear(w, b, hcat, hj);
    relu(hj);

    let mut logits = [0.0; N_ACTIONS];
    let (w, b) = split_wb(params, &layers[L_ACTOR]);
    linear(w, b, hj, &mut logits);
    let mut value = [0.0];
    let (w, b) = split_wb(params, &layers[L_CRITIC]);
    linear(w, b, hj, &mut value);
    Output {
        logits,
        value: value[0],
    }
}

/// Backward of one sample from the output gradients. Adds parameter gradients into `grad`
/// when given; writes input gradients into `input_grad` when given (then the first-layer
/// parameter gradients are still added if `grad` is given).
#[allow(clippy::too_many_arguments)]
pub(super) fn backward_sample(
    shape: &NetShape,
    params: &[f32],
    belief: &[f32],
    side: &[f32],
    acts: &[f32],
    dlogits: [f32; N_ACTIONS],
    dvalue: f32,
    mut grad: Option<&mut [f32]>,
    s: &mut Scratch,
    input_grad: Option<(&mut [f32], &mut [f32])>,
    guided: bool,
) {
    // Plain backprop masks a ReLU's gradient where its output was 0; guided backprop
    // (Springenberg et al. 2014) also where the incoming gradient is negative.
    let mask: fn(&mut [f32], &[f32]) = if guided { guided_relu_mask } else { relu_mask };
    let layers = shape.layers();
    let (a1, rest) = acts.split_at(A1);
    let (a2, rest) = rest.split_at(FLAT);
    let (hcat, hj) = rest.split_at(2 * HIDDEN);
    let (hb, hs) = hcat.split_at(HIDDEN);
    // Heads: both read hj.
    let (dinput, dside) = match input_grad {
        Some((db, ds)) => (Some(db), Some(ds)),
        None => (None, None),
    };
    s.dhj.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_ACTOR]);
    linear_backward(
        w,
        hj,
        &dlogits,
        layer_grad(&mut grad, &layers[L_ACTOR]),
        Some(&mut s.dhj),
    );
    let (w, _) = split_wb(params, &layers[L_CRITIC]);
    linear_backward(
        w,
        hj,
        &[dvalue],
        layer_grad(&mut grad, &layers[L_CRITIC]),
        Some(&mut s.dhj),
    );
    mask(&mut s.dhj, hj);

    s.dcat.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_JOINT]);
    linear_backward(
        w,
        hcat,
        &s.dhj,
        layer_grad(&mut grad, &layers[L_JOINT]),
        Some(&mut s.dcat),
    );
    mask(&mut s.dcat, hcat);
    let (dhb, dhs) = s.dcat.split_at(HIDDEN);

    let (w, _) = split_wb(params, &layers[L_SIDE]);
    if let Some(ds) = dside {
        ds.fill(0.0);
        linear_backward(
            w,
            side,
            dhs,
            layer_grad(&mut grad, &layers[L_SIDE]),
            Some(ds),
        );
    } else {
        linear_backward(w, side, dhs, layer_grad(&mut grad, &layers[L_SIDE]), None);
    }
    debug_assert_eq!(hs.len(), dhs.len());

    s.da2.fill(0.0);
    let (w, _) = split_wb(params, &layers[L_BELIEF]);
    linear_backward(
        w,
        a2,
        dhb,
        layer_grad(&mut grad, &layers[L_BELIEF]),
        Some(&mut s.da2),
    );
    mask(&mut s.da2, a2);
    debug_assert_eq!(hb.len(), dhb.len());

    // conv2: recompute its im2col from a1 rather than keeping it per sample.
    let (w, _) = split_wb(params, &layers[L_CONV2]);
    im2col(C1, S1, S2, a1, &mut s.col2);
    let dcol2 = &mut s.dcol[..C1 * KK * P2];
    conv_backward(
        C2,
        w,
        &s.col2,
        &s.da2,
        layer_grad(&mut grad, &layers[L_CONV2]),
        Some(&mut *dcol2),
    );
    s.da1.fill(0.0);
    col2im_add(C1, S1, S2, dcol2, &mut s.da1);
    mask(&mut s.da1, a1);

    let (w, _) = split_wb(params, &layers[L_CONV1]);
    im2col(shape.rot_bins, GRID, S1, belief, &mut s.col1);
    match dinput {
        Some(dbel) => {
            let dcol1 = &mut s.dcol[..shape.rot_bins * KK * P1];
            conv_backward(
                C1,
                w,
                &s.col1,
                &s.da1,
                layer_grad(&mut grad, &layers[L_CONV1]),
                Some(&mut *dcol1),
            );
            dbel.fill(0.0);
            col2im_add(shape.rot_bins, GRID, S1, dcol1, dbel);
        }
        None => conv_backward(
            C1,
            w,
            &s.col1,
            &s.da1,
            layer_grad(&mut grad, &layers[L_CONV1]),
            None,
        ),
    }
}

/// The (weight, bias) gradient slices of `layer`, when parameter gradients are wanted.
fn layer_grad<'a>(
    grad: &'a mut Option<&mut [f32]>,
    layer: &Layer,
) -> Option<(&'a mut [f32], &'a mut [f32])> {
    grad.as_deref_mut()
        .map(|g| g[layer.offset..layer.offset + layer.len()].split_at_mut(layer.weight_len))
}
