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

impl Sampled {
    /// Deals the rows out into `parts` batches, row i to batch i mod `parts`: one reply of
    /// `parts` x B transitions becomes `parts` updates of B, so the bus carries a `parts`-th of the
    /// messages for the same transitions. A prioritized reply's strata are in priority order, so
    /// dealing (not cutting) keeps each part stratified over the whole range; each part's IS weights
    /// are renormalised by their own maximum, exactly the weights of a batch sampled alone.
    pub fn split(self, parts: usize) -> Vec<Sampled> {
        let parts = parts.clamp(1, self.batch.size.max(1));
        if parts == 1 {
            return vec![self];
        }
        let b = &self.batch;
        let (o, a) = (b.observations.len() / b.size, b.actions.len() / b.size);
        (0..parts)
            .map(|p| {
                let rows: Vec<usize> = (p..b.size).step_by(parts).collect();
                let pick = |v: &[f32], width: usize| -> Vec<f32> {
                    rows.iter().flat_map(|&i| v[i * width..(i + 1) * width].iter().copied()).collect()
                };
                let is_weights = b.is_weights.as_ref().map(|w| {
                    let w = pick(w, 1);
                    let max = w.iter().copied().fold(f32::MIN, f32::max);
                    w.iter().map(|x| x / max).collect()
                });
                Sampled {
                    batch: Batch {
                        size: rows.len(),
                        observations: pick(&b.observations, o),
                        actions: pick(&b.actions, a),
                        rewards: pick(&b.rewards, 1),
                        next_observations: pick(&b.next_observations, o),
                        terminated: pick(&b.terminated, 1),
                        is_weights,
                    },
                    slots: rows.iter().map(|&i| self.slots[i]).collect(),
                    generations: rows.iter().map(|&i| self.generations[i]).collect(),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_deals_rows_out_and_renormalises_each_parts_weights() {
        let n = 6;
        let sampled = Sampled {
            batch: Batch {
                size: n,
                observations: (0..2 * n).map(|v| v as f32).collect(),
                actions: (0..n).map(|v| v as f32 * 10.0).collect(),
                rewards: (0..n).map(|v| v as f32).collect(),
                next_observations: (0..2 * n).map(|v| -(v as f32)).collect(),
                terminated: vec![0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                is_weights: Some(vec![0.2, 0.4, 0.5, 1.0, 0.25, 0.8]),
            },
            slots: (100..106).collect(),
            generations: (0..6).collect(),
        };
        let parts = sampled.clone().split(2);
        assert_eq!(parts.len(), 2);
        let (even, odd) = (&parts[0], &parts[1]);
        assert_eq!(even.slots, vec![100, 102, 104]);
        assert_eq!(odd.batch.rewards, vec![1.0, 3.0, 5.0]);
        assert_eq!(odd.batch.observations, vec![2.0, 3.0, 6.0, 7.0, 10.0, 11.0]);
        assert_eq!(odd.batch.next_observations, vec![-2.0, -3.0, -6.0, -7.0, -10.0, -11.0]);
        assert_eq!(odd.batch.terminated, vec![1.0, 0.0, 1.0]);
        assert_eq!(even.batch.actions, vec![0.0, 20.0, 40.0]);
        // Each part's weights over its own maximum: 0.2, 0.5, 0.25 -> / 0.5.
        assert_eq!(even.batch.is_weights, Some(vec![0.4, 1.0, 0.5]));
        assert_eq!(odd.batch.is_weights, Some(vec![0.4, 1.0, 0.8]));
        for part in &parts {
            part.batch.validate(2, 1).unwrap();
        }
        assert_eq!(sampled.clone().split(1), vec![sampled]);
    }
}
