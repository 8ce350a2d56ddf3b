//! The single-machine loop (`docs/sac-lsp.md` §12): each env step with the stochastic policy, one update per
//! step once the replay holds `min_replay_size` transitions, one deterministic evaluation episode per
//! epoch. Prioritized replay (§8) when `[replay] mode = "prioritized"`: new transitions enter at the
//! maximum priority, and each update sends back |δ| of its batch.

use std::time::Instant;

use agent::{Actor, AnyLearner, Batch, PolicyStack};
use anyhow::{Context, Result};
use executor::Rollout;
use rand::SeedableRng;
use rand::rngs::StdRng;
use replay::{ReplayBuffer, SampledBatch, SamplingMode, TransitionBatch};
use sim::Environment;

use learner::LossMeans;

use super::record::EpochRecord;
use super::run_config::RunConfig;

pub use learner::Evaluation;

/// A single-machine SAC-LSP run: the rollout (environment and acting policy), replay and learner.
pub struct Trainer {
    config: RunConfig,
    /// The executors' rollout: acts, stores goal rewards and relabelled copies with HER, builds the
    /// n-step transitions, drops non-finite steps and cuts episodes at the task's limit.
    rollout: Rollout,
    eval_env: Box<dyn Environment>,
    learner: AnyLearner,
    /// The frozen levels the actor acts through (empty for one level), embedded in checkpoints.
    frozen: PolicyStack,
    replay: ReplayBuffer,
    rng: StdRng,
    updates: u64,
    epoch: u64,
    sampled: SampledBatch,
    batch: Batch,
    started: Instant,
}

impl std::fmt::Debug for Trainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainer").field("epoch", &self.epoch).field("rollout", &self.rollout).finish()
    }
}

impl Trainer {
    /// Builds the run. Seeds: networks `seed`, acting noise `seed + 1`, resets `seed + 2` (training)
    /// and `seed + 3` (evaluation), replay sampling `seed + 4`, relabelling `seed + 5`.
    pub fn new(config: RunConfig) -> Result<Self> {
        let task = config.train.task().map_err(anyhow::Error::msg)?;
        let env = sim::her::make(&config.her, task, config.train.seed + 2)?;
        Self::on(config, env)
    }

    /// [`new`](Self::new) training on `env` (the task's, or a test's stand-in for it).
    fn on(config: RunConfig, env: Box<dyn Environment>) -> Result<Self> {
        let seed = config.train.seed;
        let task = config.train.task().map_err(anyhow::Error::msg)?;
        let eval_env = sim::her::make(&config.her, task, seed + 3)?;
        let learner = AnyLearner::new(config.agent.clone(), seed, config.train.backend)?;
        tracing::info!(backend = ?learner.backend(), "learner");
        let levels = config.hierarchy.read().map_err(anyhow::Error::msg)?;
        let frozen = PolicyStack::from_weights(&levels)?;
        let mut actor =
            Actor::with_stack(config.agent.clone(), PolicyStack::from_weights(&levels)?, seed + 1)?;
        actor.load(&learner.snapshot()?)?;
        let replay = ReplayBuffer::new(config.replay.clone(), config.dims())?;
        let hindsight = sim::her::hindsight(&config.her, task, seed + 5);
        let rollout = Rollout::new(0, env, actor, seed + 2).with_hindsight(hindsight);
        Ok(Self {
            config,
            rollout,
            eval_env,
            learner,
            frozen,
            replay,
            rng: StdRng::seed_from_u64(seed + 4),
            updates: 0,
            epoch: 0,
            sampled: SampledBatch::new(),
            batch: Batch::default(),
            started: Instant::now(),
        })
    }

    /// The learner.
    pub fn learner(&self) -> &AnyLearner {
        &self.learner
    }

    /// The learner's checkpoint, with the frozen levels embedded in a hierarchy.
    pub fn checkpoint(&self) -> Result<agent::Checkpoint> {
        Ok(self.frozen.embed(&self.learner.checkpoint()?)?)
    }

    /// The replay buffer (for its counters).
    pub fn replay(&self) -> &ReplayBuffer {
        &self.replay
    }

    /// Runs one epoch of `epoch_length` env steps and its evaluation.
    pub fn run_epoch(&mut self) -> Result<EpochRecord> {
        let epoch_start = Instant::now();
        let (steps_before, updates_before) = (self.rollout.env_steps(), self.updates);
        let mut losses = LossMeans::default();
        let mut finished_returns = Vec::new();
        for _ in 0..self.config.train.epoch_length {
            if let Some(episode_return) = self.env_step()? {
                finished_returns.push(episode_return);
            }
            if self.replay.len() as u64 >= self.config.train.min_replay_size {
                for _ in 0..self.config.train.updates_per_step {
                    losses.add(&self.update()?);
                }
            }
            if self.rollout.env_steps().is_multiple_of(self.config.train.sync_actor_every_steps) {
                self.rollout.load(&self.learner.snapshot()?)?;
            }
        }
        let seconds = epoch_start.elapsed().as_secs_f64();
        let evaluation = self.evaluate(self.config.train.eval_episodes)?;
        let env_steps = self.rollout.env_steps();
        let mut record = EpochRecord {
            epoch: self.epoch,
            env_steps,
            updates: self.updates,
            wall_s: self.started.elapsed().as_secs_f64(),
            evaluation,
            train_return: mean(&finished_returns),
            updates_per_s: (self.updates - updates_before) as f64 / seconds,
            env_steps_per_s: (env_steps - steps_before) as f64 / seconds,
            ..EpochRecord::default()
        };
        record.fill_losses(&losses);
        self.epoch += 1;
        Ok(record)
    }

    /// One env step of the rollout; its transitions go to the replay. Returns the episode's return
    /// when the step ended an episode (terminated or truncated).
    fn env_step(&mut self) -> Result<Option<f64>> {
        let outcome = self.rollout.step()?;
        if outcome.dropped_non_finite {
            tracing::warn!("non-finite observation or reward: transition dropped, episode reset");
        }
        let t = self.rollout.take_pending();
        if !t.is_empty() {
            self.replay
                .insert_batch(TransitionBatch {
                    observations: &t.observations,
                    actions: &t.actions,
                    rewards: &t.rewards,
                    next_observations: &t.next_observations,
                    terminated: &t.terminated,
                    abs_td_errors: None,
                })
                .context("storing transitions")?;
        }
        Ok(outcome.episode.map(|e| e.episode_return))
    }

    /// One gradient update from a replay batch; prioritized replay gets the batch's new |δ|.
    fn update(&mut self) -> Result<agent::Metrics> {
        let batch_size = self.config.agent.batch_size;
        self.replay.sample(batch_size, self.updates, &mut self.rng, &mut self.sampled)?;
        let prioritized = self.config.replay.mode == SamplingMode::Prioritized;
        let s = &self.sampled;
        // Reuse one batch's buffers: this runs once per env step.
        let batch = &mut self.batch;
        batch.size = batch_size;
        batch.observations.clone_from(&s.observations);
        batch.actions.clone_from(&s.actions);
        batch.rewards.clone_from(&s.rewards);
        batch.next_observations.clone_from(&s.next_observations);
        batch.terminated.clear();
        batch.terminated.extend(s.terminated.iter().map(|&d| if d { 1.0 } else { 0.0 }));
        match (&mut batch.is_weights, prioritized) {
            (Some(weights), true) => weights.clone_from(&s.is_weights),
            (weights, true) => *weights = Some(s.is_weights.clone()),
            (weights, false) => *weights = None,
        }
        let out = self.learner.update(batch)?;
        if prioritized {
            let abs_td: Vec<f32> = out.td_errors.iter().map(|d| d.abs()).collect();
            self.replay.update_priorities(&s.slots, &s.generations, &abs_td)?;
        }
        self.updates += 1;
        Ok(out.metrics)
    }

    /// Runs `episodes` episodes in deterministic mode on the evaluation env, with the learner's
    /// current weights: the distributed learner's evaluation, the same function.
    pub fn evaluate(&mut self, episodes: u32) -> Result<Evaluation> {
        self.rollout.load(&self.learner.snapshot()?)?;
        let actor = self.rollout.actor_mut();
        learner::evaluate(actor, self.eval_env.as_mut(), episodes, self.config.train.eval_mode)
    }
}

fn mean(values: &[f64]) -> f64 {
    if values.is_empty() { f64::NAN } else { values.iter().sum::<f64>() / values.len() as f64 }
}

#[cfg(test)]
mod tests {
    use agent::{AgentConfig, Learner};
    use replay::{ReplayConfig, SamplingMode};

    use std::path::Path;

    use super::*;
    use crate::train::TrainConfig;

    fn tiny(mode: SamplingMode) -> RunConfig {
        RunConfig {
            train: TrainConfig {
                task: "inverted-pendulum".into(),
                epochs: 2,
                epoch_length: 300,
                min_replay_size: 100,
                ..TrainConfig::default()
            },
            agent: AgentConfig {
                critic_hidden: vec![16],
                embedding_layers: vec![16, 4],
                batch_size: 16,
                ..AgentConfig::default()
            },
            replay: ReplayConfig { capacity_transitions: 1000, mode, ..ReplayConfig::default() },
            hierarchy: run::HierarchyKeys::default(),
            her: sim::her::HerConfig::default(),
        }
        .fitted()
        .unwrap()
    }

    #[test]
    fn epochs_step_update_and_evaluate_on_the_real_simulator() {
        let config = tiny(SamplingMode::Uniform);
        let mut trainer = Trainer::new(config.clone()).unwrap();
        let first = trainer.run_epoch().unwrap();
        let second = trainer.run_epoch().unwrap();
        assert_eq!((first.env_steps, second.env_steps), (300, 600));
        // Updates start once 100 transitions are stored: one per step from step 100 on.
        assert_eq!((first.updates, second.updates), (201, 501));
        assert_eq!(trainer.replay().len(), 600);
        assert!(second.evaluation.mean_return >= 1.0 && second.evaluation.mean_length >= 1.0);
        assert!(second.q_loss.is_finite() && second.v_loss.is_finite() && second.policy_loss.is_finite());
        assert!(first.train_return.is_finite(), "random pendulum episodes end within an epoch");
        let checkpoint = trainer.learner().checkpoint().unwrap();
        let restored = Learner::from_checkpoint(config.agent.clone(), &checkpoint).unwrap();
        assert_eq!(restored.step(), 501);
    }

    #[test]
    fn her_conditions_on_a_goal_and_stores_k_relabelled_copies_of_each_finished_episode() {
        use sim::her::{GoalKind, GoalReward, HerConfig};
        let mut config = tiny(SamplingMode::Uniform);
        config.her = HerConfig { goal: GoalKind::Speed, reward: GoalReward::Sum, ..HerConfig::default() };
        let config = config.fitted().unwrap();
        assert_eq!(config.agent.obs_dim, 4 + 2, "the pendulum's velocities are the goal");
        let mut trainer = Trainer::new(config).unwrap();
        let record = trainer.run_epoch().unwrap();
        // 300 online steps, and 4 copies of each step of the episodes that ended in the epoch.
        let relabelled = trainer.replay().counters().inserted_total - 300;
        assert!(relabelled > 0 && relabelled.is_multiple_of(4), "{relabelled} relabelled transitions");
        assert!(record.evaluation.mean_length >= 1.0 && record.q_loss.is_finite());
        // Relabelled n-step returns are not implemented: refused.
        let mut bad = tiny(SamplingMode::Uniform);
        bad.her = HerConfig { goal: GoalKind::Speed, ..HerConfig::default() };
        bad.agent.n_step = 3;
        assert!(bad.fitted().unwrap_err().to_string().contains("n_step"));
    }

    /// The pendulum with a shorter time limit in its spec (the env itself does not truncate there),
    /// whose every `nan_every`-th step reports a NaN observation.
    struct Blowup {
        inner: Box<dyn Environment>,
        spec: sim::EnvSpec,
        nan_every: u64,
        steps: u64,
    }

    impl Environment for Blowup {
        fn spec(&self) -> &sim::EnvSpec {
            &self.spec
        }

        fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
            self.inner.reset(seed)
        }

        fn reset_to(&mut self, state: &sim::InitState) -> Result<Vec<f64>, sim::EnvError> {
            self.inner.reset_to(state)
        }

        fn step(&mut self, action: &[f64]) -> Result<sim::Step, sim::EnvError> {
            let mut step = self.inner.step(action)?;
            self.steps += 1;
            if self.steps.is_multiple_of(self.nan_every) {
                step.observation[0] = f64::NAN;
            }
            Ok(step)
        }
    }

    #[test]
    fn non_finite_steps_are_dropped_and_episodes_cut_at_the_limit() {
        let config = tiny(SamplingMode::Uniform);
        let inner = sim::make(sim::Task::InvertedPendulum, config.train.seed + 2).unwrap();
        let spec = sim::EnvSpec { max_episode_steps: 3, ..inner.spec().clone() };
        let env = Blowup { inner, spec, nan_every: 50, steps: 0 };
        let mut trainer = Trainer::on(config, Box::new(env)).unwrap();
        let record = trainer.run_epoch().unwrap();
        // Steps 50, 100, ..., 300 are dropped: they count as env steps but store nothing, so the
        // replay reaches 100 transitions at step 102 and updates run from there.
        assert_eq!((record.env_steps, record.updates), (300, 199));
        assert_eq!(trainer.replay().len(), 294);
        // The pendulum pays 1 per step up: no episode's return is above 3, and 100 more steps
        // (two of them dropped) end some 30 episodes.
        assert!(record.train_return <= 3.0, "{}", record.train_return);
        let returns: Vec<f64> = (0..100).filter_map(|_| trainer.env_step().unwrap()).collect();
        assert!(returns.len() >= 30 && returns.iter().all(|r| *r <= 3.0), "{returns:?}");
    }

    #[test]
    fn prioritized_runs_send_priorities_back() {
        let mut trainer = Trainer::new(tiny(SamplingMode::Prioritized)).unwrap();
        trainer.run_epoch().unwrap();
        let counters = trainer.replay().counters();
        assert_eq!(counters.updates_applied, 201 * 16);
        assert!(
            trainer.replay().priority_stats().unwrap().max > trainer.replay().priority_stats().unwrap().min
        );
    }

    #[test]
    fn a_second_level_trains_through_the_frozen_first_and_checkpoints_it() {
        let mut low = Trainer::new(tiny(SamplingMode::Uniform)).unwrap();
        low.run_epoch().unwrap();
        let dir = std::env::temp_dir().join(format!("sac-lsp-train-hierarchy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let low_path = dir.join("low.safetensors");
        std::fs::write(&low_path, low.checkpoint().unwrap().safetensors).unwrap();
        let low_hash =
            PolicyStack::from_weights(&[std::fs::read(&low_path).unwrap()]).unwrap().content_hash().unwrap();

        let mut config = tiny(SamplingMode::Uniform);
        config.hierarchy.levels = vec![low_path];
        config.agent = AgentConfig { obs_dim: 4, act_dim: 1, ..config.agent.level_above() };
        let mut high = Trainer::new(config.fitted().unwrap()).unwrap();
        let record = high.run_epoch().unwrap();
        assert_eq!(record.updates, 201);
        assert!(record.evaluation.mean_length >= 1.0 && record.q_loss.is_finite());
        let checkpoint = high.checkpoint().unwrap();
        let tensors =
            agent::ParamSnapshot { version: 0, safetensors: checkpoint.safetensors }.tensors().unwrap();
        let frozen = PolicyStack::from_embedded(&tensors).unwrap();
        assert_eq!(frozen.content_hash().unwrap(), low_hash, "the first level stayed frozen");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn min_replay_size_above_capacity_is_refused() {
        let mut config = tiny(SamplingMode::Uniform);
        config.train.min_replay_size = 5000;
        assert!(config.fitted().unwrap_err().to_string().contains("never start"));
    }

    /// The pendulum run file (the ant-v5 default's options: reparameterised gradient, twin Q,
    /// learned temperature, uniform prior) on the fused learner learns to balance: evaluation
    /// return 1000 (the maximum) within its 20 epochs. About two minutes in a release build:
    /// `cargo test --release -p sac-lsp-cli -- --ignored pendulum`.
    #[test]
    #[ignore = "a learning run of ~2 minutes; run with --ignored"]
    fn the_pendulum_run_file_learns_to_balance_on_the_fused_learner() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/configs/inverted-pendulum.toml");
        let config = RunConfig::load(Some(&path)).unwrap();
        let a = &config.agent;
        assert!(a.reparameterize && a.twin_q && a.learn_temperature, "the default options: {a:?}");
        let mut trainer = Trainer::new(config.clone()).unwrap();
        assert_eq!(trainer.learner().backend(), agent::Backend::Fused);
        let mut best = f64::MIN;
        for _ in 0..config.train.epochs {
            let record = trainer.run_epoch().unwrap();
            best = best.max(record.evaluation.mean_return);
            if record.evaluation.mean_return >= 1000.0 {
                return;
            }
        }
        panic!("no evaluation reached 1000 in {} epochs (best {best})", config.train.epochs);
    }
}
