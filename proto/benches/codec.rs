//! Codec throughput: encode and decode (checksum, bincode, validation) of the messages on the hot
//! paths, led by a 128-transition Ant batch (obs 105, act 8).
//!
//! `cargo bench -p proto --bench codec` prints µs per message and MB/s of frame bytes;
//! `cargo bench -p proto --bench codec -- --test` runs each case once as a smoke test (CI).

use std::hint::black_box;
use std::time::{Duration, Instant};

use proto::{
    ExperienceBatch, Message, SampleReply, SampledBatch, Transitions, WeightsSnapshot, decode, encode,
};

/// Deterministic, non-trivial floats (xorshift), so the payload is not all-zero.
fn noise(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        })
        .collect()
}

fn transitions(n: usize, obs_dim: u32, act_dim: u32) -> Transitions {
    let (o, a) = (obs_dim as usize, act_dim as usize);
    Transitions {
        obs_dim,
        act_dim,
        observations: noise(n * o, 1),
        actions: noise(n * a, 2),
        rewards: noise(n, 3),
        next_observations: noise(n * o, 4),
        terminated: (0..n).map(|i| i % 50 == 0).collect(),
    }
}

fn ant_experience(n: usize) -> ExperienceBatch {
    ExperienceBatch {
        executor_id: 0,
        stream: 0,
        seq: 1,
        weights_version: 1000,
        env_steps: 128_000,
        transitions: transitions(n, 105, 8),
        td_errors: noise(n, 5).iter().map(|x| x.abs()).collect(),
    }
}

fn ant_sample(n: usize) -> SampleReply {
    SampleReply::Batch(SampledBatch {
        request_id: 1,
        learner_step: 1000,
        slots: (0..n as u64).map(|i| i * 7919 % 1_000_000).collect(),
        generations: vec![1; n],
        is_weights: noise(n, 6).iter().map(|x| x.abs()).collect(),
        transitions: transitions(n, 105, 8),
    })
}

/// Mean time per call of `f`, over at least `min_time` (and at least 10 calls) after a short warm-up.
fn time_per_call(min_time: Duration, mut f: impl FnMut()) -> Duration {
    for _ in 0..10 {
        f();
    }
    let (mut calls, start) = (0u32, Instant::now());
    loop {
        for _ in 0..10 {
            f();
        }
        calls += 10;
        if start.elapsed() >= min_time {
            return start.elapsed() / calls;
        }
    }
}

fn bench<M: Message + PartialEq + std::fmt::Debug>(name: &str, msg: &M, min_time: Duration) {
    let frame = encode(msg);
    assert_eq!(decode::<M>(&frame).as_ref(), Ok(msg), "{name}: round trip");
    let encode_t = time_per_call(min_time, || drop(black_box(encode(black_box(msg)))));
    let decode_t = time_per_call(min_time, || drop(black_box(decode::<M>(black_box(&frame)))));
    let mb = frame.len() as f64 / 1e6;
    println!(
        "{name:<34} {:>9} B  encode {:>8.1} µs {:>7.0} MB/s  decode {:>8.1} µs {:>7.0} MB/s",
        frame.len(),
        encode_t.as_secs_f64() * 1e6,
        mb / encode_t.as_secs_f64(),
        decode_t.as_secs_f64() * 1e6,
        mb / decode_t.as_secs_f64(),
    );
}

fn main() {
    // `cargo bench` passes `--bench`; `-- --test` asks for a quick smoke run.
    let smoke = std::env::args().any(|a| a == "--test");
    let min_time = if smoke { Duration::ZERO } else { Duration::from_secs(1) };
    bench("experience: 128 Ant transitions", &ant_experience(128), min_time);
    bench("experience: 1000 Ant transitions", &ant_experience(1000), min_time);
    bench("sample reply: 256 Ant transitions", &ant_sample(256), min_time);
    let weights = WeightsSnapshot { version: 1, learner_step: 1, safetensors: vec![7; 1 << 20], stack: None };
    bench("weights: 1 MiB safetensors", &weights, min_time);
}
