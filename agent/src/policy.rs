//! The latent-space policy (`docs/sac-lsp.md` §1): a = tanh(f(z; E(s))), z ~ N(0, I), f a real-NVP bijector
//! conditioned on the observation embedding c = E(s).
//!
//! Parameters: `embedding.layer{k}.*`, `coupling{i}.{scale,translation}.layer{k}.*`. The latent z
//! is an input: callers own their random number generators, so the policy itself is deterministic.

use candle_core::{Result, Tensor};
use candle_nn::VarBuilder;

use crate::config::AgentConfig;
use crate::coupling::{Coupling, CouplingOutput, CouplingSpec, Parity};
use crate::density::policy_log_density;
use crate::mlp::{Activation, BiasInit, Grad, Mlp, MlpSpec};

/// A policy draw for a batch.
#[derive(Clone, Debug)]
pub struct PolicySample {
    /// Actions a = tanh(y) (or y when the level does not squash), `[batch, act_dim]`.
    pub actions: Tensor,
    /// Pre-squash actions y = f(z; c), `[batch, act_dim]`.
    pub pre_squash: Tensor,
    /// log pi(a|s), `[batch]`, by the forward change of variables.
    pub log_prob: Tensor,
}

/// Output of the whole bijector in one direction.
#[derive(Clone, Debug)]
pub struct BijectorOutput {
    /// y for the forward map, z for the inverse, `[batch, act_dim]`.
    pub output: Tensor,
    /// log|det| of that direction's Jacobian, `[batch]`.
    pub log_det: Tensor,
}

/// The latent-space policy of one level.
#[derive(Clone, Debug)]
pub struct LatentPolicy {
    embedding: Mlp,
    couplings: Vec<Coupling>,
    squash: bool,
    act_dim: usize,
}

impl LatentPolicy {
    /// Builds the embedding under `vb.pp("embedding")` and coupling layer i under `vb.pp("coupling{i}")`.
    pub fn new(cfg: &AgentConfig, vb: VarBuilder) -> Result<Self> {
        let inputs = [("x", cfg.obs_dim)];
        let output = if cfg.embedding_output_relu { Activation::Relu } else { Activation::Linear };
        let embedding = MlpSpec {
            inputs: &inputs,
            layers: &cfg.embedding_layers,
            hidden: Activation::Relu,
            output,
            bias: BiasInit::Zero,
        };
        let embedding = Mlp::new(&embedding, vb.pp("embedding"))?;
        let context_dim = *cfg.embedding_layers.last().unwrap_or(&0);
        let couplings = (0..cfg.coupling_layers)
            .map(|i| {
                let spec = CouplingSpec {
                    parity: Parity::of_layer(i),
                    dim: cfg.act_dim,
                    context_dim,
                    hidden: &cfg.coupling_hidden,
                };
                Coupling::new(&spec, vb.pp(format!("coupling{i}")))
            })
            .collect::<Result<_>>()?;
        Ok(Self { embedding, couplings, squash: cfg.squash, act_dim: cfg.act_dim })
    }

    /// Action (and latent) dimension.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// Whether actions are tanh-squashed.
    pub fn squashes(&self) -> bool {
        self.squash
    }

    /// Observation embedding c = E(s), `[batch, dim c]`.
    pub fn embed(&self, obs: &Tensor) -> Result<Tensor> {
        self.embedding.forward(&[obs], Grad::Track)
    }

    /// y = f(z; c) through the coupling layers in order, with log|det df/dz| = sum of all s.
    pub fn bijector_forward(&self, z: &Tensor, context: &Tensor) -> Result<BijectorOutput> {
        fold(self.couplings.iter(), z, |layer, x| layer.forward(x, context, Grad::Track))
    }

    /// z = f^-1(y; c) through the coupling layers in reverse, with log|det dz/dy| = -sum of all s.
    pub fn bijector_inverse(&self, y: &Tensor, context: &Tensor) -> Result<BijectorOutput> {
        fold(self.couplings.iter().rev(), y, |layer, x| layer.inverse(x, context, Grad::Track))
    }

    fn squashed(&self, y: &Tensor) -> Result<Tensor> {
        if self.squash { y.tanh() } else { Ok(y.clone()) }
    }

    /// Draws actions for latents `z` given the embedding: y = f(z; c), a = tanh(y), and log pi by the
    /// forward change of variables. Gradients flow through z's map (the reparameterised path).
    pub fn sample_embedded(&self, context: &Tensor, z: &Tensor) -> Result<PolicySample> {
        let fwd = self.bijector_forward(z, context)?;
        let log_prob = policy_log_density(z, &fwd.log_det, &fwd.output, self.squash)?;
        Ok(PolicySample { actions: self.squashed(&fwd.output)?, pre_squash: fwd.output, log_prob })
    }

    /// [`sample_embedded`](Self::sample_embedded) from observations.
    pub fn sample(&self, obs: &Tensor, z: &Tensor) -> Result<PolicySample> {
        self.sample_embedded(&self.embed(obs)?, z)
    }

    /// log pi(a|s) of given pre-squash actions y through the inverse pass:
    /// log N(f^-1(y)) + log|det df^-1/dy| - squash correction. Differentiating this with y held fixed
    /// is what the likelihood-ratio gradient needs (`docs/sac-lsp.md` §4).
    pub fn log_prob_embedded(&self, context: &Tensor, pre_squash: &Tensor) -> Result<Tensor> {
        let inv = self.bijector_inverse(pre_squash, context)?;
        // policy_log_density subtracts a forward log-det; the inverse one is its negation.
        policy_log_density(&inv.output, &inv.log_det.neg()?, pre_squash, self.squash)
    }

    /// [`log_prob_embedded`](Self::log_prob_embedded) from observations.
    pub fn log_prob(&self, obs: &Tensor, pre_squash: &Tensor) -> Result<Tensor> {
        self.log_prob_embedded(&self.embed(obs)?, pre_squash)
    }

    /// Deterministic mode: a = tanh(f(h; E(s))) for a latent h held fixed by the caller
    /// (`docs/sac-lsp.md` §1), or given by the level above in a stack (§9).
    pub fn deterministic(&self, obs: &Tensor, h: &Tensor) -> Result<Tensor> {
        let y = self.bijector_forward(h, &self.embed(obs)?)?.output;
        self.squashed(&y)
    }
}

/// The bijector in one direction: `x` through `layers` in the order given, each mapped by `map` (a
/// layer's forward or inverse), with the layers' log|det| summed in that order.
fn fold<'a>(
    layers: impl Iterator<Item = &'a Coupling>,
    x: &Tensor,
    map: impl Fn(&Coupling, &Tensor) -> Result<CouplingOutput>,
) -> Result<BijectorOutput> {
    let mut x = x.clone();
    let mut log_det: Option<Tensor> = None;
    for layer in layers {
        let out = map(layer, &x)?;
        x = out.output;
        log_det = Some(match log_det {
            None => out.log_det,
            Some(acc) => (acc + out.log_det)?,
        });
    }
    let log_det = log_det.ok_or_else(|| candle_core::Error::Msg("policy without coupling layers".into()))?;
    Ok(BijectorOutput { output: x, log_det })
}
