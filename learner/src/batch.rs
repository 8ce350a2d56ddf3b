//! A sampled batch off the wire, as the agent's [`Batch`] plus what the priority update needs.

use agent::Batch;
use proto::SampledBatch;

/// One batch ready for an update.
#[derive(Debug, Clone, PartialEq)]
pub struct Sampled {
    /// The transitions, with IS weights when the replay is prioritized.
    pub batch: Batch,
    /// Ring-buffer slots, for the priority update.
    pub slots: Vec<u64>,
    /// Slot generations, for the priority update.
    pub generations: Vec<u64>,
}

impl Sampled {
    /// Moves the columns of `sampled` into an agent batch (no copies of the bulk arrays).
    pub fn from_wire(sampled: SampledBatch, prioritized: bool) -> Self {
        let t = sampled.transitions;
        let batch = Batch {
            size: t.rewards.len(),
            observations: t.observations,
            actions: t.actions,
            rewards: t.rewards,
            next_observations: t.next_observations,
            terminated: t.terminated.iter().map(|&d| if d { 1.0 } else { 0.0 }).collect(),
            is_weights: prioritized.then_some(sampled.is_weights),
        };
        Self { batch, slots: sampled.slots, generations: sampled.generations }
    }
}
