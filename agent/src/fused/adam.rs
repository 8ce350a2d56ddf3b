//! TF-style Adam as one loop per parameter array, and the Polyak average of V-bar, on the arena.
//! Both round exactly like `optim.rs` and `target.rs` (same f32 expressions, same f64 -> f32
//! casts of the scalar factors), so equal gradients give bit-equal parameters.

use crate::optim::AdamConfig;

use super::dense;
use super::layout::DenseAt;
use super::linalg::{Mat, MatMut, VectorKernel, vectorized};

/// Adam's per-step scalars, computed once per network and step.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AdamStep {
    lr_t: f32,
    beta1: f32,
    beta2: f32,
    epsilon: f32,
}

impl AdamStep {
    /// Step number `t` (1 for the first step): lr_t from [`AdamConfig::step_size`], the f64
    /// expression the candle Adam (`optim.rs`) uses too.
    pub(crate) fn new(cfg: &AdamConfig, t: u64) -> Self {
        let lr_t = cfg.step_size(t);
        Self {
            lr_t: lr_t as f32,
            beta1: cfg.beta1 as f32,
            beta2: cfg.beta2 as f32,
            epsilon: cfg.epsilon as f32,
        }
    }

    /// m = b1 m + (1 - b1) g; v = b2 v + (1 - b2) g^2; theta -= lr_t m / (sqrt(v) + eps).
    #[inline(always)]
    pub(crate) fn apply(&self, theta: &mut [f32], grad: &[f32], m: &mut [f32], v: &mut [f32]) {
        let Self { lr_t, beta1: b1, beta2: b2, epsilon: eps } = *self;
        let n = theta.len();
        let (grad, m, v) = (&grad[..n], &mut m[..n], &mut v[..n]);
        for (((p, m), v), g) in theta.iter_mut().zip(m).zip(v).zip(grad) {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= lr_t * *m / (v.sqrt() + eps);
        }
    }
}

/// One array's Adam step as a vectorised kernel.
struct AdamArray<'a> {
    step: AdamStep,
    theta: &'a mut [f32],
    grad: &'a [f32],
    m: &'a mut [f32],
    v: &'a mut [f32],
}

impl VectorKernel for AdamArray<'_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        self.step.apply(self.theta, self.grad, self.m, self.v);
    }
}

/// The arena during the backward pass: parameters, their gradients and Adam's moments. With a
/// step set, each array is stepped as soon as the backward pass reports it finished (final
/// gradient, parameter no longer read this update), while its gradient and weights are still in
/// cache: the same arithmetic as a separate Adam pass, with half its memory traffic.
#[derive(Debug)]
pub(crate) struct Trainable<'a> {
    params: &'a mut [f32],
    grads: &'a mut [f32],
    m: &'a mut [f32],
    v: &'a mut [f32],
    step: Option<AdamStep>,
}

impl<'a> Trainable<'a> {
    /// The arena, gradients only until [`set_step`](Self::set_step).
    pub(crate) fn new(
        params: &'a mut [f32],
        grads: &'a mut [f32],
        m: &'a mut [f32],
        v: &'a mut [f32],
    ) -> Self {
        Self { params, grads, m, v, step: None }
    }

    /// The Adam step of the network whose arrays are finished next (`None`: gradients only).
    pub(crate) fn set_step(&mut self, step: Option<AdamStep>) {
        self.step = step;
    }

    /// W of `layer`.
    pub(crate) fn weight(&self, layer: &DenseAt) -> Mat<'_> {
        dense::weight(self.params, layer)
    }

    /// dL/dW of `layer`, `[out, fan_in]`.
    pub(crate) fn weight_grad(&mut self, layer: &DenseAt) -> MatMut<'_> {
        self.grad_matrix(layer.weight, layer.out, layer.fan_in)
    }

    /// The gradient of the `rows x cols` weight matrix at `offset`.
    pub(crate) fn grad_matrix(&mut self, offset: usize, rows: usize, cols: usize) -> MatMut<'_> {
        MatMut::dense(&mut self.grads[offset..offset + rows * cols], rows, cols)
    }

    /// dL/db of `layer`.
    pub(crate) fn bias_grad(&mut self, layer: &DenseAt) -> &mut [f32] {
        &mut self.grads[layer.bias..layer.bias + layer.out]
    }

    /// The array at `offset .. offset + len` has its final gradient and is not read again this
    /// update: step it now if a step is set.
    pub(crate) fn finished(&mut self, offset: usize, len: usize) {
        if let Some(step) = self.step {
            let r = offset..offset + len;
            let (theta, grad) = (&mut self.params[r.clone()], &self.grads[r.clone()]);
            vectorized(AdamArray { step, theta, grad, m: &mut self.m[r.clone()], v: &mut self.v[r] });
        }
    }

    /// The parameters, for the Polyak average once every array is stepped.
    pub(crate) fn params_mut(&mut self) -> &mut [f32] {
        self.params
    }
}

/// theta' <- (1 - tau) theta' + tau theta (Eq. 2.12), rounded like candle's two `affine`s and add.
#[inline(always)]
pub(crate) fn polyak(target: &mut [f32], online: &[f32], tau: f64) {
    let keep = (1.0 - tau) as f32;
    let take = tau as f32;
    for (t, o) in target.iter_mut().zip(online) {
        *t = (*t * keep + 0.0) + (o * take + 0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::Adam;
    use candle_core::{DType, Device, Tensor};
    use candle_nn::VarMap;

    #[test]
    fn fused_adam_is_bit_equal_to_the_candle_adam() {
        let map = VarMap::new();
        map.get(5, "w", candle_nn::Init::Const(0.5), DType::F32, &Device::Cpu).unwrap();
        let cfg = AdamConfig {
            learning_rate: 3e-4,
            final_learning_rate: 3e-4,
            decay_steps: 0,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        };
        let mut adam = Adam::new(&map, cfg).unwrap();
        let w = map.all_vars()[0].clone();
        let (mut theta, mut m, mut v) = (vec![0.5f32; 5], vec![0.0; 5], vec![0.0; 5]);
        let k = Tensor::new(&[1f32, -3.0, 1e-9, 0.0, 250.0], &Device::Cpu).unwrap();
        for t in 1..=4 {
            // loss = sum(k w^2): gradient 2 k w, including a tiny and a zero element.
            let grads = w.as_tensor().sqr().unwrap().mul(&k).unwrap().sum_all().unwrap().backward().unwrap();
            let g = grads.get(w.as_tensor()).unwrap().to_vec1::<f32>().unwrap();
            adam.step(&grads).unwrap();
            AdamStep::new(&cfg, t).apply(&mut theta, &g, &mut m, &mut v);
            assert_eq!(theta, w.as_tensor().to_vec1::<f32>().unwrap(), "step {t}");
        }
    }

    #[test]
    fn polyak_matches_the_candle_update() {
        let (target, online) = (VarMap::new(), VarMap::new());
        let dev = Device::Cpu;
        target.get(3, "b", candle_nn::Init::Uniform { lo: -1.0, up: 1.0 }, DType::F32, &dev).unwrap();
        online.get(3, "b", candle_nn::Init::Uniform { lo: -1.0, up: 1.0 }, DType::F32, &dev).unwrap();
        let read = |m: &VarMap| m.all_vars()[0].as_tensor().to_vec1::<f32>().unwrap();
        let (mut t, o) = (read(&target), read(&online));
        crate::target::polyak_update(&target, &online, 0.01f32.into()).unwrap();
        polyak(&mut t, &o, 0.01f32.into());
        assert_eq!(t, read(&target));
    }
}
