//! The critics (`docs/sac-lsp.md` §11): Q(s, a) and V(s), each hidden ReLU layers and a linear scalar
//! output.
//!
//! Q's first layer has separate weight matrices `layer0.weight_observation` and
//! `layer0.weight_action` (`MLPFunction`'s multi-input layer). Outputs are squeezed to `[batch]`.

use candle_core::{Result, Tensor};
use candle_nn::VarBuilder;

use crate::config::AgentConfig;
use crate::mlp::{Activation, BiasInit, Grad, Mlp, MlpSpec};

fn critic_layers(cfg: &AgentConfig) -> Vec<usize> {
    let mut layers = cfg.critic_hidden.clone();
    layers.push(1);
    layers
}

/// Soft action value Q(s, a).
#[derive(Clone, Debug)]
pub struct QNet {
    mlp: Mlp,
}

impl QNet {
    /// Builds the layers under `vb.pp("layer{k}")`.
    pub fn new(cfg: &AgentConfig, vb: VarBuilder) -> Result<Self> {
        let inputs = [("observation", cfg.obs_dim), ("action", cfg.act_dim)];
        let layers = critic_layers(cfg);
        let spec = MlpSpec {
            inputs: &inputs,
            layers: &layers,
            hidden: Activation::Relu,
            output: Activation::Linear,
            bias: BiasInit::Zero,
        };
        Ok(Self { mlp: Mlp::new(&spec, vb)? })
    }

    /// Q(s, a) for `[batch, obs_dim]` and `[batch, act_dim]`, as `[batch]`.
    pub fn forward(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        self.mlp.forward(&[obs, act], Grad::Track)?.squeeze(1)
    }

    /// Q(s, a) with Q's parameters as constants: gradients reach `act` only.
    pub fn forward_frozen(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        self.mlp.forward(&[obs, act], Grad::Frozen)?.squeeze(1)
    }
}

/// Soft state value V(s) (also the target V-bar).
#[derive(Clone, Debug)]
pub struct ValueNet {
    mlp: Mlp,
}

impl ValueNet {
    /// Builds the layers under `vb.pp("layer{k}")`.
    pub fn new(cfg: &AgentConfig, vb: VarBuilder) -> Result<Self> {
        let inputs = [("x", cfg.obs_dim)];
        let layers = critic_layers(cfg);
        let spec = MlpSpec {
            inputs: &inputs,
            layers: &layers,
            hidden: Activation::Relu,
            output: Activation::Linear,
            bias: BiasInit::Zero,
        };
        Ok(Self { mlp: Mlp::new(&spec, vb)? })
    }

    /// V(s) for `[batch, obs_dim]`, as `[batch]`.
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        self.mlp.forward(&[obs], Grad::Track)?.squeeze(1)
    }
}
