//! A trained policy read from a checkpoint, as `sac-lsp eval` and `sac-lsp render` run it: the
//! options naming the file, the task, the run file, the latent mode and the seed, and the reading
//! and checking of the file.

use std::path::{Path, PathBuf};

use agent::{Actor, AgentConfig, ParamSnapshot, PolicyStack, Schema};
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use proto::EvalMode;
use run::{HerConfig, RunSpec, Task};

/// Which policy to run, on what, and how.
#[derive(Debug, Args)]
pub struct PolicyArgs {
    /// The weights: a learner checkpoint (the distributed learner's `learner-<step>.safetensors`,
    /// `sac-lsp train`'s `epoch-<n>.safetensors`) or a weights snapshot. The networks' sizes are
    /// read from its tensors. A hierarchy's checkpoint carries its frozen levels; for a file
    /// without them, the run file's `[hierarchy] levels` are used.
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Task to evaluate on: ant-v5, ant-rllab or inverted-pendulum (default: the run file's
    /// `[train] task`, else ant-v5).
    #[arg(long)]
    pub task: Option<Task>,
    /// Run file whose `[agent]` table gives what the tensors cannot (squashed actions, the
    /// embedding's output activation), and whose `[hierarchy]` names frozen levels the checkpoint
    /// does not carry; without it, the paper's for the level's position (a bottom level squashed
    /// with a ReLU embedding output, a level above neither).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// How the policy picks its latent: `fixed` is the paper's (one h ~ N(0, I) held for the
    /// whole evaluation), `zero` uses h = 0 (a Gaussian policy's mean action), `stochastic` draws a
    /// fresh z every step.
    #[arg(long, value_enum, default_value_t = Latent::Fixed)]
    pub latent: Latent,
    /// Seed of the resets and the latents.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `--latent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Latent {
    /// One h ~ N(0, I) for the whole evaluation (the paper's).
    Fixed,
    /// h = 0.
    Zero,
    /// A fresh z ~ N(0, I) every step.
    Stochastic,
}

impl Latent {
    /// The evaluation mode it names.
    pub fn mode(self) -> EvalMode {
        match self {
            Latent::Fixed => EvalMode::FixedLatent,
            Latent::Zero => EvalMode::ZeroLatent,
            Latent::Stochastic => EvalMode::Stochastic,
        }
    }
}

/// The policy to evaluate, as read from the checkpoint file.
pub struct Policy {
    /// The networks' shapes and settings.
    pub config: AgentConfig,
    /// The weights.
    pub snapshot: ParamSnapshot,
    /// The learner step the checkpoint was written at, if it says.
    pub learner_step: Option<u64>,
    /// The frozen levels below it, bottom first (none for a single level).
    pub frozen: Vec<Vec<u8>>,
}

impl Policy {
    /// An actor with these weights on top of the frozen levels.
    pub fn actor(&self, seed: u64) -> Result<Actor> {
        Ok(Actor::with_stack(self.config.clone(), PolicyStack::from_weights(&self.frozen)?, seed)?)
    }
}

/// A policy ready to run: its task (goal-conditioned with the run file's `[her]`) and weights.
pub struct Loaded {
    /// The task it acts on.
    pub task: Task,
    /// The run file's hindsight goals (none without one).
    pub her: HerConfig,
    /// The policy.
    pub policy: Policy,
}

impl PolicyArgs {
    /// Reads the run file and the checkpoint, and checks the networks fit the task.
    pub fn load(&self) -> Result<Loaded> {
        let run_file = self.config.as_deref().map(read_run_file).transpose()?;
        let task = match (self.task, &run_file) {
            (Some(task), _) => task,
            (None, Some(run)) => run.spec.task,
            (None, None) => Task::AntV5,
        };
        let policy = read_policy(&self.checkpoint, run_file.as_ref())?;
        // With HER the policy sees observation ++ goal: episodes step the run's goal-conditioned task.
        let her = run_file.as_ref().map(|r| r.spec.her.clone()).unwrap_or_default();
        // (Evaluation draws no n-step returns: 1 checks the goal against the task alone.)
        her.validate(task, 1).map_err(anyhow::Error::msg)?;
        let spec = her.dims(task);
        // Real NVP keeps the dimension: every level's action (and latent) is as wide as the env's.
        let (obs_dim, act_dim) = (policy.config.obs_dim, policy.config.act_dim);
        if (obs_dim, act_dim) != (spec.obs_dim, spec.act_dim) {
            bail!(
                "{}: the networks take {obs_dim} observation and {act_dim} action values, but {task} has {} and {}",
                self.checkpoint.display(),
                spec.obs_dim,
                spec.act_dim
            );
        }
        Ok(Loaded { task, her, policy })
    }
}

/// What a run file says about the policy.
pub struct RunFile {
    /// The run's shared tables (`[train] task`, `[hierarchy]`, `[her]`).
    pub spec: RunSpec,
    /// `[agent]`, over the defaults of the run's trained level.
    pub agent: AgentConfig,
}

/// The shared tables and `[agent]` of a run file.
pub fn read_run_file(path: &Path) -> Result<RunFile> {
    let spec = RunSpec::load(Some(path))?;
    let agent = AgentConfig::from_run(&spec).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(RunFile { spec, agent })
}

/// Reads the weights, the networks they fit, and the frozen levels below them.
pub fn read_policy(path: &Path, run_file: Option<&RunFile>) -> Result<Policy> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let snapshot = ParamSnapshot { version: 0, safetensors: bytes };
    let tensors = snapshot
        .tensors()
        .map_err(|e| anyhow::anyhow!("{} is not a safetensors file: {e}", path.display()))?;
    let in_file = |e: agent::Error| anyhow::anyhow!("{}: {e}", path.display());
    let embedded = PolicyStack::from_embedded(&tensors).map_err(in_file)?;
    let frozen: Vec<Vec<u8>> = match run_file {
        _ if !embedded.is_empty() => embedded.weights().into_iter().map(<[u8]>::to_vec).collect(),
        Some(run) => run.spec.hierarchy.read().map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    let base = match run_file {
        Some(run) if run.spec.hierarchy.depth() == frozen.len() => run.agent.clone(),
        _ => AgentConfig::default_at_level(frozen.len()),
    };
    let schema: Schema = tensors.iter().map(|(name, t)| (name.clone(), t.dims().to_vec())).collect();
    let config = agent::networks_from_schema(&schema, &base)
        .map_err(|e| anyhow::anyhow!("{} holds no SAC-LSP policy: {e}", path.display()))?;
    let learner_step = agent::saved_learner_step(&tensors);
    let policy = Policy { config, snapshot, learner_step, frozen };
    // Fails here, with the file named, if the levels do not chain.
    policy.actor(0).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(policy)
}

#[cfg(test)]
pub mod tests {
    use agent::Learner;

    use super::*;

    /// A tiny inverted-pendulum learner's checkpoint, written to a fresh folder.
    pub fn checkpoint(name: &str, twin_q: bool) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sac-lsp-eval-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cfg = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            coupling_hidden: vec![4],
            twin_q,
            ..AgentConfig::for_task(4, 1)
        };
        let learner = Learner::new(cfg, 7).unwrap();
        let path = dir.join("learner-000000000000.safetensors");
        std::fs::write(&path, learner.checkpoint().unwrap().safetensors).unwrap();
        path
    }

    /// Options for `checkpoint` on the pendulum, seed 11.
    pub fn policy_args(checkpoint: &Path, latent: Latent) -> PolicyArgs {
        PolicyArgs {
            checkpoint: checkpoint.to_path_buf(),
            task: Some(Task::InvertedPendulum),
            config: None,
            latent,
            seed: 11,
        }
    }
}
