//! [`Hindsight`]: the reward a goal-conditioned step stores, and the episode's relabelled copies.

use rand::{Rng, SeedableRng, rngs::StdRng};

use super::config::distance;
use super::{GoalStatus, HerConfig};

/// A transition on observation ++ goal, ready to store.
#[derive(Clone, Debug, PartialEq)]
pub struct Relabelled {
    /// s ++ g.
    pub observation: Vec<f32>,
    /// a.
    pub action: Vec<f32>,
    /// The goal reward of (r_env, distance to g).
    pub reward: f32,
    /// s' ++ g.
    pub next_observation: Vec<f32>,
    /// The episode ended inside the task at s'.
    pub terminated: bool,
}

#[derive(Debug)]
struct Stored {
    observation: Vec<f32>,
    action: Vec<f32>,
    env_reward: f64,
    next_observation: Vec<f32>,
    terminated: bool,
    achieved: Vec<f64>,
}

/// Keeps an episode's steps and, when it ends, relabels each with `k` goals achieved at the same
/// or a later step (the "future" strategy, f ~ U{t..T-1} inclusive as `sac-hind/sac/misc/sampler.py`
/// draws it; seed-impl §2.4). Relabelled rewards are recomputed from each step's own environment
/// reward (the code started from the already-shaped reward, compounding the bonus; not kept).
#[derive(Debug)]
pub struct Hindsight {
    cfg: HerConfig,
    goal_dim: usize,
    rng: StdRng,
    episode: Vec<Stored>,
}

impl Hindsight {
    /// Relabelling for goals of `goal_dim` values; draws start from `seed`.
    pub fn new(cfg: &HerConfig, goal_dim: usize, seed: u64) -> Self {
        Self { cfg: cfg.clone(), goal_dim, rng: StdRng::seed_from_u64(seed), episode: Vec::new() }
    }

    /// The reward stored for a step with the episode's own goal.
    pub fn reward(&self, env_reward: f64, status: &GoalStatus) -> f64 {
        self.cfg.reward(env_reward, status.distance)
    }

    /// Keeps one step of the current episode (observations with the goal appended).
    pub fn record(
        &mut self,
        observation: &[f32],
        action: &[f32],
        env_reward: f64,
        next_observation: &[f32],
        terminated: bool,
        status: &GoalStatus,
    ) {
        self.episode.push(Stored {
            observation: observation.to_vec(),
            action: action.to_vec(),
            env_reward,
            next_observation: next_observation.to_vec(),
            terminated,
            achieved: status.achieved.clone(),
        });
    }

    /// Restarts the relabelling stream from `seed` (as [`Hindsight::new`] seeds it).
    pub fn reseed(&mut self, seed: u64) {
        self.rng = StdRng::seed_from_u64(seed);
    }

    /// Steps kept for the current episode.
    pub fn len(&self) -> usize {
        self.episode.len()
    }

    /// Whether no step is kept.
    pub fn is_empty(&self) -> bool {
        self.episode.is_empty()
    }

    /// Forgets the current episode without relabelling it (a non-finite step reset it).
    pub fn discard_episode(&mut self) {
        self.episode.clear();
    }

    /// Ends the episode: emits k relabelled copies of each kept step and forgets the episode.
    /// Returns how many were emitted.
    pub fn finish_episode(&mut self, mut emit: impl FnMut(Relabelled)) -> usize {
        let episode = std::mem::take(&mut self.episode);
        let steps = episode.len();
        for (t, step) in episode.iter().enumerate() {
            for _ in 0..self.cfg.k {
                let future = &episode[self.rng.random_range(t..steps)];
                let goal = &future.achieved;
                emit(Relabelled {
                    observation: self.with_goal(&step.observation, goal),
                    action: step.action.clone(),
                    reward: self.cfg.reward(step.env_reward, distance(&step.achieved, goal)) as f32,
                    next_observation: self.with_goal(&step.next_observation, goal),
                    terminated: step.terminated,
                });
            }
        }
        steps * self.cfg.k
    }

    fn with_goal(&self, observation: &[f32], goal: &[f64]) -> Vec<f32> {
        let base = observation.len() - self.goal_dim;
        observation[..base].iter().copied().chain(goal.iter().map(|g| *g as f32)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::her::{GoalKind, GoalReward};

    fn status(achieved: &[f64], goal: &[f64]) -> GoalStatus {
        let d = distance(achieved, goal);
        GoalStatus { achieved: achieved.to_vec(), distance: d, reached: d < 3.0 }
    }

    #[test]
    fn future_goals_are_achieved_later_in_the_episode_and_rewards_are_recomputed() {
        let cfg = HerConfig { goal: GoalKind::Speed, reward: GoalReward::Binary, ..HerConfig::default() };
        let mut her = Hindsight::new(&cfg, 1, 7);
        let goal = [100.0];
        // Observation [t] ++ goal; achieved goal at step t is 10 t.
        for t in 0..5 {
            let achieved = [10.0 * t as f64];
            let s = status(&achieved, &goal);
            assert_eq!(her.reward(1.0, &s), -1.0, "the episode's goal is never reached");
            her.record(&[t as f32, 100.0], &[0.5], 1.0, &[t as f32 + 1.0, 100.0], t == 4, &s);
        }
        let mut out = Vec::new();
        assert_eq!(her.finish_episode(|r| out.push(r)), 20);
        assert!(her.is_empty());
        for r in &out {
            let t = r.observation[0] as usize;
            let g = r.observation[1];
            assert_eq!(r.next_observation[1], g, "one goal per relabelled transition");
            assert_eq!(g % 10.0, 0.0);
            assert!((g / 10.0) as usize >= t, "goal from step {} for step {t}", g / 10.0);
            // Reached exactly when the goal is this step's own achievement.
            assert_eq!(r.reward, if g == 10.0 * t as f32 { 0.0 } else { -1.0 });
            assert_eq!(r.terminated, t == 4);
        }
        // The last step can only be relabelled with its own achievement.
        assert!(out.iter().filter(|r| r.observation[0] == 4.0).all(|r| r.reward == 0.0));
        // Earlier steps get later goals too, not only their own.
        assert!(out.iter().any(|r| r.reward == -1.0));
    }
}
