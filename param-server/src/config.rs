//! `[param_server]` table of the run configuration.

use serde::Deserialize;

/// Configuration of the param-server role.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ParamServerConfig {
    /// How often the role publishes its stats, in milliseconds.
    pub stats_interval_ms: u64,
}

impl Default for ParamServerConfig {
    fn default() -> Self {
        Self { stats_interval_ms: 1000 }
    }
}

impl node::RoleConfig for ParamServerConfig {
    const SECTION: &'static str = "param_server";

    fn validate(&self) -> Result<(), String> {
        if self.stats_interval_ms == 0 {
            return Err("stats_interval_ms must be > 0".into());
        }
        Ok(())
    }
}
