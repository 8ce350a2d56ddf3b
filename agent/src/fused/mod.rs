//! [`FusedLearner`]: the same SAC-LSP update as [`Learner::update`](crate::Learner::update),
//! hand-fused on plain `f32` buffers and the `gemm` crate for speed (2.4-3.4x candle's updates/s on
//! one core at the Ant sizes, depending on the CPU; see `benches/update.rs` and the recorded runs in
//! `docs/results/README.md`).
//!
//! Candle spends much of an update outside its matrix kernels: bias-gradient reductions, an
//! allocation per op, unfused elementwise passes, Adam as a dozen tensor ops per array.
//! Here every parameter lives in one arena (`layout.rs`) with the
//! candle names, every intermediate in a workspace allocated once (`update.rs`), bias and
//! activation are fused into one pass after each GEMM and the bias gradient into the
//! activation-derivative pass (`dense.rs`), the bijector's sample, inverse and likelihood-ratio
//! backward are written out (`flow.rs`), the losses are one row loop (`objective.rs`), and Adam
//! runs array by array as soon as each gradient is final, while it is still in cache (`adam.rs`).
//! The elementwise loops are compiled for AVX-512 / AVX2 and picked at run time (`linalg.rs`), as
//! gemm picks its kernels. Subnormal floats are flushed to zero during an update (`denormals.rs`):
//! the Adam moments of dead ReLU units' weights decay into that range and slowed trained learners
//! by a quarter.
//!
//! # What is fused
//!
//! Every option of [`AgentConfig`] except the categorical critic (its softmax, projection and
//! cross-entropy would be kernels of their own; it runs on candle): the paper's configuration (single Q, likelihood-ratio policy
//! gradient, fixed temperature) and each option beyond it — the reparameterised policy gradient
//! (through the flow and the tanh), twin Q (clipped double Q), the learned temperature — with any
//! layer widths (a one-layer embedding included) and number of coupling layers, any action
//! dimension (a 1-d action's odd coupling layer is the identity), normal or uniform action prior,
//! squash on or off, ReLU or linear embedding output (so the hierarchy's higher levels too), IS
//! weights. [`FusedLearner::check_support`] names a configuration the fused kernels cannot run, so
//! [`Backend::Fused`] refuses it and [`Backend::Auto`] picks candle.
//!
//! # Equality with candle
//!
//! Parameters, Adam moments and step counts load from and save to the candle learner's
//! [`Checkpoint`] and [`ParamSnapshot`] formats, names included, and the latent noise is the same
//! per (seed, step) stream, so from one checkpoint both learners run the same update. Every
//! operation is rounded as candle rounds it (same gemm kernels, same order of sums, same f64 -> f32
//! scalars, candle's relu and tanh derivatives). With [`FusedLearner::with_exact_tanh`] the
//! updates are bit-identical to candle's on the tested configurations; by default the coupling
//! nets use a vectorised tanh within 1.3 ulp (`tanh.rs`) and the learners agree to ~1e-6
//! (`tests.rs` states the tolerances and why).

mod adam;
mod denormals;
mod dense;
mod dispatch;
mod flow;
pub(crate) mod layout;
mod linalg;
mod objective;
mod tanh;
mod update;

#[cfg(test)]
mod tests;

pub use dispatch::{AnyLearner, Backend};

use candle_core::{Device, Tensor};

use crate::acting::Actor;
use crate::batch::Batch;
use crate::config::AgentConfig;
use crate::error::{Error, Result};
use crate::learning::{Learner, UpdateOutput};
use crate::optim::AdamConfig;
use crate::params::{Checkpoint, ParamSnapshot, decode, encode, read_i64};

use layout::{Layout, Role};
use linalg::Gemm;
use tanh::Tanh;
use update::Workspace;

/// The SAC-LSP learner of the supported configurations, fused on `gemm` (see the module doc).
#[derive(Clone, Debug)]
pub struct FusedLearner {
    cfg: AgentConfig,
    seed: u64,
    step: u64,
    layout: Layout,
    params: Vec<f32>,
    grads: Vec<f32>,
    adam_m: Vec<f32>,
    adam_v: Vec<f32>,
    /// Adam step counts of [`Role::TRAINED`], in that order (0 for a set the level lacks).
    adam_steps: [u64; 5],
    adam: AdamConfig,
    gemm: Gemm,
    tanh: Tanh,
    /// Whether updates run with subnormals flushed to zero (`denormals.rs`; default true).
    flush_denormals: bool,
    work: Workspace,
}

impl FusedLearner {
    /// Why `cfg` cannot be fused, or `Ok` if it can.
    pub fn check_support(cfg: &AgentConfig) -> Result<()> {
        if cfg.critic != crate::config::Critic::Scalar {
            // A categorical critic's losses take a softmax, a projection and a cross-entropy: not
            // the shape of the fused kernels (`docs/sac-lsp.md` §13).
            return Err(Error::InvalidConfig(
                "the fused learner implements the scalar critic only; a categorical critic trains on the candle Learner"
                    .into(),
            ));
        }
        // Every other option is fused; a level whose every coupling layer is the identity (one coupling
        // layer on a 1-d action) has no policy parameters to train, which candle accepts.
        if cfg.act_dim < 2 && cfg.coupling_layers < 2 {
            return Err(Error::InvalidConfig(
                "the fused learner does not implement a policy without a non-identity coupling layer \
                 (act_dim 1 needs coupling_layers >= 2); use the candle Learner"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Whether [`FusedLearner`] implements `cfg`'s update (see the module doc).
    pub fn supports(cfg: &AgentConfig) -> bool {
        Self::check_support(cfg).is_ok()
    }

    /// A learner with exactly the initial state of `Learner::new(cfg, seed)` (same seeded
    /// initialisation, same initial soft update of V-bar).
    pub fn new(cfg: AgentConfig, seed: u64) -> Result<Self> {
        Self::check_support(&cfg)?;
        let candle = Learner::new(cfg.clone(), seed)?;
        Self::from_checkpoint(cfg, &candle.checkpoint()?)
    }

    /// Takes over a candle learner's full state (weights, Adam moments, step, seed).
    pub fn from_learner(learner: &Learner) -> Result<Self> {
        Self::from_checkpoint(learner.config().clone(), &learner.checkpoint()?)
    }

    /// Restores from a checkpoint of either learner; `cfg` must describe the same networks.
    pub fn from_checkpoint(cfg: AgentConfig, checkpoint: &Checkpoint) -> Result<Self> {
        cfg.validate()?;
        Self::check_support(&cfg)?;
        crate::resume::check_resume(&cfg, checkpoint)?;
        let t = decode(&checkpoint.safetensors)?;
        let layout = Layout::new(&cfg);
        let n = layout.len;
        let mut params = vec![0.0; n];
        layout.import(&Role::ALL, |r| r.name().to_string(), &t, &mut params)?;
        let (mut adam_m, mut adam_v) = (vec![0.0; n], vec![0.0; n]);
        let mut adam_steps = [0; 5];
        for (role, steps) in Role::TRAINED.iter().zip(&mut adam_steps).filter(|(r, _)| layout.has(**r)) {
            layout.import(&[*role], |r| format!("adam.{}.m", r.name()), &t, &mut adam_m)?;
            layout.import(&[*role], |r| format!("adam.{}.v", r.name()), &t, &mut adam_v)?;
            *steps = read_i64(&t, &format!("adam.{}.steps", role.name()))? as u64;
        }
        let adam = AdamConfig::for_agent(&cfg);
        let work = Workspace::new(&cfg, &layout, cfg.batch_size);
        Ok(Self {
            seed: read_i64(&t, "learner.seed")? as u64,
            step: read_i64(&t, "learner.step")? as u64,
            grads: vec![0.0; n],
            layout,
            params,
            adam_m,
            adam_v,
            adam_steps,
            adam,
            gemm: Gemm::new(1),
            tanh: Tanh::Fast,
            flush_denormals: true,
            work,
            cfg,
        })
    }

    /// Runs the matrix products on `threads` rayon threads (default 1: the calling thread only,
    /// which is fastest at these sizes).
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.gemm = Gemm::new(threads);
        self
    }

    /// With `exact`, evaluates tanh with the platform's libm `tanhf` as candle does, which makes
    /// every update bit-identical to the candle learner's on the same machine (the tests use this);
    /// by default a vectorised tanh within 1.3 ulp is used instead, ~10% faster, so the two
    /// learners agree to rounding (see `tests.rs` for the tolerances).
    pub fn with_exact_tanh(mut self, exact: bool) -> Self {
        self.tanh = if exact { Tanh::Libm } else { Tanh::Fast };
        self
    }

    /// With `flush` (the default), each update runs with the calling thread's subnormal floats
    /// flushed to zero (FTZ and DAZ; the module doc says why); without, in the caller's mode, as
    /// candle runs. GEMM worker threads of [`FusedLearner::with_threads`] keep their own mode.
    pub fn with_flush_denormals(mut self, flush: bool) -> Self {
        self.flush_denormals = flush;
        self
    }

    /// The configuration.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// Number of updates done (the version of the next snapshot).
    pub fn step(&self) -> u64 {
        self.step
    }

    /// The temperature alpha (learned, or fixed at `initial_temperature`).
    pub fn temperature(&self) -> f32 {
        match self.layout.log_alpha {
            Some(at) => f64::from(self.params[at]).exp() as f32,
            None => self.cfg.initial_temperature,
        }
    }

    /// One simultaneous update of every network from `batch` (`docs/sac-lsp.md` §2-§7), then
    /// V-bar <- (1 - tau) V-bar + tau V: the maths of [`Learner::update`].
    pub fn update(&mut self, batch: &Batch) -> Result<UpdateOutput> {
        batch.validate(self.cfg.obs_dim, self.cfg.act_dim)?;
        let _flush = self.flush_denormals.then(denormals::FlushDenormals::new);
        Ok(self.update_validated(batch))
    }

    /// Every network's weights, versioned by the learner step (the candle learner's format).
    pub fn snapshot(&self) -> Result<ParamSnapshot> {
        let mut tensors = Vec::new();
        self.layout.export(&Role::NETWORKS, |r| r.name().to_string(), &self.params, &mut tensors)?;
        let safetensors = encode(&tensors, &[("version", self.step.to_string())])?;
        Ok(ParamSnapshot { version: self.step, safetensors })
    }

    /// Overwrites every network's weights (not the optimiser state or step) from a snapshot.
    pub fn load_snapshot(&mut self, snapshot: &ParamSnapshot) -> Result<()> {
        self.layout.import(&Role::NETWORKS, |r| r.name().to_string(), &snapshot.tensors()?, &mut self.params)
    }

    /// An actor with this learner's configuration and current weights.
    pub fn actor(&self, seed: u64) -> Result<Actor> {
        let mut actor = Actor::new(self.cfg.clone(), seed)?;
        actor.load(&self.snapshot()?)?;
        Ok(actor)
    }

    /// The full training state, in the candle learner's checkpoint format.
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        let mut t = Vec::new();
        self.layout.export(&Role::ALL, |r| r.name().to_string(), &self.params, &mut t)?;
        let dev = &Device::Cpu;
        for (role, steps) in Role::TRAINED.iter().zip(&self.adam_steps).filter(|(r, _)| self.layout.has(**r))
        {
            self.layout.export(&[*role], |r| format!("adam.{}.m", r.name()), &self.adam_m, &mut t)?;
            self.layout.export(&[*role], |r| format!("adam.{}.v", r.name()), &self.adam_v, &mut t)?;
            t.push((format!("adam.{}.steps", role.name()), Tensor::from_slice(&[*steps as i64], 1, dev)?));
        }
        t.push(("learner.step".into(), Tensor::from_slice(&[self.step as i64], 1, dev)?));
        t.push(("learner.seed".into(), Tensor::from_slice(&[self.seed as i64], 1, dev)?));
        let safetensors = crate::resume::checkpoint_bytes(&t, &self.cfg, self.step)?;
        Ok(Checkpoint { step: self.step, safetensors })
    }
}
