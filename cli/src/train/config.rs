//! The `[train]` table: the single-machine loop of the dissertation's "SAC-LSP" and "Prioritized
//! SAC-LSP" runs (`docs/sac-lsp.md` §12, §8). The same run file carries `[agent]` and `[replay]`.

use agent::Backend;
use serde::Deserialize;
use sim::Task;

/// How one single-machine run is driven.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Task name (`ant-v5`, `ant-rllab`, `inverted-pendulum`). Default `ant-v5`.
    pub task: String,
    /// Seed of everything random in the run (networks, latent noise, resets, replay sampling).
    pub seed: u64,
    /// Epochs to run. Default 10_002, the paper's `int(1e4 + 1)` + 1 (10.0M env steps).
    pub epochs: u64,
    /// Env steps (and updates) per epoch. Default 1000.
    pub epoch_length: u64,
    /// Updates start once the replay holds this many transitions. Default 1000 (`min_pool`).
    pub min_replay_size: u64,
    /// Updates per env step once training has started. Default 1 (`n_train_repeat`).
    pub updates_per_step: u32,
    /// Evaluation episodes after each epoch. Default 1, as in the paper.
    pub eval_episodes: u32,
    /// How the evaluation picks the latent (`fixed_latent`, the paper's and the default;
    /// `zero_latent`; `stochastic`).
    pub eval_mode: proto::EvalMode,
    /// Write a learner checkpoint every this many epochs (0: only at the end). Default 100.
    pub checkpoint_every_epochs: u64,
    /// Copy the learner's weights to the acting policy every this many env steps. Default 1 (the
    /// paper acts with the current parameters).
    pub sync_actor_every_steps: u64,
    /// Which learner runs the updates: `auto` (default: the fused learner where it implements the
    /// configuration, else candle), `candle` or `fused`. Both compute the same update.
    pub backend: Backend,
    /// The distributed roles' deterministic mode (`[lockstep]`, README "Deterministic mode"); the
    /// single-machine loop is deterministic anyway, so here it only has to be accepted.
    pub deterministic: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            task: "ant-v5".into(),
            seed: 1,
            epochs: 10_002,
            epoch_length: 1000,
            min_replay_size: 1000,
            updates_per_step: 1,
            eval_episodes: 1,
            eval_mode: proto::EvalMode::FixedLatent,
            checkpoint_every_epochs: 100,
            sync_actor_every_steps: 1,
            backend: Backend::Auto,
            deterministic: false,
        }
    }
}

impl TrainConfig {
    /// The task, checked.
    pub fn task(&self) -> Result<Task, String> {
        self.task.parse::<Task>().map_err(|e| e.to_string())
    }

    /// Checks every value; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        self.task()?;
        let positive = [
            ("epochs", self.epochs),
            ("epoch_length", self.epoch_length),
            ("updates_per_step", u64::from(self.updates_per_step)),
            ("sync_actor_every_steps", self.sync_actor_every_steps),
        ];
        if let Some((key, _)) = positive.iter().find(|(_, v)| *v == 0) {
            return Err(format!("[train] {key} must be > 0"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        assert_eq!(TrainConfig::default().validate(), Ok(()));
        let bad = TrainConfig { epoch_length: 0, ..TrainConfig::default() };
        assert!(bad.validate().unwrap_err().contains("epoch_length"));
        let bad = TrainConfig { task: "ant-v9".into(), ..TrainConfig::default() };
        assert!(bad.validate().unwrap_err().contains("ant-v9"));
    }
}
