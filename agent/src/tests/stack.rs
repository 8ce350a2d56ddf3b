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

#[test]
fn a_stack_travels_as_weights_and_inside_a_checkpoint() {
    let low_cfg = AgentConfig { critic_hidden: vec![8], ..small() };
    let low = trained_level(&low_cfg, 1);
    let stack = PolicyStack::new(vec![low.clone()]).unwrap();
    let hash = stack.content_hash().unwrap();

    // Rebuilt from what it ships: the same acting weights, the bottom level's settings.
    let shipped: Vec<Vec<u8>> = stack.weights().into_iter().map(<[u8]>::to_vec).collect();
    let rebuilt = PolicyStack::from_weights(&shipped).unwrap();
    assert_eq!(rebuilt.content_hash().unwrap(), hash);
    assert!(rebuilt.configs().next().unwrap().squash);
    // A learner checkpoint of the level (Adam moments and all) reads as the same level.
    let mut learner = Learner::new(low_cfg.clone(), 1).unwrap();
    let batch = random_batch(&low_cfg, 16, 1);
    for _ in 0..3 {
        learner.update(&batch).unwrap();
    }
    let from_checkpoint = PolicyStack::from_weights(&[learner.checkpoint().unwrap().safetensors]).unwrap();
    assert_eq!(from_checkpoint.content_hash().unwrap(), hash);

    // Embedded in the level above's checkpoint, and read back from it.
    let high = Learner::new(low_cfg.level_above(), 2).unwrap();
    let plain = high.checkpoint().unwrap();
    let embedded = stack.embed(&plain).unwrap();
    assert_eq!(embedded.step, plain.step);
    let tensors = crate::params::decode(&embedded.safetensors).unwrap();
    assert_eq!(PolicyStack::from_embedded(&tensors).unwrap().content_hash().unwrap(), hash);
    assert!(
        PolicyStack::from_embedded(&crate::params::decode(&plain.safetensors).unwrap()).unwrap().is_empty()
    );
    // The level above resumes from it as from its own checkpoint.
    assert!(Learner::from_checkpoint(low_cfg.level_above(), &embedded).is_ok());

    // Other weights hash differently; a gap in the levels and garbage are errors.
    let other = PolicyStack::new(vec![trained_level(&low_cfg, 9)]).unwrap();
    assert_ne!(other.content_hash().unwrap(), hash);
    let mut gap = tensors.clone();
    let names: Vec<String> = gap.keys().filter(|n| n.starts_with("frozen.0.")).cloned().collect();
    for name in names {
        let t = gap.remove(&name).unwrap();
        gap.insert(name.replacen("frozen.0.", "frozen.1.", 1), t);
    }
    assert!(PolicyStack::from_embedded(&gap).unwrap_err().to_string().contains("level 0 is missing"));
    assert!(PolicyStack::from_weights(&[vec![1u8, 2, 3]]).is_err());
}
