//! Builders of test transitions shared by the unit tests.

use std::collections::HashMap;

use crate::batch::{InsertOutcome, SlotRef, TransitionBatch};
use crate::config::Dims;

/// A batch that owns its data; `batch()` borrows it as a [`TransitionBatch`].
#[derive(Debug, Clone, Default)]
pub(crate) struct OwnedBatch {
    pub dims: Option<Dims>,
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub rewards: Vec<f32>,
    pub next_observations: Vec<f32>,
    pub terminated: Vec<bool>,
    pub abs_td_errors: Option<Vec<f32>>,
}

/// The observation of step `step` of stream `stream`: distinct for every (stream, step), so that a
/// wrong row shows up.
pub(crate) fn obs(dims: Dims, stream: u32, step: u32) -> Vec<f32> {
    (0..dims.obs_dim).map(|j| stream as f32 * 10_000.0 + step as f32 + j as f32 / 128.0).collect()
}

impl OwnedBatch {
    /// `n` consecutive steps `first..first + n` of stream `stream` (one episode segment: the next
    /// observation of each step is the observation of the following one).
    pub fn run(dims: Dims, stream: u32, first: u32, n: usize) -> Self {
        let mut b = Self { dims: Some(dims), ..Self::default() };
        for step in first..first + n as u32 {
            b.push(
                obs(dims, stream, step),
                obs(dims, stream, step + 1),
                stream as f32 + step as f32 / 1024.0,
            );
        }
        b
    }

    /// Appends one transition with action = reward = `tag`.
    pub fn push(&mut self, observation: Vec<f32>, next_observation: Vec<f32>, tag: f32) {
        let dims = self.dims.expect("dims");
        self.observations.extend(observation);
        self.next_observations.extend(next_observation);
        self.actions.extend(std::iter::repeat_n(tag, dims.act_dim));
        self.rewards.push(tag);
        self.terminated.push(tag as i64 % 2 == 0);
    }

    pub fn with_td(mut self, abs_td_errors: Vec<f32>) -> Self {
        self.abs_td_errors = Some(abs_td_errors);
        self
    }

    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    pub fn batch(&self) -> TransitionBatch<'_> {
        TransitionBatch {
            observations: &self.observations,
            actions: &self.actions,
            rewards: &self.rewards,
            next_observations: &self.next_observations,
            terminated: &self.terminated,
            abs_td_errors: self.abs_td_errors.as_deref(),
        }
    }

    /// Transition `t` as (obs, action, reward, next obs, terminated).
    pub fn transition(&self, t: usize) -> Expected {
        let dims = self.dims.expect("dims");
        let (o, a) = (dims.obs_dim, dims.act_dim);
        Expected {
            observation: self.observations[t * o..(t + 1) * o].to_vec(),
            action: self.actions[t * a..(t + 1) * a].to_vec(),
            reward: self.rewards[t],
            next_observation: self.next_observations[t * o..(t + 1) * o].to_vec(),
            terminated: self.terminated[t],
        }
    }
}

/// What a slot should hold.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Expected {
    pub observation: Vec<f32>,
    pub action: Vec<f32>,
    pub reward: f32,
    pub next_observation: Vec<f32>,
    pub terminated: bool,
}

/// Everything ever inserted, by identity.
#[derive(Debug, Default)]
pub(crate) struct Ledger(pub HashMap<SlotRef, Expected>);

impl Ledger {
    pub fn record(&mut self, batch: &OwnedBatch, outcome: &InsertOutcome) {
        assert_eq!(outcome.inserted.len(), batch.len());
        for (t, id) in outcome.inserted.iter().enumerate() {
            assert!(self.0.insert(*id, batch.transition(t)).is_none(), "identity {id:?} reused");
        }
    }
}
