//! `[executor]` table of the run configuration.

use serde::Deserialize;

/// Configuration of the executor role.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExecutorConfig {
    /// How often the role publishes its stats, in milliseconds.
    pub stats_interval_ms: u64,
}

impl Default for ExecutorConfig {
    fn default() -> Self {
        Self { stats_interval_ms: 1000 }
    }
}

impl node::RoleConfig for ExecutorConfig {
    const SECTION: &'static str = "executor";

    fn validate(&self) -> Result<(), String> {
        if self.stats_interval_ms == 0 {
            return Err("stats_interval_ms must be > 0".into());
        }
        Ok(())
    }
}
