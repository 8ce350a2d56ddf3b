//! What a checkpoint says about itself: its safetensors metadata names what it contains and the
//! [`AgentConfig`] settings that shaped it, and a learner refuses to resume from it into a run whose
//! settings differ in any of those, naming the setting (a shape change would otherwise fail on a
//! tensor name, or, for `twin_q` or `learn_temperature`, silently drop state).

use std::collections::HashMap;

use crate::config::AgentConfig;
use crate::error::{Error, Result};
use candle_core::Tensor;

use crate::params::{Checkpoint, encode};

/// The metadata key listing what a learner checkpoint holds.
pub const CONTAINS_KEY: &str = "contains";
/// What every learner checkpoint holds, in words (both backends write the same tensors).
pub const CONTAINS: &str = "networks (policy, Q, V, target V), Adam moments and step counts per network, the \
                            temperature and its Adam state when learned, learner step, learner seed";
/// Prefix of the metadata keys that record a setting.
const SETTING_PREFIX: &str = "setting.";

/// The settings a checkpoint cannot be resumed across: network shapes (from the task's widths and
/// the run file), the critic's variant, and which state exists. Learning rates, batch size,
/// discount and the like may change on resume.
pub fn resume_settings(cfg: &AgentConfig) -> Vec<(&'static str, String)> {
    let c = &cfg.categorical;
    let mut settings = vec![
        ("obs_dim", cfg.obs_dim.to_string()),
        ("act_dim", cfg.act_dim.to_string()),
        ("critic_hidden", format!("{:?}", cfg.critic_hidden)),
        ("embedding_layers", format!("{:?}", cfg.embedding_layers)),
        ("embedding_output_relu", cfg.embedding_output_relu.to_string()),
        ("coupling_layers", cfg.coupling_layers.to_string()),
        ("coupling_hidden", format!("{:?}", cfg.coupling_hidden)),
        ("squash", cfg.squash.to_string()),
        ("twin_q", cfg.twin_q.to_string()),
        ("learn_temperature", cfg.learn_temperature.to_string()),
        ("critic", format!("{:?}", cfg.critic)),
    ];
    if cfg.critic == crate::config::Critic::Categorical {
        settings.push((
            "categorical",
            format!("{:?} atoms {} on [{}, {}]", c.variant, c.atoms, c.v_min, c.v_max),
        ));
    }
    settings
}

/// The safetensors bytes of a learner checkpoint of `cfg` at `step` holding `tensors`, with the
/// metadata that says what it holds and the settings that shaped it (both learners write this).
pub(crate) fn checkpoint_bytes(
    tensors: &[(String, Tensor)],
    cfg: &AgentConfig,
    step: u64,
) -> Result<Vec<u8>> {
    let settings: Vec<(String, String)> =
        resume_settings(cfg).into_iter().map(|(k, v)| (format!("{SETTING_PREFIX}{k}"), v)).collect();
    let mut metadata = vec![("step", step.to_string()), (CONTAINS_KEY, CONTAINS.to_string())];
    metadata.extend(settings.iter().map(|(k, v)| (k.as_str(), v.clone())));
    encode(tensors, &metadata)
}

/// The metadata of safetensors bytes (empty when there is none).
pub fn checkpoint_metadata(bytes: &[u8]) -> Result<HashMap<String, String>> {
    let (_, metadata) =
        safetensors::SafeTensors::read_metadata(bytes).map_err(|e| Error::BadSnapshot(e.to_string()))?;
    Ok(metadata.metadata().clone().unwrap_or_default())
}

/// Refuses `checkpoint` for a learner of `cfg` if it records a setting that differs, naming it.
/// Checkpoints written before settings were recorded pass (their tensors are still checked).
pub fn check_resume(cfg: &AgentConfig, checkpoint: &Checkpoint) -> Result<()> {
    let saved = checkpoint_metadata(&checkpoint.safetensors)?;
    for (key, now) in resume_settings(cfg) {
        match saved.get(&format!("{SETTING_PREFIX}{key}")) {
            Some(then) if *then != now => {
                // The widths are not [agent] keys: they come from the task (and HER's goal).
                let source = match key {
                    "obs_dim" | "act_dim" => "the run's task ([train] task, [her])",
                    _ => "the run file",
                };
                return Err(Error::InvalidConfig(format!(
                    "the checkpoint at step {} was trained with [agent] {key} = {then}, {source} gives {now}: \
                     resume with the same setting, or start a new run",
                    checkpoint.step
                )));
            }
            _ => {}
        }
    }
    Ok(())
}
