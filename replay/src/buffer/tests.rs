use rand::SeedableRng;
use rand::rngs::StdRng;

use super::*;
use crate::error::ConfigError;
use crate::test_support::{Ledger, OwnedBatch};

const DIMS: Dims = Dims { obs_dim: 3, act_dim: 2 };

fn config(capacity: usize) -> ReplayConfig {
    ReplayConfig { capacity_transitions: capacity, ..ReplayConfig::default() }
}

fn buffer(cfg: ReplayConfig) -> ReplayBuffer {
    ReplayBuffer::new(cfg, DIMS).unwrap()
}

/// Inserts `errors.len()` consecutive transitions with those TD errors.
fn insert_with_errors(buffer: &mut ReplayBuffer, errors: &[f32]) -> InsertOutcome {
    let b = OwnedBatch::run(DIMS, 0, buffer.counters().inserted_total as u32, errors.len());
    buffer.insert_batch(b.with_td(errors.to_vec()).batch()).unwrap()
}

/// Counts per slot over `draws` batches of `batch_size`.
fn sample_counts(buffer: &mut ReplayBuffer, batch_size: usize, draws: usize, seed: u64) -> Vec<u64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = SampledBatch::new();
    let mut counts = vec![0u64; buffer.capacity()];
    for _ in 0..draws {
        buffer.sample(batch_size, 0, &mut rng, &mut out).unwrap();
        out.slots.iter().for_each(|&s| counts[s as usize] += 1);
    }
    counts
}

/// Pearson's χ² of observed counts against expected probabilities.
fn chi_square(counts: &[u64], probabilities: &[f64]) -> f64 {
    let total: u64 = counts.iter().sum();
    counts
        .iter()
        .zip(probabilities)
        .map(|(&c, &p)| {
            let e = p * total as f64;
            (c as f64 - e).powi(2) / e
        })
        .sum()
}

#[test]
fn sampling_frequencies_follow_the_priorities() {
    let errors = [0.0, 0.1, 0.5, 1.0, 2.0, 4.0, 9.0, 25.0];
    let mut b = buffer(config(8));
    insert_with_errors(&mut b, &errors);
    let p: Vec<f64> = errors.iter().map(|&e| (f64::from(e) + 1e-6).sqrt()).collect();
    let total: f64 = p.iter().sum();
    let expected: Vec<f64> = p.iter().map(|x| x / total).collect();
    // Batches of 32 (stratified: 4 segments per item on average) and of 3 (coarser than the items).
    for (batch_size, draws) in [(32, 20_000), (3, 100_000)] {
        let counts = sample_counts(&mut b, batch_size, draws, 11);
        let n = (batch_size * draws) as f64;
        // 7 degrees of freedom: P(χ² > 24.32) = 0.001.
        let chi2 = chi_square(&counts, &expected);
        assert!(chi2 < 24.32, "batch {batch_size}: χ² {chi2}, counts {counts:?}");
        for (c, e) in counts.iter().zip(&expected) {
            let relative = (*c as f64 / n - e).abs() / e;
            assert!(relative < 0.03 || *e < 0.01, "batch {batch_size}: {c} vs {}", e * n);
        }
    }
    assert_eq!(b.counters().sampled_total, 32 * 20_000 + 3 * 100_000);
}

#[test]
fn equal_priorities_and_batch_equal_to_len_sample_each_item_once() {
    // Stratification: one draw per segment, and with equal priorities segment i is item i.
    let mut b = buffer(config(8));
    insert_with_errors(&mut b, &[1.0; 8]);
    let mut out = SampledBatch::new();
    b.sample(8, 0, &mut StdRng::seed_from_u64(3), &mut out).unwrap();
    assert_eq!(out.slots, [0, 1, 2, 3, 4, 5, 6, 7]);
}

#[test]
fn importance_weights_are_exact_on_a_small_case() {
    // α = 1 and ε = 0.5 make the priorities 1, 1, 2 (exact in binary): total 4, P = ¼, ¼, ½.
    let cfg = ReplayConfig { alpha: 1.0, epsilon: 0.5, ..config(3) };
    let mut b = buffer(cfg);
    insert_with_errors(&mut b, &[0.5, 0.5, 1.5]);
    let mut out = SampledBatch::new();
    // Four segments of width 1: [0,1) → slot 0, [1,2) → slot 1, [2,4) → slot 2 twice.
    b.sample(4, 0, &mut StdRng::seed_from_u64(5), &mut out).unwrap();
    assert_eq!(out.slots, [0, 1, 2, 2]);
    assert_eq!(out.beta, 0.4);
    // w = (3 · P)^−0.4: slots 0, 1: 0.75^−0.4 (the maximum); slot 2: 1.5^−0.4. Normalised:
    // 1, 1, 2^−0.4, 2^−0.4.
    let w2 = 2f64.powf(-0.4);
    let expected = [1.0, 1.0, w2, w2];
    for (w, e) in out.is_weights.iter().zip(expected) {
        assert!((f64::from(*w) - e).abs() < 1e-7, "{:?} vs {expected:?}", out.is_weights);
    }
    // At the end of the schedule β = 1: the weight ratio is the inverse probability ratio.
    b.sample(4, ReplayConfig::default().beta_anneal_steps, &mut StdRng::seed_from_u64(5), &mut out).unwrap();
    assert_eq!(out.beta, 1.0);
    assert_eq!(out.is_weights, [1.0, 1.0, 0.5, 0.5]);
}

#[test]
fn priorities_follow_the_formula_and_new_items_get_the_maximum() {
    let mut b = buffer(config(8));
    let first = b.insert_batch(OwnedBatch::run(DIMS, 0, 0, 2).batch()).unwrap();
    for id in &first.inserted {
        assert_eq!(b.get(*id).unwrap().priority, 1.0, "empty buffer: 1.0 as the paper");
    }
    let with = insert_with_errors(&mut b, &[3.0, 8.0]);
    let p = |e: f64| (e + 1e-6).powf(0.5);
    assert_eq!(b.get(with.inserted[0]).unwrap().priority, p(3.0));
    assert_eq!(b.get(with.inserted[1]).unwrap().priority, p(8.0));
    let without = b.insert_batch(OwnedBatch::run(DIMS, 1, 0, 2).batch()).unwrap();
    for id in &without.inserted {
        assert_eq!(b.get(*id).unwrap().priority, p(8.0));
    }
    let stats = b.priority_stats().unwrap();
    assert_eq!((stats.count, stats.min, stats.max), (6, 1.0, p(8.0)));
}

#[test]
fn stale_generation_updates_are_ignored() {
    let mut b = buffer(config(4));
    insert_with_errors(&mut b, &[1.0; 4]);
    let mut out = SampledBatch::new();
    b.sample(4, 0, &mut StdRng::seed_from_u64(1), &mut out).unwrap();
    assert!(out.generations.iter().all(|&g| g == 0));
    // Meanwhile slots 0 and 1 are overwritten (generation 1).
    let newer = insert_with_errors(&mut b, &[2.0, 2.0]);
    assert_eq!(newer.overwritten, 2);
    let outcome = b.update_priorities(&out.slots, &out.generations, &[9.0; 4]).unwrap();
    assert_eq!(outcome, UpdateOutcome { applied: 2, stale: 2 });
    let p = |e: f64| (e + 1e-6).powf(0.5);
    for id in newer.inserted {
        assert_eq!(b.get(id).unwrap().priority, p(2.0), "the new occupant keeps its priority");
    }
    assert_eq!(b.get(SlotRef { slot: 2, generation: 0 }).unwrap().priority, p(9.0));
    // A generation from the future is just as stale.
    let outcome = b.update_priorities(&[3], &[7], &[1.0]).unwrap();
    assert_eq!(outcome.stale, 1);
    let c = b.counters();
    assert_eq!((c.updates_applied, c.updates_stale), (2, 3));
}

#[test]
fn wrap_around_keeps_linked_next_observations_right() {
    let mut b = buffer(config(5));
    let mut ledger = Ledger::default();
    let mut rng = StdRng::seed_from_u64(9);
    let mut out = SampledBatch::new();
    // Runs of 3 steps: batches cross the wrap point (slots 3, 4, 0 ...) and continue an episode
    // across calls, so next observations are linked rows in every position.
    for call in 0..7u32 {
        let batch = OwnedBatch::run(DIMS, u32::from(call == 3), call * 3, 3);
        let outcome = b.insert_batch(batch.batch()).unwrap();
        ledger.record(&batch, &outcome);
        b.sample(16, 0, &mut rng, &mut out).unwrap();
        for i in 0..out.len() {
            let id = SlotRef { slot: out.slots[i], generation: out.generations[i] };
            let e = &ledger.0[&id];
            assert_eq!(&out.observations[i * 3..(i + 1) * 3], &e.observation[..]);
            assert_eq!(&out.next_observations[i * 3..(i + 1) * 3], &e.next_observation[..]);
            assert_eq!(&out.actions[i * 2..(i + 1) * 2], &e.action[..]);
            assert_eq!((out.rewards[i], out.terminated[i]), (e.reward, e.terminated));
        }
    }
    // 21 inserted into 5 slots: the oldest went first, generations grew.
    assert_eq!(b.len(), 5);
    let live: Vec<SlotRef> = b.live_slots().collect();
    let expect = |g: u64| SlotRef { slot: g % 5, generation: g / 5 };
    assert_eq!(live, (16..21).map(expect).collect::<Vec<_>>());
    assert!(b.get(expect(15)).is_none());
}

#[test]
fn early_evictions_are_never_sampled_and_their_updates_are_stale() {
    // Three rows for four slots: alternating single steps leave one transition live.
    let cfg = ReplayConfig { observation_rows: Some(3), ..config(4) };
    let mut b = buffer(cfg);
    let first = b.insert_batch(OwnedBatch::run(DIMS, 0, 0, 1).batch()).unwrap();
    let second = b.insert_batch(OwnedBatch::run(DIMS, 1, 0, 1).batch()).unwrap();
    assert_eq!((second.evicted_early, second.overwritten, b.len()), (1, 0, 1));
    assert_eq!(b.counters().evicted_early, 1);
    assert_eq!(b.tree.get(0), 0.0, "the evicted leaf is cleared");
    assert_eq!(b.tree.total(), 1.0);
    let mut out = SampledBatch::new();
    b.sample(10, 0, &mut StdRng::seed_from_u64(0), &mut out).unwrap();
    assert!(out.slots.iter().all(|&s| s == 1));
    let stale = b.update_priorities(&[0], &[first.inserted[0].generation], &[5.0]).unwrap();
    assert_eq!(stale.stale, 1);
}

#[test]
fn a_batch_larger_than_the_ring_keeps_its_newest_transitions() {
    let mut b = buffer(config(4));
    let batch = OwnedBatch::run(DIMS, 0, 0, 10).with_td((0..10).map(|i| i as f32).collect());
    let outcome = b.insert_batch(batch.batch()).unwrap();
    // Default rows for 4 slots are 5, just enough for one run: no early evictions.
    assert_eq!((outcome.inserted.len(), outcome.overwritten, outcome.evicted_early), (10, 6, 0));
    assert_eq!(b.len(), 4);
    let p = |e: f64| (e + 1e-6).powf(0.5);
    for (t, id) in outcome.inserted.iter().enumerate() {
        assert_eq!(b.get(*id).map(|v| v.priority), (t >= 6).then(|| p(t as f64)));
    }
    let expected_total: f64 = (6..10).map(|t| p(t as f64)).sum();
    assert!((b.tree.total() - expected_total).abs() < 1e-12);
}

#[test]
fn invalid_inputs_are_rejected_and_change_nothing() {
    let mut b = buffer(config(8));
    insert_with_errors(&mut b, &[1.0]);
    let before = (b.len(), b.counters(), b.tree.total());
    let good = OwnedBatch::run(DIMS, 0, 1, 3);
    let mut bad = good.clone().with_td(vec![1.0, -0.5, 1.0]);
    assert_eq!(b.insert_batch(bad.batch()), Err(ReplayError::InvalidAbsTdError { index: 1, value: -0.5 }));
    for value in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        bad.abs_td_errors = Some(vec![1.0, 1.0, value]);
        assert!(matches!(b.insert_batch(bad.batch()), Err(ReplayError::InvalidAbsTdError { index: 2, .. })));
    }
    bad.abs_td_errors = Some(vec![1.0]);
    let err = b.insert_batch(bad.batch()).unwrap_err();
    assert_eq!(err.to_string(), "abs_td_errors has 1 values, expected 3");
    let mut nan = good.clone();
    nan.next_observations[4] = f32::NAN;
    assert_eq!(
        b.insert_batch(nan.batch()),
        Err(ReplayError::NonFinite { field: "next_observations", index: 4 })
    );
    let mut inf = good.clone();
    inf.rewards[2] = f32::INFINITY;
    assert_eq!(b.insert_batch(inf.batch()).unwrap_err().to_string(), "rewards[2] is not finite");
    // Updates: all-or-nothing even when the bad value comes after good ones.
    for value in [f32::NAN, -1.0, f32::INFINITY] {
        let err = b.update_priorities(&[0, 0], &[0, 0], &[3.0, value]).unwrap_err();
        assert!(matches!(err, ReplayError::InvalidAbsTdError { index: 1, .. }));
    }
    assert_eq!(
        b.update_priorities(&[0, 8], &[0, 0], &[1.0, 1.0]),
        Err(ReplayError::SlotOutOfRange { index: 1, slot: 8, capacity: 8 })
    );
    assert_eq!(
        b.update_priorities(&[0, 1], &[0], &[1.0, 1.0]),
        Err(ReplayError::Length { field: "generations", expected: 2, found: 1 })
    );
    assert_eq!((b.len(), b.counters(), b.tree.total()), before);
}

#[test]
fn dimension_mismatches_are_rejected() {
    let mut b = buffer(config(8));
    let other = Dims { obs_dim: 4, act_dim: 2 };
    let wrong_obs = OwnedBatch::run(other, 0, 0, 2);
    assert_eq!(
        b.insert_batch(wrong_obs.batch()),
        Err(ReplayError::Length { field: "observations", expected: 6, found: 8 })
    );
    let mut wrong_act = OwnedBatch::run(DIMS, 0, 0, 2);
    wrong_act.actions.pop();
    assert_eq!(
        b.insert_batch(wrong_act.batch()).unwrap_err().to_string(),
        "actions has 3 values, expected 4"
    );
    let mut wrong_flags = OwnedBatch::run(DIMS, 0, 0, 2);
    wrong_flags.terminated.push(false);
    assert!(matches!(
        b.insert_batch(wrong_flags.batch()),
        Err(ReplayError::Length { field: "terminated", .. })
    ));
    assert!(b.is_empty());
    assert_eq!(
        ReplayBuffer::new(config(8), Dims { obs_dim: 0, act_dim: 1 }).unwrap_err(),
        ReplayError::Config(ConfigError::ObsDim)
    );
}

#[test]
fn sampling_needs_a_batch_and_data() {
    let mut b = buffer(config(8));
    let mut out = SampledBatch::new();
    let mut rng = StdRng::seed_from_u64(0);
    assert_eq!(b.sample(4, 0, &mut rng, &mut out), Err(ReplayError::Empty));
    insert_with_errors(&mut b, &[1.0]);
    assert_eq!(b.sample(0, 0, &mut rng, &mut out), Err(ReplayError::ZeroBatchSize));
    let empty = b.insert_batch(OwnedBatch::run(DIMS, 0, 0, 0).batch()).unwrap();
    assert_eq!(empty, InsertOutcome::default());
}

#[test]
fn uniform_mode_samples_uniformly_with_unit_weights() {
    let errors = [0.0, 0.1, 0.5, 1.0, 2.0, 4.0, 9.0, 25.0];
    let cfg = ReplayConfig { mode: SamplingMode::Uniform, ..config(8) };
    let mut b = buffer(cfg);
    insert_with_errors(&mut b, &errors);
    let counts = sample_counts(&mut b, 64, 5_000, 17);
    let chi2 = chi_square(&counts, &[1.0 / 8.0; 8]);
    assert!(chi2 < 24.32, "χ² {chi2}, counts {counts:?}");
    let mut out = SampledBatch::new();
    b.sample(64, 0, &mut StdRng::seed_from_u64(1), &mut out).unwrap();
    assert!(out.is_weights.iter().all(|&w| w == 1.0) && out.is_weights.len() == 64);
    // Priorities are still kept, for diagnostics and for a later prioritized run.
    let outcome = b.update_priorities(&out.slots, &out.generations, &[1.0; 64]).unwrap();
    assert_eq!(outcome.applied, 64);
}

#[test]
fn bytes_for_is_exact() {
    // Ant-v5, 1M: rows (1M + 1M/32 + 1) × 105 × 4 + 1M × (8×4 + 4 + 1 + 4) + 24 × 2^20.
    let ant = Dims { obs_dim: 105, act_dim: 8 };
    let bytes = ReplayBuffer::bytes_for(&ReplayConfig::default(), ant);
    assert_eq!(bytes, 1_031_251 * 420 + 1_000_000 * 41 + 24 * (1 << 20));
    assert!(bytes <= 500_000_000);
    let b = buffer(config(10));
    let s = &b.storage;
    let allocated = 4 * (s.rows.len() + s.actions.len() + s.rewards.len() + s.next_rows.len())
        + s.terminated.len()
        + 8 * (2 * b.tree.leaf_count() + b.tree.leaf_count());
    assert_eq!(ReplayBuffer::bytes_for(b.config(), DIMS), allocated as u64);
    let small = ReplayConfig { memory_budget_bytes: allocated as u64 - 1, ..config(10) };
    assert!(matches!(
        ReplayBuffer::new(small, DIMS),
        Err(ReplayError::Config(ConfigError::OverBudget { .. }))
    ));
}

/// Random streams, batch sizes, ring and row sizes, TD errors and updates: every sample must read
/// back exactly what was inserted under its identity, and a leaf is positive exactly when its slot
/// is live.
#[test]
fn random_use_keeps_samples_exact_and_leaves_consistent() {
    use rand::Rng;
    let mut rng = StdRng::seed_from_u64(2024);
    let mut out = SampledBatch::new();
    for case in 0..100 {
        let capacity = rng.random_range(1..20);
        let rows = rng.random_range(2..45);
        let mut b = buffer(ReplayConfig { observation_rows: Some(rows), ..config(capacity) });
        let mut ledger = Ledger::default();
        let mut steps = [0u32; 3];
        for _ in 0..40 {
            let stream = rng.random_range(0..3);
            let n = rng.random_range(0..8);
            let mut batch = OwnedBatch::run(DIMS, stream as u32, steps[stream], n);
            steps[stream] += n as u32 + u32::from(rng.random_bool(0.2)) * 50;
            if rng.random_bool(0.5) {
                batch = batch.with_td((0..n).map(|_| rng.random_range(0.0..10.0)).collect());
            }
            let outcome = b.insert_batch(batch.batch()).unwrap();
            ledger.record(&batch, &outcome);
            if b.is_empty() {
                continue;
            }
            b.sample(rng.random_range(1..10), 0, &mut rng, &mut out).unwrap();
            for i in 0..out.len() {
                let id = SlotRef { slot: out.slots[i], generation: out.generations[i] };
                let view = b.get(id).expect("sampled transitions are live");
                let e = &ledger.0[&id];
                assert_eq!(view.observation, &e.observation[..], "case {case}");
                assert_eq!(view.next_observation, &e.next_observation[..], "case {case}");
                assert_eq!(&out.next_observations[i * 3..(i + 1) * 3], &e.next_observation[..]);
                assert_eq!(&out.observations[i * 3..(i + 1) * 3], &e.observation[..]);
                assert!(out.is_weights[i] > 0.0 && out.is_weights[i] <= 1.0);
            }
            let errors: Vec<f32> = (0..out.len()).map(|_| rng.random_range(0.0..10.0)).collect();
            b.update_priorities(&out.slots, &out.generations, &errors).unwrap();
            let live: Vec<usize> = b.live_slots().map(|id| id.slot as usize).collect();
            for slot in 0..capacity {
                assert_eq!(b.tree.get(slot) > 0.0, live.contains(&slot), "case {case}, slot {slot}");
            }
            let sum: f64 = live.iter().map(|&s| b.tree.get(s)).sum();
            assert!((b.tree.total() - sum).abs() <= 1e-12 * sum);
        }
    }
}
