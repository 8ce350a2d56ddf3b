//! Counters and diagnostics of the stored priorities (for metrics such as `replay/ess`).
//!
//! Every diagnostic is one [`PriorityScan`], O(len): meant for periodic metrics, not for every
//! sample. The buffer's own methods scan in one go; the replay server scans a chunk per lock hold.

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

/// What a finished scan found.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorityDigest {
    /// Live transitions seen.
    pub count: u64,
    /// Smallest priority.
    pub min: f64,
    /// Largest priority.
    pub max: f64,
    /// Mean priority.
    pub mean: f64,
    /// Normalised effective sample size of P(i) ∝ p_i: (Σp)² / Σp² / count, in (0, 1].
    pub ess: f64,
    /// Highest priorities, highest first (ties: oldest first).
    pub top: Vec<SlotPriority>,
}

/// Orders entries by priority, then the older (smaller global index) first.
#[derive(Debug, PartialEq)]
struct Entry(f64, Reverse<u64>);

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

/// A scan of the live priorities in progress: min, max, mean, effective sample size and the `k`
/// highest. It can walk the buffer a chunk at a time (the replay server does, between lock holds,
/// reading priorities through the public `get`): transitions overwritten between chunks are
/// skipped and those inserted after it started are left for the next scan, so the result describes
/// the buffer as it was over the scan.
#[derive(Debug)]
pub struct PriorityScan {
    next: u64,
    end: u64,
    capacity: u64,
    k: usize,
    count: u64,
    min: f64,
    max: f64,
    sum: f64,
    sum_sq: f64,
    top: BinaryHeap<Reverse<Entry>>,
}

impl PriorityScan {
    /// A scan over the transitions live in `buffer` now, keeping the `k` highest.
    pub fn new(buffer: &ReplayBuffer, k: usize) -> Self {
        let end = buffer.counters().inserted_total;
        Self {
            next: end - buffer.len() as u64,
            end,
            capacity: buffer.capacity() as u64,
            k,
            count: 0,
            min: f64::INFINITY,
            max: 0.0,
            sum: 0.0,
            sum_sq: 0.0,
            top: BinaryHeap::with_capacity(k + 1),
        }
    }

    /// Examines up to `chunk` more transitions; true when the scan is complete.
    pub fn step(&mut self, buffer: &ReplayBuffer, chunk: u64) -> bool {
        let stop = self.end.min(self.next.saturating_add(chunk));
        for g in self.next..stop {
            let id = SlotRef { slot: g % self.capacity, generation: g / self.capacity };
            // None: overwritten since the scan started.
            let Some(view) = buffer.get(id) else { continue };
            let p = view.priority;
            self.count += 1;
            self.min = self.min.min(p);
            self.max = self.max.max(p);
            self.sum += p;
            self.sum_sq += p * p;
            if self.k > 0 {
                self.top.push(Reverse(Entry(p, Reverse(g))));
                if self.top.len() > self.k {
                    self.top.pop();
                }
            }
        }
        self.next = stop;
        self.next >= self.end
    }

    /// The result; `None` when no live transition was seen.
    pub fn finish(self) -> Option<PriorityDigest> {
        if self.count == 0 {
            return None;
        }
        let capacity = self.capacity;
        let mut top: Vec<Entry> = self.top.into_iter().map(|Reverse(e)| e).collect();
        top.sort_by(|a, b| b.cmp(a));
        let top = top
            .into_iter()
            .map(|Entry(priority, Reverse(g))| SlotPriority {
                id: SlotRef { slot: g % capacity, generation: g / capacity },
                priority,
            })
            .collect();
        Some(PriorityDigest {
            count: self.count,
            min: self.min,
            max: self.max,
            mean: self.sum / self.count as f64,
            ess: self.sum * self.sum / self.sum_sq / self.count as f64,
            top,
        })
    }
}

impl ReplayBuffer {
    /// Min / max / mean of the live priorities and the `k` highest, in one pass; `None` when empty.
    pub fn priority_digest(&self, k: usize) -> Option<PriorityDigest> {
        let mut scan = PriorityScan::new(self, k);
        scan.step(self, u64::MAX);
        scan.finish()
    }

    /// Min / max / mean of the live priorities, `None` when empty.
    pub fn priority_stats(&self) -> Option<PriorityStats> {
        self.priority_digest(0).map(|d| PriorityStats {
            count: d.count as usize,
            min: d.min,
            max: d.max,
            mean: d.mean,
        })
    }

    /// Normalised effective sample size of the priority distribution P(i) = p_i / Σp:
    /// (Σp)² / Σp² / len, in (0, 1]; 1 when all priorities are equal, near 1/len when one dominates.
    /// `None` when empty. (Of the stored priorities, whatever the sampling mode.)
    pub fn effective_sample_size(&self) -> Option<f64> {
        self.priority_digest(0).map(|d| d.ess)
    }

    /// The `k` live transitions of highest priority, highest first (ties: oldest first).
    pub fn top_k(&self, k: usize) -> Vec<SlotPriority> {
        self.priority_digest(k).map(|d| d.top).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::PriorityScan;
    use crate::batch::TransitionBatch;
    use crate::{Dims, ReplayBuffer, ReplayConfig};

    fn buffer_with(errors: &[f32]) -> ReplayBuffer {
        buffer(errors, 16)
    }

    /// A buffer of `capacity` holding one transition per error, α = 1 (priority = |δ| + ε).
    fn buffer(errors: &[f32], capacity: usize) -> ReplayBuffer {
        let cfg = ReplayConfig { capacity_transitions: capacity, alpha: 1.0, ..ReplayConfig::default() };
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

    #[test]
    fn a_chunked_scan_agrees_with_a_whole_one() {
        let errors: Vec<f32> = (0..50).map(|i| ((i * 37) % 11) as f32 * 0.5).collect();
        // Capacity 32: the first 18 were overwritten, the ring has wrapped.
        let b = buffer(&errors, 32);
        for chunk in [1, 7, 32, 1000] {
            let mut scan = PriorityScan::new(&b, 5);
            while !scan.step(&b, chunk) {}
            let digest = scan.finish().unwrap();
            let reference = b.priority_stats().unwrap();
            assert_eq!(digest.count, reference.count as u64);
            assert_eq!(digest.min, reference.min);
            assert_eq!(digest.max, reference.max);
            assert!((digest.mean - reference.mean).abs() < 1e-12);
            assert!((digest.ess - b.effective_sample_size().unwrap()).abs() < 1e-12);
            assert_eq!(digest.top, b.top_k(5), "chunk {chunk}");
        }
    }

    #[test]
    fn empty_buffer_has_no_digest() {
        let b = buffer(&[], 8);
        let mut scan = PriorityScan::new(&b, 3);
        assert!(scan.step(&b, 1 << 13));
        assert_eq!(scan.finish(), None);
    }
}
