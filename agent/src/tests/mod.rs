//! Cross-module tests: policy maths against brute force, gradients against finite differences,
//! training, snapshots and checkpoints, the policy stack.

mod gradients;
mod policy_math;
mod stack;
mod training;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

use crate::{AgentConfig, Batch, LatentPolicy, vars::SeededInit};

/// A tiny level: obs 3, act 4, embedding 5 -> 3, s/t nets 4 -> 3 -> 2.
fn tiny() -> AgentConfig {
    AgentConfig {
        critic_hidden: vec![6, 5],
        embedding_layers: vec![5, 3],
        coupling_hidden: vec![3],
        ..AgentConfig::for_task(3, 4)
    }
}

/// A small level that learns quickly enough for a unit test.
fn small() -> AgentConfig {
    AgentConfig {
        critic_hidden: vec![32, 32],
        embedding_layers: vec![32, 32, 4],
        learning_rate: 1e-3,
        ..AgentConfig::for_task(6, 2)
    }
}

fn f64_policy(cfg: &AgentConfig, seed: u64) -> (VarMap, LatentPolicy) {
    let map = VarMap::new();
    let policy =
        LatentPolicy::new(cfg, SeededInit::new(seed).builder(&map, DType::F64, &Device::Cpu)).unwrap();
    (map, policy)
}

fn normal(rng: &mut StdRng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.sample(StandardNormal)).collect()
}

fn tensor(values: Vec<f64>, rows: usize) -> Tensor {
    let cols = values.len() / rows;
    Tensor::from_vec(values, (rows, cols), &Device::Cpu).unwrap()
}

fn random_batch(cfg: &AgentConfig, size: usize, seed: u64) -> Batch {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut draw = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    let actions = draw(size * cfg.act_dim).iter().map(|a| a.tanh()).collect();
    Batch {
        size,
        observations: draw(size * cfg.obs_dim),
        actions,
        rewards: draw(size),
        next_observations: draw(size * cfg.obs_dim),
        terminated: (0..size).map(|i| if i % 7 == 3 { 1.0 } else { 0.0 }).collect(),
        is_weights: None,
    }
}
