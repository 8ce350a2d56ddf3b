//! The learner's checkpoint loader with both backends, the param server's weights check (against
//! the run's networks, and against none) and an executor's weights load, on arbitrary bytes and on
//! mutations of a valid checkpoint (byte flips: safetensors has no checksum, so each one reaches
//! the header parser, the shape checks and the import).
#![no_main]

use std::sync::OnceLock;

use agent::{Actor, AgentConfig, AnyLearner, Backend, Checkpoint, ParamSnapshot, snapshot_schema};
use libfuzzer_sys::fuzz_target;

fn config() -> AgentConfig {
    AgentConfig {
        obs_dim: 3,
        act_dim: 2,
        critic_hidden: vec![4],
        embedding_layers: vec![4, 2],
        coupling_hidden: vec![2],
        ..AgentConfig::default()
    }
}

fn valid() -> &'static [u8] {
    static CHECKPOINT: OnceLock<Vec<u8>> = OnceLock::new();
    CHECKPOINT.get_or_init(|| {
        let learner = AnyLearner::new(config(), 1, Backend::Fused).expect("a tiny learner");
        learner.checkpoint().expect("its checkpoint").safetensors
    })
}

fn load(bytes: &[u8]) {
    let config = config();
    let checkpoint = Checkpoint { step: 0, safetensors: bytes.to_vec() };
    for backend in [Backend::Candle, Backend::Fused] {
        let _ = AnyLearner::from_checkpoint(config.clone(), &checkpoint, backend);
    }
    let _ = agent::checkpoint_metadata(bytes);
    let schema = snapshot_schema(&config);
    let _ = param_server::check_body(bytes, Some(&schema));
    let _ = param_server::check_body(bytes, None);
    if let Ok(mut actor) = Actor::new(config, 0) {
        let _ = actor.load(&ParamSnapshot { version: 1, safetensors: bytes.to_vec() });
    }
}

fuzz_target!(|data: &[u8]| {
    load(data);
    let mut bytes = valid().to_vec();
    for edit in data.chunks_exact(4) {
        let at = u32::from_le_bytes([edit[0], edit[1], edit[2], 0]) as usize % bytes.len();
        bytes[at] ^= edit[3];
    }
    if data.len() % 4 == 1 {
        bytes.truncate(data[0] as usize * bytes.len() / 256);
    }
    load(&bytes);
});
