//! Replay configuration: documented defaults (the paper's values) and `validate()`.

use serde::{Deserialize, Serialize};

use crate::buffer::ReplayBuffer;
use crate::error::ConfigError;

/// How a batch is drawn.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplingMode {
    /// Proportional prioritized replay (Schaul et al. 2016): P(i) = p_i / Σ_k p_k, stratified over
    /// the batch, with importance-sampling weights.
    #[default]
    Prioritized,
    /// Uniform with replacement and IS weights 1: the non-prioritized baseline. Priorities are still
    /// kept (inserts and updates behave the same), so the learner code does not change with the mode
    /// and the priority diagnostics stay meaningful.
    Uniform,
}

/// Sizes of one transition, from the task's spec (Ant-v5: obs 105, action 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Dims {
    /// Length of one observation vector.
    pub obs_dim: usize,
    /// Length of one action vector.
    pub act_dim: usize,
}

impl std::fmt::Display for Dims {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "obs_dim {}, act_dim {}", self.obs_dim, self.act_dim)
    }
}

/// Configuration of a [`ReplayBuffer`]. `Default` gives the values of the prioritized SAC-LSP runs
/// (`sac-prior`, `docs/sac-lsp.md` §8), with the β precedence bug fixed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayConfig {
    /// Transitions held, N. Default 1_000_000 (the paper's pool size).
    pub capacity_transitions: usize,
    /// Observation rows, M (observations are stored once and shared by consecutive transitions; see
    /// `storage`). A run of k consecutive steps inserted in order uses k + 1 rows. `None` (default)
    /// means `capacity_transitions + capacity_transitions / 32 + 1`: a full ring of N transitions
    /// when they arrive in runs of at least 32 steps. Shorter runs make the buffer hold fewer than N
    /// transitions (counted in `Counters::evicted_early`), never wrong ones; `2 * N` stores every
    /// observation twice, like a plain buffer.
    pub observation_rows: Option<usize>,
    /// Priority exponent α in p = (|δ| + ε)^α. Default 0.5.
    pub alpha: f64,
    /// Priority offset ε, so that a zero TD error keeps a non-zero chance of replay. Default 1e-6.
    pub epsilon: f64,
    /// Importance-sampling exponent β at learner step 0. Default 0.4.
    pub beta_start: f64,
    /// β reached at `beta_anneal_steps` and kept afterwards. Default 1.0.
    pub beta_end: f64,
    /// Learner steps over which β goes linearly from `beta_start` to `beta_end`. Default 10_000_000,
    /// the paper's run length (10,002 epochs × 1,000 updates); 0 means `beta_end` from the start.
    pub beta_anneal_steps: u64,
    /// Prioritized (default) or uniform sampling.
    pub mode: SamplingMode,
    /// Upper bound on the bytes the buffer allocates ([`ReplayBuffer::bytes_for`]); `validate`
    /// refuses a larger configuration. Default 1 GiB (1M Ant-v5 transitions need about 499 MB).
    pub memory_budget_bytes: u64,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self {
            capacity_transitions: 1_000_000,
            observation_rows: None,
            alpha: 0.5,
            epsilon: 1e-6,
            beta_start: 0.4,
            beta_end: 1.0,
            beta_anneal_steps: 10_000_000,
            mode: SamplingMode::Prioritized,
            memory_budget_bytes: 1 << 30,
        }
    }
}

/// Largest ring or row count: row positions are stored as `u32` (4 bytes per transition, not 8).
pub const MAX_CAPACITY: usize = u32::MAX as usize;

impl ReplayConfig {
    /// The number of observation rows M this configuration allocates (`observation_rows` or its
    /// default).
    pub fn observation_rows_resolved(&self) -> usize {
        self.observation_rows.unwrap_or_else(|| {
            let n = self.capacity_transitions;
            n.saturating_add(n / 32).saturating_add(1)
        })
    }

    /// Checks every field and that the storage for `dims` fits in `memory_budget_bytes`.
    pub fn validate(&self, dims: Dims) -> Result<(), ConfigError> {
        if dims.obs_dim == 0 {
            return Err(ConfigError::ObsDim);
        }
        if dims.act_dim == 0 {
            return Err(ConfigError::ActDim);
        }
        let n = self.capacity_transitions;
        if n == 0 {
            return Err(ConfigError::CapacityZero);
        }
        if n > MAX_CAPACITY {
            return Err(ConfigError::CapacityTooLarge { got: n });
        }
        let rows = self.observation_rows_resolved();
        if !(2..=MAX_CAPACITY).contains(&rows) {
            return Err(ConfigError::ObservationRows { got: rows });
        }
        if !(0.0..=1.0).contains(&self.alpha) {
            return Err(ConfigError::Alpha { got: self.alpha });
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(ConfigError::Epsilon { got: self.epsilon });
        }
        if !(0.0..=1.0).contains(&self.beta_start) {
            return Err(ConfigError::BetaStart { got: self.beta_start });
        }
        if !(self.beta_start..=1.0).contains(&self.beta_end) {
            return Err(ConfigError::BetaEnd { got: self.beta_end, beta_start: self.beta_start });
        }
        let needed = ReplayBuffer::bytes_for(self, dims);
        if needed > self.memory_budget_bytes {
            return Err(ConfigError::OverBudget { needed, budget: self.memory_budget_bytes });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ANT: Dims = Dims { obs_dim: 105, act_dim: 8 };

    #[test]
    fn defaults_are_the_paper_values_and_valid_for_ant() {
        let cfg = ReplayConfig::default();
        assert_eq!(cfg.capacity_transitions, 1_000_000);
        assert_eq!((cfg.alpha, cfg.epsilon, cfg.beta_start, cfg.beta_end), (0.5, 1e-6, 0.4, 1.0));
        assert_eq!(cfg.observation_rows_resolved(), 1_031_251);
        assert_eq!(cfg.validate(ANT), Ok(()));
    }

    #[test]
    fn each_invalid_field_has_an_exact_message() {
        let base = ReplayConfig::default();
        let msg = |cfg: ReplayConfig, dims: Dims| cfg.validate(dims).unwrap_err().to_string();
        assert_eq!(msg(base.clone(), Dims { obs_dim: 0, act_dim: 8 }), "obs_dim must be at least 1");
        assert_eq!(msg(base.clone(), Dims { obs_dim: 3, act_dim: 0 }), "act_dim must be at least 1");
        let c = ReplayConfig { capacity_transitions: 0, ..base.clone() };
        assert_eq!(msg(c, ANT), "capacity_transitions must be at least 1");
        let c = ReplayConfig { capacity_transitions: MAX_CAPACITY + 1, ..base.clone() };
        assert_eq!(msg(c, ANT), "capacity_transitions must be at most 4294967295, got 4294967296");
        let c = ReplayConfig { observation_rows: Some(1), ..base.clone() };
        assert_eq!(
            msg(c, ANT),
            "observation_rows must be in [2, 4294967295] (a transition uses two rows), got 1"
        );
        let c = ReplayConfig { alpha: 1.5, ..base.clone() };
        assert_eq!(msg(c, ANT), "alpha must be in [0, 1], got 1.5");
        let c = ReplayConfig { alpha: f64::NAN, ..base.clone() };
        assert_eq!(msg(c, ANT), "alpha must be in [0, 1], got NaN");
        let c = ReplayConfig { epsilon: 0.0, ..base.clone() };
        assert_eq!(msg(c, ANT), "epsilon must be finite and positive, got 0");
        let c = ReplayConfig { beta_start: -0.1, ..base.clone() };
        assert_eq!(msg(c, ANT), "beta_start must be in [0, 1], got -0.1");
        let c = ReplayConfig { beta_end: 1.4, ..base.clone() };
        assert_eq!(msg(c, ANT), "beta_end must be in [beta_start, 1], got 1.4 with beta_start 0.4");
        let c = ReplayConfig { beta_end: 0.3, ..base.clone() };
        assert_eq!(msg(c, ANT), "beta_end must be in [beta_start, 1], got 0.3 with beta_start 0.4");
        let c = ReplayConfig { memory_budget_bytes: 400_000_000, ..base };
        assert_eq!(
            msg(c, ANT),
            "replay storage needs 499291244 bytes, more than memory_budget_bytes 400000000"
        );
    }
}
