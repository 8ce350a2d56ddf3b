//! The paper's evaluation: episodes in deterministic mode, one latent drawn per evaluation and held
//! for all its episodes (as the original's `deterministic()` context), undiscounted return.

use agent::{Actor, Mode};
use sim::Environment;

/// The outcome of one evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Mean episode length.
    pub mean_length: f64,
}

/// Runs `episodes` deterministic episodes of `actor` on `env` (each to termination or the time limit).
pub fn evaluate(actor: &mut Actor, env: &mut dyn Environment, episodes: u32) -> anyhow::Result<Evaluation> {
    actor.redraw_fixed_latent();
    let (mut total_return, mut total_length) = (0.0, 0.0);
    for _ in 0..episodes {
        let mut observation = to_f32(&env.reset(None));
        loop {
            let act = actor.act(&observation, Mode::Deterministic)?;
            let action = env.spec().action_from_unit(&act.env_action);
            let step = env.step(&action)?;
            total_return += step.reward;
            total_length += 1.0;
            if step.terminated || step.truncated {
                break;
            }
            observation = to_f32(&step.observation);
        }
    }
    let n = f64::from(episodes.max(1));
    Ok(Evaluation { mean_return: total_return / n, mean_length: total_length / n })
}

fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|v| *v as f32).collect()
}
