//! The learner's evaluation: N episodes with the policy's latent chosen by an [`EvalMode`] — the
//! paper's one latent drawn per evaluation and held for all its episodes (as the original's
//! `deterministic()` context), h = 0, or the stochastic policy — undiscounted return (the task's
//! own reward, also with HER) and, with HER, the goal success rate.

use agent::{Actor, Mode};
use proto::{EvalMode, EvalReport};
use sim::Environment;

/// The outcome of one evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Evaluation {
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Standard deviation of the episodes' returns (population; 0 for one episode).
    pub std_return: f64,
    /// Mean episode length.
    pub mean_length: f64,
    /// With HER: the fraction of episodes that reached their goal at some step.
    pub goal_success: Option<f64>,
}

impl Evaluation {
    /// The mean and (population) standard deviation of the returns and the mean length of
    /// `episodes` (zeros for none).
    pub fn of(episodes: &[Episode]) -> Self {
        let n = episodes.len().max(1) as f64;
        let mean_return = episodes.iter().map(|e| e.episode_return).sum::<f64>() / n;
        let variance = episodes.iter().map(|e| (e.episode_return - mean_return).powi(2)).sum::<f64>() / n;
        let mean_length = episodes.iter().map(|e| e.length as f64).sum::<f64>() / n;
        let reached: Option<Vec<bool>> = episodes.iter().map(|e| e.goal_reached).collect();
        let goal_success =
            reached.filter(|r| !r.is_empty()).map(|r| r.iter().filter(|x| **x).count() as f64 / n);
        Self { mean_return, std_return: variance.sqrt(), mean_length, goal_success }
    }

    /// This evaluation as reported on the bus and kept with the best policy: `episodes` episodes in
    /// `mode`, after `epoch`, of the weights at `learner_step`.
    pub fn report(&self, epoch: u64, learner_step: u64, episodes: u32, mode: EvalMode) -> EvalReport {
        EvalReport {
            epoch,
            learner_step,
            episodes,
            mean_return: self.mean_return,
            mean_length: self.mean_length,
            std_return: self.std_return,
            mode,
            goal_success: self.goal_success,
        }
    }
}

/// One evaluation episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Episode {
    /// Undiscounted return.
    pub episode_return: f64,
    /// Steps until termination or the time limit.
    pub length: u64,
    /// With a goal ([`sim::her::GoalEnv`]): whether some step reached it.
    pub goal_reached: Option<bool>,
}

/// Prepares `actor`'s latent for `mode` (the fixed-latent mode draws a new h here) and returns how
/// it must act in every episode of the evaluation.
pub fn prepare_latent(actor: &mut Actor, mode: EvalMode) -> Mode {
    match mode {
        EvalMode::FixedLatent => {
            actor.redraw_fixed_latent();
            Mode::Deterministic
        }
        EvalMode::ZeroLatent => {
            actor.zero_fixed_latent();
            Mode::Deterministic
        }
        EvalMode::Stochastic => Mode::Explore,
    }
}

/// Runs one episode of `actor` acting in `mode` on `env`, reset with `seed` (`None`: the env's own
/// stream), to termination or the time limit.
pub fn run_episode(
    actor: &mut Actor,
    env: &mut dyn Environment,
    mode: Mode,
    seed: Option<u64>,
) -> anyhow::Result<Episode> {
    run_episode_watched(actor, env, mode, seed, &mut |_| {})
}

/// [`run_episode`], calling `watch` with the environment after the reset and after every step
/// (`sac-lsp render` draws a frame there).
pub fn run_episode_watched(
    actor: &mut Actor,
    env: &mut dyn Environment,
    mode: Mode,
    seed: Option<u64>,
    watch: &mut dyn FnMut(&dyn Environment),
) -> anyhow::Result<Episode> {
    let mut observation = to_f32(&env.reset(seed));
    watch(&*env);
    let (mut episode_return, mut length, mut goal_reached) = (0.0, 0, None);
    loop {
        let act = actor.act(&observation, mode)?;
        let action = env.spec().action_from_unit(&act.env_action);
        let step = env.step(&action)?;
        watch(&*env);
        // The task's own reward, with or without a goal (the dissertation reports it for HER too).
        episode_return += step.reward;
        length += 1;
        if let Some(status) = &step.goal {
            goal_reached = Some(goal_reached.unwrap_or(false) || status.reached);
        }
        if step.terminated || step.truncated {
            return Ok(Episode { episode_return, length, goal_reached });
        }
        observation = to_f32(&step.observation);
    }
}

/// Runs `episodes` episodes of `actor` on `env` in `mode` (each to termination or the time limit).
pub fn evaluate(
    actor: &mut Actor,
    env: &mut dyn Environment,
    episodes: u32,
    mode: EvalMode,
) -> anyhow::Result<Evaluation> {
    let act_mode = prepare_latent(actor, mode);
    let episodes: Vec<Episode> =
        (0..episodes).map(|_| run_episode(actor, env, act_mode, None)).collect::<anyhow::Result<_>>()?;
    Ok(Evaluation::of(&episodes))
}

fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|v| *v as f32).collect()
}
