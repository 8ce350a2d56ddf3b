//! The learner's checkpoint loader on arbitrary bytes as the checkpoint file, with both backends;
//! the same bytes as a weights snapshot body through the param server's check (against the run's
//! networks, and against none) and through an executor's load.
#![no_main]

use agent::{Actor, AgentConfig, AnyLearner, Backend, Checkpoint, ParamSnapshot, snapshot_schema};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let config = AgentConfig {
        obs_dim: 3,
        act_dim: 2,
        critic_hidden: vec![4],
        embedding_layers: vec![4, 2],
        coupling_hidden: vec![2],
        ..AgentConfig::default()
    };
    let checkpoint = Checkpoint { step: 0, safetensors: data.to_vec() };
    for backend in [Backend::Candle, Backend::Fused] {
        let _ = AnyLearner::from_checkpoint(config.clone(), &checkpoint, backend);
    }
    let schema = snapshot_schema(&config);
    let _ = param_server::check_body(data, Some(&schema));
    let _ = param_server::check_body(data, None);
    if let Ok(mut actor) = Actor::new(config, 0) {
        let _ = actor.load(&ParamSnapshot { version: 1, safetensors: data.to_vec() });
    }
});
