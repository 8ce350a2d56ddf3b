//! The critics (`docs/sac-lsp.md` §11, §13): Q(s, a) and V(s), each hidden ReLU layers and a linear
//! output: one value (the paper's), or the logits of a categorical distribution over a fixed
//! support, whose mean is the critic's value.
//!
//! Q's first layer has separate weight matrices `layer0.weight_observation` and
//! `layer0.weight_action` (`MLPFunction`'s multi-input layer). Values are squeezed to `[batch]`.

use candle_core::{D, Device, Result, Tensor};
use candle_nn::VarBuilder;

use crate::categorical::Support;
use crate::config::{AgentConfig, CategoricalVariant, Critic};
use crate::mlp::{Activation, BiasInit, Dense, Grad, Mlp, MlpSpec};

/// What a critic's last layer means.
#[derive(Clone, Debug)]
enum Head {
    /// The value itself.
    Scalar,
    /// Logits of the atoms `z` (`[atoms]`); `bottleneck` is the dissertation code's extra
    /// Linear(1 -> atoms) after a linear width-1 layer (`sac-c51/sac/misc/mlp.py`).
    Categorical { z: Tensor, bottleneck: Option<Dense> },
}

/// An MLP and its head; shared by [`QNet`] and [`ValueNet`].
#[derive(Clone, Debug)]
struct Body {
    mlp: Mlp,
    head: Head,
}

impl Body {
    fn new(cfg: &AgentConfig, inputs: &[(&str, usize)], vb: VarBuilder) -> Result<Self> {
        let mut layers = cfg.critic_layers();
        let bottleneck =
            cfg.critic == Critic::Categorical && cfg.categorical.variant == CategoricalVariant::Dissertation;
        if bottleneck {
            layers.pop();
        }
        let spec = MlpSpec {
            inputs,
            layers: &layers,
            hidden: Activation::Relu,
            output: Activation::Linear,
            bias: BiasInit::Zero,
        };
        let mlp = Mlp::new(&spec, vb.clone())?;
        let head = match cfg.critic {
            Critic::Scalar => Head::Scalar,
            Critic::Categorical => {
                let support = Support::new(&cfg.categorical);
                let bottleneck = if bottleneck {
                    let vb = vb.pp(format!("layer{}", layers.len()));
                    Some(Dense::new(&[("x", 1)], support.atoms(), BiasInit::Zero, vb)?)
                } else {
                    None
                };
                Head::Categorical { z: Tensor::new(support.values(), &Device::Cpu)?, bottleneck }
            }
        };
        Ok(Self { mlp, head })
    }

    /// The last layer's output: `[batch, 1]` or the atoms' logits `[batch, atoms]`.
    fn raw(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        let out = self.mlp.forward(xs, grad)?;
        match &self.head {
            Head::Categorical { bottleneck: Some(dense), .. } => dense.forward(&[&out], grad),
            _ => Ok(out),
        }
    }

    /// The value: the output, or the mean sum_i z_i p_i of the atoms' probabilities.
    fn value(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        let raw = self.raw(xs, grad)?;
        match &self.head {
            Head::Scalar => raw.squeeze(1),
            Head::Categorical { z, .. } => {
                candle_nn::ops::softmax(&raw, D::Minus1)?.broadcast_mul(z)?.sum(D::Minus1)
            }
        }
    }

    /// The atoms' probabilities `[batch, atoms]` (a categorical critic only).
    fn probs(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        candle_nn::ops::softmax(&self.categorical_logits(xs, grad)?, D::Minus1)
    }

    /// The atoms' log-probabilities `[batch, atoms]` (a categorical critic only).
    fn log_probs(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        candle_nn::ops::log_softmax(&self.categorical_logits(xs, grad)?, D::Minus1)
    }

    fn categorical_logits(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        match self.head {
            Head::Categorical { .. } => self.raw(xs, grad),
            Head::Scalar => candle_core::bail!("a scalar critic has no distribution"),
        }
    }
}

fn grad(frozen: bool) -> Grad {
    if frozen { Grad::Frozen } else { Grad::Track }
}

/// Soft action value Q(s, a).
#[derive(Clone, Debug)]
pub struct QNet {
    body: Body,
}

impl QNet {
    /// Builds the layers under `vb.pp("layer{k}")`.
    pub fn new(cfg: &AgentConfig, vb: VarBuilder) -> Result<Self> {
        let inputs = [("observation", cfg.obs_dim), ("action", cfg.act_dim)];
        Ok(Self { body: Body::new(cfg, &inputs, vb)? })
    }

    /// Q(s, a) for `[batch, obs_dim]` and `[batch, act_dim]`, as `[batch]`.
    pub fn forward(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        self.body.value(&[obs, act], Grad::Track)
    }

    /// Q(s, a) with Q's parameters as constants: gradients reach `act` only.
    pub fn forward_frozen(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        self.body.value(&[obs, act], Grad::Frozen)
    }

    /// A categorical Q's atom probabilities `[batch, atoms]`; `frozen` holds its parameters constant.
    pub fn probs(&self, obs: &Tensor, act: &Tensor, frozen: bool) -> Result<Tensor> {
        self.body.probs(&[obs, act], grad(frozen))
    }

    /// A categorical Q's atom log-probabilities `[batch, atoms]`, with gradient.
    pub fn log_probs(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        self.body.log_probs(&[obs, act], Grad::Track)
    }
}

/// Soft state value V(s) (also the target V-bar).
#[derive(Clone, Debug)]
pub struct ValueNet {
    body: Body,
}

impl ValueNet {
    /// Builds the layers under `vb.pp("layer{k}")`.
    pub fn new(cfg: &AgentConfig, vb: VarBuilder) -> Result<Self> {
        Ok(Self { body: Body::new(cfg, &[("x", cfg.obs_dim)], vb)? })
    }

    /// V(s) for `[batch, obs_dim]`, as `[batch]`.
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        self.body.value(&[obs], Grad::Track)
    }

    /// A categorical V's atom probabilities `[batch, atoms]`, with gradient.
    pub fn probs(&self, obs: &Tensor) -> Result<Tensor> {
        self.body.probs(&[obs], Grad::Track)
    }

    /// A categorical V's atom log-probabilities `[batch, atoms]`, with gradient.
    pub fn log_probs(&self, obs: &Tensor) -> Result<Tensor> {
        self.body.log_probs(&[obs], Grad::Track)
    }
}
