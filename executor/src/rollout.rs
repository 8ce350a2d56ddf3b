//! The rollout, sans-IO: one environment, the acting policy and critics, and the transitions not
//! yet published. [`Rollout::step`] is one env step with the stochastic policy; [`Rollout::flush`]
//! turns the pending transitions into an [`ExperienceBatch`] with each transition's initial
//! priority |δ| from the local critics (Ape-X; the same formula the learner's updates use). With
//! `[agent] n_step` > 1 the stored transitions are n-step ones ([`NStepReturns`]).
//!
//! The single-machine trainer (`sac-lsp train`) steps the same rollout and takes the pending
//! transitions ([`Rollout::take_pending`]) into its own replay, so both store the same transitions.

use agent::{Actor, Batch, Mode, NStepReturns, ParamSnapshot, StepEnd};
use proto::{EpisodeReport, ExperienceBatch, Transition, Transitions};
use sim::Environment;
use sim::her::Hindsight;

/// What one step produced besides the stored transition.
#[derive(Debug, Clone, PartialEq)]
pub struct StepOutcome {
    /// The episode that this step finished, if it did.
    pub episode: Option<EpisodeReport>,
    /// The step produced a non-finite observation or reward: it was dropped and the episode reset.
    pub dropped_non_finite: bool,
    /// Steps of this episode that no n-step transition will start from: the last n − 1 before a
    /// time-limit truncation, or the open ones when a non-finite step reset the episode. Always 0
    /// with n = 1 (except the non-finite step itself, counted by `dropped_non_finite`).
    pub dropped_n_step_tail: usize,
}

/// An executor's environment and policy.
pub struct Rollout {
    executor_id: u32,
    env: Box<dyn Environment>,
    actor: Actor,
    observation: Vec<f32>,
    pending: Transitions,
    n_step: NStepReturns,
    /// With HER (`[her]`): the stored goal reward and each episode's relabelled copies.
    hindsight: Option<Hindsight>,
    episode: u64,
    episode_return: f64,
    episode_length: u32,
    env_steps: u64,
    /// The batches' stream (see [`ExperienceBatch::stream`]) and the next batch's number in it.
    stream: u64,
    seq: u64,
    /// Episodes are cut (as truncated) at this length: the task's limit or a shorter one.
    episode_limit: u32,
    /// The next step ends the episode as a truncation (deterministic mode's cut).
    truncate_next: bool,
}

impl std::fmt::Debug for Rollout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rollout")
            .field("executor_id", &self.executor_id)
            .field("env_steps", &self.env_steps)
            .finish()
    }
}

fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|v| *v as f32).collect()
}

impl Rollout {
    /// A rollout of `env` with `actor`; the first episode starts now, from `reset_seed`.
    pub fn new(executor_id: u32, mut env: Box<dyn Environment>, actor: Actor, reset_seed: u64) -> Self {
        let spec = env.spec().clone();
        let observation = to_f32(&env.reset(Some(reset_seed)));
        let pending = Transitions::with_capacity(spec.obs_dim as u32, spec.act_dim as u32, 64);
        let n_step = NStepReturns::for_config(actor.config());
        Self {
            executor_id,
            env,
            actor,
            observation,
            pending,
            n_step,
            hindsight: None,
            episode: 0,
            episode_return: 0.0,
            episode_length: 0,
            env_steps: 0,
            stream: 0,
            seq: 0,
            episode_limit: spec.max_episode_steps,
            truncate_next: false,
        }
    }

    /// Starts counting env steps at `env_steps` (an executor resumed at a deterministic cut).
    pub fn with_env_steps(mut self, env_steps: u64) -> Self {
        self.env_steps = env_steps;
        self
    }

    /// Ends the episode at the next step, as a truncation (its last state's value still counts).
    pub fn truncate_next_step(&mut self) {
        self.truncate_next = true;
    }

    /// Restarts the episode and every random stream from `seed`, as a new rollout seeded `seed`
    /// starts them: the environment's reset noise (and goals), the policy's noise and the
    /// relabelling. With nothing pending and no episode under way (right after a truncation), the
    /// rollout is then what a new one of the same step count is: deterministic mode's cut.
    pub fn restart_streams(&mut self, seed: u64) {
        self.actor.reseed(seed.wrapping_add(1));
        if let Some(h) = &mut self.hindsight {
            h.reseed(seed.wrapping_add(2));
        }
        self.observation = to_f32(&self.env.reset(Some(seed)));
        (self.episode_return, self.episode_length) = (0.0, 0);
    }

    /// Cuts episodes at `limit` steps if that is shorter than the task's own limit (short episodes
    /// for tests and quick runs; a cut is a truncation, so the value of the next state still counts).
    pub fn with_episode_limit(mut self, limit: Option<u32>) -> Self {
        if let Some(limit) = limit {
            self.episode_limit = self.episode_limit.min(limit.max(1));
        }
        self
    }

    /// Numbers batches in `stream` (nonzero for a spooling executor: the replay server then stores
    /// each batch once however often it is sent).
    pub fn with_stream(mut self, stream: u64) -> Self {
        self.stream = stream;
        self
    }

    /// Stores goal rewards and relabelled copies of each episode's steps (HER); `env` must be the
    /// matching [`sim::her::GoalEnv`], whose steps report their goal.
    pub fn with_hindsight(mut self, hindsight: Option<Hindsight>) -> Self {
        self.hindsight = hindsight;
        self
    }

    /// Cumulative env steps taken (dropped non-finite steps included: they cost a step too).
    pub fn env_steps(&self) -> u64 {
        self.env_steps
    }

    /// Transitions waiting to be published.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Takes every pending transition, oldest first, without initial priorities: for a caller that
    /// stores them itself (the single-machine trainer's replay gives new ones the maximum).
    pub fn take_pending(&mut self) -> Transitions {
        self.pending.split_front(usize::MAX)
    }

    /// The acting policy (the single-machine trainer evaluates with it between steps).
    pub fn actor_mut(&mut self) -> &mut Actor {
        &mut self.actor
    }

    /// The loaded weights' version, `None` before the first load.
    pub fn weights_version(&self) -> Option<u64> {
        self.actor.version()
    }

    /// Loads new weights into the policy and critics.
    pub fn load(&mut self, snapshot: &ParamSnapshot) -> agent::Result<()> {
        self.actor.load(snapshot)
    }

    /// One env step with the stochastic policy. The transition (the n-step ones it completes) joins
    /// the pending batch unless its numbers are not finite (then the episode is reset and the step
    /// reported as dropped).
    pub fn step(&mut self) -> anyhow::Result<StepOutcome> {
        let act = self.actor.act(&self.observation, Mode::Explore)?;
        let action = self.env.spec().action_from_unit(&act.env_action);
        let step = self.env.step(&action)?;
        self.env_steps += 1;
        let next_observation = to_f32(&step.observation);
        // With HER the stored reward is the goal reward; the episode's return stays the task's own.
        let reward = match (&self.hindsight, &step.goal) {
            (Some(h), Some(status)) => h.reward(step.reward, status) as f32,
            _ => step.reward as f32,
        };
        let finite = reward.is_finite() && next_observation.iter().all(|v| v.is_finite());
        if !finite {
            // MuJoCo blew up; a NaN in one transition would make the replay server reject the batch.
            let dropped_n_step_tail = self.n_step.clear();
            if let Some(h) = &mut self.hindsight {
                h.discard_episode();
            }
            self.truncate_next = false;
            self.reset_episode();
            return Ok(StepOutcome { episode: None, dropped_non_finite: true, dropped_n_step_tail });
        }
        self.episode_return += step.reward;
        self.episode_length += 1;
        let truncated = step.truncated
            || self.episode_length >= self.episode_limit
            || std::mem::take(&mut self.truncate_next);
        // Only a true termination stops bootstrapping; the time limit does not.
        let end = StepEnd { terminated: step.terminated, truncated };
        let pending = &mut self.pending;
        let dropped_n_step_tail =
            self.n_step.push(&self.observation, &act.action, reward, &next_observation, end, |t| {
                pending.push(Transition {
                    observation: t.observation,
                    action: t.action,
                    reward: t.reward,
                    next_observation: t.next_observation,
                    terminated: t.terminated,
                })
            })?;
        if let (Some(h), Some(status)) = (&mut self.hindsight, &step.goal) {
            h.record(&self.observation, &act.action, step.reward, &next_observation, step.terminated, status);
        }
        if step.terminated || truncated {
            if let Some(h) = &mut self.hindsight {
                h.finish_episode(|t| {
                    pending
                        .push(Transition {
                            observation: &t.observation,
                            action: &t.action,
                            reward: t.reward,
                            next_observation: &t.next_observation,
                            terminated: t.terminated,
                        })
                        .unwrap_or_else(|e| unreachable!("relabelled rows have the stored widths: {e}"))
                });
            }
            let report = EpisodeReport {
                executor_id: self.executor_id,
                episode: self.episode,
                episode_return: self.episode_return,
                length: self.episode_length,
                terminated: step.terminated,
                env_steps: self.env_steps,
                weights_version: self.actor.version().unwrap_or(0),
            };
            self.reset_episode();
            Ok(StepOutcome { episode: Some(report), dropped_non_finite: false, dropped_n_step_tail })
        } else {
            self.observation = next_observation;
            Ok(StepOutcome { episode: None, dropped_non_finite: false, dropped_n_step_tail })
        }
    }

    fn reset_episode(&mut self) {
        self.episode += 1;
        self.episode_return = 0.0;
        self.episode_length = 0;
        self.observation = to_f32(&self.env.reset(None));
    }

    /// At most `limit` of the pending transitions, oldest first, as one batch with their initial
    /// priorities, or `None` if there are none. (An episode's end can add k times its length at once
    /// with HER; the caller flushes until `None`.)
    pub fn flush(&mut self, limit: usize) -> anyhow::Result<Option<ExperienceBatch>> {
        if self.pending.is_empty() {
            return Ok(None);
        }
        let transitions = self.pending.split_front(limit.max(1));
        let batch = Batch {
            size: transitions.len(),
            observations: transitions.observations.clone(),
            actions: transitions.actions.clone(),
            rewards: transitions.rewards.clone(),
            next_observations: transitions.next_observations.clone(),
            terminated: transitions.terminated.iter().map(|&d| if d { 1.0 } else { 0.0 }).collect(),
            is_weights: None,
        };
        let td_errors = self.actor.td_errors(&batch)?.iter().map(|d| d.abs()).collect();
        Ok(Some(self.next_batch(transitions, td_errors)))
    }

    /// A batch without transitions that says "every step up to now is sent" (deterministic mode's
    /// block end, when the block's last steps made no transition to send).
    pub fn marker(&mut self) -> ExperienceBatch {
        let (obs_dim, act_dim) = (self.pending.obs_dim, self.pending.act_dim);
        self.next_batch(Transitions::with_capacity(obs_dim, act_dim, 0), Vec::new())
    }

    /// The stream's next batch: this executor's ids, the next sequence number, the env steps so far.
    fn next_batch(&mut self, transitions: Transitions, td_errors: Vec<f32>) -> ExperienceBatch {
        let batch = ExperienceBatch {
            executor_id: self.executor_id,
            stream: self.stream,
            seq: self.seq,
            weights_version: self.actor.version().unwrap_or(0),
            env_steps: self.env_steps,
            transitions,
            td_errors,
        };
        self.seq += 1;
        batch
    }
}

#[cfg(test)]
mod tests {
    use agent::{AgentConfig, Learner};
    use proto::Message;
    use sim::Task;

    use super::*;

    fn rollout() -> (Rollout, Learner) {
        rollout_with(1)
    }

    fn rollout_with(n_step: usize) -> (Rollout, Learner) {
        let env = sim::make(Task::InvertedPendulum, 3).unwrap();
        let cfg = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            n_step,
            ..AgentConfig::for_task(env.spec().obs_dim, env.spec().act_dim)
        };
        let learner = Learner::new(cfg.clone(), 1).unwrap();
        let mut actor = Actor::new(cfg, 2).unwrap();
        actor.load(&learner.snapshot().unwrap()).unwrap();
        (Rollout::new(7, env, actor, 3), learner)
    }

    #[test]
    fn steps_fill_batches_with_the_learners_td_errors() {
        let (mut r, learner) = rollout();
        let mut episodes = Vec::new();
        for _ in 0..200 {
            if let Some(ep) = r.step().unwrap().episode {
                episodes.push(ep);
            }
        }
        assert_eq!(r.env_steps(), 200);
        let batch = r.flush(usize::MAX).unwrap().unwrap();
        assert_eq!(batch.len(), 200);
        assert_eq!(batch.validate(), Ok(()));
        assert_eq!((batch.executor_id, batch.seq, batch.env_steps), (7, 0, 200));
        // Random pendulum episodes are short: several ended, each reported once with its length.
        assert!(episodes.len() >= 2);
        let through_last_fall = batch.transitions.terminated.iter().rposition(|&d| d).unwrap() + 1;
        assert_eq!(episodes.iter().map(|e| e.length as usize).sum::<usize>(), through_last_fall);
        // The initial priorities are |δ| with the same weights as the learner's own TD errors.
        let b = Batch {
            size: batch.len(),
            observations: batch.transitions.observations.clone(),
            actions: batch.transitions.actions.clone(),
            rewards: batch.transitions.rewards.clone(),
            next_observations: batch.transitions.next_observations.clone(),
            terminated: batch.transitions.terminated.iter().map(|&d| f32::from(u8::from(d))).collect(),
            is_weights: None,
        };
        let mut learner = learner;
        let own: Vec<f32> = learner.update(&b).unwrap().td_errors.iter().map(|d| d.abs()).collect();
        for (a, b) in batch.td_errors.iter().zip(&own) {
            assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "{a} vs {b}");
        }
        assert!(r.flush(usize::MAX).unwrap().is_none(), "nothing pending after a flush");
        r.step().unwrap();
        assert_eq!(r.flush(usize::MAX).unwrap().unwrap().seq, 1);
    }

    #[test]
    fn n_step_transitions_carry_discounted_sums_and_every_step_is_accounted_for() {
        let (r, _) = rollout_with(3);
        let mut r = r.with_episode_limit(Some(20));
        let (mut dropped, mut truncated) = (0, 0);
        for _ in 0..300 {
            let outcome = r.step().unwrap();
            assert!(!outcome.dropped_non_finite);
            dropped += outcome.dropped_n_step_tail;
            truncated += usize::from(outcome.episode.is_some_and(|e| !e.terminated));
        }
        let batch = r.flush(usize::MAX).unwrap().unwrap();
        assert_eq!(batch.validate(), Ok(()));
        // Each truncated episode leaves its last two steps out; the open ones are still pending.
        assert_eq!(dropped, 2 * truncated);
        assert_eq!(batch.len() + dropped + r.n_step.open(), 300);
        // The pendulum pays 1 per step alive: a full 3-step transition carries 1 + γ + γ².
        let full = 1.0 + 0.99 + 0.99f32 * 0.99;
        let (t, rewards) = (&batch.transitions.terminated, &batch.transitions.rewards);
        assert!(t.iter().zip(rewards).filter(|(d, _)| !**d).all(|(_, r)| (r - full).abs() < 1e-5));
        assert!(t.iter().zip(rewards).filter(|(d, _)| **d).all(|(_, r)| *r <= full + 1e-5));
    }
}

#[cfg(test)]
mod her_tests {
    use agent::{AgentConfig, Learner};
    use proto::Message;
    use sim::Task;
    use sim::her::{GoalKind, GoalReward, HerConfig};

    use super::*;

    #[test]
    fn episodes_end_with_k_relabelled_copies_published_in_bounded_batches() {
        let her = HerConfig { goal: GoalKind::Speed, reward: GoalReward::Binary, ..HerConfig::default() };
        let task = Task::InvertedPendulum;
        let env = sim::her::make(&her, task, 3).unwrap();
        let cfg = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            ..AgentConfig::for_task(env.spec().obs_dim, env.spec().act_dim)
        };
        assert_eq!(cfg.obs_dim, 6);
        let mut actor = Actor::new(cfg.clone(), 2).unwrap();
        actor.load(&Learner::new(cfg, 1).unwrap().snapshot().unwrap()).unwrap();
        let mut r = Rollout::new(7, env, actor, 3).with_hindsight(sim::her::hindsight(&her, task, 4));
        let mut finished = 0;
        for _ in 0..200 {
            if let Some(ep) = r.step().unwrap().episode {
                finished += ep.length as usize;
                // The reported return is the task's own: the pendulum pays 1 per step it stays up.
                assert_eq!(ep.episode_return, f64::from(ep.length - u32::from(ep.terminated)));
            }
        }
        assert!(finished > 0);
        assert_eq!(r.pending(), 200 + 4 * finished);
        let mut batches = Vec::new();
        while let Some(b) = r.flush(64).unwrap() {
            batches.push(b);
        }
        assert!(batches.iter().all(|b| b.len() <= 64 && b.validate() == Ok(())));
        assert_eq!(batches.iter().map(|b| b.len()).sum::<usize>(), 200 + 4 * finished);
        // Binary goal rewards only: 0 (reached) or -1.
        let rewards: Vec<f32> = batches.iter().flat_map(|b| b.transitions.rewards.clone()).collect();
        assert!(rewards.iter().all(|r| *r == 0.0 || *r == -1.0));
        assert!(rewards.contains(&0.0), "relabelled goals are reached");
    }
}
