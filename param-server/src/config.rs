//! `[param_server]` table of the run configuration, and the run's `[agent]` networks when the
//! table names the task's dimensions.

use agent::AgentConfig;
use run::RunSpec;
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
    /// The run's networks: `[agent]` with the widths of `[train] task` (and `[her]`), as the
    /// learner builds them. Every weights frame is checked against their tensor names and shapes
    /// from the first frame on. (`None`, for tests of the store alone: the schema is taken from the
    /// first frame accepted.)
    #[serde(skip)]
    pub networks: Option<AgentConfig>,
    /// `[hierarchy]`: the frozen levels this role serves to executors (`params/frozen`), and whose
    /// content hash every weights frame must carry.
    #[serde(skip)]
    pub hierarchy: run::HierarchyKeys,
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
            networks: None,
            hierarchy: run::HierarchyKeys::default(),
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

impl run::RoleConfig for ParamServerConfig {
    const SECTION: &'static str = "param_server";

    fn validate(&self) -> Result<(), String> {
        let positive = [
            ("env_steps_per_learner_step", self.env_steps_per_learner_step),
            ("warm_up_transitions", self.warm_up_transitions),
            ("announce_interval_ms", self.announce_interval_ms),
            ("stats_interval_ms", self.stats_interval_ms),
            ("max_learner_steps_per_s", self.max_learner_steps_per_s),
        ];
        if let Some(key) = run::table::first_zero(&positive) {
            return Err(format!("{key} must be > 0"));
        }
        match &self.networks {
            None => Ok(()),
            Some(networks) => networks.validate().map_err(|e| format!("[agent] {e}")),
        }
    }

    /// The `[param_server]` and `[hierarchy]` tables, and the run's networks: the `[agent]` table
    /// (over the level-above defaults in a hierarchy) with the widths of `[train] task` and `[her]`.
    fn from_spec(spec: &RunSpec) -> Result<Self, String> {
        let config: Self = spec.table(Self::SECTION)?;
        Ok(Self { networks: Some(AgentConfig::from_run(spec)?), hierarchy: spec.hierarchy.clone(), ..config })
    }
}

#[cfg(test)]
mod tests {
    use run::RoleConfig;

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
        assert!(parsed.weights_schema().is_some(), "the default task's networks");
    }

    #[test]
    fn the_task_brings_the_run_s_networks() {
        let text = "[train]\ntask = \"inverted-pendulum\"\n[agent]\ncritic_hidden = [4]\ntwin_q = true\n";
        let parsed = ParamServerConfig::parse(text).unwrap();
        assert_eq!(parsed.validate(), Ok(()));
        let networks = parsed.networks.clone().unwrap();
        assert_eq!((networks.obs_dim, networks.act_dim, networks.critic_hidden.as_slice()), (4, 1, &[4][..]));
        let schema = parsed.weights_schema().unwrap();
        assert_eq!(schema["q1.layer0.weight_observation"], vec![4, 4]);
        assert!(schema.contains_key("q2.layer0.weight_action"));
        // With HER the goal widens the input; widths of its own are refused; bad networks are named.
        let her =
            ParamServerConfig::parse("[train]\ntask = \"ant-rllab\"\n[her]\ngoal = \"speed\"\n").unwrap();
        assert_eq!(her.networks.unwrap().obs_dim, 139);
        assert!(ParamServerConfig::parse("[param_server]\nobs_dim = 3\n").unwrap_err().contains("obs_dim"));
        let bad = ParamServerConfig::parse("[agent]\ntau = 2.0\n").unwrap();
        let err = bad.validate().unwrap_err();
        assert!(err.starts_with("[agent]") && err.contains("tau must be"), "{err}");
    }
}
