//! [`PolicyStack`]: frozen lower levels of a hierarchy (`docs/sac-lsp.md` §9).
//!
//! Level k + 1 is an ordinary SAC-LSP level ([`AgentConfig::level_above`]) whose action is level k's
//! latent h. Acting maps an observation through the top (trained) level to h, then through each
//! frozen level in deterministic mode, a = f_k(h; E_k(s)) (squashed at level 0), down to the env
//! action. Frozen levels are loaded from their own learners' snapshots and are never trained; the
//! level being trained stores its own action (h) in replay and never sees the levels below.
//!
//! A stack travels as each level's network weights (what a learner snapshot holds, without Adam
//! moments): the shapes give each level's networks ([`networks_from_schema`]), so a process that
//! receives them (an executor on another host, `eval` reading a checkpoint) needs nothing else.
//! [`PolicyStack::content_hash`] names the acting weights, so processes can check they agree.

use std::collections::HashMap;

use candle_core::{DType, Tensor};
use sha3::{Digest, Sha3_256};

use crate::config::AgentConfig;
use crate::error::{Error, Result};
use crate::networks::{Net, policy_net};
use crate::params::{Checkpoint, ParamSnapshot, decode, encode, saved_learner_step};
use crate::policy::LatentPolicy;
use crate::schema::{Schema, networks_from_schema, snapshot_schema};
use crate::vars::SeededInit;

/// Prefix of the frozen levels' tensors inside a checkpoint of the level above them
/// (`frozen.<k>.<name>`, k = 0 at the bottom).
pub const FROZEN_PREFIX: &str = "frozen";

/// The most frozen levels a checkpoint may embed: the wire's limit (`proto::MAX_FROZEN_LEVELS`;
/// this crate stays off the wire, so the executor's tests check that the two agree).
pub const MAX_FROZEN_LEVELS: usize = 16;

/// A trained level to freeze: its configuration and a snapshot holding its networks (a learner's
/// snapshot or checkpoint; Adam moments and counters in it are ignored).
#[derive(Clone, Debug)]
pub struct Level {
    /// The level's configuration.
    pub config: AgentConfig,
    /// Its weights, e.g. [`Learner::snapshot`](crate::Learner::snapshot).
    pub snapshot: ParamSnapshot,
}

impl Level {
    /// Level `index` of a stack (0 = env-facing) read from safetensors bytes holding its networks:
    /// a learner checkpoint or weights snapshot. The shapes give the networks; what they cannot
    /// tell (a squashed action, the embedding's output activation) is the paper's for that position
    /// ([`AgentConfig::default_at_level`]). The version is the file's `learner.step`, else 0.
    pub fn from_weights(bytes: &[u8], index: usize) -> Result<Level> {
        let tensors = decode(bytes)?;
        let schema: Schema = tensors.iter().map(|(name, t)| (name.clone(), t.dims().to_vec())).collect();
        let config = networks_from_schema(&schema, &AgentConfig::default_at_level(index))?;
        let version = saved_learner_step(&tensors).unwrap_or(0);
        Ok(Level { config, snapshot: ParamSnapshot { version, safetensors: bytes.to_vec() } })
    }
}

#[derive(Debug)]
struct FrozenLevel {
    config: AgentConfig,
    version: u64,
    policy: Net<LatentPolicy>,
    /// The level's networks only, as shipped to other processes and embedded in checkpoints.
    weights: Vec<u8>,
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
            let tensors = level.snapshot.tensors()?;
            // Initial values are irrelevant: every variable is overwritten from the snapshot.
            let policy = policy_net(&level.config, &SeededInit::new(0), DType::F32)?;
            policy.import(&tensors)?;
            let weights = networks_only(&level.config, &tensors, level.snapshot.version)
                .map_err(|e| Error::BadStack(format!("level {k}: {e}")))?;
            frozen.push(FrozenLevel {
                config: level.config,
                version: level.snapshot.version,
                policy,
                weights,
            });
        }
        Ok(Self { levels: frozen })
    }

    /// The stack whose levels' weights are `levels` (bottom first), each as [`Level::from_weights`]
    /// reads it.
    pub fn from_weights<B: AsRef<[u8]>>(levels: &[B]) -> Result<Self> {
        let levels = levels
            .iter()
            .enumerate()
            .map(|(k, bytes)| {
                Level::from_weights(bytes.as_ref(), k).map_err(|e| Error::BadStack(format!("level {k}: {e}")))
            })
            .collect::<Result<Vec<_>>>()?;
        Self::new(levels)
    }

    /// The frozen levels a checkpoint carries ([`embed`](Self::embed)); empty when it has none.
    pub fn from_embedded(tensors: &HashMap<String, Tensor>) -> Result<Self> {
        let mut levels: Vec<Vec<(String, Tensor)>> = Vec::new();
        for (name, t) in tensors {
            let Some(rest) = name.strip_prefix(FROZEN_PREFIX).and_then(|r| r.strip_prefix('.')) else {
                continue;
            };
            let (k, inner) = rest
                .split_once('.')
                .and_then(|(k, inner)| Some((k.parse::<usize>().ok()?, inner)))
                .ok_or_else(|| Error::BadStack(format!("tensor {name} is not frozen.<level>.<name>")))?;
            if k >= MAX_FROZEN_LEVELS {
                return Err(Error::BadStack(format!(
                    "tensor {name}: at most {MAX_FROZEN_LEVELS} frozen levels"
                )));
            }
            if levels.len() <= k {
                levels.resize_with(k + 1, Vec::new);
            }
            levels[k].push((inner.to_string(), t.clone()));
        }
        if let Some(k) = levels.iter().position(Vec::is_empty) {
            return Err(Error::BadStack(format!("frozen level {k} is missing")));
        }
        let bytes = levels.iter().map(|t| encode(t, &[])).collect::<Result<Vec<_>>>()?;
        Self::from_weights(&bytes)
    }

    /// `checkpoint` with this stack's levels added as `frozen.<k>.<name>`, so evaluating or resuming
    /// it needs no other file. An empty stack returns it unchanged.
    pub fn embed(&self, checkpoint: &Checkpoint) -> Result<Checkpoint> {
        if self.is_empty() {
            return Ok(checkpoint.clone());
        }
        let mut tensors: Vec<(String, Tensor)> = decode(&checkpoint.safetensors)?.into_iter().collect();
        for (k, level) in self.levels.iter().enumerate() {
            for (name, t) in decode(&level.weights)? {
                tensors.push((format!("{FROZEN_PREFIX}.{k}.{name}"), t));
            }
        }
        let safetensors = encode(&tensors, &[("step", checkpoint.step.to_string())])?;
        Ok(Checkpoint { step: checkpoint.step, safetensors })
    }

    /// Each level's networks (safetensors bytes), bottom first: what [`from_weights`](Self::from_weights)
    /// rebuilds this stack from.
    pub fn weights(&self) -> Vec<&[u8]> {
        self.levels.iter().map(|l| l.weights.as_slice()).collect()
    }

    /// SHA3-256 of the acting weights (each level's `policy.*` tensors, names, shapes and values,
    /// bottom first): equal hashes mean the same env actions for the same latents. Versions and the
    /// critics do not count.
    pub fn content_hash(&self) -> Result<[u8; 32]> {
        let mut hasher = Sha3_256::new();
        hasher.update((self.levels.len() as u64).to_le_bytes());
        for level in &self.levels {
            let mut tensors = Vec::new();
            level.policy.export(&mut tensors)?;
            let bytes = encode(&tensors, &[])?;
            hasher.update((bytes.len() as u64).to_le_bytes());
            hasher.update(&bytes);
        }
        Ok(hasher.finalize().into())
    }

    /// Checks that a level of `cfg` can sit on top: it sees the same observations and its action is
    /// as wide as the top frozen level's latent. An empty stack fits anything.
    pub fn check_fits(&self, cfg: &AgentConfig) -> Result<()> {
        if let Some((obs_dim, latent_dim)) = self.top_dims()
            && (obs_dim, latent_dim) != (cfg.obs_dim, cfg.act_dim)
        {
            return Err(Error::BadStack(format!(
                "trained level has (obs {}, act {}), the top frozen level expects (obs {obs_dim}, act {latent_dim})",
                cfg.obs_dim, cfg.act_dim
            )));
        }
        Ok(())
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

    /// The configuration of each frozen level, bottom first.
    pub fn configs(&self) -> impl Iterator<Item = &AgentConfig> {
        self.levels.iter().map(|l| &l.config)
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

/// The tensors of `cfg`'s networks from `tensors` (each present with its shape), as safetensors.
fn networks_only(cfg: &AgentConfig, tensors: &HashMap<String, Tensor>, version: u64) -> Result<Vec<u8>> {
    let mut kept = Vec::new();
    for (name, shape) in snapshot_schema(cfg) {
        let t = tensors.get(&name).ok_or_else(|| Error::BadSnapshot(format!("no tensor {name}")))?;
        if t.dims() != shape.as_slice() {
            return Err(Error::BadSnapshot(format!("{name}: {:?}, expected {shape:?}", t.dims())));
        }
        kept.push((name, t.clone()));
    }
    encode(&kept, &[("version", version.to_string())])
}
