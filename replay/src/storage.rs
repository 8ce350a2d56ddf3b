//! Ring storage of transitions, with each observation stored once.
//!
//! Layout: transitions live in a ring of N slots (action, reward, terminated flag and one row
//! position); observations live in a second ring of M rows. A transition owns two *consecutive*
//! rows: row r − 1 holds its observation and row r its next observation, so the slot stores r only.
//! Rows are appended in order. When a transition's observation is bitwise equal to the newest row
//! (the previous transition's next observation: the usual case inside an episode, within one
//! insert call or across calls), that row is reused instead of written again. A run of k
//! consecutive steps therefore takes k + 1 rows instead of 2k, and the obs of transition t + 1 and
//! the next obs of transition t are one row.
//!
//! Why this is safe: both rings are FIFOs that advance together. Live transitions only use rows
//! among the last M written, and rows are overwritten oldest first. Before a row is overwritten,
//! every live transition that uses it is evicted; those are the oldest transitions, at the tail.
//! So a transition is either live with both of its rows intact or gone, whatever the wrap of
//! either ring, the batch boundaries or the interleaving of writers. When rows run short (runs
//! shorter than the configured headroom, e.g. single steps interleaved from many executors), the
//! tail is evicted before the ring is full ("early"); the buffer then holds fewer than N
//! transitions, never a wrong one.
//!
//! Identity: the n-th transition ever inserted (its global index g, from 0) goes to slot g mod N
//! with generation g div N. The generation is derived, not stored: slots are written strictly in
//! ring order, so the pair (slot, generation) names one insertion and changes on every overwrite.

use crate::batch::SampledBatch;
use crate::config::Dims;

/// One transition as given to [`Storage::push`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Transition<'a> {
    pub observation: &'a [f32],
    pub action: &'a [f32],
    pub reward: f32,
    pub next_observation: &'a [f32],
    pub terminated: bool,
}

/// The two rings and their counters. Fields are crate-visible for the snapshot codec; the
/// invariants are those in the module doc, checked again on restore.
#[derive(Clone)]
pub(crate) struct Storage {
    pub dims: Dims,
    /// Transition slots, N.
    pub capacity: usize,
    /// Observation rows, M ≥ 2.
    pub row_capacity: usize,
    /// M × obs_dim observation values.
    pub rows: Vec<f32>,
    /// N × act_dim action values.
    pub actions: Vec<f32>,
    /// N rewards.
    pub rewards: Vec<f32>,
    /// N terminal flags (termination only; a time-limit cut is not terminal).
    pub terminated: Vec<bool>,
    /// N row positions of each slot's next observation; its observation is the row before.
    pub next_rows: Vec<u32>,
    /// Global index of the next transition = transitions ever inserted.
    pub head: u64,
    /// Global index of the oldest live transition; live = tail..head.
    pub tail: u64,
    /// Rows ever written; the newest is at (rows_written − 1) mod M.
    pub rows_written: u64,
    /// Transitions evicted because rows ran out before their slot was needed.
    pub evicted_early: u64,
}

impl Storage {
    /// Empty storage; the arguments are validated by `ReplayConfig::validate`.
    pub fn new(capacity: usize, row_capacity: usize, dims: Dims) -> Self {
        Self {
            dims,
            capacity,
            row_capacity,
            rows: vec![0.0; row_capacity * dims.obs_dim],
            actions: vec![0.0; capacity * dims.act_dim],
            rewards: vec![0.0; capacity],
            terminated: vec![false; capacity],
            next_rows: vec![0; capacity],
            head: 0,
            tail: 0,
            rows_written: 0,
            evicted_early: 0,
        }
    }

    /// Bytes `new` allocates.
    pub fn bytes_for(capacity: usize, row_capacity: usize, dims: Dims) -> u128 {
        let row = 4 * dims.obs_dim as u128;
        // action f32s + reward f32 + terminated u8 + next-row u32
        let slot = 4 * dims.act_dim as u128 + 4 + 1 + 4;
        row_capacity as u128 * row + capacity as u128 * slot
    }

    /// Live transitions.
    pub fn len(&self) -> usize {
        (self.head - self.tail) as usize
    }

    /// Slot of global index `g`.
    pub fn slot_of(&self, g: u64) -> usize {
        (g % self.capacity as u64) as usize
    }

    /// Generation of global index `g`.
    pub fn generation_of(&self, g: u64) -> u64 {
        g / self.capacity as u64
    }

    /// Global index of (slot, generation) if that transition is still live.
    pub fn live_global(&self, slot: usize, generation: u64) -> Option<u64> {
        let g = generation.checked_mul(self.capacity as u64)?.checked_add(slot as u64)?;
        (slot < self.capacity && (self.tail..self.head).contains(&g)).then_some(g)
    }

    /// Global index of the live transition in `slot`, if any.
    pub fn occupant(&self, slot: usize) -> Option<u64> {
        let last = self.head.checked_sub(1)?;
        let slot = slot as u64;
        if slot >= self.capacity as u64 || slot > last {
            return None;
        }
        let g = last - (last - slot) % self.capacity as u64;
        (g >= self.tail).then_some(g)
    }

    /// Appends a transition, evicting the oldest ones as the rings require.
    pub fn push(&mut self, t: &Transition<'_>) {
        if self.len() == self.capacity {
            // Ring full: the oldest transition is overwritten (its slot is the one written below).
            // Done before the rows so that a ring with just enough rows never counts an early
            // eviction for what is an ordinary overwrite.
            self.tail += 1;
        }
        let reuse = self.rows_written > 0 && bits_equal(self.row(self.newest_row()), t.observation);
        if !reuse {
            self.append_row(t.observation);
        }
        self.append_row(t.next_observation);
        let slot = self.slot_of(self.head);
        let a = self.dims.act_dim;
        self.actions[slot * a..(slot + 1) * a].copy_from_slice(t.action);
        self.rewards[slot] = t.reward;
        self.terminated[slot] = t.terminated;
        // Positions are < M ≤ u32::MAX (validated), so the cast is lossless.
        self.next_rows[slot] = self.newest_row() as u32;
        self.head += 1;
    }

    fn newest_row(&self) -> usize {
        ((self.rows_written - 1) % self.row_capacity as u64) as usize
    }

    fn append_row(&mut self, values: &[f32]) {
        let pos = (self.rows_written % self.row_capacity as u64) as usize;
        // Live rows are the last M written, with distinct positions, so a live transition whose
        // observation row sits at `pos` holds the row about to be overwritten. Only the tail can:
        // rows are used in transition order. Its next row is newer and survives, which is what
        // keeps the shared row of the following transition intact.
        while self.tail < self.head && self.observation_row(self.slot_of(self.tail)) == pos {
            self.tail += 1;
            self.evicted_early += 1;
        }
        let d = self.dims.obs_dim;
        self.rows[pos * d..(pos + 1) * d].copy_from_slice(values);
        self.rows_written += 1;
    }

    fn observation_row(&self, slot: usize) -> usize {
        let next = self.next_rows[slot] as usize;
        if next == 0 { self.row_capacity - 1 } else { next - 1 }
    }

    fn row(&self, pos: usize) -> &[f32] {
        let d = self.dims.obs_dim;
        &self.rows[pos * d..(pos + 1) * d]
    }

    /// Observation of the transition in `slot`.
    pub fn observation(&self, slot: usize) -> &[f32] {
        self.row(self.observation_row(slot))
    }

    /// Next observation of the transition in `slot`.
    pub fn next_observation(&self, slot: usize) -> &[f32] {
        self.row(self.next_rows[slot] as usize)
    }

    /// Action of the transition in `slot`.
    pub fn action(&self, slot: usize) -> &[f32] {
        let a = self.dims.act_dim;
        &self.actions[slot * a..(slot + 1) * a]
    }

    /// Copies the transitions of `out.slots` into the other fields of `out`. One field at a time
    /// over the whole batch rather than one transition at a time: the loops are short and
    /// independent across transitions, so the cache misses of different transitions overlap.
    pub fn gather(&self, out: &mut SampledBatch) {
        let SampledBatch { slots, observations, actions, rewards, next_observations, terminated, .. } = out;
        let slots = || slots.iter().map(|&s| s as usize);
        slots().for_each(|s| observations.extend_from_slice(self.observation(s)));
        slots().for_each(|s| next_observations.extend_from_slice(self.next_observation(s)));
        slots().for_each(|s| actions.extend_from_slice(self.action(s)));
        rewards.extend(slots().map(|s| self.rewards[s]));
        terminated.extend(slots().map(|s| self.terminated[s]));
    }

    /// Global indices of the live transitions, oldest first.
    pub fn live_globals(&self) -> std::ops::Range<u64> {
        self.tail..self.head
    }
}

/// Bitwise equality: `==` on floats would merge 0.0 with -0.0 and return the wrong sign.
fn bits_equal(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[cfg(test)]
mod tests;
