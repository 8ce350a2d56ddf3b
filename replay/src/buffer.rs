//! `ReplayBuffer`: insert, sample, update priorities. Storage and the sum tree do the work; this
//! file validates inputs (all of them, before anything changes) and keeps the two in step: a live
//! transition's leaf holds its priority, every other leaf holds 0.

use rand::Rng;

use crate::batch::{InsertOutcome, SampledBatch, SlotRef, TransitionBatch, TransitionView, UpdateOutcome};
use crate::config::{Dims, ReplayConfig, SamplingMode};
use crate::error::{ReplayError, Result};
use crate::schedule::BetaSchedule;
use crate::stats::Counters;
use crate::storage::{Storage, Transition};
use crate::sum_tree::SumTree;

/// Prioritized replay over a ring of transitions (sans-IO: no threads, clocks or sockets).
#[derive(Clone)]
pub struct ReplayBuffer {
    pub(crate) cfg: ReplayConfig,
    pub(crate) storage: Storage,
    pub(crate) tree: SumTree,
    pub(crate) sampled_total: u64,
    pub(crate) updates_applied: u64,
    pub(crate) updates_stale: u64,
    /// Per-call scratch (priorities of an insert; the queries, then raw IS weights, of a sample),
    /// kept to avoid allocating on the hot path.
    scratch: Vec<f64>,
    /// Leaves found by a sample.
    leaves: Vec<usize>,
}

impl std::fmt::Debug for ReplayBuffer {
    // The derived form would print every stored value.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReplayBuffer")
            .field("cfg", &self.cfg)
            .field("dims", &self.storage.dims)
            .field("len", &self.len())
            .field("counters", &self.counters())
            .finish_non_exhaustive()
    }
}

impl ReplayBuffer {
    /// An empty buffer for transitions of `dims`, after `cfg.validate(dims)`.
    pub fn new(cfg: ReplayConfig, dims: Dims) -> Result<Self> {
        cfg.validate(dims)?;
        let storage = Storage::new(cfg.capacity_transitions, cfg.observation_rows_resolved(), dims);
        let tree = SumTree::new(cfg.capacity_transitions);
        Ok(Self::from_parts(cfg, storage, tree))
    }

    pub(crate) fn from_parts(cfg: ReplayConfig, storage: Storage, tree: SumTree) -> Self {
        Self {
            cfg,
            storage,
            tree,
            sampled_total: 0,
            updates_applied: 0,
            updates_stale: 0,
            scratch: Vec::new(),
            leaves: Vec::new(),
        }
    }

    /// Exact bytes a buffer of this configuration allocates for transitions of `dims`
    /// (observation rows, per-slot arrays, sum tree); saturates at `u64::MAX`.
    pub fn bytes_for(cfg: &ReplayConfig, dims: Dims) -> u64 {
        let storage = Storage::bytes_for(cfg.capacity_transitions, cfg.observation_rows_resolved(), dims);
        let total = storage.saturating_add(SumTree::bytes_for(cfg.capacity_transitions));
        u64::try_from(total).unwrap_or(u64::MAX)
    }

    /// The configuration.
    pub fn config(&self) -> &ReplayConfig {
        &self.cfg
    }

    /// Transition dimensions.
    pub fn dims(&self) -> Dims {
        self.storage.dims
    }

    /// Live transitions.
    pub fn len(&self) -> usize {
        self.storage.len()
    }

    /// True when nothing can be sampled.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Ring capacity N.
    pub fn capacity(&self) -> usize {
        self.storage.capacity
    }

    /// Observation rows M.
    pub fn observation_rows(&self) -> usize {
        self.storage.row_capacity
    }

    /// β at `learner_step` under the configured schedule.
    pub fn beta(&self, learner_step: u64) -> f64 {
        BetaSchedule {
            start: self.cfg.beta_start,
            end: self.cfg.beta_end,
            anneal_steps: self.cfg.beta_anneal_steps,
        }
        .beta(learner_step)
    }

    /// Priority p = (|δ| + ε)^α of a TD-error magnitude.
    pub fn priority_of(&self, abs_td_error: f32) -> f64 {
        priority(abs_td_error, self.cfg.alpha, self.cfg.epsilon)
    }

    /// Operation counters.
    pub fn counters(&self) -> Counters {
        Counters {
            inserted_total: self.storage.head,
            sampled_total: self.sampled_total,
            updates_applied: self.updates_applied,
            updates_stale: self.updates_stale,
            evicted_early: self.storage.evicted_early,
        }
    }

    /// Inserts a batch; all-or-nothing: on any error nothing is stored.
    pub fn insert_batch(&mut self, batch: TransitionBatch<'_>) -> Result<InsertOutcome> {
        let n = self.check_batch(&batch)?;
        let (o, a) = (self.storage.dims.obs_dim, self.storage.dims.act_dim);
        self.scratch.clear();
        match batch.abs_td_errors {
            Some(errors) => {
                let (alpha, epsilon) = (self.cfg.alpha, self.cfg.epsilon);
                self.scratch.extend(errors.iter().map(|&e| priority(e, alpha, epsilon)));
            }
            None => {
                // The paper's rule: a new item gets the maximum, so it is likely replayed (and its
                // TD error measured) soon.
                let max = if self.is_empty() { 1.0 } else { self.tree.max() };
                self.scratch.resize(n, max);
            }
        }
        let (old_head, old_tail, old_early) =
            (self.storage.head, self.storage.tail, self.storage.evicted_early);
        let mut inserted = Vec::with_capacity(n);
        for t in 0..n {
            inserted.push(self.slot_ref(self.storage.head));
            self.storage.push(&Transition {
                observation: &batch.observations[t * o..(t + 1) * o],
                action: &batch.actions[t * a..(t + 1) * a],
                reward: batch.rewards[t],
                next_observation: &batch.next_observations[t * o..(t + 1) * o],
                terminated: batch.terminated[t],
            });
        }
        let (head, tail) = (self.storage.head, self.storage.tail);
        let evicted_early = self.storage.evicted_early - old_early;
        // Zero the leaves of evicted transitions, except slots rewritten below by a live new one.
        let cap = self.capacity() as u64;
        for g in old_tail..tail {
            let latest = g + (head - 1 - g) / cap * cap;
            if latest < tail {
                self.tree.set(self.storage.slot_of(g), 0.0);
            }
        }
        // Live new transitions: contiguous in the ring except at the wrap, hence at most two fills.
        let mut g = old_head.max(tail);
        while g < head {
            let slot = self.storage.slot_of(g);
            let run = (head - g).min(cap - slot as u64);
            let from = (g - old_head) as usize;
            self.tree.fill(slot, &self.scratch[from..from + run as usize]);
            g += run;
        }
        Ok(InsertOutcome { inserted, overwritten: (tail - old_tail) - evicted_early, evicted_early })
    }

    /// Samples `batch_size` transitions into `out` (with replacement).
    ///
    /// Prioritized: the total priority is cut into `batch_size` equal segments and one u is drawn
    /// uniformly in each, [i·seg, (i+1)·seg), then mapped to its transition (stratified sampling);
    /// IS weight w_i = (len · P(i))^−β / max_j w_j with P(i) = p_i / Σp and β from `learner_step`.
    /// Uniform: indices uniform over the live transitions, weights 1.
    pub fn sample<R: Rng + ?Sized>(
        &mut self,
        batch_size: usize,
        learner_step: u64,
        rng: &mut R,
        out: &mut SampledBatch,
    ) -> Result<()> {
        if batch_size == 0 {
            return Err(ReplayError::ZeroBatchSize);
        }
        if self.is_empty() {
            return Err(ReplayError::Empty);
        }
        out.clear();
        out.beta = self.beta(learner_step);
        let len = self.len() as u64;
        match self.cfg.mode {
            SamplingMode::Uniform => {
                for _ in 0..batch_size {
                    let g = self.storage.tail + rng.random_range(0..len);
                    out.slots.push(self.storage.slot_of(g) as u64);
                    out.generations.push(self.storage.generation_of(g));
                }
                out.is_weights.resize(batch_size, 1.0);
            }
            SamplingMode::Prioritized => {
                let Self { tree, storage, scratch, leaves, .. } = self;
                let total = tree.total();
                let segment = total / batch_size as f64;
                scratch.clear();
                scratch.extend((0..batch_size).map(|i| (i as f64 + rng.random::<f64>()) * segment));
                tree.find_batch(scratch, leaves);
                let mut max_weight = 0.0f64;
                for (&slot, weight) in leaves.iter().zip(scratch.iter_mut()) {
                    let Some(g) = storage.occupant(slot) else {
                        unreachable!("leaf {slot} is positive but holds no live transition");
                    };
                    let probability = tree.get(slot) / total;
                    *weight = (len as f64 * probability).powf(-out.beta);
                    max_weight = max_weight.max(*weight);
                    out.slots.push(slot as u64);
                    out.generations.push(storage.generation_of(g));
                }
                out.is_weights.extend(scratch.iter().map(|w| (w / max_weight) as f32));
            }
        }
        self.storage.gather(out);
        self.sampled_total += batch_size as u64;
        Ok(())
    }

    /// Sets p = (|δ| + ε)^α for each (slot, generation) still live; updates whose slot was
    /// overwritten or evicted since sampling are counted as stale and ignored. All inputs are
    /// checked first: on error nothing changes. A slot named twice takes the last value.
    pub fn update_priorities(
        &mut self,
        slots: &[u64],
        generations: &[u64],
        abs_td_errors: &[f32],
    ) -> Result<UpdateOutcome> {
        let n = slots.len();
        check_len("generations", n, generations.len())?;
        check_len("abs_td_errors", n, abs_td_errors.len())?;
        check_abs_td_errors(abs_td_errors)?;
        let capacity = self.capacity();
        if let Some(index) = slots.iter().position(|&s| s >= capacity as u64) {
            return Err(ReplayError::SlotOutOfRange { index, slot: slots[index], capacity });
        }
        let (alpha, epsilon) = (self.cfg.alpha, self.cfg.epsilon);
        self.leaves.clear();
        self.scratch.clear();
        for ((&slot, &generation), &error) in slots.iter().zip(generations).zip(abs_td_errors) {
            if self.storage.live_global(slot as usize, generation).is_some() {
                self.leaves.push(slot as usize);
                self.scratch.push(priority(error, alpha, epsilon));
            }
        }
        self.tree.set_batch(&mut self.leaves, &self.scratch);
        let applied = self.scratch.len() as u64;
        let outcome = UpdateOutcome { applied, stale: n as u64 - applied };
        self.updates_applied += outcome.applied;
        self.updates_stale += outcome.stale;
        Ok(outcome)
    }

    /// The live transition `id`, or `None` if it was overwritten, evicted or never written.
    pub fn get(&self, id: SlotRef) -> Option<TransitionView<'_>> {
        let slot = usize::try_from(id.slot).ok()?;
        self.storage.live_global(slot, id.generation)?;
        Some(TransitionView {
            id,
            observation: self.storage.observation(slot),
            action: self.storage.action(slot),
            reward: self.storage.rewards[slot],
            next_observation: self.storage.next_observation(slot),
            terminated: self.storage.terminated[slot],
            priority: self.tree.get(slot),
        })
    }

    /// Identities of the live transitions, oldest first.
    pub fn live_slots(&self) -> impl Iterator<Item = SlotRef> + '_ {
        self.storage.live_globals().map(|g| self.slot_ref(g))
    }

    fn slot_ref(&self, g: u64) -> SlotRef {
        SlotRef { slot: self.storage.slot_of(g) as u64, generation: self.storage.generation_of(g) }
    }

    /// Checks lengths and values of a batch; returns n.
    fn check_batch(&self, batch: &TransitionBatch<'_>) -> Result<usize> {
        let Dims { obs_dim, act_dim } = self.storage.dims;
        let n = batch.rewards.len();
        check_len("observations", n.saturating_mul(obs_dim), batch.observations.len())?;
        check_len("actions", n.saturating_mul(act_dim), batch.actions.len())?;
        check_len("next_observations", n.saturating_mul(obs_dim), batch.next_observations.len())?;
        check_len("terminated", n, batch.terminated.len())?;
        check_finite("observations", batch.observations)?;
        check_finite("actions", batch.actions)?;
        check_finite("rewards", batch.rewards)?;
        check_finite("next_observations", batch.next_observations)?;
        if let Some(errors) = batch.abs_td_errors {
            check_len("abs_td_errors", n, errors.len())?;
            check_abs_td_errors(errors)?;
        }
        Ok(n)
    }
}

/// p = (|δ| + ε)^α, in f64 so that no f32 |δ| can overflow or round to 0.
fn priority(abs_td_error: f32, alpha: f64, epsilon: f64) -> f64 {
    (f64::from(abs_td_error) + epsilon).powf(alpha)
}

fn check_len(field: &'static str, expected: usize, found: usize) -> Result<()> {
    if expected == found { Ok(()) } else { Err(ReplayError::Length { field, expected, found }) }
}

fn check_finite(field: &'static str, values: &[f32]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(ReplayError::NonFinite { field, index }),
    }
}

fn check_abs_td_errors(values: &[f32]) -> Result<()> {
    // `>= 0.0` is false for NaN; -0.0 passes and is harmless.
    match values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
        None => Ok(()),
        Some(index) => Err(ReplayError::InvalidAbsTdError { index, value: values[index] }),
    }
}

#[cfg(test)]
mod tests;
