//! What every MuJoCo task shares: its physics, its reset-noise stream and the episode clock, and
//! the [`Environment`] methods that only forward to them ([`MujocoTask`]).

use crate::physics::{NoiseStream, Physics};
use crate::{EnvError, EnvSpec, Environment, InitState, Step};

/// Physics plus episode bookkeeping; each task adds its observation and reward on top.
#[derive(Debug)]
pub(crate) struct Episode {
    pub(crate) physics: Physics,
    pub(crate) spec: EnvSpec,
    noise: NoiseStream,
    elapsed_steps: u32,
}

impl Episode {
    pub(crate) fn new(physics: Physics, spec: EnvSpec, seed: u64) -> Self {
        Self { physics, spec, noise: NoiseStream::new(seed), elapsed_steps: 0 }
    }

    /// A seeded (or continued) noisy reset: `draw` turns the noise stream into a start state.
    pub(crate) fn noisy_restart(
        &mut self,
        seed: Option<u64>,
        draw: impl FnOnce(&mut NoiseStream, &Physics) -> InitState,
    ) {
        self.noise.reseed(seed);
        let state = draw(&mut self.noise, &self.physics);
        self.restart(&state).unwrap_or_else(|_| unreachable!("reset noise has the model's dimensions"));
    }

    /// Restarts the episode from an exact state.
    pub(crate) fn restart(&mut self, state: &InitState) -> Result<(), EnvError> {
        self.physics.reset_to(state)?;
        self.elapsed_steps = 0;
        Ok(())
    }

    /// Counts one step; true when it reaches the time limit (the episode is truncated).
    pub(crate) fn tick(&mut self) -> bool {
        self.elapsed_steps += 1;
        self.elapsed_steps >= self.spec.max_episode_steps
    }
}

/// A MuJoCo task on an [`Episode`]: what it has of its own (its start-state noise, observation and
/// step). Each is an [`Environment`] through the one implementation below, which forwards the spec,
/// the physics and both resets to the episode.
pub(crate) trait MujocoTask: Send {
    /// The task's episode.
    fn episode(&self) -> &Episode;

    /// The task's episode, to restart it.
    fn episode_mut(&mut self) -> &mut Episode;

    /// The start state a noisy reset draws from `noise`.
    fn start_state(noise: &mut NoiseStream, physics: &Physics) -> InitState;

    /// The observation of the current state.
    fn observation(&self) -> Vec<f64>;

    /// [`Environment::step`].
    fn advance(&mut self, action: &[f64]) -> Result<Step, EnvError>;
}

impl<T: MujocoTask> Environment for T {
    fn spec(&self) -> &EnvSpec {
        &self.episode().spec
    }

    fn physics(&self) -> Option<&Physics> {
        Some(&self.episode().physics)
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.episode_mut().noisy_restart(seed, T::start_state);
        self.observation()
    }

    fn reset_to(&mut self, state: &InitState) -> Result<Vec<f64>, EnvError> {
        self.episode_mut().restart(state)?;
        Ok(self.observation())
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        self.advance(action)
    }
}
