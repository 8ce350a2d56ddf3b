//! Replay hot-path figures on Ant-v5 dimensions (obs 105, action 8), plain `Instant` timing.
//!
//! `cargo bench -p replay --bench replay` fills a 1M-transition buffer (about 499 MB);
//! `cargo bench -p replay --bench replay -- --test` runs the same code on 10K for CI.

use std::hint::black_box;
use std::time::{Duration, Instant};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use replay::{Dims, ReplayBuffer, ReplayConfig, SampledBatch, SumTree, TransitionBatch};

const ANT: Dims = Dims { obs_dim: 105, act_dim: 8 };
const INSERT_BATCH: usize = 64;
const SAMPLE_BATCH: usize = 128;

/// 64 consecutive steps of one stream (next obs of step t = obs of step t + 1), with TD errors.
struct Chunk {
    observations: Vec<f32>,
    next_observations: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    abs_td_errors: Vec<f32>,
}

impl Chunk {
    fn new(rng: &mut StdRng) -> Self {
        let states: Vec<f32> = (0..(INSERT_BATCH + 1) * ANT.obs_dim).map(|_| rng.random()).collect();
        Self {
            observations: states[..INSERT_BATCH * ANT.obs_dim].to_vec(),
            next_observations: states[ANT.obs_dim..].to_vec(),
            actions: (0..INSERT_BATCH * ANT.act_dim).map(|_| rng.random_range(-1.0..1.0)).collect(),
            rewards: (0..INSERT_BATCH).map(|_| rng.random()).collect(),
            terminated: vec![false; INSERT_BATCH],
            abs_td_errors: (0..INSERT_BATCH).map(|_| rng.random_range(0.0..10.0)).collect(),
        }
    }

    fn batch(&self) -> TransitionBatch<'_> {
        TransitionBatch {
            observations: &self.observations,
            actions: &self.actions,
            rewards: &self.rewards,
            next_observations: &self.next_observations,
            terminated: &self.terminated,
            abs_td_errors: Some(&self.abs_td_errors),
        }
    }
}

/// Runs `f` repeatedly for about `budget`; returns calls per second.
fn rate(budget: Duration, mut f: impl FnMut()) -> f64 {
    let start = Instant::now();
    let mut calls = 0u64;
    while start.elapsed() < budget {
        for _ in 0..16 {
            f();
        }
        calls += 16;
    }
    calls as f64 / start.elapsed().as_secs_f64()
}

fn main() {
    let quick = std::env::args().any(|a| a == "--test");
    let capacity = if quick { 10_000 } else { 1_000_000 };
    let budget = Duration::from_millis(if quick { 50 } else { 3_000 });
    let cfg = ReplayConfig { capacity_transitions: capacity, ..ReplayConfig::default() };
    println!(
        "replay bench: capacity {capacity}, obs {}, act {}, {} bytes ({:.1} per transition)",
        ANT.obs_dim,
        ANT.act_dim,
        ReplayBuffer::bytes_for(&cfg, ANT),
        ReplayBuffer::bytes_for(&cfg, ANT) as f64 / capacity as f64
    );
    let mut rng = StdRng::seed_from_u64(0);
    // Distinct data per chunk would cost 0.5 GB more; 16 chunks in turn look the same to the buffer.
    let chunks: Vec<Chunk> = (0..16).map(|_| Chunk::new(&mut rng)).collect();
    let mut buffer = ReplayBuffer::new(cfg, ANT).expect("valid config");

    let start = Instant::now();
    let mut i = 0;
    while buffer.len() < capacity {
        buffer.insert_batch(chunks[i % chunks.len()].batch()).expect("valid batch");
        i += 1;
    }
    let fill = start.elapsed().as_secs_f64();
    println!(
        "fill to {capacity}: {fill:.2} s ({:.0} transitions/s), evicted early {}",
        capacity as f64 / fill,
        buffer.counters().evicted_early
    );

    let mut i = 0;
    let inserts = rate(budget, || {
        black_box(buffer.insert_batch(chunks[i % chunks.len()].batch()).expect("valid batch"));
        i += 1;
    });
    println!(
        "insert_batch(64) on a full buffer: {inserts:.0} batches/s ({:.2} M transitions/s)",
        inserts * INSERT_BATCH as f64 / 1e6
    );

    let mut out = SampledBatch::new();
    let mut step = 0u64;
    let samples = rate(budget, || {
        buffer.sample(SAMPLE_BATCH, step, &mut rng, &mut out).expect("non-empty");
        black_box(&out);
        step += 1;
    });
    println!("sample(128) prioritized: {samples:.0} batches/s ({:.1} µs each)", 1e6 / samples);

    let errors: Vec<f32> = (0..SAMPLE_BATCH).map(|i| i as f32 * 0.05).collect();
    // Many distinct sampled batches in turn, so that the updates touch cold paths as in training.
    let batches: Vec<SampledBatch> = (0..512)
        .map(|_| {
            let mut b = SampledBatch::new();
            buffer.sample(SAMPLE_BATCH, 0, &mut rng, &mut b).expect("non-empty");
            b
        })
        .collect();
    let mut k = 0;
    let updates = rate(budget, || {
        let b = &batches[k % batches.len()];
        black_box(buffer.update_priorities(&b.slots, &b.generations, &errors).expect("valid"));
        k += 1;
    });
    println!(
        "update_priorities(128): {updates:.0} calls/s ({:.2} M priority updates/s)",
        updates * SAMPLE_BATCH as f64 / 1e6
    );

    let cycles = rate(budget, || {
        buffer.sample(SAMPLE_BATCH, step, &mut rng, &mut out).expect("non-empty");
        buffer.update_priorities(&out.slots, &out.generations, &errors).expect("valid");
    });
    println!("learner cycle sample(128) + update(128): {cycles:.0} /s");

    let mut tree = SumTree::new(capacity);
    for leaf in 0..capacity {
        tree.set(leaf, rng.random_range(0.1..3.0));
    }
    let leaves: Vec<usize> = (0..4096).map(|_| rng.random_range(0..capacity)).collect();
    let mut j = 0;
    let sets = rate(budget, || {
        tree.set(leaves[j % leaves.len()], (j % 97) as f64 * 0.01 + 0.1);
        j += 1;
    });
    println!("SumTree::set (random leaves of {capacity}): {:.2} M updates/s", sets / 1e6);
    let total = tree.total();
    let mut queries = vec![0.0; SAMPLE_BATCH];
    let mut found = Vec::new();
    let singles = rate(budget, || {
        for q in &mut queries {
            *q = rng.random_range(0.0..total);
        }
        queries.iter().for_each(|&u| {
            black_box(tree.find(u));
        });
    });
    let batched = rate(budget, || {
        for q in &mut queries {
            *q = rng.random_range(0.0..total);
        }
        tree.find_batch(&mut queries, &mut found);
        black_box(&found);
    });
    println!("SumTree 128 finds: one by one {:.1} µs, find_batch {:.1} µs", 1e6 / singles, 1e6 / batched);

    let start = Instant::now();
    let mut bytes = Vec::with_capacity(ReplayBuffer::bytes_for(buffer.config(), ANT) as usize);
    buffer.write_snapshot(&mut bytes).expect("in-memory write");
    let write = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let restored =
        ReplayBuffer::read_snapshot(&mut &bytes[..], buffer.config().clone(), ANT).expect("round trip");
    let read = start.elapsed().as_secs_f64();
    assert_eq!(restored.counters(), buffer.counters());
    println!("snapshot {} bytes: write {write:.2} s, read {read:.2} s (in memory)", bytes.len());
}
