//! The learner's evaluation: N episodes with the policy's latent chosen by an [`EvalMode`] — the
//! paper's one latent drawn per evaluation and held for all its episodes (as the original's
//! `deterministic()` context), h = 0, or the stochastic policy — undiscounted return.

use agent::{Actor, Mode};
use proto::EvalMode;
use sim::Environment;

/// The outcome of one evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Standard deviation of the episodes' returns (population; 0 for one episode).
    pub std_return: f64,
    /// Mean episode length.
    pub mean_length: f64,
}

/// Runs `episodes` episodes of `actor` on `env` in `mode` (each to termination or the time limit).
pub fn evaluate(
    actor: &mut Actor,
    env: &mut dyn Environment,
    episodes: u32,
    mode: EvalMode,
) -> anyhow::Result<Evaluation> {
    let act_mode = match mode {
        EvalMode::FixedLatent => {
            actor.redraw_fixed_latent();
            Mode::Deterministic
        }
        EvalMode::ZeroLatent => {
            actor.zero_fixed_latent();
            Mode::Deterministic
        }
        EvalMode::Stochastic => Mode::Explore,
    };
    let (mut returns, mut total_length) = (Vec::new(), 0.0);
    for _ in 0..episodes {
        let mut observation = to_f32(&env.reset(None));
        let mut episode_return = 0.0;
        loop {
            let act = actor.act(&observation, act_mode)?;
            let action = env.spec().action_from_unit(&act.env_action);
            let step = env.step(&action)?;
            episode_return += step.reward;
            total_length += 1.0;
            if step.terminated || step.truncated {
                break;
            }
            observation = to_f32(&step.observation);
        }
        returns.push(episode_return);
    }
    let n = f64::from(episodes.max(1));
    let mean_return = returns.iter().sum::<f64>() / n;
    let variance = returns.iter().map(|r| (r - mean_return).powi(2)).sum::<f64>() / n;
    Ok(Evaluation { mean_return, std_return: variance.sqrt(), mean_length: total_length / n })
}

fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|v| *v as f32).collect()
}
