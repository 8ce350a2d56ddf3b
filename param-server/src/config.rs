//! `[param_server]` table of the run configuration.

use serde::Deserialize;

use crate::BarrierRule;

/// Configuration of the param-server role.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ParamServerConfig {
    /// k: env steps each executor may take per learner step. Default 1, the dissertation's text
    /// (its code allowed 2).
    pub env_steps_per_learner_step: u64,
    /// Transitions the live executors may collect together before the learner's first update.
    /// Must be at least the replay server's `min_size_to_sample`, or the learner never starts.
    /// Default 10 000 (the replay server's default minimum).
    pub warm_up_transitions: u64,
    /// Most weight versions an executor may act behind the newest; absent = no bound (default; the
    /// paper's executors read whatever the variables held).
    pub max_weight_lag: Option<u64>,
    /// The global step is re-announced at least this often, so late joiners and a restarted peer
    /// see it without waiting for the learner, and executors notice a silent param server. Default 200.
    pub announce_interval_ms: u64,
    /// How often the role publishes its stats, in milliseconds. Default 1000.
    pub stats_interval_ms: u64,
    /// Most learner steps per second the global step may move by; a step further ahead is refused
    /// and counted (`param/rejected.learner_step/implausible_step`), so a forged frame cannot pin
    /// the barrier. Default 100 000, ~50x what the fused learner makes here.
    pub max_learner_steps_per_s: u64,
}

impl Default for ParamServerConfig {
    fn default() -> Self {
        Self {
            env_steps_per_learner_step: 1,
            warm_up_transitions: 10_000,
            max_weight_lag: None,
            announce_interval_ms: 200,
            stats_interval_ms: 1000,
            max_learner_steps_per_s: crate::step_guard::DEFAULT_MAX_LEARNER_STEPS_PER_S,
        }
    }
}

impl ParamServerConfig {
    /// The barrier these values describe.
    pub fn rule(&self) -> BarrierRule {
        BarrierRule {
            env_steps_per_learner_step: self.env_steps_per_learner_step,
            warm_up_transitions: self.warm_up_transitions,
            max_weight_lag: self.max_weight_lag,
        }
    }
}

impl node::RoleConfig for ParamServerConfig {
    const SECTION: &'static str = "param_server";

    fn validate(&self) -> Result<(), String> {
        let positive = [
            ("env_steps_per_learner_step", self.env_steps_per_learner_step),
            ("warm_up_transitions", self.warm_up_transitions),
            ("announce_interval_ms", self.announce_interval_ms),
            ("stats_interval_ms", self.stats_interval_ms),
            ("max_learner_steps_per_s", self.max_learner_steps_per_s),
        ];
        if let Some(key) = node::config::first_zero(&positive) {
            return Err(format!("{key} must be > 0"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use node::RoleConfig;

    use super::*;

    #[test]
    fn defaults_are_the_papers_and_zeros_are_named() {
        let d = ParamServerConfig::default();
        assert_eq!(d.validate(), Ok(()));
        assert_eq!(d.rule().env_steps_per_learner_step, 1);
        let bad = ParamServerConfig { env_steps_per_learner_step: 0, ..d.clone() };
        assert!(bad.validate().unwrap_err().contains("env_steps_per_learner_step"));
        let parsed = ParamServerConfig::parse("[param_server]\nmax_weight_lag = 3\n").unwrap();
        assert_eq!(parsed.max_weight_lag, Some(3));
        assert!(ParamServerConfig::parse("[param_server]\nmax_wieght_lag = 3\n").is_err());
    }
}
