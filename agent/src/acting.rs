//! [`Actor`]: what an executor runs each env step, with weights loaded from [`ParamSnapshot`]s.

use candle_core::{DType, Device, Tensor};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

use crate::batch::{Batch, BatchTensors, q_regression};
use crate::config::AgentConfig;
use crate::error::{Error, Result};
use crate::networks::Networks;
use crate::params::ParamSnapshot;
use crate::stack::PolicyStack;

/// How the trained level picks its latent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// A fresh z ~ N(0, I) every step: the stochastic policy used for data collection
    /// (`docs/sac-lsp.md` §12).
    Explore,
    /// The fixed latent h drawn when the actor was made (or last redrawn): evaluation mode
    /// (`docs/sac-lsp.md` §1). The "MAP" candidate selection of the original is degenerate and is not
    /// reproduced.
    Deterministic,
}

/// One decision.
#[derive(Clone, Debug, PartialEq)]
pub struct Act {
    /// The trained level's action: what replay stores (for a higher level, the latent h).
    pub action: Vec<f32>,
    /// The action to send to the environment (equal to `action` without frozen levels).
    pub env_action: Vec<f32>,
}

/// An executor's policy and critics: acts on single observations and computes initial priorities.
#[derive(Debug)]
pub struct Actor {
    cfg: AgentConfig,
    nets: Networks,
    stack: PolicyStack,
    rng: StdRng,
    fixed_latent: Vec<f32>,
    version: Option<u64>,
}

impl Actor {
    /// A single-level actor. Its weights are random until [`load`](Self::load).
    pub fn new(cfg: AgentConfig, seed: u64) -> Result<Self> {
        Self::with_stack(cfg, PolicyStack::empty(), seed)
    }

    /// An actor whose trained level (`cfg`) sits on top of frozen `stack` levels.
    pub fn with_stack(cfg: AgentConfig, stack: PolicyStack, seed: u64) -> Result<Self> {
        cfg.validate()?;
        stack.check_fits(&cfg)?;
        let nets = Networks::new(&cfg, seed, DType::F32)?;
        let mut rng = StdRng::seed_from_u64(seed);
        let fixed_latent = (0..cfg.act_dim).map(|_| rng.sample(StandardNormal)).collect();
        Ok(Self { cfg, nets, stack, rng, fixed_latent, version: None })
    }

    /// Loads every network of the trained level from a learner snapshot.
    pub fn load(&mut self, snapshot: &ParamSnapshot) -> Result<()> {
        self.nets.import(&snapshot.tensors()?)?;
        self.version = Some(snapshot.version);
        Ok(())
    }

    /// Version of the loaded snapshot, `None` before the first load.
    pub fn version(&self) -> Option<u64> {
        self.version
    }

    /// The configuration of the trained level.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// Draws a new fixed latent for [`Mode::Deterministic`].
    pub fn redraw_fixed_latent(&mut self) {
        let rng = &mut self.rng;
        self.fixed_latent = (0..self.cfg.act_dim).map(|_| rng.sample(StandardNormal)).collect();
    }

    /// Sets the fixed latent to `h` (one value per action dimension) until the next redraw: one h
    /// shared by several actors, as an evaluation spread over threads needs.
    pub fn set_fixed_latent(&mut self, h: &[f32]) -> Result<()> {
        if h.len() != self.cfg.act_dim {
            return Err(Error::BadInput(format!(
                "latent has {} values, expected {}",
                h.len(),
                self.cfg.act_dim
            )));
        }
        self.fixed_latent = h.to_vec();
        Ok(())
    }

    /// Restarts the actor's random stream (the stochastic policy's z and the next redrawn latent)
    /// at `seed`: an episode's draws then depend on its seed alone, not on what ran before.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = StdRng::seed_from_u64(seed);
    }

    /// The fixed latent of [`Mode::Deterministic`].
    pub fn fixed_latent(&self) -> &[f32] {
        &self.fixed_latent
    }

    /// Sets the fixed latent to h = 0 (the counterpart of a Gaussian policy's mean action) until the
    /// next redraw.
    pub fn zero_fixed_latent(&mut self) {
        self.fixed_latent = vec![0.0; self.cfg.act_dim];
    }

    /// Acts on one observation.
    pub fn act(&mut self, obs: &[f32], mode: Mode) -> Result<Act> {
        if obs.len() != self.cfg.obs_dim {
            return Err(Error::BadInput(format!(
                "observation has {} values, expected {}",
                obs.len(),
                self.cfg.obs_dim
            )));
        }
        let d = self.cfg.act_dim;
        let latent: Vec<f32> = match mode {
            Mode::Explore => (0..d).map(|_| self.rng.sample(StandardNormal)).collect(),
            Mode::Deterministic => self.fixed_latent.clone(),
        };
        let dev = &Device::Cpu;
        let obs = Tensor::from_slice(obs, (1, self.cfg.obs_dim), dev)?;
        let z = Tensor::from_vec(latent, (1, d), dev)?;
        let action = self.nets.policy.model.deterministic(&obs, &z)?;
        let env_action = self.stack.env_action(&obs, &action)?;
        Ok(Act { action: action.flatten_all()?.to_vec1()?, env_action: env_action.flatten_all()?.to_vec1()? })
    }

    /// Signed TD errors delta = scale r + (1 - d) gamma V-bar(s') - Q1(s, a) with the loaded weights:
    /// the same formula as [`UpdateOutput::td_errors`](crate::UpdateOutput::td_errors), for an
    /// executor's initial priorities (`docs/sac-lsp.md` §10).
    pub fn td_errors(&self, batch: &Batch) -> Result<Vec<f32>> {
        let b = BatchTensors::new(batch, &self.cfg)?;
        Ok(q_regression(&self.nets, &self.cfg, &b)?.td_errors.to_vec1()?)
    }
}
