//! `[param_server]` table of the run configuration, and the run's `[agent]` networks when the
//! table names the task's dimensions.

use agent::AgentConfig;
use serde::Deserialize;

use crate::{BarrierRule, Schema};

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
    /// Observation width of the task. With `act_dim`, the weights frames are checked against the
    /// tensor names and shapes of the run's `[agent]` networks from the first frame on; absent
    /// (default), the schema is taken from the first frame accepted, so a forged frame that
    /// arrives before the learner's would pin it. The learner refuses to start if these differ
    /// from its task's.
    pub obs_dim: Option<u32>,
    /// Action width of the task; see `obs_dim`.
    pub act_dim: Option<u32>,
    /// The run's networks (`[agent]` with the dimensions above), read when both are set.
    #[serde(skip)]
    pub networks: Option<AgentConfig>,
    /// `[hierarchy]`: the frozen levels this role serves to executors (`params/frozen`), and whose
    /// content hash every weights frame must carry.
    #[serde(skip)]
    pub hierarchy: node::HierarchyKeys,
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
            obs_dim: None,
            act_dim: None,
            networks: None,
            hierarchy: node::HierarchyKeys::default(),
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

    /// The tensor names and shapes every weights frame must have, when the run's networks are known.
    pub fn weights_schema(&self) -> Option<Schema> {
        self.networks.as_ref().map(agent::snapshot_schema)
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
        match (self.obs_dim, self.act_dim, &self.networks) {
            (None, None, None) => Ok(()),
            (Some(_), Some(_), Some(networks)) => networks.validate().map_err(|e| format!("[agent] {e}")),
            _ => Err("obs_dim and act_dim must be set together (or neither)".into()),
        }
    }

    /// The `[param_server]` and `[hierarchy]` tables; with both dimensions set, also the `[agent]`
    /// table (over the level-above defaults in a hierarchy).
    fn parse(text: &str) -> Result<Self, String> {
        let mut config: Self = node::config::parse_section(text, Self::SECTION)?;
        config.hierarchy =
            node::config::parse_section(text, "hierarchy").map_err(|e| format!("[hierarchy] {e}"))?;
        if let (Some(obs_dim), Some(act_dim)) = (config.obs_dim, config.act_dim) {
            let base = AgentConfig::default_at_level(config.hierarchy.depth());
            let agent: AgentConfig =
                node::config::parse_section_over(text, "agent", &base).map_err(|e| format!("[agent] {e}"))?;
            config.networks =
                Some(AgentConfig { obs_dim: obs_dim as usize, act_dim: act_dim as usize, ..agent });
        }
        Ok(config)
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
        assert_eq!(parsed.weights_schema(), None);
    }

    #[test]
    fn the_dimensions_bring_the_run_s_networks() {
        let text = "[agent]\ncritic_hidden = [4]\ntwin_q = true\n[param_server]\nobs_dim = 3\nact_dim = 2\n";
        let parsed = ParamServerConfig::parse(text).unwrap();
        assert_eq!(parsed.validate(), Ok(()));
        let networks = parsed.networks.clone().unwrap();
        assert_eq!((networks.obs_dim, networks.act_dim, networks.critic_hidden.as_slice()), (3, 2, &[4][..]));
        let schema = parsed.weights_schema().unwrap();
        assert_eq!(schema["q1.layer0.weight_observation"], vec![4, 3]);
        assert!(schema.contains_key("q2.layer0.weight_action"));
        // One dimension alone, or bad networks, are named.
        let half = ParamServerConfig::parse("[param_server]\nobs_dim = 3\n").unwrap();
        assert!(half.validate().unwrap_err().contains("obs_dim and act_dim"));
        let bad = ParamServerConfig::parse("[agent]\ntau = 2.0\n[param_server]\nobs_dim = 3\nact_dim = 2\n")
            .unwrap();
        let err = bad.validate().unwrap_err();
        assert!(err.starts_with("[agent]") && err.contains("tau must be"), "{err}");
    }
}
