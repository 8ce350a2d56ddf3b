//! Env steps/s of ant-v5 against raw physics (`mj_step` × 5 on the same model) in the same run.
//!
//! `cargo bench -p sim --bench env` prints both rates and their ratio (the goal is ≥ 0.9: the
//! environment's own work, observation and rewards, costs almost nothing next to the physics).
//! `-- --test` runs a short pass only, for CI.

use std::time::Instant;

use rand::{Rng, SeedableRng, rngs::StdRng};
use sim::ant_model::{AntVariant, ant_mjcf};
use sim::physics::Physics;
use sim::{InitState, Task};

fn actions(n: usize) -> Vec<[f64; 8]> {
    let mut rng = StdRng::seed_from_u64(0);
    (0..n).map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0))).collect()
}

/// Steps/s of `mj_step` × 5 with the given controls.
fn raw_physics(actions: &[[f64; 8]]) -> f64 {
    let mut physics =
        Physics::load("ant-v5", &ant_mjcf(AntVariant::V5).expect("bench set-up")).expect("bench set-up");
    let start = InitState { qpos: physics.qpos0(), qvel: vec![0.0; physics.nv()] };
    physics.reset_to(&start).expect("bench set-up");
    let t = Instant::now();
    for a in actions {
        physics.step(a, 5);
    }
    actions.len() as f64 / t.elapsed().as_secs_f64()
}

/// Steps/s of the ant-v5 environment with the same controls (no resets, like the raw loop).
fn environment(actions: &[[f64; 8]]) -> f64 {
    let mut env = sim::make(Task::AntV5, 0).expect("bench set-up");
    let nv = env.spec().nv;
    let mut qpos = vec![0.0; env.spec().nq];
    qpos[2] = 0.75;
    qpos[3] = 1.0;
    env.reset_to(&InitState { qpos, qvel: vec![0.0; nv] }).expect("bench set-up");
    let t = Instant::now();
    let mut total = 0.0;
    for a in actions {
        total += std::hint::black_box(env.step(a).expect("bench set-up")).reward;
    }
    std::hint::black_box(total);
    actions.len() as f64 / t.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--test");
    let (steps, rounds) = if quick { (200, 1) } else { (20_000, 7) };
    let actions = actions(steps);
    // Interleave the two so that a busy neighbour on the machine slows both alike.
    let (mut raw, mut env) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        raw.push(raw_physics(&actions));
        env.push(environment(&actions));
    }
    let (raw, env) = (median(raw), median(env));
    println!("ant-v5 raw mj_step x5   : {raw:>9.0} steps/s (median of {rounds} rounds of {steps})");
    println!("ant-v5 environment step : {env:>9.0} steps/s");
    println!("ratio env / raw physics : {:>9.3}", env / raw);
}
