//! The learner's configuration: its `[learner]` table, plus the run's `[agent]` table (the networks
//! executors act with) and the run's shared tables ([`RunSpec`]).

use std::path::PathBuf;

use agent::{AgentConfig, Backend};
use proto::EvalMode;
use run::RunSpec;
use serde::Deserialize;

/// The `[learner]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LearnerSettings {
    /// Sample requests kept in flight, so a batch is ready whenever an update ends. Default 3.
    pub prefetch_batches: u32,
    /// Batches per sample request: each reply carries this many batches' transitions and is dealt
    /// out into that many updates (`batch.rs`, `Sampled::split`). On one host the bus's cost is
    /// mostly per message (thread wake-ups on both sides), so this frees CPU for the executors at
    /// the same updates/s. Default 1; `[agent] batch_size` times this must not exceed the replay
    /// server's `max_batch_size`.
    pub batches_per_request: u32,
    /// How long one sample request may take before it counts as unanswered and is re-sent; must
    /// exceed the replay server's `request_deadline_ms`. Default 5000.
    pub sample_timeout_ms: u64,
    /// Publish the weights to the param server every this many updates (and at step 0). Default 100.
    pub publish_weights_every_updates: u64,
    /// Report the learner step to the param server every this many updates. Default 10.
    pub announce_every_updates: u64,
    /// Updates per epoch: the unit of evaluation and checkpoints. Default 1000, as the paper.
    pub epoch_length_updates: u64,
    /// Episodes per evaluation (on a thread of their own, niced by `deploy/local.sh`). 0 = none.
    /// Default 1, as the paper.
    pub eval_episodes: u32,
    /// How the evaluation picks the latent: `fixed_latent` (default, the paper's: one h ~ N(0, I)
    /// per evaluation), `zero_latent` (h = 0) or `stochastic`.
    pub eval_mode: EvalMode,
    /// Evaluate after every this many epochs. One evaluation runs at a time: one due while the
    /// previous still runs is skipped and counted (`learner/evals_skipped`), so on two cores the
    /// evaluations never hold up the updates. Default 1.
    pub eval_every_epochs: u64,
    /// Write a checkpoint every this many epochs (0: only at shutdown). Default 100.
    pub checkpoint_every_epochs: u64,
    /// Where checkpoints go; the newest one found there at start is resumed from. None = no checkpoints.
    pub checkpoint_dir: Option<PathBuf>,
    /// Stop after this many updates (None: until shut down). The paper ran 10M.
    pub max_updates: Option<u64>,
    /// Send |δ| back to the replay server after every update (prioritized replay). Default true.
    pub send_priorities: bool,
    /// Which update implementation runs (`auto`, `candle`, `fused`). Default `auto`.
    pub backend: Backend,
    /// How often the role publishes its stats, in milliseconds. Default 1000.
    pub stats_interval_ms: u64,
}

impl Default for LearnerSettings {
    fn default() -> Self {
        Self {
            prefetch_batches: 3,
            batches_per_request: 1,
            sample_timeout_ms: 5000,
            publish_weights_every_updates: 100,
            announce_every_updates: 10,
            epoch_length_updates: 1000,
            eval_episodes: 1,
            eval_mode: EvalMode::FixedLatent,
            eval_every_epochs: 1,
            checkpoint_every_epochs: 100,
            checkpoint_dir: None,
            max_updates: None,
            send_priorities: true,
            backend: Backend::Auto,
            stats_interval_ms: 1000,
        }
    }
}

/// Everything the learner reads from the run file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LearnerConfig {
    /// `[learner]`.
    pub learner: LearnerSettings,
    /// `[agent]`: the networks and the update, sized to the run's widths.
    pub agent: AgentConfig,
    /// `[replay_server]`: the keys the learner must agree with.
    pub replay_server: ReplayDeadline,
    /// The run's shared tables: task, seed, `[hierarchy]` (frozen levels below the trained one,
    /// whose files are read here), `[her]` (with goals, the networks' input is observation ++ goal
    /// and evaluations step the goal-conditioned task; relabelling happens in the executors) and
    /// deterministic mode's schedule (one sample request in flight, each for an exact learner step).
    pub run: RunSpec,
}

/// The replay server's request deadline, read from the shared run file to check the learner's
/// sample timeout against it.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(default)]
pub struct ReplayDeadline {
    /// `request_deadline_ms` (absent: the replay server's default).
    pub request_deadline_ms: Option<u64>,
}

impl run::RoleConfig for LearnerConfig {
    const SECTION: &'static str = "learner";

    fn validate(&self) -> Result<(), String> {
        let s = &self.learner;
        let positive = [
            ("prefetch_batches", u64::from(s.prefetch_batches)),
            ("batches_per_request", u64::from(s.batches_per_request)),
            ("sample_timeout_ms", s.sample_timeout_ms),
            ("publish_weights_every_updates", s.publish_weights_every_updates),
            ("announce_every_updates", s.announce_every_updates),
            ("epoch_length_updates", s.epoch_length_updates),
            ("eval_every_epochs", s.eval_every_epochs),
            ("stats_interval_ms", s.stats_interval_ms),
        ];
        if let Some(key) = run::table::first_zero(&positive) {
            return Err(format!("[learner] {key} must be > 0"));
        }
        let deadline = self.replay_server.request_deadline_ms.unwrap_or(proto::DEFAULT_REQUEST_DEADLINE_MS);
        if s.sample_timeout_ms <= deadline {
            // A request the replay server holds to its deadline would look like silence, so a
            // learner starved of data could not say so and a deadlock would never be broken.
            return Err(format!(
                "[learner] sample_timeout_ms ({}) must exceed [replay_server] request_deadline_ms ({deadline})",
                s.sample_timeout_ms
            ));
        }
        if s.prefetch_batches > 64 {
            return Err("[learner] prefetch_batches must be at most 64".into());
        }
        if self.agent.batch_size * s.batches_per_request as usize > proto::MAX_BATCH_LEN {
            return Err(format!(
                "[agent] batch_size times [learner] batches_per_request must be at most {}",
                proto::MAX_BATCH_LEN
            ));
        }
        if let Some(lockstep) = &self.run.lockstep {
            if s.publish_weights_every_updates != lockstep.updates_per_round {
                return Err(format!(
                    "deterministic mode publishes the weights once per round: [learner] \
                     publish_weights_every_updates ({}) must equal [lockstep] updates_per_round ({})",
                    s.publish_weights_every_updates, lockstep.updates_per_round
                ));
            }
            let every = lockstep.checkpoint_every_updates;
            if let Some(max) = s.max_updates.filter(|max| every > 0 && !max.is_multiple_of(every)) {
                return Err(format!(
                    "deterministic mode ends at a checkpoint: [learner] max_updates ({max}) must be a \
                     multiple of epoch_length_updates × checkpoint_every_epochs ({every})"
                ));
            }
            if !s.send_priorities {
                return Err("deterministic mode needs [learner] send_priorities = true: each sample \
                            waits for the priorities of the updates before it"
                    .into());
            }
        }
        self.agent.validate_for_run(&self.run)
    }

    /// `[learner]` with `SACLSP_CHECKPOINT_DIR` over its `checkpoint_dir` (so a launcher can put
    /// checkpoints in the run's folder without editing the shared run file), `[agent]` for the run,
    /// and the replay server's deadline.
    fn from_spec(spec: &RunSpec) -> Result<Self, String> {
        let mut learner: LearnerSettings = spec.table(Self::SECTION)?;
        if let Some(dir) = &spec.overrides.checkpoint_dir {
            learner.checkpoint_dir = Some(dir.clone());
        }
        Ok(Self {
            learner,
            agent: AgentConfig::from_run(spec)?,
            replay_server: spec.table("replay_server")?,
            run: spec.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use run::RoleConfig;

    use super::*;

    #[test]
    fn reads_its_table_the_agent_and_the_task() {
        let text = "[train]\ntask = \"ant-v5\"\nepochs = 3\n[learner]\nprefetch_batches = 2\n\
                    checkpoint_dir = \"/tmp/x\"\n[agent]\nbatch_size = 64\n";
        let c = LearnerConfig::parse(text).unwrap();
        assert_eq!((c.agent.obs_dim, c.agent.act_dim), (105, 8));
        assert_eq!(c.learner.prefetch_batches, 2);
        assert_eq!(c.learner.checkpoint_dir, Some(PathBuf::from("/tmp/x")));
        assert_eq!(c.validate(), Ok(()));
        assert!(LearnerConfig::parse("[learner]\nprefetch = 2\n").unwrap_err().contains("prefetch"));
        let zero = LearnerConfig {
            learner: LearnerSettings { epoch_length_updates: 0, ..LearnerSettings::default() },
            ..c
        };
        assert!(zero.validate().unwrap_err().contains("epoch_length_updates"));
    }

    #[test]
    fn the_sample_timeout_must_outlast_the_replay_servers_deadline() {
        let text = |timeout: u64| {
            format!(
                "[train]\ntask = \"ant-v5\"\n[learner]\nsample_timeout_ms = {timeout}\n\
                 [replay_server]\nrequest_deadline_ms = 3000\nmin_size_to_sample = 10\n\
                 [replay]\ncapacity_transitions = 100\n"
            )
        };
        assert_eq!(LearnerConfig::parse(&text(3001)).unwrap().validate(), Ok(()));
        let err = LearnerConfig::parse(&text(3000)).unwrap().validate().unwrap_err();
        assert!(err.contains("must exceed [replay_server] request_deadline_ms (3000)"), "{err}");
        // Without the key, the replay server's default deadline is the one to outlast.
        let short = LearnerConfig {
            learner: LearnerSettings { sample_timeout_ms: 900, ..LearnerSettings::default() },
            ..LearnerConfig::parse("[train]\ntask = \"ant-v5\"\n").unwrap()
        };
        assert!(short.validate().unwrap_err().contains("(1000)"));
    }
}
