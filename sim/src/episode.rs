//! What every MuJoCo task shares: its physics, its reset-noise stream and the episode clock.

use crate::physics::{NoiseStream, Physics};
use crate::{EnvError, EnvSpec, InitState};

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
