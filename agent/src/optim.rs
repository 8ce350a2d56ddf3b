//! Adam as TensorFlow 1 implements it (`tf.train.AdamOptimizer`, which `sac.py` uses):
//! lr_t = lr sqrt(1 - b2^t) / (1 - b1^t); m = b1 m + (1 - b1) g; v = b2 v + (1 - b2) g^2;
//! theta -= lr_t m / (sqrt(v) + eps). This places epsilon differently from candle's `AdamW`
//! (which adds it to sqrt(v_hat)), and keeps its moments by parameter name for checkpoints.

use std::collections::HashMap;

use candle_core::{Device, Tensor, Var, backprop::GradStore};
use candle_nn::VarMap;

use crate::error::{Error, Result};
use crate::vars::sorted_vars;

/// Adam's hyperparameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    /// Learning rate (at the first step, when it decays).
    pub learning_rate: f64,
    /// The learning rate reached after `decay_steps` steps, linearly, and kept after.
    pub final_learning_rate: f64,
    /// Steps of the linear decay; 0: the learning rate is constant.
    pub decay_steps: u64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Added to sqrt(v).
    pub epsilon: f64,
}

impl AdamConfig {
    /// The Adam settings of `cfg`'s networks.
    pub fn for_agent(cfg: &crate::AgentConfig) -> Self {
        Self {
            learning_rate: cfg.learning_rate,
            final_learning_rate: cfg.final_learning_rate.unwrap_or(cfg.learning_rate),
            decay_steps: cfg.learning_rate_decay_updates,
            beta1: cfg.adam_beta1,
            beta2: cfg.adam_beta2,
            epsilon: cfg.adam_epsilon,
        }
    }

    /// lr_t = lr(t) sqrt(1 - b2^t) / (1 - b1^t) for step `t` (1 for the first), in f64, as
    /// `tf.train.AdamOptimizer` computes it; lr(t) decays linearly from `learning_rate` to
    /// `final_learning_rate` over `decay_steps`. Both learners take it from here, so they agree bit
    /// for bit.
    pub fn step_size(&self, t: u64) -> f64 {
        let lr = if self.decay_steps == 0 {
            self.learning_rate
        } else {
            let done = ((t.saturating_sub(1)) as f64 / self.decay_steps as f64).min(1.0);
            self.learning_rate + (self.final_learning_rate - self.learning_rate) * done
        };
        let t = t as f64;
        lr * (1.0 - self.beta2.powf(t)).sqrt() / (1.0 - self.beta1.powf(t))
    }
}

#[derive(Debug)]
struct Slot {
    name: String,
    var: Var,
    m: Vec<f32>,
    v: Vec<f32>,
}

/// One Adam optimiser over all variables of one network.
#[derive(Debug)]
pub struct Adam {
    slots: Vec<Slot>,
    steps: u64,
    cfg: AdamConfig,
}

impl Adam {
    /// An optimiser over every variable of `vars`, with zero moments.
    pub fn new(vars: &VarMap, cfg: AdamConfig) -> Result<Self> {
        let slots = sorted_vars(vars)?
            .into_iter()
            .map(|(name, var)| {
                let n = var.elem_count();
                Slot { name, var, m: vec![0.0; n], v: vec![0.0; n] }
            })
            .collect();
        Ok(Self { slots, steps: 0, cfg })
    }

    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// One step with the gradients in `grads`; variables without a gradient are left alone.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.steps += 1;
        let c = &self.cfg;
        let lr_t = c.step_size(self.steps) as f32;
        let (b1, b2, eps) = (c.beta1 as f32, c.beta2 as f32, c.epsilon as f32);
        for slot in &mut self.slots {
            let Some(g) = grads.get(slot.var.as_tensor()) else { continue };
            let g = g.flatten_all()?.to_vec1::<f32>()?;
            let mut theta = slot.var.as_tensor().flatten_all()?.to_vec1::<f32>()?;
            for (((p, m), v), g) in theta.iter_mut().zip(&mut slot.m).zip(&mut slot.v).zip(&g) {
                *m = b1 * *m + (1.0 - b1) * g;
                *v = b2 * *v + (1.0 - b2) * g * g;
                *p -= lr_t * *m / (v.sqrt() + eps);
            }
            let shape = slot.var.shape().clone();
            slot.var.set(&Tensor::from_vec(theta, shape, slot.var.device())?)?;
        }
        Ok(())
    }

    /// Moments and step count as named tensors: `{prefix}.m.{name}`, `{prefix}.v.{name}`,
    /// `{prefix}.steps` (i64).
    pub fn export(&self, prefix: &str, out: &mut Vec<(String, Tensor)>) -> Result<()> {
        for s in &self.slots {
            let shape = s.var.shape().clone();
            out.push((
                format!("{prefix}.m.{}", s.name),
                Tensor::from_slice(&s.m, shape.clone(), &Device::Cpu)?,
            ));
            out.push((format!("{prefix}.v.{}", s.name), Tensor::from_slice(&s.v, shape, &Device::Cpu)?));
        }
        out.push((format!("{prefix}.steps"), Tensor::from_slice(&[self.steps as i64], 1, &Device::Cpu)?));
        Ok(())
    }

    /// Restores what [`export`](Self::export) wrote.
    pub fn import(&mut self, prefix: &str, tensors: &HashMap<String, Tensor>) -> Result<()> {
        let get = |key: String| {
            tensors.get(&key).ok_or_else(|| Error::BadSnapshot(format!("missing tensor {key}")))
        };
        for s in &mut self.slots {
            for (kind, dst) in [("m", &mut s.m), ("v", &mut s.v)] {
                let src = get(format!("{prefix}.{kind}.{}", s.name))?.flatten_all()?.to_vec1::<f32>()?;
                if src.len() != dst.len() {
                    return Err(Error::BadSnapshot(format!("{prefix}.{kind}.{}: wrong size", s.name)));
                }
                *dst = src;
            }
        }
        let steps = get(format!("{prefix}.steps"))?.to_vec1::<i64>()?;
        self.steps = steps.first().map(|&s| s as u64).unwrap_or(0);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;

    #[test]
    fn the_learning_rate_decays_linearly_then_stays() {
        let cfg = AdamConfig {
            learning_rate: 2e-3,
            final_learning_rate: 5e-4,
            decay_steps: 100,
            beta1: 0.0,
            beta2: 0.0,
            epsilon: 1e-8,
        };
        // With both betas 0 the bias correction is 1, so the step size is lr(t) itself.
        assert_eq!(cfg.step_size(1), 2e-3);
        assert!((cfg.step_size(51) - 1.25e-3).abs() < 1e-15);
        assert_eq!(cfg.step_size(101), 5e-4);
        assert_eq!(cfg.step_size(10_000), 5e-4);
        let constant = AdamConfig { decay_steps: 0, ..cfg };
        assert_eq!(constant.step_size(10_000), 2e-3);
    }

    #[test]
    fn first_steps_match_tensorflow_formula() {
        let map = VarMap::new();
        map.get(2, "w", candle_nn::Init::Const(1.0), DType::F32, &Device::Cpu).unwrap();
        let cfg = AdamConfig {
            learning_rate: 0.1,
            final_learning_rate: 0.1,
            decay_steps: 0,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        };
        let mut adam = Adam::new(&map, cfg).unwrap();
        let w = sorted_vars(&map).unwrap()[0].1.clone();
        let (mut m, mut v, mut p) = ([0f64; 2], [0f64; 2], [1f64; 2]);
        for t in 1..=3 {
            // loss = sum(w^2 * [1, -3]): gradient 2 w * [1, -3].
            let k = Tensor::new(&[1f32, -3.0], &Device::Cpu).unwrap();
            let grads = w.as_tensor().sqr().unwrap().mul(&k).unwrap().sum_all().unwrap().backward().unwrap();
            adam.step(&grads).unwrap();
            let lr_t = 0.1 * (1.0 - 0.999f64.powi(t)).sqrt() / (1.0 - 0.9f64.powi(t));
            for i in 0..2 {
                let g = 2.0 * p[i] * [1.0, -3.0][i];
                m[i] = 0.9 * m[i] + 0.1 * g;
                v[i] = 0.999 * v[i] + 0.001 * g * g;
                p[i] -= lr_t * m[i] / (v[i].sqrt() + 1e-8);
            }
        }
        let got = w.as_tensor().to_vec1::<f32>().unwrap();
        for i in 0..2 {
            assert!((got[i] as f64 - p[i]).abs() < 1e-5, "{got:?} vs {p:?}");
        }
    }
}
