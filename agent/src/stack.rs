//! [`PolicyStack`]: frozen lower levels of a hierarchy (§1.5).
//!
//! Level k + 1 is an ordinary SAC-LSP level ([`AgentConfig::level_above`]) whose action is level k's
//! latent h. Acting maps an observation through the top (trained) level to h, then through each
//! frozen level in deterministic mode, a = f_k(h; E_k(s)) (squashed at level 0), down to the env
//! action. Frozen levels are loaded from their own learners' snapshots and are never trained; the
//! level being trained stores its own action (h) in replay and never sees the levels below.

use candle_core::{DType, Tensor};

use crate::config::AgentConfig;
use crate::error::{Error, Result};
use crate::networks::{Net, policy_net};
use crate::params::{ParamSnapshot, encode};
use crate::policy::LatentPolicy;
use crate::vars::SeededInit;

/// A trained level to freeze: its configuration and a snapshot holding its `policy.*` weights (other
/// networks in the snapshot are ignored).
#[derive(Clone, Debug)]
pub struct Level {
    /// The level's configuration.
    pub config: AgentConfig,
    /// Its weights, e.g. [`Learner::snapshot`](crate::Learner::snapshot).
    pub snapshot: ParamSnapshot,
}

#[derive(Debug)]
struct FrozenLevel {
    config: AgentConfig,
    version: u64,
    policy: Net<LatentPolicy>,
}

/// Frozen levels, bottom (env-facing) first; empty for a single-level agent.
#[derive(Debug, Default)]
pub struct PolicyStack {
    levels: Vec<FrozenLevel>,
}

impl PolicyStack {
    /// No frozen levels: the trained level acts on the environment directly.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Freezes `levels`, bottom first. Every level must see the same observations, and level k + 1's
    /// action dimension must equal level k's (its latent).
    pub fn new(levels: Vec<Level>) -> Result<Self> {
        let mut frozen: Vec<FrozenLevel> = Vec::with_capacity(levels.len());
        for (k, level) in levels.into_iter().enumerate() {
            level.config.validate()?;
            if let Some(below) = frozen.last() {
                let (c, b) = (&level.config, &below.config);
                if c.obs_dim != b.obs_dim || c.act_dim != b.act_dim {
                    return Err(Error::BadStack(format!(
                        "level {k} has (obs {}, act {}), level {} below it (obs {}, act {})",
                        c.obs_dim,
                        c.act_dim,
                        k - 1,
                        b.obs_dim,
                        b.act_dim
                    )));
                }
            }
            // Initial values are irrelevant: every variable is overwritten from the snapshot.
            let policy = policy_net(&level.config, &SeededInit::new(0), DType::F32)?;
            policy.import(&level.snapshot.tensors()?)?;
            frozen.push(FrozenLevel { config: level.config, version: level.snapshot.version, policy });
        }
        Ok(Self { levels: frozen })
    }

    /// Number of frozen levels.
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// Whether there are no frozen levels.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// (obs_dim, action dimension expected from the level above), if the stack is not empty.
    pub fn top_dims(&self) -> Option<(usize, usize)> {
        self.levels.last().map(|l| (l.config.obs_dim, l.config.act_dim))
    }

    /// Maps the trained level's actions `[batch, act]` down to env actions `[batch, env act]`,
    /// each frozen level in deterministic mode with the latent given by the level above. An empty
    /// stack returns `action` unchanged.
    pub fn env_action(&self, obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        let mut h = action.clone();
        for level in self.levels.iter().rev() {
            h = level.policy.model.deterministic(obs, &h)?;
        }
        Ok(h)
    }

    /// Each frozen level's policy weights as a snapshot (names `policy.*`, the version it was
    /// frozen at), bottom first: what executors need to rebuild the stack.
    pub fn snapshots(&self) -> Result<Vec<ParamSnapshot>> {
        self.levels
            .iter()
            .map(|l| {
                let mut tensors = Vec::new();
                l.policy.export(&mut tensors)?;
                let safetensors = encode(&tensors, &[("version", l.version.to_string())])?;
                Ok(ParamSnapshot { version: l.version, safetensors })
            })
            .collect()
    }
}
