//! The real-NVP bijector of the latent-space policy on the arena (`docs/sac-lsp.md` §1): the
//! sampling pass y = f(z; c), the inverse pass z = f^-1(y; c) that log pi is evaluated through with
//! y held fixed, and the likelihood-ratio gradient back through that inverse pass to the coupling
//! nets and to the embedding c.
//!
//! Coupling layer l keeps columns K and moves columns M of x; its nets see u = [x_K, c]:
//! forward x'_M = x_M exp(s(u)) + t(u); inverse x_M = (x'_M - t(u)) exp(-s(u)), log|det| = -sum s.
//! log pi = log N(z) - sum_l sum_j s_lj - sum_j log(1 - tanh(y_j)^2 + eps) (`docs/sac-lsp.md` §1).
//!
//! With the reparameterised gradient (an option beyond the paper) log pi comes from the sampling
//! pass itself, z held fixed, and [`backward_sample`] differentiates y and log pi through it.

use crate::density::SQUASH_EPSILON;

use super::adam::Trainable;
use super::dense::{Activation, MlpBufs, Net, backward_to_first, first_layer_backward, forward};
use super::layout::CouplingAt;
use super::layout::MlpAt;
use super::linalg::{Gemm, Mat, MatMut};
use super::tanh::Tanh;

/// log N(x; 0, I) of one row as candle's `standard_normal_log_density` rounds it:
/// (sum x^2) * -0.5 + (-D/2 log 2 pi).
pub(crate) fn standard_normal_log_density(x: &[f32]) -> f32 {
    let constant = (-0.5 * x.len() as f64 * (2.0 * std::f64::consts::PI).ln()) as f32;
    x.iter().map(|v| v * v).sum::<f32>() * -0.5 + constant
}

/// sum_j log(1 - a_j^2 + eps) of one row of a = tanh(y) (candle's `tanh_log_det_jacobian`).
fn tanh_log_det(a: &[f32]) -> f32 {
    let one_plus_eps = (1.0 + SQUASH_EPSILON) as f32;
    // -(t t) + c is candle's affine(-1, c) of t^2: negation is exact.
    a.iter().map(|t| (-(t * t) + one_plus_eps).ln()).sum()
}

/// The bijector: its coupling layers and the tanh their nets' hidden layers use.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Flow<'a> {
    pub couplings: &'a [CouplingAt],
    pub tanh: Tanh,
}

/// A scale or translation net: tanh hidden layers, linear output.
fn st_net(at: &MlpAt, tanh: Tanh) -> Net<'_> {
    Net { at, hidden: Activation::Tanh(tanh), output: Activation::Linear }
}

/// Buffers of one coupling layer for `rows` rows.
#[derive(Clone, Debug)]
struct CouplingBufs {
    /// |K| + dim c.
    width: usize,
    /// u = [x_K, c], `rows x width`.
    input: Vec<f32>,
    scale: MlpBufs,
    translation: MlpBufs,
    /// x'_M - t of the inverse pass, or x_M of a recorded sampling pass, `rows x |M|`.
    diff: Vec<f32>,
    /// exp(-s) of the inverse pass, or exp(s) of a recorded sampling pass, `rows x |M|`.
    neg_exp: Vec<f32>,
    /// dL/du, `rows x (|K| + dim c)`.
    input_grad: Vec<f32>,
}

/// All buffers of the bijector.
#[derive(Clone, Debug)]
pub(crate) struct FlowBufs {
    layers: Vec<CouplingBufs>,
    dim: usize,
    /// y = f(z; c), `rows x D`.
    pub y: Vec<f32>,
    /// f^-1(y; c) by the inverse pass, `rows x D`.
    pub z: Vec<f32>,
    /// log pi(a|s) through the inverse pass, `rows`.
    pub log_pi: Vec<f32>,
    /// log|det dz/dy| = -sum of every s of the inverse pass, or log|det dy/dz| = sum of every s
    /// of a recorded sampling pass, `rows`.
    log_det: Vec<f32>,
    /// Gradient of the current state of the backward pass, `rows x D`.
    state_grad: Vec<f32>,
}

impl FlowBufs {
    /// Buffers for `couplings` on `rows` rows of D = `dim` latents and `context` embedding columns.
    pub(crate) fn new(couplings: &[CouplingAt], rows: usize, dim: usize, context: usize) -> Self {
        let layers = couplings
            .iter()
            .map(|at| CouplingBufs {
                width: at.kept + context,
                input: vec![0.0; rows * (at.kept + context)],
                scale: MlpBufs::new(&at.scale.widths(), rows, true),
                translation: MlpBufs::new(&at.translation.widths(), rows, true),
                diff: vec![0.0; rows * at.moved],
                neg_exp: vec![0.0; rows * at.moved],
                input_grad: vec![0.0; rows * (at.kept + context)],
            })
            .collect();
        let zeros = |n| vec![0.0; n];
        Self {
            layers,
            dim,
            y: zeros(rows * dim),
            z: zeros(rows * dim),
            log_pi: zeros(rows),
            log_det: zeros(rows),
            state_grad: zeros(rows * dim),
        }
    }
}

/// Fills u = [x_K, c] from the state x (`rows x D`) and runs the layer's s and t nets on it.
fn nets_forward(
    gemm: &Gemm,
    params: &[f32],
    at: &CouplingAt,
    tanh: Tanh,
    bufs: &mut CouplingBufs,
    x: Mat,
    c: Mat,
) {
    let (rows, width) = (c.rows(), at.kept + c.cols());
    for i in 0..rows {
        let row = &mut bufs.input[i * width..(i + 1) * width];
        row[..at.kept].copy_from_slice(&x.row(i)[at.kept_from..at.kept_from + at.kept]);
        row[at.kept..].copy_from_slice(c.row(i));
    }
    let u = Mat::dense(&bufs.input, rows, width);
    forward(gemm, params, st_net(&at.scale, tanh), &mut bufs.scale, u);
    forward(gemm, params, st_net(&at.translation, tanh), &mut bufs.translation, u);
}

/// Sampling pass y = f(z; c). `z` and the result `bufs.y` are `rows x D`; `c` is the embedding.
/// The likelihood-ratio update treats y as a constant; with `record` (the reparameterised
/// update) the pass keeps what [`backward_sample`] needs (x_M, exp(s), the nets' activations) and
/// log|det dy/dz| for [`sample_log_pi`].
pub(crate) fn sample(
    gemm: &Gemm,
    params: &[f32],
    flow: Flow,
    bufs: &mut FlowBufs,
    z: &[f32],
    c: Mat,
    record: bool,
) {
    let (rows, dim) = (c.rows(), bufs.dim);
    bufs.y[..rows * dim].copy_from_slice(&z[..rows * dim]);
    for (l, (at, layer)) in flow.couplings.iter().zip(&mut bufs.layers).enumerate() {
        nets_forward(gemm, params, at, flow.tanh, layer, Mat::dense(&bufs.y, rows, dim), c);
        let (s, t) = (layer.scale.output(rows), layer.translation.output(rows));
        for i in 0..rows {
            let moved = &mut bufs.y[i * dim + at.moved_from..i * dim + at.moved_from + at.moved];
            if record {
                let input = &mut layer.diff[i * at.moved..(i + 1) * at.moved];
                let exp_s = &mut layer.neg_exp[i * at.moved..(i + 1) * at.moved];
                for ((((x, s), t), x0), e) in
                    moved.iter_mut().zip(s.row(i)).zip(t.row(i)).zip(input).zip(exp_s)
                {
                    *x0 = *x;
                    *e = s.exp();
                    *x = *x * *e + t;
                }
                // The candle policy accumulates the layers' sum s in forward order.
                let layer_log_det = s.row(i).iter().sum::<f32>();
                bufs.log_det[i] = if l == 0 { layer_log_det } else { bufs.log_det[i] + layer_log_det };
            } else {
                for ((x, s), t) in moved.iter_mut().zip(s.row(i)).zip(t.row(i)) {
                    *x = *x * s.exp() + t;
                }
            }
        }
    }
}

/// log pi(a~|s) by the forward change of variables of a recorded [`sample`] from latents `z`:
/// log N(z) - log|det dy/dz| - (if `squashed`, a = tanh(y)) sum_j log(1 - a_j^2 + eps).
pub(crate) fn sample_log_pi(bufs: &mut FlowBufs, z: &[f32], rows: usize, squashed: Option<&[f32]>) {
    let dim = bufs.dim;
    for i in 0..rows {
        let log_py = standard_normal_log_density(&z[i * dim..(i + 1) * dim]) - bufs.log_det[i];
        bufs.log_pi[i] = match squashed {
            Some(a) => log_py - tanh_log_det(&a[i * dim..(i + 1) * dim]),
            None => log_py,
        };
    }
}

/// Inverse pass z = f^-1(y; c) from `bufs.y`, then log pi through it; `squashed` is a = tanh(y)
/// (`rows x D`, computed once by the caller for Q) when the level squashes.
///
/// With `reuse_last`, the last coupling layer's nets are not run again: right after
/// [`sample`] with the same c and parameters their buffers already hold exactly the values the
/// inverse needs, because that layer leaves its kept half of y untouched.
pub(crate) fn inverse(
    gemm: &Gemm,
    params: &[f32],
    flow: Flow,
    bufs: &mut FlowBufs,
    c: Mat,
    squashed: Option<&[f32]>,
    reuse_last: bool,
) {
    let (rows, dim) = (c.rows(), bufs.dim);
    bufs.z[..rows * dim].copy_from_slice(&bufs.y[..rows * dim]);
    let last = flow.couplings.len() - 1;
    for (l, (at, layer)) in flow.couplings.iter().zip(&mut bufs.layers).enumerate().rev() {
        if !(reuse_last && l == last) {
            nets_forward(gemm, params, at, flow.tanh, layer, Mat::dense(&bufs.z, rows, dim), c);
        }
        let (s, t) = (layer.scale.output(rows), layer.translation.output(rows));
        for i in 0..rows {
            let moved = &mut bufs.z[i * dim + at.moved_from..i * dim + at.moved_from + at.moved];
            let diff = &mut layer.diff[i * at.moved..(i + 1) * at.moved];
            let neg_exp = &mut layer.neg_exp[i * at.moved..(i + 1) * at.moved];
            for ((((x, s), t), d), e) in moved.iter_mut().zip(s.row(i)).zip(t.row(i)).zip(diff).zip(neg_exp) {
                *d = *x - t;
                *e = (-s).exp();
                *x = *d * *e;
            }
            // The candle policy accumulates the layers' -sum s in inverse-pass order.
            let layer_log_det = -s.row(i).iter().sum::<f32>();
            bufs.log_det[i] = if l == last { layer_log_det } else { bufs.log_det[i] + layer_log_det };
        }
    }
    for i in 0..rows {
        // candle: log N(z) - (bijector log-det), the bijector log-det being the negated inverse one.
        let log_py = standard_normal_log_density(&bufs.z[i * dim..(i + 1) * dim]) - (-bufs.log_det[i]);
        bufs.log_pi[i] = match squashed {
            Some(a) => log_py - tanh_log_det(&a[i * dim..(i + 1) * dim]),
            None => log_py,
        };
    }
}

/// Backward of the inverse pass for dL/dlog pi = `log_pi_grad` (y fixed): finishes every coupling
/// net's parameters in `train` and writes dL/dc into `context_grad`.
///
/// d log N(z)/dz = -z; through layer l's inverse map x_M = d e, d = x'_M - t, e = exp(-s):
/// dL/dt = -g e, dL/ds = -(g d) e - dL/dlog pi (the second term from log|det| = -sum s),
/// dL/dx'_M = g e, dL/dx'_K = g_K + dL/du_K, dL/dc += dL/du_c.
pub(crate) fn backward(
    gemm: &Gemm,
    train: &mut Trainable,
    flow: Flow,
    bufs: &mut FlowBufs,
    log_pi_grad: &[f32],
    context_grad: &mut MatMut,
) {
    let (rows, dim) = (context_grad.rows(), bufs.dim);
    let state = bufs.state_grad[..rows * dim].chunks_exact_mut(dim);
    for ((dz, z), g) in state.zip(bufs.z.chunks_exact(dim)).zip(log_pi_grad) {
        for (dz, z) in dz.iter_mut().zip(z) {
            *dz = -(z * g);
        }
    }
    // The inverse pass ran the layers last to first, so its backward runs them first to last.
    for (l, (at, layer)) in flow.couplings.iter().zip(&mut bufs.layers).enumerate() {
        {
            let mut ds = layer.scale.output_grad_mut(rows);
            let mut dt = layer.translation.output_grad_mut(rows);
            for (i, log_pi_grad) in log_pi_grad.iter().enumerate().take(rows) {
                let state = &mut bufs.state_grad[i * dim + at.moved_from..i * dim + at.moved_from + at.moved];
                let diff = &layer.diff[i * at.moved..(i + 1) * at.moved];
                let neg_exp = &layer.neg_exp[i * at.moved..(i + 1) * at.moved];
                let (ds, dt) = (ds.row_mut(i), dt.row_mut(i));
                for ((((g, d), e), ds), dt) in state.iter_mut().zip(diff).zip(neg_exp).zip(ds).zip(dt) {
                    let through_diff = *g * e;
                    *ds = -((*g * d) * e) + -log_pi_grad;
                    *dt = -through_diff;
                    *g = through_diff;
                }
            }
        }
        let mut state = MatMut::dense(&mut bufs.state_grad[..rows * dim], rows, dim);
        nets_backward(gemm, train, flow.tanh, (at, layer), &mut state, context_grad, l == 0);
    }
}

/// The s and t nets' backward for layer `at` from their output gradients (already in `layer`'s
/// buffers): finishes their parameters in `train`, adds dL/du_K into the state gradient's kept
/// columns and dL/du_c into `context_grad` (overwriting it when `first`).
fn nets_backward(
    gemm: &Gemm,
    train: &mut Trainable,
    tanh: Tanh,
    (at, layer): (&CouplingAt, &mut CouplingBufs),
    state_grad: &mut MatMut,
    context_grad: &mut MatMut,
    first: bool,
) {
    let rows = context_grad.rows();
    let width = layer.width;
    let u = Mat::dense(&layer.input, rows, width);
    let mut du = MatMut::dense(&mut layer.input_grad[..rows * width], rows, width);
    for (k, (net, net_bufs)) in
        [(&at.scale, &mut layer.scale), (&at.translation, &mut layer.translation)].into_iter().enumerate()
    {
        backward_to_first(gemm, train, st_net(net, tanh), net_bufs, rows, None);
        let g0 = net_bufs.first_grad(rows);
        first_layer_backward(gemm, train, &net.layers[0], g0, u, Some((&mut du, k == 1)));
    }
    for i in 0..rows {
        let du = du.as_mat();
        let (du_kept, du_c) = du.row(i).split_at(at.kept);
        let state = &mut state_grad.row_mut(i)[at.kept_from..at.kept_from + at.kept];
        for (g, d) in state.iter_mut().zip(du_kept) {
            *g += d;
        }
        let dc = context_grad.row_mut(i);
        if first {
            dc.copy_from_slice(du_c);
        } else {
            for (g, d) in dc.iter_mut().zip(du_c) {
                *g += d;
            }
        }
    }
}

/// What the reparameterised loss sends back into a recorded [`sample`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleGrads<'a> {
    /// dL/da~ of everything but log pi (Q's and the action prior's terms), `rows x D`.
    pub action: &'a [f32],
    /// a~ = tanh(y), `rows x D`, when the level squashes.
    pub squashed: Option<&'a [f32]>,
    /// dL/dlog pi, `rows`.
    pub log_pi: &'a [f32],
}

/// Backward of a recorded [`sample`] (the reparameterised gradient, z fixed) from `grads`:
/// finishes every coupling net's parameters in `train` and writes dL/dc into `context_grad`.
///
/// The squash a = tanh(y) enters twice, as candle's graph has it: through a itself, and through
/// log pi's correction -sum log(1 - a^2 + eps), whose derivative in a is 2a / (1 - a^2 + eps);
/// both reach y through tanh' = 1 - a^2. Through layer l's forward map x'_M = x_M e + t, e = exp(s):
/// dL/dt = g, dL/ds = (g x_M) e - dL/dlog pi (log pi has -log|det| = -sum s), dL/dx_M = g e,
/// dL/dx_K = g_K + dL/du_K, dL/dc += dL/du_c.
pub(crate) fn backward_sample(
    gemm: &Gemm,
    train: &mut Trainable,
    flow: Flow,
    bufs: &mut FlowBufs,
    grads: SampleGrads,
    context_grad: &mut MatMut,
) {
    let SampleGrads { action: action_grad, squashed, log_pi: log_pi_grad } = grads;
    let (rows, dim) = (context_grad.rows(), bufs.dim);
    let one_plus_eps = (1.0 + SQUASH_EPSILON) as f32;
    for i in 0..rows {
        let dy = &mut bufs.state_grad[i * dim..(i + 1) * dim];
        let da = &action_grad[i * dim..(i + 1) * dim];
        match squashed {
            Some(a) => {
                let g = log_pi_grad[i];
                for ((dy, da), t) in dy.iter_mut().zip(da).zip(&a[i * dim..(i + 1) * dim]) {
                    // d/da of -g log(1 - a^2 + eps), then both paths through tanh.
                    let through_log_pi = (g / (-(t * t) + one_plus_eps)) * t * 2.0;
                    *dy = -((da + through_log_pi) * (t * t - 1.0));
                }
            }
            None => dy.copy_from_slice(da),
        }
    }
    // The sampling pass ran the layers first to last, so its backward runs them last to first.
    let last = flow.couplings.len() - 1;
    for (l, (at, layer)) in flow.couplings.iter().zip(&mut bufs.layers).enumerate().rev() {
        {
            let mut ds = layer.scale.output_grad_mut(rows);
            let mut dt = layer.translation.output_grad_mut(rows);
            for (i, log_pi_grad) in log_pi_grad.iter().enumerate().take(rows) {
                let state = &mut bufs.state_grad[i * dim + at.moved_from..i * dim + at.moved_from + at.moved];
                let input = &layer.diff[i * at.moved..(i + 1) * at.moved];
                let exp_s = &layer.neg_exp[i * at.moved..(i + 1) * at.moved];
                let (ds, dt) = (ds.row_mut(i), dt.row_mut(i));
                for ((((g, x), e), ds), dt) in state.iter_mut().zip(input).zip(exp_s).zip(ds).zip(dt) {
                    *ds = (*g * x) * e - log_pi_grad;
                    *dt = *g;
                    *g *= e;
                }
            }
        }
        let mut state = MatMut::dense(&mut bufs.state_grad[..rows * dim], rows, dim);
        nets_backward(gemm, train, flow.tanh, (at, layer), &mut state, context_grad, l == last);
    }
}
