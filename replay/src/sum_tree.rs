//! Array-based sum tree with maximum tracking over the leaves.
//!
//! Layout: a complete binary tree over `L` leaves, `L` the capacity rounded up to a power of two
//! (at least 2); node 1 is the root, node k has children 2k and 2k + 1, leaf i is node L + i.
//! Padding leaves stay 0 and are never found. `sums` holds every node (2L f64); `maxes` holds the
//! internal nodes only (L f64), a leaf's maximum being its own value.
//!
//! Bounded drift: on every write the ancestors are recomputed as `left + right` from their
//! children, never adjusted by a delta. Each node is therefore a pure function of the current
//! leaves (the same value a rebuild from scratch gives, bit for bit), so rounding does not
//! accumulate over any number of updates; the root is a pairwise sum whose relative error is at
//! most depth × 2⁻⁵³ (about 2.3e-15 for 2²⁰ leaves). Delta propagation, the usual alternative,
//! drifts without bound and needs periodic rebuilds; recomputing costs the same memory traffic
//! (the sibling is read either way).

/// Sum tree over non-negative `f64` leaves: O(log n) write, prefix-sum search and total/maximum in
/// O(1).
#[derive(Debug, Clone)]
pub struct SumTree {
    /// Number of leaves, a power of two ≥ 2.
    leaves: usize,
    /// Node sums, index 1..2L (index 0 unused).
    sums: Vec<f64>,
    /// Internal node maxima, index 1..L (index 0 unused).
    maxes: Vec<f64>,
}

impl SumTree {
    /// An all-zero tree with room for `capacity` leaves.
    pub fn new(capacity: usize) -> Self {
        let leaves = Self::padded(capacity);
        Self { leaves, sums: vec![0.0; 2 * leaves], maxes: vec![0.0; leaves] }
    }

    /// Bytes `new(capacity)` allocates.
    pub fn bytes_for(capacity: usize) -> u128 {
        // 2L sums + L maxima, 8 bytes each; u128 so that absurd capacities cannot overflow.
        24 * (capacity as u128).next_power_of_two().max(2)
    }

    fn padded(capacity: usize) -> usize {
        capacity.next_power_of_two().max(2)
    }

    /// Number of leaves (capacity rounded up to a power of two).
    pub fn leaf_count(&self) -> usize {
        self.leaves
    }

    /// Sum of all leaves.
    pub fn total(&self) -> f64 {
        self.sums[1]
    }

    /// Largest leaf.
    pub fn max(&self) -> f64 {
        self.maxes[1]
    }

    /// Value of leaf `leaf`.
    pub fn get(&self, leaf: usize) -> f64 {
        self.sums[self.leaves + leaf]
    }

    /// All leaf values, padding included.
    pub fn leaf_values(&self) -> &[f64] {
        &self.sums[self.leaves..]
    }

    /// Sets leaf `leaf` to `value` (finite, ≥ 0) and recomputes its ancestors.
    pub fn set(&mut self, leaf: usize, value: f64) {
        debug_assert!(value.is_finite() && value >= 0.0, "leaf value {value}");
        let mut k = self.leaves + leaf;
        self.sums[k] = value;
        // The lowest internal level reads its children's maxima from the leaves themselves.
        k /= 2;
        let (l, r) = (self.sums[2 * k], self.sums[2 * k + 1]);
        self.sums[k] = l + r;
        self.maxes[k] = l.max(r);
        while k > 1 {
            k /= 2;
            self.recompute_internal(k);
        }
    }

    /// Sets `leaves[i]` to `values[i]` for all i (a leaf named twice takes the later value), then
    /// recomputes the ancestors one level at a time for all of them; `leaves` is used as working
    /// space. Same result as separate [`set`](Self::set)s (each node is a function of the leaves
    /// alone), but the cache misses of the different paths overlap.
    pub fn set_batch(&mut self, leaves: &mut [usize], values: &[f64]) {
        debug_assert_eq!(leaves.len(), values.len());
        for (leaf, &value) in leaves.iter_mut().zip(values) {
            debug_assert!(value.is_finite() && value >= 0.0, "leaf value {value}");
            self.sums[self.leaves + *leaf] = value;
            *leaf = (self.leaves + *leaf) / 2;
        }
        for &k in leaves.iter() {
            let (l, r) = (self.sums[2 * k], self.sums[2 * k + 1]);
            self.sums[k] = l + r;
            self.maxes[k] = l.max(r);
        }
        let mut width = self.leaves / 2;
        while width > 1 {
            for k in leaves.iter_mut() {
                *k /= 2;
                self.recompute_internal(*k);
            }
            width /= 2;
        }
    }

    /// Sets the contiguous leaves `start..start + values.len()` and recomputes their ancestors
    /// level by level: O(n + log L) instead of O(n log L) for n separate writes.
    pub fn fill(&mut self, start: usize, values: &[f64]) {
        if values.is_empty() {
            return;
        }
        debug_assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0));
        let first = self.leaves + start;
        self.sums[first..first + values.len()].copy_from_slice(values);
        let (mut lo, mut hi) = (first / 2, (first + values.len() - 1) / 2);
        for k in lo..=hi {
            let (l, r) = (self.sums[2 * k], self.sums[2 * k + 1]);
            self.sums[k] = l + r;
            self.maxes[k] = l.max(r);
        }
        while lo > 1 {
            (lo, hi) = (lo / 2, hi / 2);
            for k in lo..=hi {
                self.recompute_internal(k);
            }
        }
    }

    /// Recomputes every internal node from the leaves.
    pub fn rebuild(&mut self) {
        for k in (self.leaves / 2..self.leaves).rev() {
            let (l, r) = (self.sums[2 * k], self.sums[2 * k + 1]);
            self.sums[k] = l + r;
            self.maxes[k] = l.max(r);
        }
        for k in (1..self.leaves / 2).rev() {
            self.recompute_internal(k);
        }
    }

    /// The leaf whose cumulative interval [Σ_{j<i} p_j, Σ_{j≤i} p_j) contains `u`, for
    /// 0 ≤ u < total. Never returns a zero leaf while the total is positive: rounding can make `u`
    /// reach a subtree's sum, so the walk only enters a child with positive mass, and a `u` at or
    /// past the end lands on the last positive leaf.
    pub fn find(&self, mut u: f64) -> usize {
        debug_assert!(self.total() > 0.0, "find in an empty tree");
        let mut k = 1;
        while k < self.leaves {
            self.descend(&mut k, &mut u);
        }
        k - self.leaves
    }

    /// [`find`](Self::find) for many queries at once, into `leaves` (same results); the queries
    /// are used as working space and left as remainders. The walks advance one level at a time
    /// together, so their cache misses overlap instead of queueing: in a large tree the lower
    /// levels miss for every query.
    pub fn find_batch(&self, queries: &mut [f64], leaves: &mut Vec<usize>) {
        debug_assert!(self.total() > 0.0, "find in an empty tree");
        leaves.clear();
        leaves.resize(queries.len(), 1);
        let mut width = 1;
        while width < self.leaves {
            for (k, u) in leaves.iter_mut().zip(queries.iter_mut()) {
                self.descend(k, u);
            }
            width *= 2;
        }
        leaves.iter_mut().for_each(|k| *k -= self.leaves);
    }

    /// One step of the walk from node `k` to the child whose interval holds `u`.
    #[inline]
    fn descend(&self, k: &mut usize, u: &mut f64) {
        let left = 2 * *k;
        let left_sum = self.sums[left];
        if *u < left_sum {
            *k = left;
        } else if self.sums[left + 1] > 0.0 {
            *u -= left_sum;
            *k = left + 1;
        } else {
            *k = left;
        }
    }

    fn recompute_internal(&mut self, k: usize) {
        let (l, r) = (2 * k, 2 * k + 1);
        self.sums[k] = self.sums[l] + self.sums[r];
        self.maxes[k] = self.maxes[l].max(self.maxes[r]);
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    use super::*;

    /// Neumaier-compensated sum: an accurate reference for the tree's root.
    fn accurate_sum(values: &[f64]) -> f64 {
        let (mut sum, mut c) = (0.0f64, 0.0f64);
        for &v in values {
            let t = sum + v;
            c += if sum.abs() >= v.abs() { (sum - t) + v } else { (v - t) + sum };
            sum = t;
        }
        sum + c
    }

    #[test]
    fn pads_to_a_power_of_two_and_tracks_sum_and_max() {
        let mut tree = SumTree::new(5);
        assert_eq!(tree.leaf_count(), 8);
        assert_eq!(SumTree::new(1).leaf_count(), 2);
        for (i, v) in [1.0, 2.0, 3.0, 4.0, 0.5].into_iter().enumerate() {
            tree.set(i, v);
        }
        assert_eq!(tree.total(), 10.5);
        assert_eq!(tree.max(), 4.0);
        tree.set(3, 0.25);
        assert_eq!(tree.total(), 6.75);
        assert_eq!(tree.max(), 3.0);
        assert_eq!(tree.get(3), 0.25);
    }

    #[test]
    fn find_maps_prefix_sums_to_leaves() {
        let mut tree = SumTree::new(4);
        tree.fill(0, &[1.0, 0.0, 2.0, 1.0]);
        assert_eq!(tree.find(0.0), 0);
        assert_eq!(tree.find(0.999), 0);
        assert_eq!(tree.find(1.0), 2, "zero leaf 1 is skipped");
        assert_eq!(tree.find(2.999), 2);
        assert_eq!(tree.find(3.0), 3);
        assert_eq!(tree.find(3.999), 3);
    }

    #[test]
    fn find_past_the_end_never_returns_a_zero_leaf() {
        let mut tree = SumTree::new(8);
        tree.fill(0, &[0.0, 0.3, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0]);
        for u in [tree.total(), tree.total() * (1.0 + 1e-12), 1e300] {
            assert_eq!(tree.find(u), 3);
        }
    }

    #[test]
    fn find_batch_equals_find() {
        let mut tree = SumTree::new(1000);
        let mut rng = StdRng::seed_from_u64(3);
        for leaf in 0..1000 {
            // Every third leaf empty, to exercise the skips.
            tree.set(leaf, if leaf % 3 == 0 { 0.0 } else { rng.random_range(0.0..5.0) });
        }
        let mut queries: Vec<f64> = (0..500).map(|_| rng.random_range(0.0..tree.total())).collect();
        queries.extend([0.0, tree.total(), tree.total() * 2.0]);
        let one_by_one: Vec<usize> = queries.iter().map(|&u| tree.find(u)).collect();
        let mut leaves = Vec::new();
        tree.find_batch(&mut queries, &mut leaves);
        assert_eq!(leaves, one_by_one);
        assert!(leaves.iter().all(|&l| tree.get(l) > 0.0));
    }

    #[test]
    fn set_batch_equals_individual_sets() {
        let mut rng = StdRng::seed_from_u64(5);
        for n in [1, 2, 3, 64, 1000] {
            let mut a = SumTree::new(n);
            let mut b = SumTree::new(n);
            for _ in 0..5 {
                // Repeated leaves included: the later value wins in both.
                let mut leaves: Vec<usize> = (0..50).map(|_| rng.random_range(0..n)).collect();
                let values: Vec<f64> = (0..50).map(|_| rng.random_range(0.0..3.0)).collect();
                for (&l, &v) in leaves.iter().zip(&values) {
                    b.set(l, v);
                }
                a.set_batch(&mut leaves, &values);
                assert_eq!(a.sums, b.sums, "n {n}");
                assert_eq!(a.maxes, b.maxes, "n {n}");
            }
        }
    }

    #[test]
    fn fill_equals_individual_sets() {
        let mut a = SumTree::new(100);
        let mut b = SumTree::new(100);
        let values: Vec<f64> = (0..37).map(|i| (i as f64 * 0.37).sin().abs()).collect();
        a.fill(41, &values);
        for (i, v) in values.iter().enumerate() {
            b.set(41 + i, *v);
        }
        assert_eq!(a.sums, b.sums);
        assert_eq!(a.maxes, b.maxes);
    }

    #[test]
    fn drift_is_bounded_after_many_updates() {
        // Leaves spanning twelve orders of magnitude, rewritten a million times: the root must be
        // bit-identical to a fresh rebuild (no accumulated rounding) and within the pairwise bound
        // of an accurate sum.
        let n = 1 << 12;
        let mut tree = SumTree::new(n);
        let mut rng = StdRng::seed_from_u64(7);
        for _ in 0..1_000_000 {
            let leaf = rng.random_range(0..n);
            let value = 10f64.powf(rng.random_range(-6.0..6.0));
            tree.set(leaf, value);
        }
        let (root, max) = (tree.total(), tree.max());
        let mut fresh = tree.clone();
        fresh.rebuild();
        assert_eq!(root.to_bits(), fresh.total().to_bits());
        assert_eq!(max, fresh.max());
        assert_eq!(tree.sums, fresh.sums);
        let exact = accurate_sum(tree.leaf_values());
        let depth = n.trailing_zeros() as f64;
        assert!((root - exact).abs() <= depth * f64::EPSILON * exact, "{root} vs {exact}");
        let leaf_max = tree.leaf_values().iter().copied().fold(0.0, f64::max);
        assert_eq!(max, leaf_max);
    }
}
