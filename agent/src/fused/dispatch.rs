//! [`AnyLearner`]: one type over the candle [`Learner`] and the [`FusedLearner`], chosen by a
//! [`Backend`]. Both run the same update and share the snapshot and checkpoint formats, so callers
//! can switch (or resume a run) across backends.

use serde::{Deserialize, Serialize};

use crate::acting::Actor;
use crate::batch::Batch;
use crate::config::AgentConfig;
use crate::error::Result;
use crate::learning::{Learner, UpdateOutput};
use crate::params::{Checkpoint, ParamSnapshot};

use super::FusedLearner;

/// Which implementation trains a level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    /// The fused learner when [`FusedLearner::supports`] the configuration, else candle.
    #[default]
    Auto,
    /// Always the candle [`Learner`] (every option).
    Candle,
    /// Always the [`FusedLearner`]; an unsupported configuration is an error.
    Fused,
}

impl Backend {
    /// The concrete backend for `cfg`: `Candle` or `Fused`.
    pub fn resolve(self, cfg: &AgentConfig) -> Result<Self> {
        match self {
            Self::Auto if FusedLearner::supports(cfg) => Ok(Self::Fused),
            Self::Auto | Self::Candle => Ok(Self::Candle),
            Self::Fused => FusedLearner::check_support(cfg).map(|()| Self::Fused),
        }
    }
}

/// A learner of either backend.
///
/// ```
/// use agent::{AgentConfig, AnyLearner, Backend, Batch};
///
/// let cfg = AgentConfig { critic_hidden: vec![16], embedding_layers: vec![16, 4], ..AgentConfig::for_task(3, 2) };
/// // Every scalar-critic configuration is fused (twin Q and the learned temperature too); a
/// // categorical critic would fall back to candle.
/// let mut learner = AnyLearner::new(cfg, 7, Backend::Auto)?;
/// assert_eq!(learner.backend(), Backend::Fused);
/// let batch = Batch {
///     size: 1,
///     observations: vec![0.1; 3],
///     actions: vec![0.5, -0.5],
///     rewards: vec![1.0],
///     next_observations: vec![0.2; 3],
///     terminated: vec![0.0],
///     is_weights: None,
/// };
/// assert_eq!(learner.update(&batch)?.td_errors.len(), 1);
/// # Ok::<(), agent::Error>(())
/// ```
#[derive(Debug)]
pub enum AnyLearner {
    /// The candle reference implementation.
    Candle(Box<Learner>),
    /// The fused implementation.
    Fused(Box<FusedLearner>),
}

impl AnyLearner {
    /// A new learner; both backends start from the same seeded initial state.
    pub fn new(cfg: AgentConfig, seed: u64, backend: Backend) -> Result<Self> {
        Ok(match backend.resolve(&cfg)? {
            Backend::Fused => Self::Fused(Box::new(FusedLearner::new(cfg, seed)?)),
            _ => Self::Candle(Box::new(Learner::new(cfg, seed)?)),
        })
    }

    /// Restores a checkpoint written by either backend.
    pub fn from_checkpoint(cfg: AgentConfig, checkpoint: &Checkpoint, backend: Backend) -> Result<Self> {
        Ok(match backend.resolve(&cfg)? {
            Backend::Fused => Self::Fused(Box::new(FusedLearner::from_checkpoint(cfg, checkpoint)?)),
            _ => Self::Candle(Box::new(Learner::from_checkpoint(cfg, checkpoint)?)),
        })
    }

    /// `Candle` or `Fused`.
    pub fn backend(&self) -> Backend {
        match self {
            Self::Candle(_) => Backend::Candle,
            Self::Fused(_) => Backend::Fused,
        }
    }

    /// See [`Learner::update`].
    pub fn update(&mut self, batch: &Batch) -> Result<UpdateOutput> {
        match self {
            Self::Candle(l) => l.update(batch),
            Self::Fused(l) => l.update(batch),
        }
    }

    /// See [`Learner::snapshot`].
    pub fn snapshot(&self) -> Result<ParamSnapshot> {
        match self {
            Self::Candle(l) => l.snapshot(),
            Self::Fused(l) => l.snapshot(),
        }
    }

    /// See [`Learner::load_snapshot`].
    pub fn load_snapshot(&mut self, snapshot: &ParamSnapshot) -> Result<()> {
        match self {
            Self::Candle(l) => l.load_snapshot(snapshot),
            Self::Fused(l) => l.load_snapshot(snapshot),
        }
    }

    /// See [`Learner::checkpoint`].
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        match self {
            Self::Candle(l) => l.checkpoint(),
            Self::Fused(l) => l.checkpoint(),
        }
    }

    /// See [`Learner::actor`].
    pub fn actor(&self, seed: u64) -> Result<Actor> {
        match self {
            Self::Candle(l) => l.actor(seed),
            Self::Fused(l) => l.actor(seed),
        }
    }

    /// See [`Learner::step`].
    pub fn step(&self) -> u64 {
        match self {
            Self::Candle(l) => l.step(),
            Self::Fused(l) => l.step(),
        }
    }

    /// See [`Learner::config`].
    pub fn config(&self) -> &AgentConfig {
        match self {
            Self::Candle(l) => l.config(),
            Self::Fused(l) => l.config(),
        }
    }

    /// See [`Learner::temperature`].
    pub fn temperature(&self) -> Result<f32> {
        match self {
            Self::Candle(l) => l.temperature(),
            Self::Fused(l) => Ok(l.temperature()),
        }
    }
}
