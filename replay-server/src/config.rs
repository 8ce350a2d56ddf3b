//! `[replay_server]` table of the run configuration; the buffer's settings are the run's `[replay]`
//! table, the one single-machine runs read too.
//!
//! `validate` refuses, with a message that names the key and says why, every configuration that
//! could not run or could hang: a minimum size the buffer can never reach, a rate limiter whose
//! first batch would need more inserts than the minimum size provides, deadlines longer than a
//! learner would wait, and memory plans over the budget.

use std::path::PathBuf;

use replay::{Dims, ReplayBuffer, ReplayConfig};
use run::RunSpec;
use serde::Deserialize;

use crate::limiter::LimiterConfig;

/// Where a new transition's priority comes from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitialPriority {
    /// p = (|δ| + ε)^α from the TD errors the executor sent (Ape-X's actor-side priorities).
    #[default]
    TdError,
    /// The current maximum priority (1 when empty), ignoring the executor's TD errors: the paper's rule.
    Max,
}

/// Configuration of the replay-server role. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayServerConfig {
    /// Observation width of the task, read from the run file's `[train] task` (with `[her]`, the
    /// goal appended) as every role reads it, never from a key of this table. Default 105 (ant-v5).
    #[serde(skip)]
    pub obs_dim: u32,
    /// Action width of the task, read likewise. Default 8 (ant-v5).
    #[serde(skip)]
    pub act_dim: u32,
    /// The buffer: the run file's `[replay]` table (capacity, α, β, mode, and
    /// `memory_budget_bytes`, which here bounds *everything* the server holds (see [`MemoryPlan`]).
    #[serde(skip)]
    pub buffer: ReplayConfig,
    /// Deterministic mode's schedule (`[train] deterministic`, `[lockstep]`; `None` otherwise):
    /// experience is staged and inserted by the schedule, and the limiter and minimum size are
    /// replaced by it.
    #[serde(skip)]
    pub lockstep: Option<run::Lockstep>,
    /// Source of new transitions' priorities. Default `td_error`.
    pub initial_priority: InitialPriority,
    /// No sampling below this many stored transitions. Default 10_000 (the paper's warm-up).
    pub min_size_to_sample: u64,
    /// Transitions sampled per transition inserted, as Reverb's `SampleToInsertRatio`; `None`
    /// (default) lets the learner sample freely once the minimum size is reached, as the paper.
    pub samples_per_insert: Option<f64>,
    /// Slack of the ratio, in sampled transitions: a sample is served while
    /// `sampled + batch ≤ samples_per_insert · (inserted − min_size_to_sample) + tolerance`.
    /// Must be at least `max_batch_size`. Default 4096.
    pub samples_per_insert_tolerance: f64,
    /// Largest batch a sample request may ask for. Default 1024.
    pub max_batch_size: u32,
    /// Most transitions one experience message may carry; larger messages are rejected before
    /// decoding. Default 4096.
    pub max_insert_transitions: u32,
    /// How long a blocked sample request waits for inserts before a typed refusal. Default 1000 ms;
    /// the learner's query timeout must be longer.
    pub request_deadline_ms: u64,
    /// Blocked requests held at once; more are refused at once. Default 64.
    pub max_pending_requests: u32,
    /// Seed of the sampling RNG; batch i uses a generator derived from (seed, i), so a restored
    /// server continues the same sample sequence. Default 0.
    pub seed: u64,
    /// Snapshot file; restored at start when it exists, written periodically and at shutdown.
    /// Default none: no snapshots (and no snapshot replica in memory). The environment variable
    /// `SACLSP_REPLAY_SNAPSHOT` overrides it (`deploy/local.sh` with `DURABLE=1`).
    pub snapshot_path: Option<PathBuf>,
    /// Seconds between periodic snapshots; 0 = only at shutdown. Default 600.
    pub snapshot_interval_s: u64,
    /// Bytes of operations the snapshot replica may lag behind while it writes; past this the
    /// write is abandoned (and retried next interval) rather than letting memory grow. Default 128 MiB.
    pub snapshot_log_budget_bytes: u64,
    /// Experience messages zenoh may queue for the server. Default 64.
    pub subscriber_queue_messages: u32,
    /// How often stats are published on `stats/replay/<id>`, in milliseconds. Default 1000.
    pub stats_interval_ms: u64,
    /// Entries in the top-k priority list of the state query (`?k=` overrides). Default 10, at most 256.
    pub top_k: u32,
}

impl Default for ReplayServerConfig {
    fn default() -> Self {
        Self {
            obs_dim: proto::DEFAULT_TRANSITION_DIMS.0,
            act_dim: proto::DEFAULT_TRANSITION_DIMS.1,
            buffer: ReplayConfig::default(),
            lockstep: None,
            initial_priority: InitialPriority::TdError,
            min_size_to_sample: 10_000,
            samples_per_insert: None,
            samples_per_insert_tolerance: 4096.0,
            max_batch_size: 1024,
            max_insert_transitions: 4096,
            request_deadline_ms: proto::DEFAULT_REQUEST_DEADLINE_MS,
            max_pending_requests: 64,
            seed: 0,
            snapshot_path: None,
            snapshot_interval_s: 600,
            snapshot_log_budget_bytes: 128 << 20,
            subscriber_queue_messages: 64,
            stats_interval_ms: 1000,
            top_k: 10,
        }
    }
}

/// Largest top-k served: 3 metrics each must fit in a stats report next to the others.
pub const MAX_TOP_K: u32 = 256;
/// Longest deadline accepted for a blocked request (a minute: far beyond any sane learner timeout).
pub const MAX_REQUEST_DEADLINE_MS: u64 = 60_000;

/// Bytes the server may hold, by part; `total` is checked against `[replay] memory_budget_bytes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryPlan {
    /// The buffer's storage and sum tree (`ReplayBuffer::bytes_for`).
    pub buffer: u64,
    /// The snapshot replica: a second buffer, when snapshots are on.
    pub replica: u64,
    /// Operations queued for the replica, at most `snapshot_log_budget_bytes`.
    pub replica_log: u64,
    /// Experience messages queued by zenoh: `subscriber_queue_messages` of the largest size.
    pub in_flight: u64,
    /// Sum of the above.
    pub total: u64,
}

impl ReplayServerConfig {
    /// The task's dimensions as the buffer sees them.
    pub fn dims(&self) -> Dims {
        Dims { obs_dim: self.obs_dim as usize, act_dim: self.act_dim as usize }
    }

    /// The rate limiter's part of the configuration.
    pub fn limiter(&self) -> LimiterConfig {
        LimiterConfig {
            min_size_to_sample: self.min_size_to_sample,
            samples_per_insert: self.samples_per_insert,
            tolerance: self.samples_per_insert_tolerance,
        }
    }

    /// Whether snapshots (and the replica that writes them) are on.
    pub fn snapshots_enabled(&self) -> bool {
        self.snapshot_path.is_some()
    }

    /// Upper bound on the encoded size of an experience message of `max_insert_transitions`:
    /// per transition two observations, an action, reward and TD error as f32, one flag byte.
    pub fn max_experience_bytes(&self) -> u64 {
        let floats = 2 * u64::from(self.obs_dim) + u64::from(self.act_dim) + 2;
        let per_transition = 4 * floats + 1;
        // Frame header, ids and counters, and bincode length prefixes: far below 256 bytes.
        256 + u64::from(self.max_insert_transitions) * per_transition
    }

    /// Fewest transitions the buffer is sure to hold once filled, however short the inserted runs
    /// are: each transition uses at most two observation rows.
    pub fn guaranteed_capacity(&self) -> u64 {
        let rows = self.buffer.observation_rows_resolved() as u64;
        (self.buffer.capacity_transitions as u64).min(rows / 2)
    }

    /// What the server may hold in memory, by part.
    pub fn memory_plan(&self) -> MemoryPlan {
        let buffer = ReplayBuffer::bytes_for(&self.buffer, self.dims());
        let (replica, replica_log) =
            if self.snapshots_enabled() { (buffer, self.snapshot_log_budget_bytes) } else { (0, 0) };
        let in_flight = u64::from(self.subscriber_queue_messages).saturating_mul(self.max_experience_bytes());
        let total = [buffer, replica, replica_log, in_flight].iter().fold(0u64, |a, &b| a.saturating_add(b));
        MemoryPlan { buffer, replica, replica_log, in_flight, total }
    }

    fn check(&self) -> Result<(), String> {
        let max_batch = proto::MAX_BATCH_LEN as u32;
        if self.obs_dim == 0 || self.obs_dim > proto::MAX_DIM {
            return Err(format!("obs_dim must be in 1..={}, got {}", proto::MAX_DIM, self.obs_dim));
        }
        if self.act_dim == 0 || self.act_dim > proto::MAX_DIM {
            return Err(format!("act_dim must be in 1..={}, got {}", proto::MAX_DIM, self.act_dim));
        }
        self.buffer.validate(self.dims()).map_err(|e| format!("[replay] {e}"))?;
        if self.max_batch_size == 0 || self.max_batch_size > max_batch {
            return Err(format!("max_batch_size must be in 1..={max_batch}, got {}", self.max_batch_size));
        }
        if self.max_insert_transitions == 0 || self.max_insert_transitions > max_batch {
            return Err(format!(
                "max_insert_transitions must be in 1..={max_batch}, got {}",
                self.max_insert_transitions
            ));
        }
        self.check_limiter()?;
        if self.request_deadline_ms == 0 || self.request_deadline_ms > MAX_REQUEST_DEADLINE_MS {
            return Err(format!(
                "request_deadline_ms must be in 1..={MAX_REQUEST_DEADLINE_MS} (a blocked request must be \
                 answered before the learner gives up), got {}",
                self.request_deadline_ms
            ));
        }
        let positive = [
            ("max_pending_requests", u64::from(self.max_pending_requests)),
            ("subscriber_queue_messages", u64::from(self.subscriber_queue_messages)),
            ("stats_interval_ms", self.stats_interval_ms),
        ];
        if let Some((key, _)) = positive.iter().find(|(_, v)| *v == 0) {
            return Err(format!("{key} must be at least 1"));
        }
        if self.top_k > MAX_TOP_K {
            return Err(format!("top_k must be at most {MAX_TOP_K}, got {}", self.top_k));
        }
        if self.snapshots_enabled() && self.snapshot_log_budget_bytes < self.max_experience_bytes() {
            return Err(format!(
                "snapshot_log_budget_bytes ({}) must hold at least one experience message of \
                 max_insert_transitions ({} bytes)",
                self.snapshot_log_budget_bytes,
                self.max_experience_bytes()
            ));
        }
        self.check_memory()
    }

    /// The liveness checks: refuse limiter settings under which sampling could never start.
    fn check_limiter(&self) -> Result<(), String> {
        let min = self.min_size_to_sample;
        if min == 0 {
            return Err(
                "min_size_to_sample must be at least 1 (nothing can be sampled from an empty buffer)".into(),
            );
        }
        let capacity = self.buffer.capacity_transitions as u64;
        if min > capacity {
            return Err(format!(
                "min_size_to_sample ({min}) exceeds [replay] capacity_transitions ({capacity}): the buffer could \
                 never hold enough to sample, and every sample request would wait forever"
            ));
        }
        let guaranteed = self.guaranteed_capacity();
        if min > guaranteed {
            return Err(format!(
                "min_size_to_sample ({min}) exceeds the {guaranteed} transitions the buffer is sure to hold \
                 ([replay] observation_rows / 2 = {}): with short episodes it could never be reached; raise \
                 [replay] observation_rows or lower min_size_to_sample",
                self.buffer.observation_rows_resolved() / 2
            ));
        }
        let Some(ratio) = self.samples_per_insert else { return Ok(()) };
        if !(ratio.is_finite() && ratio > 0.0) {
            return Err(format!("samples_per_insert must be finite and positive, got {ratio}"));
        }
        let tolerance = self.samples_per_insert_tolerance;
        if !tolerance.is_finite() {
            return Err(format!("samples_per_insert_tolerance must be finite, got {tolerance}"));
        }
        if tolerance < f64::from(self.max_batch_size) {
            return Err(format!(
                "samples_per_insert_tolerance ({tolerance}) must be at least max_batch_size ({}): with less, \
                 the first batch after min_size_to_sample needs further inserts, while executors paced by \
                 learner steps may be waiting for that very batch (a deadlock)",
                self.max_batch_size
            ));
        }
        Ok(())
    }

    fn check_memory(&self) -> Result<(), String> {
        let plan = self.memory_plan();
        let budget = self.buffer.memory_budget_bytes;
        if plan.total > budget {
            return Err(format!(
                "the replay server needs {} bytes (buffer {}, snapshot replica {}, replica log {}, in-flight \
                 messages {}), more than [replay] memory_budget_bytes {budget}; raise the budget, lower \
                 [replay] capacity_transitions, subscriber_queue_messages or max_insert_transitions, or turn \
                 snapshots off",
                plan.total, plan.buffer, plan.replica, plan.replica_log, plan.in_flight
            ));
        }
        Ok(())
    }
}

impl run::RoleConfig for ReplayServerConfig {
    const SECTION: &'static str = "replay_server";

    fn validate(&self) -> Result<(), String> {
        self.check()
    }

    /// Its table, the buffer's (`[replay]`), and the widths of the run's task: `[train] task` and `[her]`, as the learner and
    /// the executors size their networks, so no table of a run file can disagree with another.
    fn from_spec(spec: &RunSpec) -> Result<Self, String> {
        let mut config: ReplayServerConfig = spec.table(Self::SECTION)?;
        config.buffer = spec.table("replay")?;
        let dims = spec.dims();
        (config.obs_dim, config.act_dim) = (dims.obs_dim as u32, dims.act_dim as u32);
        if let Some(path) = &spec.overrides.replay_snapshot {
            config.snapshot_path = Some(path.clone());
        }
        config.lockstep = spec.lockstep;
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use run::RoleConfig;

    use super::*;

    fn small() -> ReplayServerConfig {
        ReplayServerConfig {
            buffer: ReplayConfig { capacity_transitions: 1000, ..ReplayConfig::default() },
            min_size_to_sample: 100,
            max_batch_size: 64,
            ..ReplayServerConfig::default()
        }
    }

    fn message(cfg: ReplayServerConfig) -> String {
        cfg.validate().unwrap_err()
    }

    #[test]
    fn defaults_are_valid_and_documented_values() {
        let cfg = ReplayServerConfig::default();
        assert_eq!(cfg.validate(), Ok(()));
        assert_eq!((cfg.obs_dim, cfg.act_dim, cfg.min_size_to_sample), (105, 8, 10_000));
        assert_eq!(cfg.samples_per_insert, None);
        let plan = cfg.memory_plan();
        assert_eq!(plan.replica, 0);
        assert_eq!(plan.total, plan.buffer + plan.in_flight);
    }

    #[test]
    fn the_widths_are_the_run_tasks() {
        let cfg =
            ReplayServerConfig::parse("[train]\ntask = \"ant-rllab\"\n[her]\ngoal = \"speed\"\n").unwrap();
        assert_eq!((cfg.obs_dim, cfg.act_dim), (125 + 14, 8));
        let pendulum = ReplayServerConfig::parse("[train]\ntask = \"inverted-pendulum\"\n").unwrap();
        assert_eq!((pendulum.obs_dim, pendulum.act_dim), (4, 1));
        // A width of its own would be a second source: refused, named.
        let own = ReplayServerConfig::parse("[replay_server]\nobs_dim = 4\n").unwrap_err();
        assert!(own.contains("obs_dim"), "{own}");
        assert!(
            ReplayServerConfig::parse("[train]\ntask = \"walker\"\n").unwrap_err().contains("[train] task")
        );
    }

    #[test]
    fn the_buffer_is_the_runs_replay_table() {
        let text = "[replay_server]\nmin_size_to_sample = 50\nsamples_per_insert = 8.0\n\
                    [replay]\ncapacity_transitions = 500\nmode = \"uniform\"\n";
        let cfg = ReplayServerConfig::parse(text).unwrap();
        assert_eq!(cfg.buffer.capacity_transitions, 500);
        assert_eq!(cfg.buffer.mode, replay::SamplingMode::Uniform);
        assert_eq!(cfg.samples_per_insert, Some(8.0));
        let typo = "[replay_server]\nmin_size = 50\n";
        assert!(ReplayServerConfig::parse(typo).is_err());
        let old =
            "[replay_server]\nmin_size_to_sample = 50\n[replay_server.buffer]\ncapacity_transitions = 500\n";
        assert!(ReplayServerConfig::parse(old).unwrap_err().contains("is now [replay]"));
        assert!(ReplayServerConfig::parse("[replay]\ncapacity = 5\n").unwrap_err().starts_with("[replay]"));
    }

    #[test]
    fn deadlocking_limiters_are_refused_with_reasons() {
        let msg = message(ReplayServerConfig { min_size_to_sample: 1001, ..small() });
        assert!(
            msg.starts_with("min_size_to_sample (1001) exceeds [replay] capacity_transitions (1000)"),
            "{msg}"
        );
        let rows = ReplayConfig { capacity_transitions: 1000, observation_rows: Some(600), ..small().buffer };
        let msg = message(ReplayServerConfig { buffer: rows, min_size_to_sample: 400, ..small() });
        assert!(msg.starts_with("min_size_to_sample (400) exceeds the 300 transitions"), "{msg}");
        let msg = message(ReplayServerConfig { min_size_to_sample: 0, ..small() });
        assert!(msg.starts_with("min_size_to_sample must be at least 1"), "{msg}");
        let msg = message(ReplayServerConfig {
            samples_per_insert: Some(4.0),
            samples_per_insert_tolerance: 10.0,
            ..small()
        });
        assert!(
            msg.starts_with("samples_per_insert_tolerance (10) must be at least max_batch_size (64)"),
            "{msg}"
        );
        let msg = message(ReplayServerConfig { samples_per_insert: Some(0.0), ..small() });
        assert_eq!(msg, "samples_per_insert must be finite and positive, got 0");
        let msg = message(ReplayServerConfig { samples_per_insert: Some(f64::NAN), ..small() });
        assert_eq!(msg, "samples_per_insert must be finite and positive, got NaN");
        let ok = ReplayServerConfig {
            samples_per_insert: Some(4.0),
            samples_per_insert_tolerance: 64.0,
            ..small()
        };
        assert_eq!(ok.validate(), Ok(()));
    }

    #[test]
    fn other_fields_have_exact_messages() {
        assert_eq!(
            message(ReplayServerConfig { obs_dim: 0, ..small() }),
            "obs_dim must be in 1..=4096, got 0"
        );
        assert_eq!(
            message(ReplayServerConfig { max_batch_size: 0, ..small() }),
            "max_batch_size must be in 1..=65536, got 0"
        );
        assert_eq!(
            message(ReplayServerConfig { stats_interval_ms: 0, ..small() }),
            "stats_interval_ms must be at least 1"
        );
        assert_eq!(
            message(ReplayServerConfig { top_k: 300, ..small() }),
            "top_k must be at most 256, got 300"
        );
        let msg = message(ReplayServerConfig { request_deadline_ms: 0, ..small() });
        assert!(msg.starts_with("request_deadline_ms must be in 1..=60000"), "{msg}");
        let buffer = ReplayConfig { alpha: 2.0, ..small().buffer };
        assert_eq!(
            message(ReplayServerConfig { buffer, ..small() }),
            "[replay] alpha must be in [0, 1], got 2"
        );
    }

    #[test]
    fn memory_budget_covers_the_replica_and_in_flight_messages() {
        let with_snapshots =
            ReplayServerConfig { snapshot_path: Some("/tmp/x.snap".into()), ..ReplayServerConfig::default() };
        let plan = with_snapshots.memory_plan();
        assert_eq!(plan.replica, plan.buffer);
        let msg = message(with_snapshots.clone());
        assert!(msg.starts_with(&format!("the replay server needs {} bytes", plan.total)), "{msg}");
        let mut roomy = with_snapshots;
        roomy.buffer.memory_budget_bytes = 2 << 30;
        assert_eq!(roomy.validate(), Ok(()));
    }
}
