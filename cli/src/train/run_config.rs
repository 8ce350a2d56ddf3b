//! One run file, its tables: `[train]` (the loop), `[agent]` (SAC-LSP), `[replay]` (the buffer),
//! `[hierarchy]` (frozen levels below), `[her]` (goals).
//! The distributed roles read the same file, so network shapes cannot drift between processes.

use std::path::Path;

use agent::AgentConfig;
use anyhow::{Context, Result, bail};
use replay::{Dims, ReplayConfig};

use super::TrainConfig;

/// Everything a single-machine run needs.
#[derive(Debug, Clone, PartialEq)]
pub struct RunConfig {
    /// The loop.
    pub train: TrainConfig,
    /// The agent; `obs_dim` and `act_dim` are taken from the task.
    pub agent: AgentConfig,
    /// The replay buffer.
    pub replay: ReplayConfig,
    /// Frozen levels below the trained one (`[hierarchy]`); none by default.
    pub hierarchy: run::HierarchyKeys,
    /// Hindsight experience replay (`[her]`); off by default.
    pub her: run::HerConfig,
}

impl RunConfig {
    /// Reads the tables of `path` (defaults for missing tables; unknown keys are errors) and fits the
    /// agent's dimensions to the task.
    pub fn load(path: Option<&Path>) -> Result<Self> {
        let spec = run::RunSpec::load(path)?;
        let in_file = |e: String| {
            let file = path.map(|p| format!("{}: ", p.display())).unwrap_or_default();
            anyhow::anyhow!("{file}{e}")
        };
        let config = RunConfig {
            train: spec.table("train").map_err(in_file)?,
            agent: AgentConfig::from_run(&spec).map_err(in_file)?,
            replay: spec.table("replay").map_err(in_file)?,
            hierarchy: spec.hierarchy.clone(),
            her: spec.her.clone(),
        };
        config.fitted()
    }

    /// Sets the agent's dimensions from the task and validates every table.
    pub fn fitted(mut self) -> Result<Self> {
        self.train.validate().map_err(anyhow::Error::msg)?;
        let task = self.train.task().map_err(anyhow::Error::msg)?;
        self.her.validate(task, self.agent.n_step).map_err(anyhow::Error::msg)?;
        // With HER the networks' input is observation ++ goal.
        let dims = self.her.dims(task);
        (self.agent.obs_dim, self.agent.act_dim) = (dims.obs_dim, dims.act_dim);
        self.agent.validate().context("[agent]")?;
        self.replay.validate(self.dims()).context("[replay]")?;
        if self.train.min_replay_size > self.replay.capacity_transitions as u64 {
            bail!(
                "[train] min_replay_size {} exceeds [replay] capacity_transitions {}: training would never start",
                self.train.min_replay_size,
                self.replay.capacity_transitions
            );
        }
        if (self.agent.batch_size as u64) > self.train.min_replay_size.max(1) * 1000 {
            bail!("[agent] batch_size {} is implausibly large", self.agent.batch_size);
        }
        Ok(self)
    }

    /// The replay's transition dimensions.
    pub fn dims(&self) -> Dims {
        Dims { obs_dim: self.agent.obs_dim, act_dim: self.agent.act_dim }
    }
}
