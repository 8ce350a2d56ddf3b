//! [`NStepReturns`]: n-step transitions from a stream of env steps, sans-IO (Ape-X's n-step
//! returns; an option beyond the paper, `AgentConfig::n_step`).
//!
//! The transition that starts at step t carries R = r_t + γ r_{t+1} + … + γ^{n-1} r_{t+n-1} and the
//! observation n steps later, so the learner's target R + γ^n (1 − d) V̄(s_{t+n}) (the discount is
//! [`AgentConfig::bootstrap_discount`]) propagates reward n
//! steps per update instead of one. The entropy terms of the n − 1 intermediate steps are left out,
//! as in Ape-X and D4PG's uncorrected n-step returns.
//!
//! Episode ends: a termination completes every open transition (its bootstrap is cut, so a horizon
//! shorter than n is exact). A time-limit truncation cannot: the last n − 1 steps have horizons
//! below n and the learner bootstraps with γ^n, so they are dropped and counted (2 of 1,000 per Ant
//! episode at n = 3). With n = 1 every step is emitted at once, unchanged.

use std::collections::VecDeque;

use crate::config::AgentConfig;

/// One completed n-step transition, borrowed from the accumulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NStepTransition<'a> {
    /// Observation at the first step.
    pub observation: &'a [f32],
    /// Action taken at the first step.
    pub action: &'a [f32],
    /// Discounted sum of the rewards of up to n steps.
    pub reward: f32,
    /// Observation after the last of those steps.
    pub next_observation: &'a [f32],
    /// The episode terminated within the n steps (the bootstrap is cut).
    pub terminated: bool,
}

/// How an env step ended, for [`NStepReturns::push`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepEnd {
    /// The environment terminated.
    pub terminated: bool,
    /// The episode was cut by a time limit (without terminating).
    pub truncated: bool,
}

/// A transition whose n steps are not all taken yet.
#[derive(Debug, Clone, Default)]
struct Open {
    observation: Vec<f32>,
    action: Vec<f32>,
    reward: f32,
    steps: u32,
}

/// Accumulates one episode's env steps into n-step transitions.
#[derive(Debug, Clone)]
pub struct NStepReturns {
    n: u32,
    discount: f32,
    open: VecDeque<Open>,
    /// Emitted entries, kept for their buffers.
    spare: Vec<Open>,
}

impl NStepReturns {
    /// An accumulator for `n`-step returns (n ≥ 1) with per-step discount γ.
    pub fn new(n: usize, discount: f32) -> Self {
        let n = u32::try_from(n.max(1)).unwrap_or(u32::MAX);
        Self { n, discount, open: VecDeque::with_capacity(n as usize), spare: Vec::new() }
    }

    /// The accumulator whose transitions `cfg`'s Q target expects: `cfg.n_step` steps at
    /// `cfg.discount` (the target then bootstraps with [`AgentConfig::bootstrap_discount`]).
    pub fn for_config(cfg: &AgentConfig) -> Self {
        Self::new(cfg.n_step, cfg.discount)
    }

    /// Transitions begun but not yet complete.
    pub fn open(&self) -> usize {
        self.open.len()
    }

    /// Adds one env step (observation, action, reward, next observation, how it ended). Calls `emit`
    /// for each transition it completes, oldest first, and returns how many open transitions a
    /// truncation dropped (0 unless `end.truncated` and n > 1). The first error of `emit` is
    /// returned at once; the transitions not yet emitted stay open.
    pub fn push<E>(
        &mut self,
        observation: &[f32],
        action: &[f32],
        reward: f32,
        next_observation: &[f32],
        end: StepEnd,
        mut emit: impl FnMut(NStepTransition<'_>) -> Result<(), E>,
    ) -> Result<usize, E> {
        let mut entry = self.spare.pop().unwrap_or_default();
        entry.observation.clear();
        entry.observation.extend_from_slice(observation);
        entry.action.clear();
        entry.action.extend_from_slice(action);
        entry.reward = 0.0;
        entry.steps = 0;
        self.open.push_back(entry);
        for open in &mut self.open {
            open.reward += self.discount.powi(open.steps as i32) * reward;
            open.steps += 1;
        }
        let complete = if end.terminated {
            self.open.len()
        } else {
            self.open.iter().take_while(|o| o.steps >= self.n).count()
        };
        for _ in 0..complete {
            let done = self.open.pop_front().expect("counted above");
            let emitted = emit(NStepTransition {
                observation: &done.observation,
                action: &done.action,
                reward: done.reward,
                next_observation,
                terminated: end.terminated,
            });
            self.spare.push(done);
            emitted?;
        }
        Ok(if end.truncated && !end.terminated { self.clear() } else { 0 })
    }

    /// Abandons the open transitions (a truncation, or an episode reset after a bad step) and
    /// returns how many there were.
    pub fn clear(&mut self) -> usize {
        let dropped = self.open.len();
        self.spare.extend(self.open.drain(..));
        dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pushes scalar steps (observation = [t], next = [t + 1], reward r_t) and collects the output.
    fn run(n: usize, rewards: &[f32], last: StepEnd) -> (Vec<(f32, f32, f32, bool)>, usize) {
        let mut acc = NStepReturns::new(n, 0.5);
        let mut out = Vec::new();
        let mut dropped = 0;
        for (t, &r) in rewards.iter().enumerate() {
            let end = if t + 1 == rewards.len() { last } else { StepEnd::default() };
            let (obs, next) = ([t as f32], [t as f32 + 1.0]);
            let emitted = acc.push(&obs, &[0.0], r, &next, end, |tr| {
                out.push((tr.observation[0], tr.reward, tr.next_observation[0], tr.terminated));
                Ok::<_, ()>(())
            });
            dropped += emitted.unwrap();
        }
        (out, dropped)
    }

    #[test]
    fn one_step_emits_every_step_unchanged() {
        let (out, dropped) = run(1, &[1.0, 2.0, 3.0], StepEnd { terminated: false, truncated: true });
        assert_eq!(out, vec![(0.0, 1.0, 1.0, false), (1.0, 2.0, 2.0, false), (2.0, 3.0, 3.0, false)]);
        assert_eq!(dropped, 0);
    }

    #[test]
    fn three_step_sums_discounted_rewards_and_bootstraps_three_ahead() {
        let (out, _) = run(3, &[1.0, 2.0, 4.0, 8.0], StepEnd::default());
        // R_0 = 1 + 0.5·2 + 0.25·4 = 3, next s_3; R_1 = 2 + 0.5·4 + 0.25·8 = 6, next s_4.
        assert_eq!(out, vec![(0.0, 3.0, 3.0, false), (1.0, 6.0, 4.0, false)]);
    }

    #[test]
    fn termination_completes_every_open_transition_with_a_cut_bootstrap() {
        let (out, dropped) = run(3, &[1.0, 2.0, 4.0, 8.0], StepEnd { terminated: true, truncated: false });
        assert_eq!(dropped, 0);
        assert_eq!(
            out,
            vec![(0.0, 3.0, 3.0, false), (1.0, 6.0, 4.0, true), (2.0, 8.0, 4.0, true), (3.0, 8.0, 4.0, true)]
        );
    }

    #[test]
    fn truncation_drops_the_short_tail_and_counts_it() {
        let (out, dropped) = run(3, &[1.0, 2.0, 4.0, 8.0], StepEnd { terminated: false, truncated: true });
        assert_eq!(out.len(), 2);
        assert_eq!(dropped, 2);
    }

    #[test]
    fn an_episode_after_a_clear_starts_fresh() {
        let mut acc = NStepReturns::new(2, 1.0);
        acc.push(&[0.0], &[0.0], 5.0, &[1.0], StepEnd::default(), |_| Err("incomplete")).unwrap();
        assert_eq!(acc.clear(), 1);
        let mut out = Vec::new();
        for t in 0..2 {
            acc.push(&[t as f32], &[0.0], 1.0, &[t as f32 + 1.0], StepEnd::default(), |tr| {
                out.push(tr.reward);
                Ok::<_, ()>(())
            })
            .unwrap();
        }
        assert_eq!(out, vec![2.0]);
        assert_eq!(acc.open(), 1);
    }
}
