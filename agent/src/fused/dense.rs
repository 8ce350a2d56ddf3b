//! Dense layers and MLPs on the arena: the GEMM, then one row pass that adds the bias and applies
//! the activation (forward), or one row pass that multiplies by the activation's derivative and
//! sums the bias gradient (backward).
//!
//! Forward, layer k: h_k = act(h_{k-1} W_k^T + b_k). Backward, with g_k = dL/d(h_{k-1} W_k^T + b_k):
//! dW_k = g_k^T h_{k-1}, db_k = sum over rows of g_k, g_{k-1} = (g_k W_k) * act'(h_{k-1}).
//! Derivatives are written the way candle's backprop computes them, so both sides round alike:
//! relu' is 1 where the pre-activation is >= 0 (candle's `ge`), tanh' enters as
//! -(g (tanh^2 - 1)).

use super::adam::Trainable;
use super::layout::{DenseAt, MlpAt};
use super::linalg::{Gemm, Mat, MatMut, VectorKernel, vectorized};
use super::tanh::{Tanh, fast_tanh};

/// Nonlinearity after a layer, as the fused kernels evaluate it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Activation {
    /// max(x, 0) (see [`relu`]).
    Relu,
    /// tanh(x), by libm or the vectorised approximation.
    Tanh(Tanh),
    /// Identity.
    Linear,
}

/// ReLU that writes -0.0 for a negative pre-activation and +|x| otherwise, so the backward pass
/// can recover candle's `x >= 0` mask (which passes x = 0) from the sign bit of the output alone.
#[inline(always)]
fn relu(x: f32) -> f32 {
    if x >= 0.0 { x.abs() } else { -0.0 }
}

/// Applies `f(x_ij, pre_ij, b_j)` to every element of x, one row at a time.
#[inline(always)]
fn map_rows(x: &mut MatMut, pre: Option<Mat>, bias: &[f32], f: impl Fn(f32, f32, f32) -> f32 + Copy) {
    for i in 0..x.rows() {
        let row = x.row_mut(i);
        let n = row.len();
        match pre {
            Some(pre) => {
                for ((v, p), b) in row.iter_mut().zip(&pre.row(i)[..n]).zip(&bias[..n]) {
                    *v = f(*v, *p, *b);
                }
            }
            None => {
                for (v, b) in row.iter_mut().zip(&bias[..n]) {
                    *v = f(*v, 0.0, *b);
                }
            }
        }
    }
}

/// x <- act(f(x, pre) + b), vectorised (libm's tanh stays a call per element, as candle's `f32::tanh`).
struct BiasAct<'a, 'b, F> {
    x: &'a mut MatMut<'b>,
    pre: Option<Mat<'a>>,
    bias: &'a [f32],
    act: Activation,
    f: F,
}

impl<F: Fn(f32, f32) -> f32 + Copy> VectorKernel for BiasAct<'_, '_, F> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let Self { x, pre, bias, act, f } = self;
        match act {
            Activation::Relu => map_rows(x, pre, bias, |v, p, b| relu(f(v, p) + b)),
            Activation::Tanh(kind) => {
                // The s and t nets' rows are short (their hidden width): add the bias row by row,
                // then take tanh over the whole buffer in one long, vectorisable loop.
                map_rows(x, pre, bias, |v, p, b| f(v, p) + b);
                let tanh = |v: &mut f32| {
                    *v = match kind {
                        Tanh::Libm => v.tanh(),
                        Tanh::Fast => fast_tanh(*v),
                    }
                };
                match x.contiguous_mut() {
                    Some(all) => all.iter_mut().for_each(tanh),
                    None => (0..x.rows()).for_each(|i| x.row_mut(i).iter_mut().for_each(tanh)),
                }
            }
            Activation::Linear => map_rows(x, pre, bias, |v, p, b| f(v, p) + b),
        }
    }
}

/// x <- act(x + b), row by row (the bias add and activation after a forward GEMM).
pub(crate) fn bias_act(x: &mut MatMut, bias: &[f32], act: Activation) {
    vectorized(BiasAct { x, pre: None, bias, act, f: |v, _| v });
}

/// x <- act((pre + x) + b): Q's first layer, whose observation product `pre` comes from the stacked
/// GEMM and whose action product is already in x. The order of the sums is candle's (Dense adds
/// the per-input products, then the bias).
pub(crate) fn sum_bias_act(x: &mut MatMut, pre: Mat, bias: &[f32], act: Activation) {
    vectorized(BiasAct { x, pre: Some(pre), bias, act, f: |v, p| p + v });
}

/// dst <- act(src + b).
pub(crate) fn bias_act_from(dst: &mut MatMut, src: Mat, bias: &[f32], act: Activation) {
    vectorized(BiasAct { x: dst, pre: Some(src), bias, act, f: |_, s| s });
}

/// g <- g * act'(h) and db <- column sums of the result: the bias gradient, fused in the same pass.
struct ActBackward<'a, 'b> {
    g: &'a mut MatMut<'b>,
    h: Mat<'a>,
    act: Activation,
    db: &'a mut [f32],
}

#[inline(always)]
fn backward_rows(g: &mut MatMut, h: Mat, db: &mut [f32], f: impl Fn(f32, f32) -> f32 + Copy) {
    db.fill(0.0);
    for i in 0..g.rows() {
        let row = g.row_mut(i);
        let n = row.len();
        for ((gv, hv), d) in row.iter_mut().zip(&h.row(i)[..n]).zip(&mut db[..n]) {
            *gv = f(*gv, *hv);
            *d += *gv;
        }
    }
}

impl VectorKernel for ActBackward<'_, '_> {
    type Output = ();

    /// Derivatives as candle's backprop computes them: relu' from the sign bit (see [`relu`]),
    /// tanh' as -(g (h^2 - 1)).
    #[inline(always)]
    fn run(self) {
        let Self { g, h, act, db } = self;
        match act {
            Activation::Relu => backward_rows(g, h, db, |g, h| if h.is_sign_positive() { g } else { 0.0 }),
            Activation::Tanh(_) => {
                let tanh_grad = |g: f32, h: f32| -(g * (h * h - 1.0));
                match (h.contiguous(), g.contiguous_mut()) {
                    // Short rows again: the derivative over the whole buffer, then the sums.
                    (Some(h_all), Some(g_all)) => {
                        g_all.iter_mut().zip(h_all).for_each(|(g, h)| *g = tanh_grad(*g, *h));
                        backward_rows(g, h, db, |g, _| g);
                    }
                    _ => backward_rows(g, h, db, tanh_grad),
                }
            }
            Activation::Linear => backward_rows(g, h, db, |g, _| g),
        }
    }
}

/// g <- g * act'(h) and db <- column sums of the result (see [`ActBackward`]).
pub(crate) fn act_backward(g: &mut MatMut, h: Mat, act: Activation, db: &mut [f32]) {
    vectorized(ActBackward { g, h, act, db });
}

/// The activations (and, for trained networks, gradients) of one MLP for `rows` rows.
#[derive(Clone, Debug)]
pub(crate) struct MlpBufs {
    /// Output of layer k, `rows x width_k`.
    pub acts: Vec<Vec<f32>>,
    /// dL/d(pre-activation of layer k), `rows x width_k` (empty when not trained; layer 0's may be
    /// unused when the caller keeps it in a shared buffer).
    pub grads: Vec<Vec<f32>>,
    /// The bias sums of [`input_gradient`]'s derivative passes, which no parameter takes.
    scratch: Vec<f32>,
    widths: Vec<usize>,
    rows: usize,
}

impl MlpBufs {
    /// Buffers for `rows` rows of an MLP with layer widths `widths`.
    pub(crate) fn new(widths: &[usize], rows: usize, trained: bool) -> Self {
        let make = || widths.iter().map(|w| vec![0.0; w * rows]).collect();
        Self {
            acts: make(),
            grads: if trained { make() } else { Vec::new() },
            scratch: vec![0.0; widths.iter().copied().max().unwrap_or(0)],
            widths: widths.to_vec(),
            rows,
        }
    }

    /// Layer k's output, the first `rows` rows.
    pub(crate) fn act(&self, k: usize, rows: usize) -> Mat<'_> {
        Mat::dense(&self.acts[k], self.rows, self.widths[k]).top(rows)
    }

    /// Layer k's output buffer, the first `rows` rows.
    pub(crate) fn act_mut(&mut self, k: usize, rows: usize) -> MatMut<'_> {
        MatMut::dense(&mut self.acts[k][..rows * self.widths[k]], rows, self.widths[k])
    }

    /// The last layer's output.
    pub(crate) fn output(&self, rows: usize) -> Mat<'_> {
        self.act(self.widths.len() - 1, rows)
    }

    /// dL/d(output of the last layer) for the caller to fill, the first `rows` rows.
    pub(crate) fn output_grad_mut(&mut self, rows: usize) -> MatMut<'_> {
        let last = self.widths.len() - 1;
        MatMut::dense(&mut self.grads[last][..rows * self.widths[last]], rows, self.widths[last])
    }

    /// Layer 0's pre-activation gradient, when kept here.
    pub(crate) fn first_grad(&self, rows: usize) -> Mat<'_> {
        Mat::dense(&self.grads[0], self.rows, self.widths[0]).top(rows)
    }
}

/// W of `layer` as an `[out, fan_in]` view.
pub(crate) fn weight<'a>(params: &'a [f32], layer: &DenseAt) -> Mat<'a> {
    Mat::dense(&params[layer.weight..layer.weight + layer.out * layer.fan_in], layer.out, layer.fan_in)
}

/// b of `layer`.
pub(crate) fn bias<'a>(params: &'a [f32], layer: &DenseAt) -> &'a [f32] {
    &params[layer.bias..layer.bias + layer.out]
}

/// An MLP: where its layers live, `hidden` after every layer but the last, `output` after the last.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Net<'a> {
    pub at: &'a MlpAt,
    pub hidden: Activation,
    pub output: Activation,
}

impl Net<'_> {
    /// The activation after layer `k`.
    pub(crate) fn act(&self, k: usize) -> Activation {
        if k + 1 == self.at.layers.len() { self.output } else { self.hidden }
    }
}

/// Layer 0 on input x: acts[0] = act(x W_0^T + b_0), then the rest.
pub(crate) fn forward(gemm: &Gemm, params: &[f32], net: Net, bufs: &mut MlpBufs, x: Mat) {
    let rows = x.rows();
    let first = &net.at.layers[0];
    let mut h = bufs.act_mut(0, rows);
    gemm.mul(&mut h, x, weight(params, first).t(), false);
    bias_act(&mut h, bias(params, first), net.act(0));
    forward_rest(gemm, params, net, bufs, rows);
}

/// Layers 1.. for `rows` rows, acts[0] already holding layer 0's output.
pub(crate) fn forward_rest(gemm: &Gemm, params: &[f32], net: Net, bufs: &mut MlpBufs, rows: usize) {
    let layers = &net.at.layers;
    for (k, layer) in layers.iter().enumerate().skip(1) {
        let (before, after) = bufs.acts.split_at_mut(k);
        let input = Mat::dense(&before[k - 1], bufs.rows, layers[k - 1].out).top(rows);
        let mut h = MatMut::dense(&mut after[0][..rows * layer.out], rows, layer.out);
        gemm.mul(&mut h, input, weight(params, layer).t(), false);
        bias_act(&mut h, bias(params, layer), net.act(k));
    }
}

/// Backward from grads[last] = dL/d(output) (first `rows` rows) down to layer 0's pre-activation
/// gradient, written into `first` or, when `None`, grads[0]. Finishes dW_k and db_k for k >= 1
/// and db_0 in `train` (each array as soon as its gradient is final and the pass no longer reads
/// it); dW_0 is left to the caller, whose input may be shared with other networks.
pub(crate) fn backward_to_first(
    gemm: &Gemm,
    train: &mut Trainable,
    net: Net,
    bufs: &mut MlpBufs,
    rows: usize,
    mut first: Option<MatMut>,
) {
    let layers = &net.at.layers;
    let (stride, acts, grads) = (bufs.rows, &bufs.acts, &mut bufs.grads);
    for k in (0..layers.len()).rev() {
        let layer = &layers[k];
        let h = Mat::dense(&acts[k], stride, layer.out).top(rows);
        let (lower, upper) = grads.split_at_mut(k);
        let g = match (k, first.as_mut()) {
            (0, Some(view)) => {
                if layers.len() == 1 {
                    // A one-layer net: the caller's output gradient is in grads[0], not yet here.
                    for i in 0..rows {
                        view.row_mut(i).copy_from_slice(&upper[0][i * layer.out..(i + 1) * layer.out]);
                    }
                }
                act_backward(view, h, net.act(k), train.bias_grad(layer));
                train.finished(layer.bias, layer.out);
                break;
            }
            _ => {
                let mut g = MatMut::dense(&mut upper[0][..rows * layer.out], rows, layer.out);
                act_backward(&mut g, h, net.act(k), train.bias_grad(layer));
                g
            }
        };
        train.finished(layer.bias, layer.out);
        if k == 0 {
            break;
        }
        let prev = &layers[k - 1];
        let input = Mat::dense(&acts[k - 1], stride, prev.out).top(rows);
        gemm.mul(&mut train.weight_grad(layer), g.as_mat().t(), input, false);
        match (k - 1, first.as_mut()) {
            (0, Some(view)) => gemm.mul(view, g.as_mat(), train.weight(layer), false),
            _ => {
                let mut below = MatMut::dense(&mut lower[k - 1][..rows * prev.out], rows, prev.out);
                gemm.mul(&mut below, g.as_mat(), train.weight(layer), false);
            }
        }
        train.finished(layer.weight, layer.out * layer.fan_in);
    }
}

/// dL/dx of one input block of layer 0 (weights `input_weight`, `[out_0, cols]`) for the rows
/// `rows` of `bufs`, from grads[last] = dL/d(output) there, with the net's parameters held fixed:
/// the backward pass of a frozen network (Q(s, a~) with respect to a~ in the reparameterised
/// policy loss). No parameter gradient is formed; `dx` is written, or added to with its flag.
pub(crate) fn input_gradient(
    gemm: &Gemm,
    params: &[f32],
    net: Net,
    bufs: &mut MlpBufs,
    rows: std::ops::Range<usize>,
    input_weight: Mat,
    (dx, accumulate): (&mut MatMut, bool),
) {
    let layers = &net.at.layers;
    let (from, n) = (rows.start, rows.len());
    let MlpBufs { acts, grads, scratch, .. } = bufs;
    for k in (0..layers.len()).rev() {
        let layer = &layers[k];
        let span = |width: usize| from * width..(from + n) * width;
        let h = Mat::dense(&acts[k][span(layer.out)], n, layer.out);
        let (lower, upper) = grads.split_at_mut(k);
        let mut g = MatMut::dense(&mut upper[0][span(layer.out)], n, layer.out);
        act_backward(&mut g, h, net.act(k), &mut scratch[..layer.out]);
        if k == 0 {
            gemm.mul(dx, g.as_mat(), input_weight, accumulate);
            break;
        }
        let prev = &layers[k - 1];
        let mut below = MatMut::dense(&mut lower[k - 1][span(prev.out)], n, prev.out);
        gemm.mul(&mut below, g.as_mat(), weight(params, layer), false);
    }
}

/// Layer 0's weight gradient dW_0 = g_0^T x, and optionally its input gradient dx (+)= g_0 W_0;
/// then W_0 is finished.
pub(crate) fn first_layer_backward(
    gemm: &Gemm,
    train: &mut Trainable,
    layer: &DenseAt,
    g0: Mat,
    x: Mat,
    dx: Option<(&mut MatMut, bool)>,
) {
    gemm.mul(&mut train.weight_grad(layer), g0.t(), x, false);
    if let Some((dx, accumulate)) = dx {
        gemm.mul(dx, g0, train.weight(layer), accumulate);
    }
    train.finished(layer.weight, layer.out * layer.fan_in);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relu_keeps_candles_ge_zero_mask_in_the_sign_bit() {
        for (x, passes) in [(1.5f32, true), (0.0, true), (-0.0, true), (-2.0, false)] {
            let mut h = [x];
            bias_act(&mut MatMut::dense(&mut h, 1, 1), &[0.0], Activation::Relu);
            assert_eq!(h[0], x.max(0.0));
            let (mut g, mut db) = ([3.0], [0.0]);
            act_backward(&mut MatMut::dense(&mut g, 1, 1), Mat::dense(&h, 1, 1), Activation::Relu, &mut db);
            assert_eq!((g[0] == 3.0, db[0] == g[0]), (passes, true), "x = {x}");
        }
        let mut t = [0.3f32, 0.0];
        bias_act(&mut MatMut::dense(&mut t, 2, 1), &[0.1], Activation::Tanh(Tanh::Libm));
        assert_eq!(t[0], 0.4f32.tanh());
        let (mut g, mut db) = ([2.0, 1.0], [0.0]);
        act_backward(
            &mut MatMut::dense(&mut g, 2, 1),
            Mat::dense(&t, 2, 1),
            Activation::Tanh(Tanh::Fast),
            &mut db,
        );
        assert!((g[0] - 2.0 * (1.0 - t[0] * t[0])).abs() < 1e-7 && db[0] == g[0] + g[1]);
    }
}
