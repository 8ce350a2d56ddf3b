//! Counters and diagnostics of the stored priorities (for metrics such as `replay/ess`).
//!
//! The scans here are O(len); they are meant for periodic metrics, not for every sample.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use crate::batch::SlotRef;
use crate::buffer::ReplayBuffer;

/// Operation counters since the buffer was created (restored with a snapshot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Transitions ever inserted.
    pub inserted_total: u64,
    /// Transitions ever sampled (batch sizes summed).
    pub sampled_total: u64,
    /// Priority updates written.
    pub updates_applied: u64,
    /// Priority updates ignored because their slot had been overwritten or evicted.
    pub updates_stale: u64,
    /// Transitions evicted before the ring was full because observation rows ran out (raise
    /// `observation_rows` or insert longer runs if this grows).
    pub evicted_early: u64,
}

/// Minimum, maximum and mean of the live priorities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorityStats {
    /// Live transitions the statistics cover.
    pub count: usize,
    /// Smallest priority.
    pub min: f64,
    /// Largest priority.
    pub max: f64,
    /// Mean priority.
    pub mean: f64,
}

/// A live transition and its priority, from [`ReplayBuffer::top_k`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotPriority {
    /// The transition.
    pub id: SlotRef,
    /// Its priority p = (|δ| + ε)^α.
    pub priority: f64,
}

/// Orders by priority (then by age, oldest first) for the top-k heap.
#[derive(PartialEq)]
struct ByPriority(f64, Reverse<u64>);

impl Eq for ByPriority {}

impl PartialOrd for ByPriority {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for ByPriority {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

impl ReplayBuffer {
    /// Priorities of the live transitions, oldest first.
    fn live_priorities(&self) -> impl Iterator<Item = (u64, f64)> + '_ {
        self.storage.live_globals().map(|g| (g, self.tree.get(self.storage.slot_of(g))))
    }

    /// Min / max / mean of the live priorities, `None` when empty.
    pub fn priority_stats(&self) -> Option<PriorityStats> {
        if self.is_empty() {
            return None;
        }
        let min = self.live_priorities().map(|(_, p)| p).fold(f64::INFINITY, f64::min);
        Some(PriorityStats {
            count: self.len(),
            min,
            max: self.tree.max(),
            mean: self.tree.total() / self.len() as f64,
        })
    }

    /// Normalised effective sample size of the priority distribution P(i) = p_i / Σp:
    /// (Σp)² / Σp² / len, in (0, 1]; 1 when all priorities are equal, near 1/len when one dominates.
    /// `None` when empty. (Of the stored priorities, whatever the sampling mode.)
    pub fn effective_sample_size(&self) -> Option<f64> {
        if self.is_empty() {
            return None;
        }
        let (sum, sum_sq) =
            self.live_priorities().fold((0.0f64, 0.0f64), |(s, q), (_, p)| (s + p, q + p * p));
        Some(sum * sum / sum_sq / self.len() as f64)
    }

    /// The `k` live transitions of highest priority, highest first (ties: oldest first).
    pub fn top_k(&self, k: usize) -> Vec<SlotPriority> {
        if k == 0 {
            return Vec::new();
        }
        // A min-heap of the best k so far: O(len log k) time, O(k) memory.
        let mut heap: BinaryHeap<Reverse<ByPriority>> = BinaryHeap::with_capacity(k + 1);
        for (g, p) in self.live_priorities() {
            heap.push(Reverse(ByPriority(p, Reverse(g))));
            if heap.len() > k {
                heap.pop();
            }
        }
        let mut best: Vec<ByPriority> = heap.into_iter().map(|Reverse(b)| b).collect();
        best.sort_by(|a, b| b.cmp(a));
        best.into_iter()
            .map(|ByPriority(priority, Reverse(g))| SlotPriority {
                id: SlotRef {
                    slot: self.storage.slot_of(g) as u64,
                    generation: self.storage.generation_of(g),
                },
                priority,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use crate::batch::TransitionBatch;
    use crate::{Dims, ReplayBuffer, ReplayConfig};

    fn buffer_with(errors: &[f32]) -> ReplayBuffer {
        let cfg = ReplayConfig { capacity_transitions: 16, alpha: 1.0, ..ReplayConfig::default() };
        let mut buffer = ReplayBuffer::new(cfg, Dims { obs_dim: 1, act_dim: 1 }).unwrap();
        let n = errors.len();
        let obs: Vec<f32> = (0..n).map(|i| i as f32).collect();
        let next: Vec<f32> = (1..=n).map(|i| i as f32).collect();
        buffer
            .insert_batch(TransitionBatch {
                observations: &obs,
                actions: &vec![0.0; n],
                rewards: &vec![0.0; n],
                next_observations: &next,
                terminated: &vec![false; n],
                abs_td_errors: Some(errors),
            })
            .unwrap();
        buffer
    }

    #[test]
    fn empty_buffer_has_no_stats() {
        let buffer = buffer_with(&[]);
        assert_eq!(buffer.priority_stats(), None);
        assert_eq!(buffer.effective_sample_size(), None);
        assert!(buffer.top_k(3).is_empty());
    }

    #[test]
    fn stats_ess_and_top_k() {
        let eps = 1e-6;
        let buffer = buffer_with(&[1.0, 3.0, 2.0, 3.0]);
        let stats = buffer.priority_stats().unwrap();
        assert_eq!(stats.count, 4);
        assert!((stats.min - (1.0 + eps)).abs() < 1e-12);
        assert!((stats.max - (3.0 + eps)).abs() < 1e-12);
        assert!((stats.mean - (2.25 + eps)).abs() < 1e-12);
        let p = [1.0 + eps, 3.0 + eps, 2.0 + eps, 3.0 + eps];
        let ess = p.iter().sum::<f64>().powi(2) / p.iter().map(|x| x * x).sum::<f64>() / 4.0;
        assert!((buffer.effective_sample_size().unwrap() - ess).abs() < 1e-12);
        let top = buffer.top_k(3);
        let slots: Vec<u64> = top.iter().map(|s| s.id.slot).collect();
        assert_eq!(slots, [1, 3, 2], "highest first, ties oldest first");
        assert!((top[2].priority - (2.0 + eps)).abs() < 1e-12);
        assert_eq!(buffer.top_k(10).len(), 4);
        assert!((buffer_with(&[5.0; 6]).effective_sample_size().unwrap() - 1.0).abs() < 1e-12);
    }
}
