//! [`Batch`]: transitions as flat row-major `f32` buffers, and their upload to tensors.

use candle_core::{Device, Tensor};

use crate::config::AgentConfig;
use crate::error::{Error, Result};
use crate::losses::{q_target, td_error};
use crate::networks::Networks;

/// A batch of transitions (s, a, r, s', done), row-major, with optional importance-sampling weights.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// Number of transitions B.
    pub size: usize,
    /// s, `B * obs_dim`.
    pub observations: Vec<f32>,
    /// a as stored in replay (for a higher level: the latent h it chose), `B * act_dim`.
    pub actions: Vec<f32>,
    /// Unscaled environment rewards r, `B`.
    pub rewards: Vec<f32>,
    /// s', `B * obs_dim`.
    pub next_observations: Vec<f32>,
    /// 1.0 where the episode terminated at s' (not time-limit truncation), else 0.0; `B`.
    pub terminated: Vec<f32>,
    /// Prioritized replay's importance-sampling weights w (Eq. 2.32), `B`; `None` means all 1.
    /// They weight the Q loss only.
    pub is_weights: Option<Vec<f32>>,
}

impl Batch {
    /// Checks every buffer's length against `size` and the dimensions.
    pub fn validate(&self, obs_dim: usize, act_dim: usize) -> Result<()> {
        if self.size == 0 {
            return Err(Error::BadInput("batch is empty".into()));
        }
        let b = self.size;
        let mut checks = vec![
            ("observations", self.observations.len(), b * obs_dim),
            ("actions", self.actions.len(), b * act_dim),
            ("rewards", self.rewards.len(), b),
            ("next_observations", self.next_observations.len(), b * obs_dim),
            ("terminated", self.terminated.len(), b),
        ];
        if let Some(w) = &self.is_weights {
            checks.push(("is_weights", w.len(), b));
        }
        for (name, got, want) in checks {
            if got != want {
                return Err(Error::BadInput(format!("batch.{name} has {got} values, expected {want}")));
            }
        }
        Ok(())
    }
}

/// A validated batch on the device.
#[derive(Debug)]
pub(crate) struct BatchTensors {
    pub observations: Tensor,
    pub actions: Tensor,
    pub rewards: Tensor,
    pub next_observations: Tensor,
    pub terminated: Tensor,
    pub is_weights: Option<Tensor>,
}

impl BatchTensors {
    pub fn new(batch: &Batch, cfg: &AgentConfig) -> Result<Self> {
        batch.validate(cfg.obs_dim, cfg.act_dim)?;
        let (b, dev) = (batch.size, &Device::Cpu);
        Ok(Self {
            observations: Tensor::from_slice(&batch.observations, (b, cfg.obs_dim), dev)?,
            actions: Tensor::from_slice(&batch.actions, (b, cfg.act_dim), dev)?,
            rewards: Tensor::from_slice(&batch.rewards, b, dev)?,
            next_observations: Tensor::from_slice(&batch.next_observations, (b, cfg.obs_dim), dev)?,
            terminated: Tensor::from_slice(&batch.terminated, b, dev)?,
            is_weights: batch.is_weights.as_ref().map(|w| Tensor::from_slice(w, b, dev)).transpose()?,
        })
    }
}

/// The Q regression of a batch: y_q (Eq. 2.25 with reward scale), each Q's Q(s, a), and the signed
/// TD errors y_q - Q1(s, a) that prioritized replay uses (`docs/sac-lsp.md` §8, §10).
#[derive(Debug)]
pub(crate) struct QRegression {
    pub target: Tensor,
    pub q_values: Vec<Tensor>,
    pub td_errors: Tensor,
}

/// Evaluates the Q regression with the networks' current parameters (the learner's pre-update
/// forward pass, or an executor's local copy).
pub(crate) fn q_regression(nets: &Networks, cfg: &AgentConfig, batch: &BatchTensors) -> Result<QRegression> {
    let next_value = nets.v_target.model.forward(&batch.next_observations)?.detach();
    let target = q_target(
        &batch.rewards,
        &batch.terminated,
        &next_value,
        cfg.scale_reward.into(),
        cfg.bootstrap_discount().into(),
    )?;
    let q_values = nets
        .qs
        .iter()
        .map(|q| q.model.forward(&batch.observations, &batch.actions))
        .collect::<candle_core::Result<Vec<_>>>()?;
    let td_errors = td_error(&target, &q_values[0])?;
    Ok(QRegression { target, q_values, td_errors })
}
