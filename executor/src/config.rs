//! The executor's configuration: its `[executor]` table, plus the run's `[agent]` table (the same
//! networks the learner trains) and the run's shared tables ([`RunSpec`]).

use agent::AgentConfig;
use run::RunSpec;
use serde::Deserialize;

/// The `[executor]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExecutorSettings {
    /// Transitions per published batch. A partial batch is also sent at the end of an episode and
    /// before the executor waits at the barrier, so the learner is never starved of its warm-up.
    /// Default 64.
    pub batch_transitions: u32,
    /// The barrier report (`control/barrier/<id>`) is sent at least this often. Default 100.
    pub report_interval_ms: u64,
    /// A wait (barrier, weights) that lasts this long is logged with its reason and re-reported;
    /// the executor keeps waiting until the reason goes away or shutdown. Default 2000.
    pub wait_deadline_ms: u64,
    /// How long one weights query may take before it is retried. Default 2000.
    pub weights_timeout_ms: u64,
    /// Take new weights from the param server's push (`params/stream`), which each host's zenoh
    /// router fans out, asking the param server only for what no push brought within
    /// `weights::PUSH_GRACE` of its announcement. `false`: ask for every version (the param
    /// server then sends one copy per executor; `deploy/scale.sh` runs both). Deterministic mode
    /// always asks, for exact versions. Default true.
    pub weights_push: bool,
    /// Cut episodes at this many steps when shorter than the task's limit (tests, quick runs).
    /// Default none: the task's own limit (1000 for the Ants).
    pub max_episode_steps: Option<u32>,
    /// How often the role publishes its stats, in milliseconds. Default 1000.
    pub stats_interval_ms: u64,
    /// Durable experience: keep every published batch in `<spool_dir>/executor-<id>/` until the
    /// replay server's snapshot holds it, and send it again when a replay server (re)starts (see
    /// `spool.rs`). Needs the replay server's snapshots on (`[replay_server] snapshot_path`), or
    /// nothing is ever released and the spool only drops its oldest past `spool_max_bytes`. The
    /// environment variable `SACLSP_SPOOL_DIR` overrides it (`deploy/local.sh` with `DURABLE=1`).
    /// Default none: no spool; a batch the replay server misses is lost.
    pub spool_dir: Option<std::path::PathBuf>,
    /// Disk the spool may hold; past it the oldest batches are dropped (counted, in the ledger as
    /// `dropped spool_overflow`). It must hold what one executor sends between two snapshots: about
    /// (obs_dim × 2 + act_dim + 3) × 4 bytes per transition (900 B on ant-v5) times its env steps
    /// per second (150 with 8 executors on 2 cores) times `snapshot_interval_s` plus the snapshot's
    /// write time (~12 MB for 60 s). Disk only: the spool holds nothing in memory but its index.
    /// Default 256 MiB.
    pub spool_max_bytes: u64,
}

impl Default for ExecutorSettings {
    fn default() -> Self {
        Self {
            batch_transitions: 64,
            report_interval_ms: 100,
            wait_deadline_ms: 2000,
            weights_timeout_ms: 2000,
            weights_push: true,
            max_episode_steps: None,
            stats_interval_ms: 1000,
            spool_dir: None,
            spool_max_bytes: 256 << 20,
        }
    }
}

/// Everything an executor reads from the run file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExecutorConfig {
    /// `[executor]`.
    pub executor: ExecutorSettings,
    /// `[agent]`: the policy and critics, sized to the run's widths.
    pub agent: AgentConfig,
    /// The run's shared tables: task, seed, `[her]` (goals appended to the observation, goal
    /// rewards, relabelled episodes), `[hierarchy]` (only how many frozen levels there are: the
    /// levels themselves come over the bus from the param server, so this host needs none of their
    /// files) and deterministic mode's schedule.
    pub run: RunSpec,
}

impl run::RoleConfig for ExecutorConfig {
    const SECTION: &'static str = "executor";

    fn validate(&self) -> Result<(), String> {
        let s = &self.executor;
        let positive = [
            ("batch_transitions", u64::from(s.batch_transitions)),
            ("report_interval_ms", s.report_interval_ms),
            ("wait_deadline_ms", s.wait_deadline_ms),
            ("weights_timeout_ms", s.weights_timeout_ms),
            ("stats_interval_ms", s.stats_interval_ms),
            ("spool_max_bytes", s.spool_max_bytes),
        ];
        if let Some(key) = run::table::first_zero(&positive) {
            return Err(format!("[executor] {key} must be > 0"));
        }
        if s.batch_transitions as usize > proto::MAX_BATCH_LEN {
            return Err(format!("[executor] batch_transitions must be at most {}", proto::MAX_BATCH_LEN));
        }
        self.agent.validate_for_run(&self.run)
    }

    /// `[executor]` with `SACLSP_SPOOL_DIR` over its `spool_dir`, and `[agent]` for the run.
    fn from_spec(spec: &RunSpec) -> Result<Self, String> {
        let mut executor: ExecutorSettings = spec.table(Self::SECTION)?;
        if let Some(dir) = &spec.overrides.spool_dir {
            executor.spool_dir = Some(dir.clone());
        }
        Ok(Self { executor, agent: AgentConfig::from_run(spec)?, run: spec.clone() })
    }
}

#[cfg(test)]
mod tests {
    use run::RoleConfig;

    use super::*;

    #[test]
    fn reads_its_table_the_agent_and_the_task() {
        let text = "[train]\ntask = \"inverted-pendulum\"\nseed = 4\nepochs = 3\n[agent]\nscale_reward = 3.0\n\
                    [executor]\nbatch_transitions = 8\n[replay]\nmode = \"uniform\"\n";
        let c = ExecutorConfig::parse(text).unwrap();
        assert_eq!((c.agent.obs_dim, c.agent.act_dim), (4, 1));
        assert_eq!(c.executor.batch_transitions, 8);
        assert_eq!(c.run.seed(), 4);
        assert_eq!(c.validate(), Ok(()));
        assert!(
            ExecutorConfig::parse("[executor]\nbatch_transitons = 8\n")
                .unwrap_err()
                .contains("batch_transitons")
        );
        assert!(ExecutorConfig::parse("[train]\ntask = \"ant-v9\"\n").is_err());
        let zero = ExecutorConfig {
            executor: ExecutorSettings { batch_transitions: 0, ..ExecutorSettings::default() },
            ..c
        };
        assert!(zero.validate().unwrap_err().contains("batch_transitions"));
    }
}
