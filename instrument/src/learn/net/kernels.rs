//! The layer kernels, written as contiguous-slice loops the compiler vectorises: dot
//! products with a fixed accumulation order (so results are reproducible), the 3×3 / stride 2
//! / pad 1 convolution as im2col plus a small matmul and its adjoint, fully-connected layers
//! and the ReLU with its plain and guided backward masks.

use super::{CONV_KERNEL, CONV_PAD, CONV_STRIDE};

/// Dot product with 8 independent accumulators: f32 sums are not reassociated by the
/// compiler, so one accumulator would run serially; 8 lanes vectorise (and the order is
/// fixed, so results are reproducible).
#[inline]
pub(super) fn dot(a: &[f32], b: &[f32]) -> f32 {
    debug_assert_eq!(a.len(), b.len());
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for j in 0..8 {
            acc[j] += x[j] * y[j];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

#[inline]
pub(super) fn sum(a: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let c = a.chunks_exact(8);
    let tail: f32 = c.remainder().iter().sum();
    for x in c {
        for j in 0..8 {
            acc[j] += x[j];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// `y += a·x`.
#[inline]
pub(super) fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

pub(super) fn relu(v: &mut [f32]) {
    for x in v {
        *x = if *x > 0.0 { *x } else { 0.0 };
    }
}

/// Zeroes the gradient where the ReLU output was 0 (derivative 0 at the kink).
pub(super) fn relu_mask(d: &mut [f32], y: &[f32]) {
    for (di, yi) in d.iter_mut().zip(y) {
        if *yi <= 0.0 {
            *di = 0.0;
        }
    }
}

/// The guided-back-propagation ReLU rule: the gradient `d` passes where the ReLU output
/// `y` was positive and `d` itself is positive; everywhere else it becomes 0.
pub fn guided_relu_mask(d: &mut [f32], y: &[f32]) {
    debug_assert_eq!(d.len(), y.len());
    for (di, yi) in d.iter_mut().zip(y) {
        if *yi <= 0.0 || *di <= 0.0 {
            *di = 0.0;
        }
    }
}

/// `y = W·x + b` with `W` `[out][in]`.
pub(super) fn linear(w: &[f32], b: &[f32], x: &[f32], y: &mut [f32]) {
    let n = x.len();
    for (o, yo) in y.iter_mut().enumerate() {
        *yo = b[o] + dot(&w[o * n..(o + 1) * n], x);
    }
}

/// Backward of `y = W·x + b` given `dy`: `dW += dy·xᵀ`, `db += dy`, `dx += Wᵀ·dy`.
/// Rows with `dy = 0` (dead ReLUs) are skipped.
pub(super) fn linear_backward(
    w: &[f32],
    x: &[f32],
    dy: &[f32],
    dwb: Option<(&mut [f32], &mut [f32])>,
    dx: Option<&mut [f32]>,
) {
    let n = x.len();
    if let Some((dw, db)) = dwb {
        for (o, &g) in dy.iter().enumerate() {
            if g != 0.0 {
                db[o] += g;
                axpy(&mut dw[o * n..(o + 1) * n], g, x);
            }
        }
    }
    if let Some(dx) = dx {
        for (o, &g) in dy.iter().enumerate() {
            if g != 0.0 {
                axpy(dx, g, &w[o * n..(o + 1) * n]);
            }
        }
    }
}

/// Unfolds a `cin × size_in²` map into the `[cin·9][size_out²]` patch matrix of a 3×3,
/// stride 2, pad 1 convolution; row `(c·3 + ky)·3 + kx` matches the weight layout.
pub(super) fn im2col(cin: usize, size_in: usize, size_out: usize, input: &[f32], col: &mut [f32]) {
    let p = size_out * size_out;
    for c in 0..cin {
        let plane = &input[c * size_in * size_in..(c + 1) * size_in * size_in];
        for ky in 0..CONV_KERNEL {
            for kx in 0..CONV_KERNEL {
                let r = (c * CONV_KERNEL + ky) * CONV_KERNEL + kx;
                let row = &mut col[r * p..(r + 1) * p];
                for oy in 0..size_out {
                    let dst = &mut row[oy * size_out..(oy + 1) * size_out];
                    let iy = (oy * CONV_STRIDE + ky).wrapping_sub(CONV_PAD);
                    if iy >= size_in {
                        dst.fill(0.0);
                        continue;
                    }
                    let src = &plane[iy * size_in..(iy + 1) * size_in];
                    for (ox, d) in dst.iter_mut().enumerate() {
                        let ix = (ox * CONV_STRIDE + kx).wrapping_sub(CONV_PAD);
                        *d = if ix < size_in { src[ix] } else { 0.0 };
                    }
                }
            }
        }
    }
}

/// Adjoint of [`im2col`]: scatters patch-matrix gradients back onto the input map (`+=`).
pub(super) fn col2im_add(
    cin: usize,
    size_in: usize,
    size_out: usize,
    col: &[f32],
    dinput: &mut [f32],
) {
    let p = size_out * size_out;
    for c in 0..cin {
        let plane = &mut dinput[c * size_in * size_in..(c + 1) * size_in * size_in];
        for ky in 0..CONV_KERNEL {
            for kx in 0..CONV_KERNEL {
                let r = (c * CONV_KERNEL + ky) * CONV_KERNEL + kx;
                let row = &col[r * p..(r + 1) * p];
                for oy in 0..size_out {
                    let iy = (oy * CONV_STRIDE + ky).wrapping_sub(CONV_PAD);
                    if iy >= size_in {
                        continue;
                    }
                    let src = &row[oy * size_out..(oy + 1) * size_out];
                    let dst = &mut plane[iy * size_in..(iy + 1) * size_in];
                    for (ox, g) in src.iter().enumerate() {
                        let ix = (ox * CONV_STRIDE + kx).wrapping_sub(CONV_PAD);
                        if ix < size_in {
                            dst[ix] += g;
                        }
                    }
                }
            }
        }
    }
}

/// `out[o] = b[o] + Σ_r W[o][r]·col[r]`: the convolution as a small matmul. Row-outer so each
/// patch row is read once and the few output rows stay in L1.
pub(super) fn conv_forward(w: &[f32], b: &[f32], col: &[f32], out: &mut [f32]) {
    let cout = b.len();
    let p = out.len() / cout;
    let rows = w.len() / cout;
    for (o, ob) in out.chunks_exact_mut(p).enumerate() {
        ob.fill(b[o]);
    }
    for r in 0..rows {
        let cr = &col[r * p..(r + 1) * p];
        for (o, ob) in out.chunks_exact_mut(p).enumerate() {
            axpy(ob, w[o * rows + r], cr);
        }
    }
}

/// Backward of [`conv_forward`] for `cout` output channels: `dW[o][r] += dout[o]·col[r]`,
/// `db[o] += Σ dout[o]`, and `dcol[r] = Σ_o W[o][r]·dout[o]` when wanted (overwritten).
pub(super) fn conv_backward(
    cout: usize,
    w: &[f32],
    col: &[f32],
    dout: &[f32],
    dwb: Option<(&mut [f32], &mut [f32])>,
    dcol: Option<&mut [f32]>,
) {
    let rows = w.len() / cout;
    let p = dout.len() / cout;
    if let Some((dw, db)) = dwb {
        for (o, d) in dout.chunks_exact(p).enumerate() {
            db[o] += sum(d);
            let dwo = &mut dw[o * rows..(o + 1) * rows];
            for (r, g) in dwo.iter_mut().enumerate() {
                *g += dot(d, &col[r * p..(r + 1) * p]);
            }
        }
    }
    if let Some(dcol) = dcol {
        for (r, dc) in dcol.chunks_exact_mut(p).enumerate() {
            dc.fill(0.0);
            for (o, d) in dout.chunks_exact(p).enumerate() {
                let wv = w[o * rows + r];
                if wv != 0.0 {
                    axpy(dc, wv, d);
                }
            }
        }
    }
}
