//! What goes in and out of the buffer: borrowed transition batches, the reusable sampled batch,
//! slot identities and operation outcomes.

/// A batch of n transitions to insert, as borrowed flat row-major slices (zero copy from a decoded
/// message). n is `rewards.len()`; every other slice must match it.
#[derive(Debug, Clone, Copy)]
pub struct TransitionBatch<'a> {
    /// n × obs_dim observations s_t.
    pub observations: &'a [f32],
    /// n × act_dim actions a_t.
    pub actions: &'a [f32],
    /// n rewards r_t (unscaled environment rewards).
    pub rewards: &'a [f32],
    /// n × obs_dim next observations s_{t+1}.
    pub next_observations: &'a [f32],
    /// n termination flags (true only for a real termination, not a time-limit cut, so the learner
    /// bootstraps through truncations).
    pub terminated: &'a [bool],
    /// n TD-error magnitudes |δ| ≥ 0 from the executor, giving p = (|δ| + ε)^α; `None` gives every
    /// new transition the current maximum priority (1.0 when the buffer is empty), as the paper.
    pub abs_td_errors: Option<&'a [f32]>,
}

/// Identity of one insertion: ring index plus the slot's generation (how many times the slot was
/// written before). A slot that is overwritten gets a new generation, so a stale reference is
/// recognised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SlotRef {
    /// Ring index in [0, capacity).
    pub slot: u64,
    /// Generation of the slot when it was written.
    pub generation: u64,
}

/// What `insert_batch` did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InsertOutcome {
    /// Identity of each inserted transition, in batch order. When one batch is larger than the
    /// buffer, its first transitions are already gone again.
    pub inserted: Vec<SlotRef>,
    /// Transitions overwritten because the ring was full (the oldest, as in any ring).
    pub overwritten: u64,
    /// Transitions evicted before the ring was full because observation rows ran out.
    pub evicted_early: u64,
}

/// What `update_priorities` did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UpdateOutcome {
    /// Updates written to live transitions.
    pub applied: u64,
    /// Updates ignored because their slot was overwritten (or evicted) since it was sampled.
    pub stale: u64,
}

/// A sampled batch, reused across calls to avoid allocation: `sample` overwrites every field.
/// Flat row-major like [`TransitionBatch`]; entry i of each field belongs to the same transition.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SampledBatch {
    /// Ring index of each sampled transition (send back with the new TD errors).
    pub slots: Vec<u64>,
    /// Generation of each sampled slot (send back with the new TD errors).
    pub generations: Vec<u64>,
    /// Importance-sampling weights (N·P(i))^−β / max over the batch, in (0, 1]; all 1 in uniform
    /// mode.
    pub is_weights: Vec<f32>,
    /// batch × obs_dim observations.
    pub observations: Vec<f32>,
    /// batch × act_dim actions.
    pub actions: Vec<f32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// batch × obs_dim next observations.
    pub next_observations: Vec<f32>,
    /// Termination flags.
    pub terminated: Vec<bool>,
    /// The β the weights were computed with.
    pub beta: f64,
}

impl SampledBatch {
    /// An empty batch; the first `sample` sizes it.
    pub fn new() -> Self {
        Self::default()
    }

    /// Transitions in the batch.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// True before the first `sample`.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    pub(crate) fn clear(&mut self) {
        self.slots.clear();
        self.generations.clear();
        self.is_weights.clear();
        self.observations.clear();
        self.actions.clear();
        self.rewards.clear();
        self.next_observations.clear();
        self.terminated.clear();
    }
}

/// A borrowed view of one stored transition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransitionView<'a> {
    /// Its identity.
    pub id: SlotRef,
    /// Observation s_t.
    pub observation: &'a [f32],
    /// Action a_t.
    pub action: &'a [f32],
    /// Reward r_t.
    pub reward: f32,
    /// Next observation s_{t+1}.
    pub next_observation: &'a [f32],
    /// Termination flag.
    pub terminated: bool,
    /// Stored priority p = (|δ| + ε)^α.
    pub priority: f64,
}
