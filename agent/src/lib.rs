//! SAC-LSP (Soft Actor-Critic with Latent Space Policies; Haarnoja et al. 2018, arXiv 1804.02808)
//! in candle, sans-IO: no transport, no simulator. `docs/sac-lsp.md` states the maths and
//! where each equation is computed (`haarnoja/sac` at ca39be1 is the code behind the dissertation).
//!
//! # Layout
//!
//! | file | what |
//! | --- | --- |
//! | `config.rs` | [`AgentConfig`]: paper defaults, `validate()`, [`AgentConfig::level_above`] |
//! | `mlp.rs` | Xavier-initialised dense layers and MLPs (per-input first-layer matrices) |
//! | `coupling.rs` | one conditional affine coupling layer (real NVP) |
//! | `policy.rs` | [`LatentPolicy`]: embedding, N(0, I) latent, couplings, tanh; sample, log pi, deterministic |
//! | `density.rs` | log-densities: latent prior, squash correction, action prior |
//! | `critic.rs` | [`QNet`], [`ValueNet`]: a scalar or a categorical output |
//! | `categorical.rs` | [`Support`]: the atoms, C51's projection, the dissertation code's brackets |
//! | `distributional.rs` | the losses of a categorical critic (soft C51, the dissertation's) |
//! | `losses.rs` | the losses, one function per equation |
//! | `optim.rs` | [`Adam`] with TensorFlow's epsilon placement and named moments |
//! | `target.rs` | [`polyak_update`] between two `VarMap`s |
//! | `batch.rs` | [`Batch`] of transitions (with optional IS weights) |
//! | `nstep.rs` | [`NStepReturns`]: n-step transitions from a stream of env steps |
//! | `learning.rs` | [`Learner`]: `update(&Batch) -> UpdateOutput { metrics, td_errors }`, snapshots, checkpoints |
//! | `acting.rs` | [`Actor`]: `act(obs, Mode)`, `load(&ParamSnapshot)`, `td_errors(&Batch)` |
//! | `stack.rs` | [`PolicyStack`]: frozen lower levels of a hierarchy, shipped as weights, content-hashed, embedded in checkpoints |
//! | `params.rs` | [`ParamSnapshot`], [`Checkpoint`]: safetensors bytes with stable names |
//! | `resume.rs` | what a checkpoint holds and the settings it refuses to resume across |
//! | `networks.rs`, `vars.rs` | the networks of one level, each in its own `VarMap`, seeded init |
//! | `fused/` | [`FusedLearner`]: the same update hand-fused on `gemm`; [`AnyLearner`] picks a [`Backend`] |
//!
//! # Use
//!
//! ```
//! use agent::{Actor, AgentConfig, Batch, Learner, Mode};
//!
//! let cfg = AgentConfig { critic_hidden: vec![16], embedding_layers: vec![16, 4], ..AgentConfig::for_task(3, 2) };
//! let mut learner = Learner::new(cfg.clone(), 7)?;
//! let batch = Batch {
//!     size: 2,
//!     observations: vec![0.1; 6],
//!     actions: vec![0.5, -0.5, 0.0, 0.2],
//!     rewards: vec![1.0, 0.0],
//!     next_observations: vec![0.2; 6],
//!     terminated: vec![0.0, 1.0],
//!     is_weights: None,
//! };
//! let out = learner.update(&batch)?;
//! assert_eq!(out.td_errors.len(), 2);
//!
//! let mut actor = Actor::new(cfg, 1)?;
//! actor.load(&learner.snapshot()?)?;
//! let act = actor.act(&[0.0, 0.1, 0.2], Mode::Explore)?;
//! assert!(act.env_action.iter().all(|a| a.abs() <= 1.0));
//! # Ok::<(), agent::Error>(())
//! ```
//!
//! All tensors are `f32` on candle's CPU device.

#![deny(missing_docs)]

mod acting;
mod batch;
mod categorical;
mod config;
mod coupling;
mod critic;
mod density;
mod distributional;
mod error;
mod fused;
mod learning;
mod losses;
mod mlp;
mod networks;
mod nstep;
mod optim;
mod params;
mod policy;
mod resume;
mod schema;
mod stack;
mod target;
mod vars;

pub use acting::{Act, Actor, Mode};
pub use batch::Batch;
pub use categorical::{Brackets, Support};
pub use config::{ActionPrior, AgentConfig, CategoricalConfig, CategoricalVariant, Critic};
pub use coupling::{Coupling, CouplingOutput, CouplingSpec, Parity};
pub use critic::{QNet, ValueNet};
pub use density::{
    SQUASH_EPSILON, action_prior_log_density, policy_log_density, standard_normal_log_density,
    tanh_log_det_jacobian,
};
pub use error::{Error, Result};
pub use fused::{AnyLearner, Backend, FusedLearner};
pub use learning::{Learner, Metrics, UpdateOutput};
pub use losses::{
    likelihood_ratio_policy_loss, q_loss, q_target, reparameterized_policy_loss, td_error, temperature_loss,
    v_loss, v_target,
};
pub use mlp::{Activation, BiasInit, Dense, Grad, Mlp, MlpSpec, xavier_limit};
pub use nstep::{NStepReturns, NStepTransition, StepEnd};
pub use optim::{Adam, AdamConfig};
pub use params::{Checkpoint, ParamSnapshot, saved_learner_step};
pub use policy::{BijectorOutput, LatentPolicy, PolicySample};
pub use resume::{CONTAINS, CONTAINS_KEY, check_resume, checkpoint_metadata, resume_settings};
pub use schema::{Schema, networks_from_schema, snapshot_schema};
pub use stack::{FROZEN_PREFIX, Level, MAX_FROZEN_LEVELS, PolicyStack};
pub use target::polyak_update;

#[cfg(test)]
mod tests;
