//! The policy stack: higher levels act through frozen lower levels down to env actions.

use candle_core::{Device, Tensor};

use super::{random_batch, small};
use crate::{Actor, AgentConfig, Learner, Level, Mode, PolicyStack};

fn trained_level(cfg: &AgentConfig, seed: u64) -> Level {
    let mut learner = Learner::new(cfg.clone(), seed).unwrap();
    let batch = random_batch(cfg, 16, seed);
    for _ in 0..3 {
        learner.update(&batch).unwrap();
    }
    Level { config: cfg.clone(), snapshot: learner.snapshot().unwrap() }
}

#[test]
fn two_level_stack_acts_in_the_env_box_and_keeps_lower_level_frozen() {
    let low_cfg = AgentConfig::for_task(6, 4).clone();
    let low_cfg = AgentConfig { critic_hidden: vec![16], embedding_layers: vec![16, 8], ..low_cfg };
    let low = trained_level(&low_cfg, 1);
    let stack = PolicyStack::new(vec![low.clone()]).unwrap();
    let frozen_before = stack.snapshots().unwrap();

    let high_cfg = low_cfg.level_above();
    let mut high = Learner::new(high_cfg.clone(), 2).unwrap();
    // The high level's replay holds latents h: unbounded, N(0, I)-like.
    let mut batch = random_batch(&high_cfg, 32, 3);
    batch.actions.iter_mut().for_each(|a| *a = a.atanh() * 2.0);
    for _ in 0..5 {
        high.update(&batch).unwrap();
    }
    assert_eq!(stack.snapshots().unwrap(), frozen_before, "frozen level changed");

    let mut actor = Actor::with_stack(high_cfg.clone(), stack, 3).unwrap();
    actor.load(&high.snapshot().unwrap()).unwrap();
    let obs: Vec<f32> = batch.observations[..6].to_vec();
    for mode in [Mode::Explore, Mode::Deterministic] {
        for _ in 0..20 {
            let act = actor.act(&obs, mode).unwrap();
            assert_eq!((act.action.len(), act.env_action.len()), (4, 4));
            assert!(act.env_action.iter().all(|a| a.abs() <= 1.0), "{:?}", act.env_action);
        }
    }
    // The env action is the low level's deterministic map of the high level's h.
    let act = actor.act(&obs, Mode::Explore).unwrap();
    let low_only = PolicyStack::new(vec![low]).unwrap();
    let t = |v: &[f32], n| Tensor::from_slice(v, (1, n), &Device::Cpu).unwrap();
    let mapped = low_only.env_action(&t(&obs, 6), &t(&act.action, 4)).unwrap();
    assert_eq!(mapped.flatten_all().unwrap().to_vec1::<f32>().unwrap(), act.env_action);
}

#[test]
fn three_level_stack_and_mismatch_errors() {
    let l1 = AgentConfig { critic_hidden: vec![8], ..small() };
    let l2 = l1.level_above();
    let l3 = l2.level_above();
    let stack = PolicyStack::new(vec![trained_level(&l1, 1), trained_level(&l2, 2)]).unwrap();
    assert_eq!(stack.depth(), 2);
    let mut actor = Actor::with_stack(l3.clone(), stack, 1).unwrap();
    actor.load(&Learner::new(l3, 5).unwrap().snapshot().unwrap()).unwrap();
    for _ in 0..10 {
        let act = actor.act(&[0.5; 6], Mode::Explore).unwrap();
        assert!(act.env_action.iter().all(|a| a.abs() <= 1.0) && act.env_action.len() == 2);
    }
    let wide = AgentConfig { act_dim: 4, ..l1.level_above() };
    let stack = PolicyStack::new(vec![trained_level(&l1, 1)]).unwrap();
    assert!(Actor::with_stack(wide.clone(), stack, 1).is_err());
    let err = PolicyStack::new(vec![trained_level(&l1, 1), trained_level(&wide, 1)]).unwrap_err();
    assert!(err.to_string().contains("level 1"));
}
